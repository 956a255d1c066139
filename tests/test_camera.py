"""Blender's camera model: projection, sensor fit, shift, ortho, clipping and the aperture."""

import math

import numpy as np
import pytest

from drt.camera import Camera
from drt.scene import scene_from_dict
from scene_builders import base_header, look_at


def make_camera(width=64, height=32, **cam):
    spec = {"type": "PERSP", "matrix_world": np.eye(4).tolist(), "lens": 50.0, "sensor_width": 36.0, "sensor_height": 24.0}
    spec.update(cam)
    scene = scene_from_dict(base_header(width, height, camera=spec))
    return Camera(scene.camera, scene.render, np.zeros(3))


def directions(cam, u, v):
    r = cam.generate(np.asarray(u, float), np.asarray(v, float), np.zeros((len(u), 2)), np.zeros(len(u)))
    return r


@pytest.mark.parametrize("fit, w, h", [("AUTO", 64, 32), ("AUTO", 32, 64), ("HORIZONTAL", 32, 64), ("VERTICAL", 64, 32)])
def test_projection_matches_blender_formula(fit, w, h):
    cam = make_camera(w, h, sensor_fit=fit, shift_x=0.1, shift_y=-0.05, lens=35.0)
    u = np.array([0.0, w / 2, w, 3.7])
    v = np.array([0.0, h / 2, h, 11.2])
    if fit == "AUTO":
        D, S = max(w, h), 36.0
    elif fit == "HORIZONTAL":
        D, S = w, 36.0
    else:
        D, S = h, 24.0
    x = ((u - w / 2) / D + 0.1) * S / 35.0
    y = ((v - h / 2) / D - 0.05) * S / 35.0
    expect = np.stack([x, y, -np.ones_like(x)], 1)
    expect /= np.linalg.norm(expect, axis=1, keepdims=True)
    r = directions(cam, u, v)
    np.testing.assert_allclose(r.d, expect, atol=1e-12)


def test_world_point_projects_to_its_pixel():
    """A world point seen by a rotated camera lands on the pixel the formula predicts (< 0.01 px)."""
    m = look_at((3, -4, 2), (0, 0, 0.5))
    cam = make_camera(96, 54, matrix_world=m, lens=42.0)
    target = np.array([0.3, 0.2, 0.7])
    minv = np.linalg.inv(np.asarray(m))
    pc = minv[:3, :3] @ target + minv[:3, 3]
    u = (pc[0] / -pc[2] * 42.0 / 36.0) * 96 + 48
    v = (pc[1] / -pc[2] * 42.0 / 36.0) * 96 + 27
    r = directions(cam, [u], [v])
    to_target = target - r.eye[0]
    to_target /= np.linalg.norm(to_target)
    assert np.degrees(np.arccos(np.clip(np.dot(to_target, r.d[0]), -1, 1))) < 0.01 * (36.0 / 42.0) / 96 * 57.3


def test_clip_planes():
    cam = make_camera(clip_start=0.5, clip_end=10.0)
    r = directions(cam, [0.0, 32.0], [0.0, 16.0])
    # rays start on the plane z = -clip_start and end on z = -clip_end (planes, not spheres)
    np.testing.assert_allclose(r.o[:, 2], -0.5, atol=1e-12)
    np.testing.assert_allclose((r.o + r.d * r.tmax[:, None])[:, 2], -10.0, atol=1e-9)


def test_orthographic_extent():
    cam = make_camera(64, 32, type="ORTHO", ortho_scale=4.0)
    r = directions(cam, [0.0, 64.0], [16.0, 16.0])
    np.testing.assert_allclose(r.o[:, 0], [-2.0, 2.0], atol=1e-12)
    np.testing.assert_allclose(r.d, [[0, 0, -1], [0, 0, -1]], atol=1e-12)


def test_aperture_radius_and_focus_plane():
    cam = make_camera(dof={"use": True, "focus_distance": 4.0, "fstop": 2.0})
    assert math.isclose(cam.lens_radius, 50e-3 / 4.0)
    n = 4000
    rng = np.random.default_rng(1)
    r = cam.generate(np.full(n, 40.0), np.full(n, 20.0), rng.random((n, 2)), np.zeros(n))
    # every lens ray passes through the same point of the focus plane z = -4
    t = (-4.0 - r.eye[:, 2]) / r.d[:, 2]
    focus = r.eye + r.d * t[:, None]
    assert np.ptp(focus[:, 0]) < 1e-9 and np.ptp(focus[:, 1]) < 1e-9
    lens = np.linalg.norm(r.eye[:, :2], axis=1)
    assert lens.max() <= cam.lens_radius * (1 + 1e-9)
    assert lens.max() > 0.98 * cam.lens_radius


def test_polygonal_aperture_stays_inside_polygon():
    cam = make_camera(dof={"use": True, "focus_distance": 4.0, "fstop": 2.0, "blades": 5, "rotation": 0.3})
    rng = np.random.default_rng(2)
    pts = cam.lens_offsets(rng.random((20000, 2))) / cam.lens_radius
    # inside a regular pentagon inscribed in the unit circle: radius <= 1, and the apothem bound
    r = np.linalg.norm(pts, axis=1)
    assert r.max() <= 1 + 1e-9
    assert r.max() > 0.97
    assert np.mean(r < math.cos(math.pi / 5)) > 0.5
