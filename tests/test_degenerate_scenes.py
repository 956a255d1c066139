"""Degenerate but legal scenes render (issue 5, bullet 2): finite pixels, sensible values, and
no NaN/Inf sample reaching the film. A sample that does produce NaN/Inf is counted, dropped and
reported (film.nan_samples, stats.nan_samples, the CLI's summary line).

Every render here is small (≤ 24×24, few spp). Set DRT_TEST_PNG=/some/dir to write previews.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys

import numpy as np
import pytest

from drt.render import prepare, render
from drt.scene import scene_from_dict
from drt.scene_file import save_scene
from scene_builders import add_material, add_mesh, base_header, box_mesh, look_at, quad, translation, uv_sphere

WHITE = [{"type": "DIFFUSE", "color": [0.8, 0.8, 0.8]}]
PNG_DIR = os.environ.get("DRT_TEST_PNG")


def render_ok(h, a, name="", spp=None, **kw):
    """Render, asserting finite passes and that no sample had to be dropped."""
    film = render(scene_from_dict(h, a), spp=spp, threads=2, parallel="threads", **kw)
    img = film.combined
    assert np.all(np.isfinite(img)), "NaN/Inf pixel"
    assert np.all(img[..., :3] >= 0)
    assert np.all(np.isfinite(film.variance)) and np.all(np.isfinite(film.normal)) and np.all(np.isfinite(film.albedo))
    assert film.nan_samples == 0 and film.stats.nan_samples == 0, f"{film.nan_samples} NaN/Inf samples dropped"
    assert np.all(film.sample_count > 0)
    if PNG_DIR and name:
        from drt.preview import write_png

        write_png(os.path.join(PNG_DIR, f"degenerate_{name}.png"), img)
    return film


def lit_floor(width=16, height=16, spp=8, **render_kw):
    """A white floor seen from above at 45°, lit by an area light: the reference setup."""
    h = base_header(width, height, spp, camera={"type": "PERSP", "matrix_world": look_at((0, -3, 3), (0, 0, 0)), "lens": 50.0},
                    **render_kw)
    a = {}
    m = add_material(h, "white", WHITE)
    add_mesh(h, a, "floor", *quad((0, 0, 0), (3, 0, 0), (0, 3, 0)), material=m)
    h["lights"].append({"type": "AREA", "matrix_world": translation(0, 0, 2), "power": 100.0, "size": 1.0, "shape": "SQUARE"})
    return h, a


# ------------------------------------------------------------------------------ empty / unlit


def test_empty_scene_shows_the_world():
    h = base_header(8, 8, 4, world=(0.25, 0.5, 0.75))
    img = render_ok(h, {}, "empty").combined
    assert np.allclose(img[..., :3], [0.25, 0.5, 0.75], atol=1e-6) and np.allclose(img[..., 3], 1.0)


def test_empty_scene_with_black_world_is_black_with_a_warning():
    h = base_header(8, 8, 2)
    assert any("no lights" in w for w in prepare(scene_from_dict(h, {})).warnings)
    assert np.all(render_ok(h, {}).combined[..., :3] == 0)


def test_no_lights_renders_black_and_warns():
    h, a = lit_floor()
    h["lights"] = []
    scene = scene_from_dict(h, a)
    assert any("black" in w for w in prepare(scene).warnings)
    film = render_ok(h, a, "no_lights")
    assert np.all(film.combined[..., :3] == 0)
    assert np.all(film.albedo[8, 8] > 0.7)  # the floor is there, just unlit


def test_a_moving_emitter_is_no_reason_to_warn_of_a_black_image():
    """Moving emitters are no lights (NEE samples static triangles), but the camera sees them:
    a scene lit only by one is not black and gets no such warning."""
    h = base_header(8, 8, 4, shutter=[0.0, 1.0])
    a = {}
    glow = add_material(h, "glow", [], emission=(1, 1, 1))
    motion = {"matrix_open": translation(0, 0, 0), "matrix_close": translation(0.2, 0, 0)}
    add_mesh(h, a, "card", *quad((0, 0, 0), (1, 0, 0), (0, 0, 1)), material=glow, motion=motion)
    assert not any("black" in w for w in prepare(scene_from_dict(h, a)).warnings)
    assert render_ok(h, a, "moving_emitter").combined[..., :3].mean() > 0.1


def test_no_lights_warning_on_the_cli(tmp_path):
    h, a = lit_floor(4, 4, 1)
    h["lights"] = []
    save_scene(tmp_path / "s.npz", h, a)
    r = subprocess.run([sys.executable, "-m", "drt", "render", str(tmp_path / "s.npz"), "-o", str(tmp_path / "o.exr")],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "o.exr").exists()


# ------------------------------------------------------------------------------ degenerate geometry


def test_degenerate_triangles_are_harmless():
    """Zero-area (collinear, repeated-index, all-coincident) triangles beside a real floor."""
    h, a = lit_floor()
    ref = render_ok(h, a).combined
    m = 0
    pos = np.array([[0, 0, 0.5], [1, 0, 0.5], [2, 0, 0.5], [0.3, 0.3, 0.3], [0.3, 0.3, 0.3], [0.3, 0.3, 0.3]], float)
    tri = np.array([[0, 1, 2], [0, 0, 1], [3, 4, 5], [1, 1, 1]])
    nrm = np.zeros((len(tri), 3, 3), np.float32)  # zero shading normals as well
    add_mesh(h, a, "degenerate", pos, tri, material=m, normals=nrm)
    img = render_ok(h, a, "degenerate_tris").combined
    assert np.allclose(img, ref, rtol=0.02, atol=1e-4)  # same samples: nothing visible changed


def test_zero_scale_object_is_invisible():
    h, a = lit_floor()
    ref = render_ok(h, a).combined
    pos, tri, nrm = uv_sphere(0.5, rings=6, segments=8)
    m = np.diag([0.0, 0.0, 0.0, 1.0])  # "scale to zero", the usual way to hide an object
    m[:3, 3] = (0, 0, 0.5)
    add_mesh(h, a, "flat", pos, tri, material=0, normals=nrm, matrix=m.tolist())
    img = render_ok(h, a, "zero_scale").combined
    assert np.allclose(img, ref, rtol=0.05, atol=1e-3)


def test_meshes_without_uvs_or_normals_next_to_ones_with():
    h, a = lit_floor()
    pos, tri, nrm = uv_sphere(0.4, rings=8, segments=12)
    k = add_mesh(h, a, "smooth", pos, tri, material=0, normals=nrm, matrix=translation(-0.6, 0, 0.4))
    a[f"mesh{k}.uvs"] = np.zeros((len(tri), 3, 2), np.float32)
    add_mesh(h, a, "flat", pos, tri, material=0, matrix=translation(0.6, 0, 0.4))  # no normals, no uvs
    img = render_ok(h, a, "uv_normals").combined
    assert img[..., :3].max() > 0


def test_non_manifold_and_inverted_meshes():
    """Three quads sharing one edge (non-manifold), and a floor whose winding AND normals point
    down: a two-sided diffuse floor looks the same either way."""
    h, a = lit_floor(spp=16)
    ref = render_ok(h, a).combined
    h2, a2 = lit_floor(spp=16)
    pos, tri = quad((0, 0, 0), (3, 0, 0), (0, 3, 0))
    a2["mesh0.triangles"] = tri[:, ::-1].astype(np.int32).copy()
    a2["mesh0.normals"] = np.full((2, 3, 3), [0, 0, -1], np.float32)
    h2["meshes"][0]["name"] = "inverted"
    inv = render_ok(h2, a2, "inverted").combined
    assert abs(inv[..., 0].mean() - ref[..., 0].mean()) < 0.05 * ref[..., 0].mean()
    fin = np.array([[0, 0, 0.3], [0, 0, 0.9], [0.5, 0, 0.3], [-0.5, 0, 0.3], [0, 0.5, 0.3]], float)
    add_mesh(h2, a2, "fins", fin, [[0, 1, 2], [0, 1, 3], [1, 0, 4]], material=0)
    render_ok(h2, a2, "non_manifold")


def test_coincident_faces_give_a_value_between_the_two_materials():
    h, a = lit_floor(spp=16)
    dark = add_material(h, "dark", [{"type": "DIFFUSE", "color": [0.1, 0.1, 0.1]}])
    add_mesh(h, a, "floor2", *quad((0, 0, 0), (3, 0, 0), (0, 3, 0)), material=dark)
    img = render_ok(h, a, "coincident").combined
    h_w, a_w = lit_floor(spp=16)
    white = render_ok(h_w, a_w).combined[..., 0].mean()
    v = img[..., 0].mean()
    assert white * 0.1 / 0.8 * 0.9 < v < white * 1.01


# ------------------------------------------------------------------------------ lights


@pytest.mark.parametrize(
    "light",
    [
        {"type": "AREA", "power": 100.0, "size": 0.0, "size_y": 0.0, "shape": "RECTANGLE"},
        {"type": "AREA", "power": 100.0, "size": 1.0, "size_y": 0.0, "shape": "ELLIPSE"},
        {"type": "AREA", "power": 100.0, "size": 1.0, "spread": 0.0, "shape": "SQUARE"},
        {"type": "POINT", "power": 100.0, "radius": 0.0},
        {"type": "SPOT", "power": 100.0, "radius": 0.0, "spot_size": 0.0},
        {"type": "SPOT", "power": 100.0, "radius": 0.2, "spot_size": math.pi, "spot_blend": 1.0},
        {"type": "SUN", "strength": 3.0, "angle": 0.0},
        {"type": "SUN", "strength": 3.0, "angle": math.pi},
        {"type": "AREA", "power": 0.0, "size": 1.0},
        {"type": "POINT", "power": 0.0, "radius": 0.1},
        {"type": "SUN", "strength": 0.0},
        {"type": "POINT", "power": 100.0, "radius": 0.1, "color": [0, 0, 0]},
    ],
    ids=lambda l: "-".join(f"{k}={v}" for k, v in l.items() if k != "type") + "-" + l["type"],
)
def test_zero_size_and_zero_power_lights(light):
    h, a = lit_floor(8, 8, 4)
    h["lights"] = [dict(light, matrix_world=look_at((0.2, 0.1, 2), (0, 0, 0)), visible_camera=True)]
    img = render_ok(h, a).combined
    zero = light.get("power", light.get("strength")) == 0 or light.get("color") == [0, 0, 0]
    if zero:
        assert np.all(img[..., :3] == 0)


def test_light_shut_inside_a_closed_box_leaks_nothing():
    """A point light and an area light inside a closed box (outward faces, seen from outside,
    black world): the outside of the box must stay exactly black."""
    h = base_header(16, 16, 16, camera={"type": "PERSP", "matrix_world": look_at((2, -3, 2), (0, 0, 0.5)), "lens": 35.0})
    a = {}
    m = add_material(h, "white", WHITE)
    add_mesh(h, a, "box", *box_mesh(0.5, 1.0), material=m)
    h["lights"] += [
        {"type": "POINT", "matrix_world": translation(0, 0, 0.5), "power": 1000.0, "radius": 0.05},
        {"type": "AREA", "matrix_world": translation(0, 0, 0.9), "power": 1000.0, "size": 0.3},
        {"type": "SPOT", "matrix_world": translation(0.2, 0.2, 0.2), "power": 1000.0, "radius": 0.0, "spot_size": 2.0},
    ]
    film = render_ok(h, a, "light_in_box")
    assert np.all(film.combined[..., :3] == 0)
    assert film.albedo[..., 0].max() > 0.7  # the box is in view


def test_camera_inside_geometry():
    """Camera inside a closed box, lit only from outside: black inside; and inside a lit sphere."""
    h = base_header(12, 12, 8, world=(1, 1, 1), camera={"type": "PERSP", "matrix_world": translation(0, 0, 0.5), "lens": 20.0})
    a = {}
    m = add_material(h, "white", WHITE)
    add_mesh(h, a, "box", *box_mesh(0.5, 1.0), material=m)
    h["lights"].append({"type": "SUN", "matrix_world": np.eye(4).tolist(), "strength": 5.0})
    assert np.all(render_ok(h, a, "camera_in_box").combined[..., :3] == 0)
    h["lights"].append({"type": "POINT", "matrix_world": translation(0.2, 0, 0.3), "power": 20.0, "radius": 0.05})
    assert render_ok(h, a, "camera_in_box_lit").combined[..., 0].mean() > 0
    # camera exactly on a surface (clip_start 0): still finite
    h["camera"] = {"type": "PERSP", "matrix_world": look_at((0, -0.5, 0.5), (0, 0, 0.5)), "lens": 20.0, "clip_start": 0.0}
    render_ok(h, a, "camera_on_wall")


# ------------------------------------------------------------------------------ camera & film


@pytest.mark.parametrize("fstop", [1e-4, 0.01, 1e4, 1e9])
def test_fstop_extremes(fstop):
    h, a = lit_floor(12, 12, 8)
    h["camera"]["dof"] = {"use": True, "fstop": fstop, "focus_distance": 4.2}
    film = render_ok(h, a, f"fstop_{fstop:g}")
    if fstop >= 1e4:  # a pinhole: the same image as without DOF, within noise
        h2, a2 = lit_floor(12, 12, 8)
        ref = render_ok(h2, a2).combined
        assert abs(film.combined[..., 0].mean() - ref[..., 0].mean()) < 0.05 * ref[..., 0].mean()


def test_zero_focus_distance_and_orthographic_dof():
    h, a = lit_floor(8, 8, 4)
    h["camera"]["dof"] = {"use": True, "fstop": 0.5, "focus_distance": 0.0, "blades": 3, "ratio": 0.01}
    render_ok(h, a)
    h["camera"].update(type="ORTHO", ortho_scale=4.0)
    render_ok(h, a)


def test_zero_shutter_means_no_blur():
    """A moving object with shutter [0, 0] (and a reversed-free zero interval) renders as the
    object at matrix_world; same for the camera's motion."""
    h, a = lit_floor(12, 12, 8)
    pos, tri, nrm = uv_sphere(0.4, rings=8, segments=12)
    add_mesh(h, a, "ball", pos, tri, material=0, normals=nrm, matrix=translation(0, 0, 0.4))
    ref = render_ok(h, a).combined
    h["render"]["shutter"] = [0.0, 0.0]
    h["objects"][1]["motion"] = {"matrix_open": translation(-2, 0, 0.4), "matrix_close": translation(2, 0, 0.4)}
    h["camera"]["motion"] = {"matrix_open": look_at((0, -3, 3), (1, 0, 0)), "matrix_close": look_at((0, -3, 3), (-1, 0, 0))}
    img = render_ok(h, a, "zero_shutter").combined
    assert np.allclose(img, ref, rtol=1e-4, atol=1e-6)


@pytest.mark.parametrize("size", [(1, 1), (4000, 1), (1, 300)])
def test_one_pixel_and_very_wide_images(size):
    w, hh = size
    h, a = lit_floor(w, hh, 2)
    film = render_ok(h, a, f"size_{w}x{hh}")
    assert film.combined.shape == (hh, w, 4)
    assert film.combined[..., 0].max() > 0


# ------------------------------------------------------------------------------ NaN accounting


def test_nan_samples_are_counted_dropped_and_reported(tmp_path):
    """Poison the world's radiance with NaN in the compiled light data: camera rays that miss
    the black emitter filling the left half of the view return NaN, those samples never reach
    the film, the film and the stats count them, and the rest of the image is the emitter."""
    h = base_header(8, 8, 4, camera={"type": "ORTHO", "matrix_world": look_at((0, 0, 5), (0, 0, 0), up=(0, 1, 0)),
                                     "ortho_scale": 2.0})
    a = {}
    m = add_material(h, "black_emitter", [], emission=(0.5, 0.5, 0.5))
    add_mesh(h, a, "half", *quad((-0.5, 0, 0), (0.5, 0, 0), (0, 1.0, 0)), material=m)
    scene = scene_from_dict(h, a)
    ctx = prepare(scene)
    lights = ctx.integrator.lights
    lights.data = lights.data._replace(world_color=np.full(3, np.nan), has_world=True)
    film = render(scene, context=ctx, threads=1, parallel="threads")
    n = 8 * 8 * 4
    assert film.nan_samples == film.stats.nan_samples and n // 3 < film.nan_samples <= n // 2 + 8
    assert np.all(np.isfinite(film.combined))
    seen = film.sample_count > 0
    assert np.allclose(film.combined[seen][:, :3], 0.5)
    assert film.stats.camera_paths == n  # tried = kept + dropped
    assert int(film.sample_count.sum()) + film.nan_samples == n
