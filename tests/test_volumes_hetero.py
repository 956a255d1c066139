"""Heterogeneous media (issue 14 step 7, drt.volumes.hetero): a density from the material's
program, tracked against a majorant. Analytic checks within 4 standard errors."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from drt.materials.program_format import OP_COMPONENT, OP_GENERATED, OP_MATH
from drt.render import prepare, render
from drt.scene import SceneError, scene_from_dict
from drt.volumes.hetero import pcg_next, seed_of
from scene_builders import add_mesh, base_header, box_mesh, look_at, translation

FOG_ONLY = {"name": "fog", "lobes": [], "surface": False}


def _gradient_program(axis=2, scale=1.0):
    """density = scale · Generated[axis] (a linear gradient through the box's texture space);
    registers: 0 Generated, 1 its component, 2 the scale, 3 the product (the density)."""
    return {"registers": 4, "constants": [[2, scale, scale, scale]],
            "ops": [[OP_GENERATED, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0],
                    [OP_COMPONENT, axis, 1, 0, 0, 0, 0, 0, 0, 0, 0],
                    [OP_MATH, 2, 3, 0, 1, 2, 2, 0, 0, 0, 0]],  # MULTIPLY (Blender's enum order)
            "data": []}


def _box_with_generated(h, a, name, half, height, material, z0):
    """box_mesh(half, height) moved to z0, with per-corner Generated = its bounding-box map."""
    pos, tri = box_mesh(half, height)
    k = add_mesh(h, a, name, pos, tri, material=material, matrix=translation(0, 0, z0))
    lo, hi = pos.min(0), pos.max(0)
    a[f"mesh{k}.generated"] = ((pos[tri] - lo) / (hi - lo)).astype(np.float32)
    return k


def _within_4se(samples, expected):
    mean = samples.mean(0)
    se = samples.std(0, ddof=1) / math.sqrt(len(samples))
    assert np.all(np.abs(mean - expected) <= 4 * se + 1e-12), (mean, expected, se)
    return mean, se


def test_program_math_multiply_is_mode_2():
    from drt.materials.programs import math_op

    assert math_op(2, 3.0, 4.0, 0.0) == 12.0


def test_pcg_is_uniform():
    s = seed_of(1, 2, 3)
    u = np.empty(20000)
    for k in range(len(u)):
        u[k], s = pcg_next(s)
    assert 0.0 <= u.min() and u.max() < 1.0
    counts = np.histogram(u, 20, (0, 1))[0]
    assert np.all(np.abs(counts - 1000) < 5 * math.sqrt(1000))


def test_gradient_density_transmittance_is_the_analytic_integral():
    """An absorbing box 1 m thick whose density rises linearly (Generated z: 0 at the bottom, 1
    at the top) in front of a white world: T = exp(−σa·∫ρ dz) = exp(−σa/2) within 4 SE (ratio
    tracking), where a homogeneous density 1 would give exp(−σa)."""
    sigma = np.array([1.0, 2.0, 4.0])
    h = base_header(16, 16, 8, world=(1, 1, 1), camera={"type": "ORTHO", "matrix_world": translation(0, 0, 3.0),
                                                       "ortho_scale": 1.0, "clip_start": 0.01, "clip_end": 100.0})
    a = {}
    h["materials"].append(dict(FOG_ONLY, volume={"absorption": sigma.tolist(), "density_reg": 3},
                               program=_gradient_program(2, 1.0)))
    _box_with_generated(h, a, "slab", 2.0, 1.0, 0, -0.5)
    scene = scene_from_dict(h, a)
    integ = prepare(scene).integrator
    vd = integ.media
    assert vd.hetero and vd.density_reg[0] == 3
    assert abs(vd.majorant[0] - 1.5) < 1e-6  # max density 1 × the safety factor
    # Generated z = world z + 0.5, the map acting on shifted world positions (world − shift)
    shift = integ.geom.origin_shift
    np.testing.assert_allclose(vd.coord_map[0, 2], [0, 0, 1, 0.5 + shift[2]], atol=1e-6)
    img = render(scene, threads=2).combined[..., :3].reshape(-1, 3)
    mean, se = _within_4se(img, np.exp(-sigma / 2))
    assert np.all(se < 0.02)
    assert np.all(np.abs(mean - np.exp(-sigma)) > 8 * se)  # not the homogeneous answer


def test_heterogeneous_open_furnace_stays_white():
    """A non-absorbing (albedo 1, chromatic, anisotropic) box with a gradient density in a white
    world, all volume bounces: radiance 1 (delta tracking, next-event estimation to the world,
    phase sampling all unbiased) within 4 SE; with absorption it is visibly darker."""
    h = base_header(12, 12, 32, world=(1, 1, 1), volume_bounces=256, max_bounces=512,
                    camera={"type": "PERSP", "matrix_world": look_at((0, -6, 0.5), (0, 0, 0.5)), "lens": 120.0})
    a = {}
    h["materials"].append(dict(FOG_ONLY, volume={"scatter": [2.0, 4.0, 8.0], "anisotropy": 0.3, "density_reg": 3},
                               program=_gradient_program(2, 1.0)))
    _box_with_generated(h, a, "fog", 0.5, 1.0, 0, 0.0)
    img = render(scene_from_dict(h, a), threads=2).combined[..., :3]
    _within_4se(img[3:9, 3:9].reshape(-1, 3), np.ones(3))
    h["materials"][0]["volume"]["absorption"] = [2.0, 2.0, 2.0]
    dark = render(scene_from_dict(h, a), threads=2).combined[..., :3]
    assert dark[3:9, 3:9].mean() < 0.8 and np.all(np.isfinite(dark))


def test_density_reg_validation_names_the_field():
    h = base_header(4, 4, 1)
    h["materials"].append(dict(FOG_ONLY, volume={"absorption": [1, 1, 1], "density_reg": 3}))
    try:
        scene_from_dict(h, {})
    except SceneError as e:
        assert "materials[0].volume.density_reg" in str(e)
    else:
        raise AssertionError("no error")


def test_heterogeneous_inside_a_homogeneous_medium_adds_coefficients():
    """The gradient slab (σa/2 integrated) inside a homogeneous absorbing box 2 m thick (σ = 0.3):
    the mixed stack tracks both, T = exp(−0.3·2 − σa/2) within 4 SE."""
    sigma = np.array([1.0, 2.0, 0.5])
    h = base_header(12, 12, 8, world=(1, 1, 1), camera={"type": "ORTHO", "matrix_world": translation(0, 0, 3.0),
                                                       "ortho_scale": 1.0, "clip_start": 0.01, "clip_end": 100.0})
    a = {}
    h["materials"].append(dict(FOG_ONLY, volume={"absorption": sigma.tolist(), "density_reg": 3},
                               program=_gradient_program(2, 1.0)))
    h["materials"].append(dict(FOG_ONLY, name="outer", volume={"absorption": [0.3, 0.3, 0.3]}))
    _box_with_generated(h, a, "slab", 2.0, 1.0, 0, -0.5)
    add_mesh(h, a, "outer", *box_mesh(3.0, 2.0), material=1, matrix=translation(0, 0, -1.0))
    img = render(scene_from_dict(h, a), threads=2).combined[..., :3].reshape(-1, 3)
    _within_4se(img, np.exp(-0.6 - sigma / 2))


@pytest.mark.parametrize("gain", [2000.0, 1e-4])
def test_stability_dense_and_thin_heterogeneous_media_with_point_light_inside(gain):
    """Gradient density × gain (σt·size up to 2000, or 1e-4) in a 1 m box with a point light
    inside: finite, non-negative, bounded time; the thin one transmits the world unchanged."""
    h = base_header(8, 8, 16, world=(1, 1, 1), volume_bounces=8,
                    camera={"type": "PERSP", "matrix_world": look_at((0, -3, 0.5), (0, 0, 0.5)), "lens": 50.0})
    a = {}
    h["materials"].append(dict(FOG_ONLY, volume={"scatter": [0.9, 0.9, 0.9], "absorption": [0.1, 0.1, 0.1],
                                                 "anisotropy": 0.5, "density_reg": 3},
                               program=_gradient_program(2, gain)))
    _box_with_generated(h, a, "fog", 0.5, 1.0, 0, 0.0)
    h["lights"].append({"type": "POINT", "matrix_world": translation(0, 0, 0.5), "color": [1, 1, 1],
                        "energy": 100.0, "radius": 0.0})
    scene = scene_from_dict(h, a)
    t0 = time.perf_counter()
    img = render(scene, threads=2).combined[..., :3]
    assert time.perf_counter() - t0 < 20.0
    assert np.all(np.isfinite(img)) and np.all(img >= 0)
    if gain < 1:
        assert abs(img[0, 0].mean() - 1.0) < 0.01


def test_textured_colour_absorption_and_scatter():
    """A textured colour c = Generated z with constant density: Volume Absorption's σa = A·(1 − c)
    integrates to A/2 through the 1 m slab (T = exp(−A/2) within 4 SE), and Volume Scatter's
    σs = S·c (chromatic, no absorption) keeps the white furnace at 1 within 4 SE."""
    absorb = np.array([1.0, 2.0, 4.0])
    h = base_header(16, 16, 8, world=(1, 1, 1), camera={"type": "ORTHO", "matrix_world": translation(0, 0, 3.0),
                                                       "ortho_scale": 1.0, "clip_start": 0.01, "clip_end": 100.0})
    a = {}
    h["materials"].append(dict(FOG_ONLY, volume={"absorption": absorb.tolist(), "color_reg": 1},
                               program=_gradient_program(2, 1.0)))
    _box_with_generated(h, a, "slab", 2.0, 1.0, 0, -0.5)
    scene = scene_from_dict(h, a)
    vd = prepare(scene).integrator.media
    assert vd.hetero and vd.color_reg[0] == 1 and vd.density_reg[0] == -1
    img = render(scene, threads=2).combined[..., :3].reshape(-1, 3)
    _within_4se(img, np.exp(-absorb / 2))

    h = base_header(12, 12, 32, world=(1, 1, 1), volume_bounces=256, max_bounces=512,
                    camera={"type": "PERSP", "matrix_world": look_at((0, -6, 0.5), (0, 0, 0.5)), "lens": 120.0})
    a = {}
    h["materials"].append(dict(FOG_ONLY, volume={"scatter": [2.0, 4.0, 8.0], "anisotropy": 0.3, "color_reg": 1},
                               program=_gradient_program(2, 1.0)))
    _box_with_generated(h, a, "fog", 0.5, 1.0, 0, 0.0)
    img = render(scene_from_dict(h, a), threads=2).combined[..., :3]
    _within_4se(img[3:9, 3:9].reshape(-1, 3), np.ones(3))


def test_area_light_inside_a_heterogeneous_medium_is_seen_attenuated():
    """A camera-visible area light facing up in the middle of the gradient slab (z = 0): the
    camera sees it through z ∈ [0, 0.5], ∫ρ = 0.375, so the image is the clear image ×
    exp(−0.375·σa) within 4 SE (the light shape's independent ratio-tracking estimate)."""
    sigma = np.array([1.0, 2.0, 4.0])

    def scene(with_slab):
        h = base_header(12, 12, 8, world=(0, 0, 0),
                        camera={"type": "ORTHO", "matrix_world": translation(0, 0, 3.0),
                                "ortho_scale": 1.0, "clip_start": 0.01, "clip_end": 100.0})
        a = {}
        h["materials"].append(dict(FOG_ONLY, volume={"absorption": sigma.tolist(), "density_reg": 3},
                                   program=_gradient_program(2, 1.0)))
        if with_slab:
            _box_with_generated(h, a, "slab", 2.0, 1.0, 0, -0.5)
        else:
            add_mesh(h, a, "far", *box_mesh(0.1, 0.1), material=0, matrix=translation(20, 0, 0))
        flip = [[1, 0, 0, 0], [0, -1, 0, 0], [0, 0, -1, 0], [0, 0, 0, 1]]  # emits toward +z
        h["lights"].append({"type": "AREA", "matrix_world": flip, "color": [1, 1, 1], "power": 50.0,
                            "size": 4.0, "visible_camera": True})
        return scene_from_dict(h, a)

    clear = render(scene(False), threads=2).combined[..., :3].reshape(-1, 3)
    seen = render(scene(True), threads=2).combined[..., :3].reshape(-1, 3)
    assert clear.min() > 0 and np.allclose(clear, clear[0], rtol=1e-6)
    _within_4se(seen / clear[0], np.exp(-0.375 * sigma))


def test_viewport_live_scene_renders_a_heterogeneous_medium():
    """The viewport's LiveScene with the gradient slab (1 m, per-corner Generated on the mesh):
    exp(−σa/2) within 4 SE, as the final render."""
    from drt.interactive import LiveScene
    from drt.materials.program_format import validate_program
    from drt.scene import CameraSpec, MeshData, RenderSettings

    sigma = np.array([0.5, 1.0, 2.0])
    pos, tri = box_mesh(3.0, 1.0)
    lo, hi = pos.min(0), pos.max(0)
    box = MeshData("box", pos.astype(np.float64), tri.astype(np.int64), np.zeros(len(tri), np.int64),
                   corner_attrs={"generated": ((pos[tri] - lo) / (hi - lo)).astype(np.float32)})
    mat = dict(FOG_ONLY, volume={"scatter": [0, 0, 0], "absorption": sigma.tolist(), "emission": [0, 0, 0],
                                 "anisotropy": 0.0, "density_reg": 3},
               program=validate_program(_gradient_program(2, 1.0), 0, "program"))
    live = LiveScene(RenderSettings(width=8, height=8, spp=16), [mat], [], (1.0, 1.0, 1.0))
    live.set_object("box", "box", box, np.eye(4))
    m = np.eye(4)
    m[:3, 3] = (0, 0, 3.0)
    cam = CameraSpec(type="ORTHO", matrix=m, ortho_scale=1.0, clip_start=0.01, clip_end=10.0)
    scene, ctx = live.context(cam, 8, 8, spp=16)
    img = render(scene, spp=16, context=ctx, threads=1).combined[..., :3]
    _within_4se(img.reshape(-1, 3), np.exp(-sigma / 2))
