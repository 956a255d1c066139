"""Textured worlds in the core, without Blender (drt.lights.world_map, OP_ENVIRONMENT):
direction ↔ image mappings, the environment lookup, the importance map's pdf (integral,
chi-square of sampled directions) and a render converging to an analytic irradiance."""

from __future__ import annotations

import math

import numpy as np
import pytest

import scene_builders as B
from drt.lights.world_map import build_world_map, map_pdf, sample_map, shade_directions
from drt.materials import program_format as F
from drt.render import prepare, render
from drt.sampling import spherical_maps as S
from drt.scene import SceneError, scene_from_dict


# ------------------------------------------------------------------------- mappings
def _uv(fn, d):
    out = np.array([fn(*row) for row in np.asarray(d, float)])
    return out


def test_equirectangular_conventions():
    # Cycles: u = 1/2 − atan2(y, x)/2π, v = 1 − acos(z)/π
    d = [(1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1), (-1, 0, 1e-9)]
    uv = _uv(S.direction_to_equirectangular, d)
    np.testing.assert_allclose(uv[:5], [[0.5, 0.5], [0.25, 0.5], [0.75, 0.5], [0.5, 1.0], [0.5, 0.0]], atol=1e-12)
    assert uv[5][0] == pytest.approx(0.0, abs=1e-9) or uv[5][0] == pytest.approx(1.0, abs=1e-9)
    rng = np.random.default_rng(1)
    u = rng.random((200, 2)) * [1, 0.98] + [0, 0.01]
    back = _uv(S.direction_to_equirectangular, [S.equirectangular_to_direction(a, b) for a, b in u])
    np.testing.assert_allclose(back, u, atol=1e-9)


def test_mirrorball_conventions():
    # the ball's centre reflects the view ray back toward the viewer (−Y); its rim sees +Y
    np.testing.assert_allclose(S.mirrorball_to_direction(0.5, 0.5), (0, -1, 0), atol=1e-12)
    np.testing.assert_allclose(S.direction_to_mirrorball(0.0, -1.0, 0.0), (0.5, 0.5), atol=1e-12)
    np.testing.assert_allclose(S.direction_to_mirrorball(0.0, 0.0, 1.0), (0.5, 0.5 + 0.5 * math.sqrt(0.5)), atol=1e-12)
    assert S.mirrorball_to_direction(0.0, 0.0) == (0.0, 0.0, 0.0)
    rng = np.random.default_rng(2)
    r = np.sqrt(rng.random(200)) * 0.99
    a = rng.random(200) * 2 * np.pi
    uv = np.stack([0.5 + 0.5 * r * np.cos(a), 0.5 + 0.5 * r * np.sin(a)], 1)
    back = _uv(S.direction_to_mirrorball, [S.mirrorball_to_direction(u, v) for u, v in uv])
    np.testing.assert_allclose(back, uv, atol=1e-9)


# ------------------------------------------------------------------------- a world program
def _world_image(w=16, h=8, seed=3, sun=None):
    rng = np.random.default_rng(seed)
    px = np.ones((h, w, 4), np.float32)
    px[..., :3] = rng.random((h, w, 3)) * 2.0
    if sun is not None:
        px[sun[0], sun[1], :3] = sun[2]
    return px.astype(np.float16)


def world_header(h, arrays, px, projection=S.EQUIRECTANGULAR, interpolation=0, strength=1.5,
                 map_size=(64, 32)):
    """Adds the world (direction → Environment Texture × strength) and its image to a header."""
    img = len(h.setdefault("images", []))
    h["images"].append({"name": "env", "width": px.shape[1], "height": px.shape[0], "srgb": False,
                        "array": f"image{img}.pixels"})
    arrays[f"image{img}.pixels"] = px
    mode = projection * F.ENV_PROJECTION_STRIDE + interpolation * 8
    prog = {"registers": 5, "constants": [[3, strength, strength, strength]],
            "ops": [[F.OP_GENERATED, 0, 0, -1, -1, -1, -1, -1, -1, -1, 0],
                    [F.OP_ENVIRONMENT, mode, 1, 2, 0, -1, -1, -1, -1, -1, img],
                    [F.OP_VMATH, 2, 4, -1, 1, 3, -1, -1, -1, -1, 0]], "data": []}
    h["world"] = {"color": [0.5, 0.5, 0.5], "program": prog, "radiance_reg": 4,
                  "map_size": list(map_size)}
    return h


def _reference_lookup(px, uv):
    """Closest lookup with REPEAT, as Cycles (texel floor(u·w), bottom row first)."""
    h, w = px.shape[:2]
    ix = np.floor(uv[:, 0] * w).astype(int) % w
    iy = np.floor(uv[:, 1] * h).astype(int) % h
    return px[iy, ix, :3].astype(np.float64)


@pytest.mark.parametrize("projection", [S.EQUIRECTANGULAR, S.MIRROR_BALL])
def test_environment_lookup_matches_reference(projection):
    px = _world_image()
    a = {}
    h = world_header(B.base_header(width=4, height=4, spp=1), a, px, projection)
    scene = scene_from_dict(h, a)
    ctx = prepare(scene)
    ld = ctx.integrator.lights.data
    rng = np.random.default_rng(4)
    d = rng.normal(size=(500, 3)) * [1, 1, 1]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    got = shade_directions(ctx.integrator.programs, ld.world_prog, ld.world_reg, 5, d * 3.0)
    fn = S.direction_to_equirectangular if projection == S.EQUIRECTANGULAR else S.direction_to_mirrorball
    want = 1.5 * _reference_lookup(px, _uv(fn, d))
    np.testing.assert_allclose(got, want, rtol=1e-12)


def test_constant_world_keeps_the_constant_path():
    h, a = B.cornell_box(width=8, height=8, spp=1)
    ld = prepare(scene_from_dict(h, a)).integrator.lights.data
    assert ld.world_prog == -1 and ld.wm_cond.shape[0] == 0


# ------------------------------------------------------------------------- importance map
def _map_ld(pixels):
    from drt.lights.common import build_light_data

    cond, marg, avg = build_world_map(pixels)
    return build_light_data([], None, np.ones(3), world_map=(cond, marg)), avg


def test_map_pdf_integrates_to_one_and_matches_cycles_formula():
    rng = np.random.default_rng(5)
    pixels = rng.random((16, 32, 3)) ** 4
    pixels[3, 7] = 50.0
    ld, _ = _map_ld(pixels)
    # midpoint quadrature over (u, v): dω = 2π² sin θ du dv
    n = 512
    u, v = np.meshgrid((np.arange(2 * n) + 0.5) / (2 * n), (np.arange(n) + 0.5) / n)
    d = np.array([S.equirectangular_to_direction(a, b) for a, b in zip(u.ravel(), v.ravel())])
    pdf = map_pdf(ld, d)
    integral = np.sum(pdf * 2 * np.pi ** 2 * np.sin(np.pi * v.ravel())) / (2 * n * n)
    assert integral == pytest.approx(1.0, abs=1e-9)
    # pdf ∝ channel average in the pixel / (its row's) − the sin θ of the row centre cancels
    f = pixels.mean(axis=2) * np.sin(np.pi * (np.arange(16) + 0.5) / 16)[:, None]
    iy, ix = 3, 7
    dd = S.equirectangular_to_direction((ix + 0.3) / 32, (iy + 0.6) / 16)
    want = f[iy, ix] / (2 * np.pi ** 2 * math.sin(np.pi * (iy + 0.6) / 16) * f.sum() / (32 * 16))
    assert map_pdf(ld, [dd])[0] == pytest.approx(want, rel=1e-12)


def test_sampled_directions_follow_the_pdf_chi_square():
    from stats_util import chi2_test_sphere

    rng = np.random.default_rng(6)
    pixels = rng.random((8, 16, 3)) ** 3 + 0.01
    pixels[2, 5] = 20.0
    ld, _ = _map_ld(pixels)
    d, pdf = sample_map(ld, rng.random((1000, 2)))
    np.testing.assert_allclose(pdf, map_pdf(ld, d), rtol=1e-9)
    # θ/φ bins not aligned with the 8 × 16 map
    res = chi2_test_sphere(lambda u: sample_map(ld, u)[0], lambda d: map_pdf(ld, d), 200_000,
                           bins_theta=12, bins_phi=20, return_details=True)
    assert res.pdf_integral == pytest.approx(1.0, abs=2e-3)
    assert res.p_value > 1e-3, res.message


# ------------------------------------------------------------------------- rendering
def _irradiance_up(px, strength):
    """E at an upward normal of the Closest-interpolated equirectangular image (fine quadrature
    in (u, v): dω = 2π² sin θ du dv, cos θ = z)."""
    h, w = px.shape[:2]
    k = 64
    v = (np.arange(h * k) + 0.5) / (h * k)
    z = -np.cos(np.pi * v)  # θ = π − πv
    row_w = np.clip(z, 0, None) * np.sin(np.pi * v) * 2 * np.pi ** 2 / (h * k)
    lum_rows = px[..., :3].astype(np.float64).mean(axis=1)  # (h, 3): mean over u of each row
    return strength * np.sum(row_w[:, None] * np.repeat(lum_rows, k, axis=0), axis=0)


@pytest.mark.parametrize("direct, importance", [("MIS_POWER", True), ("LIGHT", True), ("BSDF", True),
                                               ("MIS_POWER", False)])
def test_diffuse_plane_converges_to_analytic_irradiance(direct, importance):
    px = _world_image(w=32, h=16, sun=(13, 9, 400.0))
    strength = 1.0
    h = B.base_header(width=8, height=8, spp=256, max_bounces=0, direct=direct,
                      camera={"type": "ORTHO", "matrix_world": B.translation(0, 0, 5), "ortho_scale": 1.0},
                      filter={"type": "BOX", "width": 0.01})
    a = {}
    world_header(h, a, px, strength=strength, map_size=(128, 64) if importance else (0, 0))
    B.add_material(h, "white", [{"type": "DIFFUSE", "color": [0.8, 0.8, 0.8]}])
    pos, tri = B.quad((0, 0, 0), (50, 0, 0), (0, 50, 0))
    B.add_mesh(h, a, "plane", pos, tri)
    img = render(scene_from_dict(h, a), threads=1).combined[..., :3].reshape(-1, 3)
    want = 0.8 / np.pi * _irradiance_up(px, strength)
    mean = img.mean(axis=0)
    se = img.std(axis=0) / math.sqrt(len(img))
    assert np.all(np.abs(mean - want) < 4 * se + 1e-3 * want), (mean, want, se)


def test_camera_sees_the_world_and_film_transparent_clears_alpha():
    px = _world_image()
    h = B.base_header(width=4, height=4, spp=1, max_bounces=0, filter={"type": "BOX", "width": 0.01},
                      camera={"type": "ORTHO", "matrix_world": B.look_at((0, 0, 0), (1, 0, 0)), "ortho_scale": 1.0})
    a = {}
    world_header(h, a, px)
    res = render(scene_from_dict(h, a), threads=1).combined
    # every ray looks along +X: u = v = 1/2 → texel (w/2, h/2)
    want = 1.5 * px[4, 8, :3].astype(np.float64)
    np.testing.assert_allclose(res[..., :3].reshape(-1, 3), np.broadcast_to(want, (16, 3)), rtol=1e-5)
    assert np.all(res[..., 3] == 1.0)
    h["render"]["film_transparent"] = True
    res = render(scene_from_dict(h, a), threads=1).combined
    assert np.all(res[..., 3] == 0.0)


@pytest.mark.parametrize("change, field", [
    (lambda w: w.update(radiance_reg=9), "world.radiance_reg"),
    (lambda w: w.update(map_size=[4, 0]), "world.map_size"),
    (lambda w: w.update(map_size=[4, -1]), "world.map_size"),
    (lambda w: w["program"]["ops"].append([F.OP_ENVIRONMENT, 0, 1, 2, 0, -1, -1, -1, -1, -1, 5]), "world.program.ops[3]"),
])
def test_bad_world_programs_are_refused_by_name(change, field):
    h = world_header(B.base_header(width=4, height=4, spp=1), a := {}, _world_image())
    change(h["world"])
    with pytest.raises(SceneError) as e:
        scene_from_dict(h, a)
    assert field in str(e.value)


def test_map_weights_bound_radiance_over_pdf_next_to_a_sun():
    """A map as fine as the image, a sun texel, bilinear lookups: pixels whose centre is dark
    but whose edge sees the sun's interpolated radiance weigh their corners' radiance too, so
    L/pdf stays bounded (with Cycles's centre-only weights it reached ~10⁴ × its mean here)."""
    from drt.lights.world_map import build_world_map, shade_map, shade_map_corners
    from drt.lights.common import build_light_data

    px = _world_image(w=32, h=16, sun=(10, 9, 5000.0))
    a = {}
    h = world_header(B.base_header(width=4, height=4, spp=1), a, px, interpolation=1, map_size=(32, 16))
    ctx = prepare(scene_from_dict(h, a))
    pd, ld0 = ctx.integrator.programs, ctx.integrator.lights.data
    ratios = {}
    for corners in (False, True):
        c = shade_map_corners(pd, ld0.world_prog, ld0.world_reg, 5, 32, 16) if corners else None
        cond, marg, _ = build_world_map(shade_map(pd, ld0.world_prog, ld0.world_reg, 5, 32, 16), c)
        ld = build_light_data([], None, np.ones(3), world_map=(cond, marg))
        d, pdf = sample_map(ld, np.random.default_rng(7).random((100_000, 2)))
        r = shade_directions(pd, ld0.world_prog, ld0.world_reg, 5, d).mean(axis=1) / pdf
        ratios[corners] = r.max() / r.mean()
    assert ratios[True] < 20 < 100 < ratios[False], ratios


def test_viewport_live_scene_renders_the_textured_world_like_the_final_render():
    """LiveScene (the rendered viewport) with the world's program and images gives the final
    render's image for the same camera and seed; a constant world afterwards drops the map."""
    from drt.interactive import LiveScene
    from drt.scene import MeshData

    px = _world_image(w=32, h=16, sun=(13, 9, 400.0))
    h = B.base_header(width=16, height=16, spp=8, max_bounces=2,
                      camera={"type": "PERSP", "matrix_world": B.look_at((0, -4, 2), (0, 0, 0)), "lens": 30.0})
    a = {}
    world_header(h, a, px, map_size=(32, 16))
    B.add_material(h, "white", [{"type": "DIFFUSE", "color": [0.8, 0.8, 0.8]}])
    pos, tri = B.quad((0, 0, 0), (3, 0, 0), (0, 3, 0))
    B.add_mesh(h, a, "plane", pos, tri)
    scene = scene_from_dict(h, a)
    want = render(scene, threads=1).combined

    live = LiveScene(scene.render, scene.materials, [], scene.world_color)
    live.set_world(scene.world_color, program=scene.world_program, images=scene.images)
    m = scene.meshes[0]
    live.set_object("plane", "plane", MeshData("plane", m.positions, m.triangles, m.material_index),
                    np.eye(4))
    s, ctx = live.context(scene.camera, 16, 16, spp=8)
    assert ctx.integrator.lights.data.world_prog >= 0 and ctx.integrator.lights.world is not None
    got = render(s, spp=8, context=ctx, threads=1).combined
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12)
    live.set_world((0.2, 0.2, 0.2))
    s, ctx = live.context(scene.camera, 16, 16, spp=1)
    assert ctx.integrator.lights.data.world_prog == -1 and ctx.integrator.lights.world is None
