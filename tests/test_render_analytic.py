"""Whole-renderer tests against closed forms, with Monte-Carlo confidence intervals.

Each render's pixels are independent estimates, so the standard error of an average over pixels
is their standard deviation / sqrt(count). Tolerances are 4 standard errors plus a small
deterministic allowance where a closed form is itself approximate (stated per test).
"""

import math

import numpy as np
import pytest

from drt.render import render
from drt.scene import scene_from_dict
from scene_builders import add_material, add_mesh, base_header, look_at, quad, translation, uv_sphere

DIFFUSE_WHITE = [{"type": "DIFFUSE", "color": [1.0, 1.0, 1.0]}]


def ortho_down(scale, height=3.0):
    """Orthographic camera at (0, 0, height) looking down −Z (camera +Y = world +Y)."""
    return {"type": "PERSP" if scale is None else "ORTHO", "matrix_world": translation(0, 0, height),
            "ortho_scale": scale, "clip_start": 0.01, "clip_end": 100.0}


def assert_mean_close(values, expected, rel_allow=0.0, k=4.0):
    values = np.asarray(values, dtype=np.float64).ravel()
    mean = values.mean()
    se = values.std(ddof=1) / math.sqrt(len(values))
    tol = k * se + rel_allow * abs(expected)
    assert abs(mean - expected) <= tol, f"mean {mean:.6f} vs expected {expected:.6f} (±{tol:.2e}, se {se:.2e})"


# ---------------------------------------------------------------------------------- furnaces


def test_open_white_furnace_diffuse_sphere():
    """A convex diffuse sphere of albedo a under a uniform world L reflects exactly a·L."""
    h = base_header(24, 24, 32, world=(1.0, 1.0, 1.0),
                    camera={"type": "PERSP", "matrix_world": look_at((0, -6, 0), (0, 0, 0)), "lens": 120.0})
    a = {}
    m = add_material(h, "grey", [{"type": "DIFFUSE", "color": [0.5, 0.5, 0.5]}])
    add_mesh(h, a, "sphere", *uv_sphere(1.0)[:2], material=m, normals=uv_sphere(1.0)[2])
    img = render(scene_from_dict(h, a), threads=2).combined
    centre = img[8:16, 8:16, :3]  # pixels well inside the sphere's silhouette
    assert_mean_close(centre[..., 0], 0.5)
    assert np.all(np.abs(centre - 0.5) < 0.1)


def test_open_white_furnace_glass_sphere():
    """A clear glass sphere in a white furnace returns the world radiance (Cycles: 1.000)."""
    h = base_header(16, 16, 64, world=(1.0, 1.0, 1.0),
                    camera={"type": "PERSP", "matrix_world": look_at((0, -6, 0), (0, 0, 0)), "lens": 150.0})
    a = {}
    m = add_material(h, "glass", [{"type": "GLASS", "color": [1, 1, 1], "roughness": 0.0, "ior": 1.5}])
    pos, tri, nrm = uv_sphere(1.0)
    add_mesh(h, a, "sphere", pos, tri, material=m, normals=nrm)
    img = render(scene_from_dict(h, a), threads=2).combined
    # energy lost only to the transmission bounce limit (12): a small, bounded shortfall
    assert_mean_close(img[4:12, 4:12, 0], 1.0, rel_allow=0.01)


@pytest.mark.parametrize("bounces, expected", [(0, 1.5), (1, 1.75), (2, 1.875), (3, 1.9375)])
def test_closed_furnace_counts_bounces_like_cycles(bounces, expected):
    """Inside a closed emissive sphere (Le = 1, albedo 0.5), max_bounces N gives N + 1
    reflections: 1 + 0.5 + ... + 0.5^(N+1) (Cycles's numbers, blender-conventions.md)."""
    h = base_header(8, 8, 64, max_bounces=bounces, diffuse_bounces=bounces,
                    camera={"type": "PERSP", "matrix_world": np.eye(4).tolist(), "lens": 50.0})
    a = {}
    m = add_material(h, "wall", [{"type": "DIFFUSE", "color": [0.5, 0.5, 0.5]}], emission=(1, 1, 1))
    pos, tri, nrm = uv_sphere(3.0, rings=24, segments=48, inward=True)
    add_mesh(h, a, "inside", pos, tri, material=m, normals=nrm)
    img = render(scene_from_dict(h, a), threads=2).combined
    assert_mean_close(img[..., 0], expected)


# ---------------------------------------------------------------------------------- direct light


def lit_plane(light, spp=64, size=8):
    """A white Lambert plane at z = 0 seen from straight above through a tiny orthographic window
    (every pixel sees the plane near the origin): pixel radiance = E/π."""
    h = base_header(size, size, spp, camera=ortho_down(0.004))
    a = {}
    m = add_material(h, "white", DIFFUSE_WHITE)
    add_mesh(h, a, "plane", *quad((0, 0, 0), (20, 0, 0), (0, 20, 0)), material=m)
    h["lights"].append(light)
    return scene_from_dict(h, a)


def rectangle_irradiance(L, corners, p=np.zeros(3), n=np.array([0, 0, 1.0])):
    """Lambert's polygon formula: E = L/2 Σ Θ_i (n · (r_i × r_{i+1}) / |…|)."""
    r = [c - p for c in corners]
    r = [v / np.linalg.norm(v) for v in r]
    e = 0.0
    for i in range(len(r)):
        a, b = r[i], r[(i + 1) % len(r)]
        g = np.cross(a, b)
        e += math.acos(np.clip(np.dot(a, b), -1, 1)) * np.dot(n, g / np.linalg.norm(g))
    return abs(L * e / 2)

@pytest.mark.parametrize("diffuse_bounces", [0, 3])
def test_inside_a_lit_sphere_every_bounce_adds_albedo_times_the_last(diffuse_bounces):
    """A point light of power P at the centre of a closed diffuse sphere (radius R, albedo a):
    every wall point sees the whole interior (form factor 1), so each bounce's irradiance is a
    times the last, E_k = a^k P/(4πR²), and the walls' radiance with b diffuse bounces is
    a/π · E_0 · (1 + a + … + a^b). The same closed form holds in Cycles (bpy 5.0.1, 4096 spp:
    ratios 1.0003, 1.0002, 1.0002, 1.0000 for b = 0, 1, 2, 4). Tolerance: 4 standard errors
    plus 0.2% for the tessellation."""
    a_alb, radius, power = 0.7, 1.0, 100.0
    h = base_header(8, 8, 256, camera={"type": "PERSP", "matrix_world": look_at((0, 0, 0), (1, 0, 0)),
                                       "lens": 200.0}, max_bounces=64, diffuse_bounces=diffuse_bounces)
    arrays = {}
    pos, tri, _ = uv_sphere(radius, rings=96, segments=192, inward=True)
    add_mesh(h, arrays, "shell", pos, tri, material=add_material(h, "wall", [{"type": "DIFFUSE", "color": [a_alb] * 3}]))
    h["lights"].append({"type": "POINT", "matrix_world": translation(0, 0, 0), "color": [1, 1, 1],
                        "power": power, "radius": 0.0, "soft_falloff": False})
    film = render(scene_from_dict(h, arrays), threads=2)
    e0 = power / (4 * math.pi * radius ** 2)
    expected = a_alb / math.pi * e0 * sum(a_alb ** k for k in range(diffuse_bounces + 1))
    value = float(film.combined[..., 0].mean())
    se = math.sqrt(float(film.variance.mean()) / 256 / 64)
    assert abs(value - expected) <= 4 * se + 2e-3 * expected, (value, expected, se)



@pytest.mark.parametrize("size_x, size_y", [(1.0, 1.0), (2.0, 0.5)])
def test_rectangle_light_matches_lambert_polygon_formula(size_x, size_y):
    power, d = 100.0, 2.0
    light = {"type": "AREA", "matrix_world": translation(0, 0, d), "color": [1, 1, 1], "power": power,
             "shape": "RECTANGLE", "size": size_x, "size_y": size_y}
    L = power / (math.pi * size_x * size_y)
    corners = [np.array([sx * size_x / 2, sy * size_y / 2, d]) for sx, sy in [(-1, -1), (1, -1), (1, 1), (-1, 1)]]
    expected = rectangle_irradiance(L, corners) / math.pi
    img = render(lit_plane(light), threads=2).combined
    assert_mean_close(img[..., 0], expected, rel_allow=0.002)  # the window spans ±2 mm of the plane
    if (size_x, size_y) == (1.0, 1.0):
        assert abs(expected - 2.33892) / 2.33892 < 0.001  # Cycles's measurement


@pytest.mark.parametrize("d", [1.0, 2.0, 4.0])
def test_point_light_inverse_square(d):
    power = 100.0
    light = {"type": "POINT", "matrix_world": translation(0, 0, d), "color": [1, 1, 1], "power": power, "radius": 0.0}
    img = render(lit_plane(light, spp=4), threads=2).combined
    expected = power / (4 * math.pi**2 * d * d)  # I/d² · 1/π with I = P/(4π)
    np.testing.assert_allclose(img[..., 0].mean(), expected, rtol=1e-4)


# ---------------------------------------------------------------------------------- pixel filter


def blackman_harris_step_response(offset, width=1.5, n=20001):
    """Fraction of the (separable) Blackman-Harris filter of a pixel that lies beyond an edge
    ``offset`` pixels from the pixel centre, computed by quadrature (support ±width)."""
    x = np.linspace(-width, width, n)
    v = 2 * np.pi * (x / (2 * width) + 0.5)
    f = 0.35875 - 0.48829 * np.cos(v) + 0.14128 * np.cos(2 * v) - 0.01168 * np.cos(3 * v)
    cdf = np.cumsum(f)
    cdf /= cdf[-1]
    return 1.0 - np.interp(offset, x, cdf, left=0.0, right=1.0)


def edge_scene(width=16, spp=256, motion=None, shutter=None):
    """An emissive half-plane x > 0 (radiance 1) seen by an orthographic camera, one pixel per
    scene unit, edge on a pixel boundary."""
    h = base_header(width, 4, spp, camera=ortho_down(float(width)), shutter=shutter)
    a = {}
    m = add_material(h, "emitter", [], emission=(1, 1, 1))
    add_mesh(h, a, "half", *quad((50, 0, 0), (50, 0, 0), (0, 50, 0)), material=m, motion=motion)
    return h, a


def test_antialiased_edge_gives_exact_filter_coverage():
    h, a = edge_scene()
    img = render(scene_from_dict(h, a), threads=2).combined[..., 0]
    centres = np.arange(16) + 0.5 - 8.0  # pixel centres relative to the edge at x = 0
    expected = blackman_harris_step_response(-centres)
    measured = img.mean(axis=0)
    se = img.std(axis=0, ddof=1).clip(1e-3) / 2 / math.sqrt(256)
    assert np.all(np.abs(measured - expected) < 4 * se + 2e-3), (measured, expected)
    # the conventions' measured number: 0.1182 in the pixel centred 0.5 px outside the edge
    assert abs(expected[7] - 0.1186) < 5e-4 and abs(measured[7] - 0.1182) < 0.01


@pytest.mark.parametrize("companions", [0, 2])
def test_rigidly_moving_edge_gives_a_linear_ramp(companions):
    """The edge moves +4 px over the shutter: each pixel's value is the time average of the
    filtered step, i.e. a linear ramp over the motion convolved with the filter. With moving
    companions out of view the scene's objects are one Embree scene of instances (drt.trace):
    the same ramp."""
    from drt import embree_direct
    from drt.render import prepare

    motion = {"matrix_open": translation(0, 0, 0), "matrix_close": translation(4, 0, 0)}
    h, a = edge_scene(spp=256, motion=motion, shutter=[-0.25, 0.25])
    h["objects"][0]["matrix_world"] = translation(2, 0, 0)
    for k in range(companions):
        turn = np.array([[0.0, -1.0, 0.0, 500.0], [1.0, 0.0, 0.0, 30.0 * k], [0.0, 0.0, 1.0, 0.0], [0, 0, 0, 1]])
        add_mesh(h, a, f"companion{k}", *quad((0, 0, 0), (1, 0, 0), (0, 1, 0)), material=0,
                 motion={"matrix_open": translation(400, 30.0 * k, 0), "matrix_close": turn.tolist()})
    scene = scene_from_dict(h, a)
    ctx = prepare(scene, threads=2)
    assert (ctx.tracer.instanced is not None) == (companions > 0 and bool(embree_direct.intersect1_address()))
    img = render(scene, threads=2, context=ctx).combined[..., 0]
    centres = np.arange(16) + 0.5 - 8.0
    taus = (np.arange(4000) + 0.5) / 4000
    expected = np.mean([blackman_harris_step_response(4 * t - centres) for t in taus], axis=0)
    measured = img.mean(axis=0)
    assert np.all(np.abs(measured - expected) < 0.01), (measured.round(3), expected.round(3))
    # where the filter's reach stays inside the sweep (centres 1.5..2.5 px) the profile is
    # exactly linear with slope 1/4 per pixel
    assert abs((measured[10] - measured[9]) - 0.25) < 0.02


# ---------------------------------------------------------------------------------- depth of field


def test_defocused_point_gives_the_circle_of_confusion():
    """A small emitter out of focus images as a uniform disk of radius ρ = f·R·|1/z_f − 1/z|
    (on the sensor; Cycles's thin-lens variant), measured via the image's second moment:
    E[r²] = ρ²/2 + 2·(filter variance) + 2·(emitter-square variance, side²/12) per axis."""
    W = 64
    lens, fstop, zf, z, half = 100.0, 1.0, 1.0, 10.0, 0.05
    h = base_header(W, W, 256, camera={
        "type": "PERSP", "matrix_world": np.eye(4).tolist(), "lens": lens, "sensor_width": 36.0,
        "clip_start": 0.01, "clip_end": 100.0,
        "dof": {"use": True, "focus_distance": zf, "fstop": fstop, "blades": 0}})
    a = {}
    m = add_material(h, "dot", [], emission=(1, 1, 1))
    add_mesh(h, a, "dot", *quad((0, 0, -z), (half, 0, 0), (0, half, 0)), material=m)
    img = render(scene_from_dict(h, a), threads=2).combined[..., 0].astype(np.float64)
    R = lens * 1e-3 / (2 * fstop)
    px_per_mm = W / 36.0
    rho_px = lens * R * abs(1 / zf - 1 / z) * px_per_mm  # f [mm] · R [m] · 1/m = mm on the sensor
    side_px = 2 * half * lens / z * px_per_mm  # the emitter's in-focus image size
    yy, xx = np.mgrid[0:W, 0:W] + 0.5
    wsum = img.sum()
    cx, cy = (img * xx).sum() / wsum, (img * yy).sum() / wsum
    m2 = (img * ((xx - cx) ** 2 + (yy - cy) ** 2)).sum() / wsum
    x = np.linspace(-1.5, 1.5, 4001)
    v = 2 * np.pi * (x / 3.0 + 0.5)
    f = 0.35875 - 0.48829 * np.cos(v) + 0.14128 * np.cos(2 * v) - 0.01168 * np.cos(3 * v)
    var_f = (f * x * x).sum() / f.sum()
    r_est = math.sqrt(2 * (m2 - 2 * var_f - 2 * side_px**2 / 12))
    assert abs(r_est - rho_px) / rho_px < 0.03, (r_est, rho_px)
    # and the disk is uniform inside: the centre and half-radius ring agree within noise
    r = np.hypot(xx - cx, yy - cy)
    inner, ring = img[r < 0.3 * rho_px].mean(), img[(r > 0.5 * rho_px) & (r < 0.7 * rho_px)].mean()
    assert abs(inner - ring) / ring < 0.1


# ---------------------------------------------------------------------------------- estimator


def test_same_seed_is_bit_identical_across_thread_counts():
    s = lit_plane({"type": "POINT", "matrix_world": translation(0.3, 0, 1), "power": 10.0, "radius": 0.5,
                   "soft_falloff": False}, spp=8)
    one = render(s, threads=1).combined
    two = render(s, threads=2).combined
    again = render(s, threads=2).combined
    assert np.array_equal(one, two) and np.array_equal(two, again)
    other = render(s, threads=2, seed=7).combined
    assert not np.array_equal(two, other)
