"""Numerical stability (issue 5, bullet 3): no shadow acne or light leaks at grazing angles, the
same image 10⁵ m from the origin, shading normals on the wrong side never give black spots or
leaks, thin geometry and nested dielectrics behave.

Lighting uses delta lights (sun with angle 0) where possible, so every pixel is deterministic and
a single acne or leak pixel shows up exactly. Set DRT_TEST_PNG=/dir to write previews.
"""

from __future__ import annotations

import math
import os

import numpy as np
import pytest

from drt.render import render
from drt.scene import scene_from_dict
from scene_builders import add_material, add_mesh, base_header, look_at, quad, translation, uv_sphere

PNG_DIR = os.environ.get("DRT_TEST_PNG")


def run(h, a, name="", **kw):
    film = render(scene_from_dict(h, a), threads=2, parallel="threads", **kw)
    img = film.combined
    assert np.all(np.isfinite(img)) and film.nan_samples == 0
    if PNG_DIR and name:
        from drt.preview import write_png

        write_png(os.path.join(PNG_DIR, f"stability_{name}.png"), img)
    return img


def grid(n=8, half=2.0, z=0.0, offset=(0, 0, 0)):
    """A tessellated square (n×n quads, 2n² triangles) facing +Z: many edges and vertices for
    acne to show on."""
    xs = np.linspace(-half, half, n + 1)
    X, Y = np.meshgrid(xs, xs)
    pos = np.stack([X.ravel(), Y.ravel(), np.full(X.size, z)], 1) + np.asarray(offset, float)
    tris = []
    for j in range(n):
        for i in range(n):
            a, b, c, d = j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1, (j + 1) * (n + 1) + i
            tris += [[a, b, c], [a, c, d]]
    return pos, np.array(tris)


def sun_from(elevation_deg, azimuth_deg=0.0, strength=1.0):
    """A sun (angle 0: a delta light) whose light arrives from the given elevation above the
    XY plane (negative: from below)."""
    el, az = math.radians(elevation_deg), math.radians(azimuth_deg)
    toward = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    return {"type": "SUN", "matrix_world": look_at(toward * 10, (0, 0, 0)), "strength": strength, "angle": 0.0}


def plane_scene(light, size=24, spp=4, normals=None, camera_height=3.0, albedo=1.0):
    h = base_header(size, size, spp, camera={"type": "ORTHO", "matrix_world": translation(0, 0, camera_height),
                                             "ortho_scale": 3.5, "clip_start": 0.01, "clip_end": 100.0})
    a = {}
    m = add_material(h, "white", [{"type": "DIFFUSE", "color": [albedo] * 3}])
    pos, tri = grid()
    add_mesh(h, a, "plane", pos, tri, material=m, normals=normals(pos, tri) if normals else None)
    h["lights"].append(light)
    return h, a


# ------------------------------------------------------------------------------ grazing angles


@pytest.mark.parametrize("elevation", [1.0, 0.1])
def test_grazing_light_gives_the_cosine_value_without_acne(elevation):
    """Sun 89° (and 89.9°) from the normal: every pixel is S·cos θ/π, none darker (acne)."""
    img = run(*plane_scene(sun_from(elevation, 30.0, strength=10.0)), f"grazing_{elevation}")
    expected = 10.0 * math.sin(math.radians(elevation)) / math.pi
    np.testing.assert_allclose(img[..., :3], expected, rtol=1e-4)


@pytest.mark.parametrize("elevation", [-0.1, -1.0, -45.0])
def test_light_from_below_never_leaks_through(elevation):
    img = run(*plane_scene(sun_from(elevation, 30.0, strength=10.0)))
    assert np.all(img[..., :3] == 0)


def test_grazing_point_light_has_no_acne():
    """A point light 1 cm above a 4 m plane, off to the side: radiance I·cos θ/(π d²) per point."""
    light = {"type": "POINT", "matrix_world": translation(-2.5, 0, 0.01), "power": 1000.0, "radius": 0.0}
    h, a = plane_scene(light, size=32)
    img = run(h, a, "grazing_point")
    # each pixel's radiance at its centre (ortho camera, 3.5 m window, 32 px); 4 spp filter jitter
    c = (np.arange(32) + 0.5) / 32 * 3.5 - 1.75
    X, Y = np.meshgrid(c, -c)
    d2 = (X + 2.5) ** 2 + Y**2 + 0.01**2
    expected = 1000.0 / (4 * math.pi) * (0.01 / np.sqrt(d2)) / d2 / math.pi
    ratio = img[..., 0] / expected
    assert ratio.min() > 0.8 and np.median(np.abs(ratio - 1)) < 0.05, (ratio.min(), ratio.max())


# ------------------------------------------------------------------------------ far from the origin


def far_scene(offset, spp=16):
    o = np.asarray(offset, float)
    h = base_header(24, 24, spp, world=(0.05, 0.05, 0.05),
                    camera={"type": "PERSP", "matrix_world": look_at(o + (0, -4, 2.5), o + (0, 0, 0.3)), "lens": 40.0})
    a = {}
    m = add_material(h, "white", [{"type": "DIFFUSE", "color": [0.8, 0.8, 0.8]}])
    g = add_material(h, "glossy", [{"type": "GLOSSY", "color": [0.9, 0.9, 0.9], "roughness": 0.2}])
    pos, tri = grid(half=2.0)
    add_mesh(h, a, "floor", pos + o, tri, material=m)
    sp, st_, sn = uv_sphere(0.5, rings=12, segments=24)
    add_mesh(h, a, "ball", sp, st_, material=g, normals=sn, matrix=translation(*(o + (0, 0, 0.5))))
    # a thin sheet 1 mm above the floor: needs sub-mm precision at 10⁵ m
    qp, qt = quad(o + (1.0, -1.0, 0.001), (0.4, 0, 0), (0, 0.4, 0))
    add_mesh(h, a, "sheet", qp, qt, material=g)
    h["lights"].append({"type": "AREA", "matrix_world": translation(*(o + (0.5, -0.5, 2.0))), "power": 200.0, "size": 0.6})
    h["lights"].append({"type": "POINT", "matrix_world": translation(*(o + (-1, -1, 1))), "power": 50.0, "radius": 0.05})
    return h, a


@pytest.mark.parametrize("offset", [(1e5, 0, 0), (-7e4, 7e4, 3e4)])
def test_translated_far_from_the_origin_renders_the_same(offset):
    ref = run(*far_scene((0, 0, 0)), "far_origin")
    img = run(*far_scene(offset), "far_translated")
    diff = np.abs(img[..., :3] - ref[..., :3])
    # the camera-centred frame makes both renders see (nearly) the same float32 geometry: the
    # images agree far below Monte Carlo noise (4 standard errors of the pixel mean)
    noise = np.sqrt(np.mean((ref[..., :3] - np.mean(ref[..., :3])) ** 2))
    assert abs(img[..., :3].mean() - ref[..., :3].mean()) < 0.01 * ref[..., :3].mean()
    assert np.mean(diff) < 0.02 * ref[..., :3].mean(), (np.mean(diff), noise)


# ------------------------------------------------------------------------------ shading normals


def inverted_normals(pos, tri):
    return np.full((len(tri), 3, 3), [0, 0, -1.0], np.float32)


def mixed_normals(pos, tri):
    """Per-corner normals: random tilts up to 60°, a third of the corners flipped below the
    surface (pointing away from the geometric side), some exactly in the plane."""
    rng = np.random.default_rng(3)
    n = np.empty((len(tri), 3, 3))
    th = np.radians(rng.uniform(0, 60, (len(tri), 3)))
    ph = rng.uniform(0, 2 * np.pi, (len(tri), 3))
    n[..., 0], n[..., 1], n[..., 2] = np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)
    flip = rng.random((len(tri), 3)) < 0.33
    n[flip] *= -1
    n[::7, 0] = [1, 0, 0]
    return n.astype(np.float32)


def test_shading_normals_on_the_back_side_change_nothing():
    """Normals pointing away from the geometric front are flipped back: same image as flat."""
    sun = sun_from(60, 20, strength=5.0)
    ref = run(*plane_scene(sun))
    img = run(*plane_scene(sun, normals=inverted_normals), "normals_inverted")
    np.testing.assert_allclose(img, ref, rtol=1e-5, atol=1e-7)


def test_bent_shading_normals_give_no_black_spots_and_no_leaks():
    lit = run(*plane_scene(sun_from(70, 20, strength=5.0), normals=mixed_normals), "normals_mixed")
    flat = 5.0 * math.sin(math.radians(70)) / math.pi
    assert lit[..., 0].min() > 0.05 * flat, lit[..., 0].min()  # every pixel lit: no black spots
    assert lit[..., 0].max() < 2.0 * flat
    below = run(*plane_scene(sun_from(-40, 20, strength=5.0), normals=mixed_normals))
    assert np.all(below[..., :3] == 0)  # light under the plane never reaches its top


def test_smooth_low_poly_sphere_terminator_has_no_black_holes():
    """A coarse sphere with smooth normals lit from the side: on the lit half (by the shading
    normal) no pixel is black, where flat-shaded triangles self-shadow (terminator problem)."""
    h = base_header(32, 32, 4, camera={"type": "ORTHO", "matrix_world": look_at((0, -5, 0), (0, 0, 0)),
                                       "ortho_scale": 2.2, "clip_end": 100.0})
    a = {}
    m = add_material(h, "white", [{"type": "DIFFUSE", "color": [1, 1, 1]}])
    pos, tri, nrm = uv_sphere(1.0, rings=6, segments=10)
    add_mesh(h, a, "ball", pos, tri, material=m, normals=nrm)
    h["lights"].append({"type": "SUN", "matrix_world": look_at((10, -3, 0), (0, 0, 0)), "strength": 3.0, "angle": 0.0})
    film = render(scene_from_dict(h, a), threads=2, parallel="threads")
    img = film.combined[..., 0]
    n = film.normal
    to_sun = np.array([10, -3, 0]) / np.linalg.norm([10, -3, 0])
    facing = (n @ to_sun > 0.3) & (np.linalg.norm(n, axis=-1) > 0.5)
    assert facing.sum() > 50
    assert np.all(img[facing] > 0), f"{np.sum(img[facing] == 0)} black pixels on the lit side"
    if PNG_DIR:
        from drt.preview import write_png

        write_png(os.path.join(PNG_DIR, "stability_terminator.png"), film.combined)


# ------------------------------------------------------------------------------ thin geometry


@pytest.mark.parametrize("gap, offset", [(1e-4, (0, 0, 0)), (1e-4, (1e5, 1e5, 0))])
def test_thin_sheets_do_not_leak_or_fight(gap, offset):
    """Two sheets ``gap`` apart (white on top, black below). From above: exactly the sunlit white
    top; from below: the lower sheet's underside, in the top sheet's shadow, exactly black."""
    o = np.asarray(offset, float)
    sun = sun_from(50, 10, strength=4.0)
    sun["matrix_world"] = np.array(sun["matrix_world"])
    sun["matrix_world"][:3, 3] += o
    sun["matrix_world"] = sun["matrix_world"].tolist()

    def scene(cam_z):
        cam = look_at(o + (0.01, 0.01, cam_z), o)  # straight down or up
        h = base_header(16, 16, 4, camera={"type": "ORTHO", "matrix_world": cam, "ortho_scale": 2.0,
                                           "clip_start": 0.001, "clip_end": 100.0})
        a = {}
        white = add_material(h, "white", [{"type": "DIFFUSE", "color": [1, 1, 1]}])
        black = add_material(h, "grey", [{"type": "DIFFUSE", "color": [0.5, 0.5, 0.5]}])
        pos, tri = grid(n=4, half=2.0)
        add_mesh(h, a, "top", pos + o, tri, material=white)
        add_mesh(h, a, "bottom", pos + o - (0, 0, gap), tri[:, ::-1], material=black)  # faces down
        h["lights"].append(sun)
        return h, a

    top = run(*scene(3.0), "thin_top")
    np.testing.assert_allclose(top[..., 0], 4.0 * math.sin(math.radians(50)) / math.pi, rtol=1e-4)
    bottom = run(*scene(-3.0), "thin_bottom")
    assert np.all(bottom[..., :3] == 0)


# ------------------------------------------------------------------------------ nested dielectrics


def glass_scene(inner_ior=None, spp=32):
    """A glass sphere over a checkered floor under a uniform sky; optionally a second glass
    sphere inside it (``inner_ior``: the IOR the exporter writes for the inner interface)."""
    h = base_header(20, 20, spp, world=(1.0, 1.0, 1.0),
                    camera={"type": "PERSP", "matrix_world": look_at((0, -4, 2), (0, 0, 0.6)), "lens": 60.0})
    a = {}
    light = add_material(h, "light", [{"type": "DIFFUSE", "color": [0.9, 0.9, 0.9]}])
    dark = add_material(h, "dark", [{"type": "DIFFUSE", "color": [0.05, 0.05, 0.05]}])
    glass = add_material(h, "glass", [{"type": "GLASS", "color": [1, 1, 1], "roughness": 0.0, "ior": 1.5}])
    for j in range(6):
        for i in range(6):
            c = (-1.5 + 0.5 * i + 0.25, -1.5 + 0.5 * j + 0.25, 0)
            add_mesh(h, a, f"tile{i}{j}", *quad(c, (0.25, 0, 0), (0, 0.25, 0)), material=light if (i + j) % 2 else dark)
    pos, tri, nrm = uv_sphere(0.6, rings=24, segments=48)
    add_mesh(h, a, "outer", pos, tri, material=glass, normals=nrm, matrix=translation(0, 0, 0.6))
    if inner_ior is not None:
        inner = add_material(h, "inner", [{"type": "GLASS", "color": [1, 1, 1], "roughness": 0.0, "ior": inner_ior}])
        pos2, tri2, nrm2 = uv_sphere(0.3, rings=16, segments=32)
        add_mesh(h, a, "inner", pos2, tri2, material=inner, normals=nrm2, matrix=translation(0, 0, 0.6))
    return h, a


def nested_difference_z(inner_ior):
    """Per-pixel z-scores of (nested − single sphere) luminance, from each film's variance pass."""
    from drt.film import luminance

    films = [render(scene_from_dict(*glass_scene(ior)), threads=2, parallel="threads") for ior in (None, inner_ior)]
    if PNG_DIR:
        from drt.preview import write_png

        write_png(os.path.join(PNG_DIR, f"stability_glass_nested_{inner_ior}.png"), films[1].combined)
    lum = [luminance(f.combined[..., :3].astype(np.float64)) for f in films]
    var = films[0].variance.astype(np.float64) + films[1].variance.astype(np.float64)
    return (lum[1] - lum[0]) / np.sqrt(np.maximum(var, 1e-12)), lum


def test_glass_in_glass_with_relative_ior_one_is_invisible():
    """Nested media the way Cycles users model them: the inner interface carries the IOR ratio
    (1.5/1.5 = 1), so it neither bends nor reflects: the image equals the single sphere within
    noise (the pass-through only shifts later bounces to other sample dimensions)."""
    z, lum = nested_difference_z(1.0)
    assert abs(lum[1].mean() - lum[0].mean()) < 0.01 * lum[0].mean()
    assert np.mean(np.abs(z) > 4) < 0.01 and abs(z.mean()) < 0.2, (np.mean(np.abs(z) > 4), z.mean())


@pytest.mark.xfail(reason="no nested-dielectric (IOR stack / priority) tracking: an inner sphere of the same "
                          "absolute IOR is treated as an air-glass interface, as in Cycles", strict=True)
def test_glass_in_glass_with_the_same_absolute_ior_is_invisible():
    z, lum = nested_difference_z(1.5)
    assert np.mean(np.abs(z) > 4) < 0.01
