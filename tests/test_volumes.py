"""Participating media (issue 14, docs/volumes.md): sampling routines against their densities,
the segment estimators against closed forms, and whole renders (absorbing slab, furnaces,
volume stack semantics, stability)."""

import math
import time

import numpy as np
import pytest

from drt.lights import LightSet
from drt.render import prepare, render
from drt.sampling.sequences import Sampler
from drt.scene import SceneError, scene_from_dict
from drt.volumes import distance as D
from drt.volumes.media import STACK_SIZE, build_medium_data, principled_volume, volume_absorption
from drt.volumes.phase import hg_pdf, hg_sample_rows
from drt.materials.program_format import POINT_ROWS, empty_program_data
from drt.volumes.stage import transmit_rows
from scene_builders import add_mesh, base_header, box_mesh, look_at, translation, uv_sphere
from stats_util import chi2_pvalue, chi2_test_sphere

SIGMA = np.array([0.5, 1.0, 2.0])


def _hg_np(cos, g):
    return (1 - g * g) / (4 * np.pi * (1 + g * g - 2 * g * cos) ** 1.5)


# ------------------------------------------------------------------------------ sampling


@pytest.mark.parametrize("g", [0.0, 0.3, -0.6, 0.9])
def test_hg_chi_square(g):
    def sample(u):
        d = np.tile([0.0, 0.0, 1.0], (len(u), 1))
        wi, pdf = np.empty_like(d), np.empty(len(u))
        hg_sample_rows(d, g, np.ascontiguousarray(u), wi, pdf)
        return wi

    p = chi2_test_sphere(sample, lambda dirs: _hg_np(dirs[:, 2], g), n_samples=100_000,
                         bins_theta=24, bins_phi=12)
    assert p > 1e-4
    for c in (-0.9, 0.0, 0.5, 0.99):
        assert hg_pdf(c, g) == pytest.approx(_hg_np(c, g), rel=1e-12)


def test_hg_sample_pdf_matches_eval_off_axis():
    rng = np.random.default_rng(1)
    d = rng.normal(size=(1000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    wi, pdf = np.empty_like(d), np.empty(1000)
    hg_sample_rows(d, 0.5, rng.random((1000, 2)), wi, pdf)
    np.testing.assert_allclose(np.linalg.norm(wi, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(pdf, _hg_np(np.sum(d * wi, axis=1), 0.5), rtol=1e-9)


@pytest.mark.parametrize("sigma,length", [(0.7, 2.0), (0.7, math.inf), (0.0, 3.0), (1e-6, 1.0), (1e3, 1.0)])
def test_distance_pdf_integrates_to_one_and_matches_samples(sigma, length):
    hi = length if math.isfinite(length) else 60.0 / sigma
    # integrate on a grid refined where the density varies (scale 1/σ)
    edges = np.unique(np.concatenate([np.linspace(0, hi, 20001),
                                      np.linspace(0, min(hi, 40.0 / max(sigma, 1e-9)), 20001)]))
    mid = 0.5 * (edges[1:] + edges[:-1])
    pdf = np.array([D.exp_pdf(t, sigma, length) for t in mid])
    assert np.sum(pdf * np.diff(edges)) == pytest.approx(1.0, abs=2e-4)
    rng = np.random.default_rng(2)
    t = np.array([D.exp_sample(u, sigma, length) for u in rng.random(20000)])
    assert np.all((t >= 0) & (t < length))
    bins = np.quantile(t, np.linspace(0, 1, 21))  # 20 bins; expected from the pdf
    bins[0], bins[-1] = 0.0, hi
    cdf = np.concatenate([[0.0], np.cumsum(pdf * np.diff(edges))])
    expected = np.diff(np.interp(bins, edges, cdf)) * len(t)
    observed = np.histogram(np.minimum(t, hi), bins)[0]
    assert chi2_pvalue(observed, expected)[0] > 1e-4


@pytest.mark.parametrize("c,length", [((0.5, 1.0, 0.3), 4.0), ((0.0, 0.2, 0.0), math.inf), ((3.0, -1.0, 0.0), 2.0)])
def test_equiangular_pdf_integrates_to_one_and_matches_samples(c, length):
    o, d = (0.0, 0.0, 0.0), (1.0, 0.0, 0.0)
    delta, dist, ta, tb = D.equiangular_setup(o, d, c, length)
    hi = length if math.isfinite(length) else 1e6
    # substitute t = Δ + D tan θ: exact integral is the θ span; check numerically in t too
    edges = np.unique(np.concatenate([np.linspace(0, min(hi, 50), 200001), np.geomspace(1e-3, hi, 20001)]))
    mid = 0.5 * (edges[1:] + edges[:-1])
    pdf = np.array([D.equiangular_pdf(t, delta, dist, ta, tb, length) for t in mid])
    tail = 0.0 if math.isfinite(length) else dist / (tb - ta) / hi  # ∫_hi^∞ ≈ D/(span·hi)
    assert np.sum(pdf * np.diff(edges)) + tail == pytest.approx(1.0, abs=2e-3)
    rng = np.random.default_rng(3)
    t = np.array([D.equiangular_sample(u, delta, dist, ta, tb) for u in rng.random(20000)])
    assert np.all((t >= 0) & (t < length))
    cdf = np.concatenate([[0.0], np.cumsum(pdf * np.diff(edges))])
    bins = np.quantile(t, np.linspace(0, 1, 21))
    bins[0], bins[-1] = 0.0, hi
    expected = np.diff(np.interp(bins, edges, cdf)) * len(t)
    expected[-1] += tail * len(t)
    observed = np.histogram(np.minimum(t, hi), bins)[0]
    assert chi2_pvalue(observed, expected)[0] > 1e-4


# ------------------------------------------------------------------------------ segment estimators


def _segment(sigma_s, sigma_a, thr, length=1.0, n=40000):
    vd = build_medium_data([{"volume": {"scatter": list(sigma_s), "absorption": list(sigma_a),
                                        "emission": [0, 0, 0], "anisotropy": 0.0}}], None,
                           tri_object=np.zeros(1, np.int32))
    stack = np.full((1, STACK_SIZE), -1, np.int64)
    stack[0, 0] = 0
    ld = LightSet([], np.zeros(3), None).data
    sd = Sampler("SOBOL", 0, 1).data
    tr, sc, t = np.empty((n, 3)), np.empty((n, 3)), np.empty(n)
    pd = empty_program_data()
    transmit_rows(sd, ld, vd, pd, np.zeros((1, 3)), np.zeros((POINT_ROWS, 3)), stack, (0.0, 0.0, 0.0),
                  (0.0, 0.0, 1.0), length, tuple(thr), tr, sc, t)
    return tr, sc, t


def _within_4se(samples, expected):
    mean = samples.mean(0)
    se = samples.std(0, ddof=1) / math.sqrt(len(samples))
    assert np.all(np.abs(mean - expected) <= 4 * se + 1e-12), (mean, expected, se)


@pytest.mark.parametrize("thr", [(1.0, 1.0, 1.0), (0.2, 1.0, 3.0)])
def test_slab_transmittance_and_scatter_estimators(thr):
    """Chromatic medium σt = (0.5, 1, 2)/m, albedo 0.8: E[transmitted weight] = thr·e^(−σt·d)
    and E[scattered weight] = thr·σs·(1 − e^(−σt·d))/σt, within 4 standard errors."""
    d = 1.3
    sigma_s = 0.8 * SIGMA
    tr, sc, t = _segment(sigma_s, 0.2 * SIGMA, thr, d)
    _within_4se(tr, np.array(thr) * np.exp(-SIGMA * d))
    _within_4se(sc, np.array(thr) * sigma_s * (1 - np.exp(-SIGMA * d)) / SIGMA)
    assert np.all(t[np.isfinite(t)] < d)


# ------------------------------------------------------------------------------ whole renders

FOG_ONLY = {"name": "fog", "lobes": [], "surface": False}


def ortho_down(scale, height=3.0):
    return {"type": "ORTHO", "matrix_world": translation(0, 0, height), "ortho_scale": scale,
            "clip_start": 0.01, "clip_end": 100.0}


def _render(h, a, threads=2):
    return render(scene_from_dict(h, a), threads=threads).combined[..., :3]


def test_absorbing_slab_renders_exp_minus_sigma_d():
    """A volume-only absorbing box (1 m thick) in front of a white world: exactly e^(−σa·d)."""
    h = base_header(8, 8, 4, world=(1, 1, 1), camera=ortho_down(1.0))
    a = {}
    h["materials"].append(dict(FOG_ONLY, volume={"absorption": SIGMA.tolist()}))
    add_mesh(h, a, "slab", *box_mesh(2.0, 1.0), material=0, matrix=translation(0, 0, -0.5))
    img = _render(h, a)
    np.testing.assert_allclose(img.reshape(-1, 3), np.tile(np.exp(-SIGMA), (64, 1)), rtol=1e-4)


def test_overlapping_and_nested_media_add_and_camera_inside():
    """Two overlapping absorbing boxes (coefficients add where both are), one holding the camera:
    every pixel sees e^(−Σ σ·path length), computed here in closed form."""
    h = base_header(8, 8, 2, world=(1, 1, 1), camera=ortho_down(0.5, height=0.5))
    a = {}
    h["materials"].append(dict(FOG_ONLY, name="outer", volume={"absorption": [0.3, 0.3, 0.3]}))
    h["materials"].append(dict(FOG_ONLY, name="inner", volume={"absorption": [0.0, 1.0, 2.0]}))
    # outer box z ∈ [-1, 1] holds the camera (z = 0.5); inner z ∈ [-0.5, 0.3] overlaps it
    add_mesh(h, a, "outer", *box_mesh(2.0, 2.0), material=0, matrix=translation(0, 0, -1.0))
    add_mesh(h, a, "inner", *box_mesh(1.0, 0.8), material=1, matrix=translation(0, 0, -0.5))
    img = _render(h, a)
    # camera rays start at clip_start (0.01) below the camera: 1.49 m in the outer box
    expected = np.exp(-(0.3 * 1.49 + np.array([0.0, 1.0, 2.0]) * 0.8))
    np.testing.assert_allclose(img.reshape(-1, 3), np.tile(expected, (64, 1)), rtol=1e-4)


def test_glass_box_with_absorbing_medium_inside():
    """A smooth glass box (ior 1: no refraction, no Fresnel) filled with an absorbing medium:
    the medium is entered through the glass's front faces."""
    h = base_header(8, 8, 4, world=(1, 1, 1), camera=ortho_down(1.0))
    a = {}
    h["materials"].append({"name": "glass", "lobes": [{"type": "GLASS", "color": [1, 1, 1], "roughness": 0.0, "ior": 1.0}],
                           "volume": {"absorption": SIGMA.tolist()}})
    add_mesh(h, a, "box", *box_mesh(2.0, 1.0), material=0, matrix=translation(0, 0, -0.5))
    img = _render(h, a)
    np.testing.assert_allclose(img.reshape(-1, 3), np.tile(np.exp(-SIGMA), (64, 1)), rtol=1e-4)


def test_open_furnace_albedo_one_sphere():
    """An albedo-1 chromatic, anisotropic medium sphere in a white world stays white (1)."""
    h = base_header(12, 12, 32, world=(1, 1, 1), volume_bounces=256, max_bounces=512,
                    camera={"type": "PERSP", "matrix_world": look_at((0, -6, 0), (0, 0, 0)), "lens": 150.0})
    a = {}
    h["materials"].append(dict(FOG_ONLY, volume={"scatter": SIGMA.tolist(), "anisotropy": 0.3}))
    pos, tri, _ = uv_sphere(1.0, rings=24, segments=48)
    add_mesh(h, a, "s", pos, tri, material=0)
    img = _render(h, a)
    _within_4se(img[3:9, 3:9].reshape(-1, 3), np.ones(3))
    h["materials"][0]["volume"]["absorption"] = SIGMA.tolist()  # albedo ½: visibly darker
    assert _render(h, a)[3:9, 3:9].mean() < 0.8


def test_closed_furnace_emissive_box_filled_with_albedo_one_medium():
    """Camera inside a closed box whose black walls emit 1 (lights, so next-event estimation
    from the medium is exercised), filled with a non-absorbing medium: radiance 1 everywhere."""
    h = base_header(10, 10, 32, world=(0, 0, 0), volume_bounces=1024, max_bounces=1024,
                    camera={"type": "PERSP", "matrix_world": look_at((0, -0.5, 1.0), (0, 1, 1.0)), "lens": 20.0})
    a = {}
    h["materials"].append({"name": "walls", "lobes": [], "emission": [1.0, 1.0, 1.0],
                           "volume": {"scatter": [0.5, 1.0, 1.5], "anisotropy": -0.2}})
    add_mesh(h, a, "room", *box_mesh(1.5, 2.0), material=0)
    scene = scene_from_dict(h, a)
    assert prepare(scene).integrator.media.camera_stack[0] == 0  # the camera starts inside the room's medium
    img = render(scene, threads=2).combined[..., :3]
    _within_4se(img.reshape(-1, 3), np.ones(3))
    # the same room with an absorbing medium is darker: the medium is really there
    h["materials"][0]["volume"]["absorption"] = [0.5, 0.5, 0.5]
    assert _render(h, a).mean() < 0.8


# ------------------------------------------------------------------------------ stability


@pytest.mark.parametrize("sigma", [1000.0, 1e-4])
def test_stability_dense_and_thin_media_with_point_light_inside(sigma):
    """σt·size ≥ 1000 and ≤ 1e-4 (1 m box) with a point light inside: finite, bounded time,
    and the thin medium transmits the white world almost unchanged."""
    h = base_header(8, 8, 16, world=(1, 1, 1), volume_bounces=8,
                    camera={"type": "PERSP", "matrix_world": look_at((0, -3, 0.5), (0, 0, 0.5)), "lens": 50.0})
    a = {}
    h["materials"].append(dict(FOG_ONLY, volume={"scatter": [0.9 * sigma] * 3, "absorption": [0.1 * sigma] * 3,
                                                 "anisotropy": 0.5}))
    add_mesh(h, a, "fog", *box_mesh(0.5, 1.0), material=0)
    h["lights"].append({"type": "POINT", "matrix_world": translation(0, 0, 0.5), "color": [1, 1, 1],
                        "energy": 100.0, "radius": 0.0})
    t0 = time.perf_counter()
    img = _render(h, a)
    assert time.perf_counter() - t0 < 20.0
    assert np.all(np.isfinite(img)) and np.all(img >= 0)
    if sigma < 1:
        assert abs(img[0, 0].mean() - 1.0) < 0.01  # a corner sees the world past the box


def test_scene_validation_names_the_field():
    h = base_header(4, 4, 1)
    h["materials"].append({"name": "m", "lobes": [], "volume": {"scatter": [1, -1, 0]}})
    with pytest.raises(SceneError, match=r"materials\[0\]\.volume\.scatter"):
        scene_from_dict(h, {})
    h["materials"][0]["volume"] = {"anisotropy": 2}
    with pytest.raises(SceneError, match=r"materials\[0\]\.volume\.anisotropy"):
        scene_from_dict(h, {})
    h["materials"][0]["volume"] = {"density": 1}
    with pytest.raises(SceneError, match=r"materials\[0\]\.volume\.density"):
        scene_from_dict(h, {})
    h["materials"][0] = {"name": "m", "lobes": [], "surface": 0}
    with pytest.raises(SceneError, match=r"materials\[0\]\.surface"):
        scene_from_dict(h, {})
    h["materials"][0] = {"name": "m", "lobes": []}
    h["world"] = {"color": [0, 0, 0], "volume": {"emission": "x"}}
    with pytest.raises(SceneError, match=r"world\.volume\.emission"):
        scene_from_dict(h, {})


def test_node_conversions_follow_cycles():
    m = principled_volume((0.8, 0.5, 0.2), 2.0, 0.4, (0.25, 0.0, 1.0), 3.0, (1.0, 0.5, 0.0))
    c = np.array([0.8, 0.5, 0.2])
    np.testing.assert_allclose(m["scatter"], 2 * c)
    np.testing.assert_allclose(m["absorption"], 2 * (1 - c) * (1 - np.sqrt([0.25, 0.0, 1.0])))
    np.testing.assert_allclose(m["emission"], [3.0, 1.5, 0.0])
    np.testing.assert_allclose(volume_absorption((0.9, 0.3, 0.1), 4.0)["absorption"], 4 * np.array([0.1, 0.7, 0.9]))


def test_spot_interval_is_the_part_of_the_ray_inside_the_enclosing_cone():
    """The direct-light sub-segment for a spot light (Cycles's valid ray segment) against a
    brute-force classification of points along random rays (sphere spots: apex moved back)."""
    from drt.lights.common import L_COS_HALF, L_POS, L_RADIUS, L_SPOT_DIR
    from drt.volumes.stage import spot_interval

    rng = np.random.default_rng(0)
    hits = 0
    for _ in range(150):
        m = np.eye(4)
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        m[:3, :3] = q * np.sign(np.linalg.det(q))
        m[:3, 3] = rng.normal(size=3)
        ld = LightSet([{"type": "SPOT", "matrix_world": m.tolist(), "color": [1, 1, 1], "power": 10.0,
                        "radius": float(rng.choice([0.0, 0.1])), "spot_size": float(rng.uniform(0.2, 2.8)),
                        "spot_blend": 0.0}], np.zeros(3), None).data
        o = rng.normal(size=3) * 2
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        a, b = spot_interval(ld, 0, tuple(o), tuple(d), 0.0, 10.0)
        c, axis, ch = ld.lf[0, L_POS:L_POS + 3], ld.lf[0, L_SPOT_DIR:L_SPOT_DIR + 3], ld.lf[0, L_COS_HALF]
        apex = c - axis * ld.lf[0, L_RADIUS] / math.sqrt(1 - ch * ch)
        ts = np.linspace(0, 10.0, 10001)[:-1]
        v = o + ts[:, None] * d - apex
        av = v @ axis
        inside = (av > 0) & (av ** 2 >= ch ** 2 * (v * v).sum(1))
        got = (ts >= a) & (ts < b)
        assert (inside != got).sum() <= 2  # grid points at the boundary may fall either way
        hits += inside.any()
    assert hits > 30  # enough rays actually cross a cone


def test_viewport_live_scene_renders_media_and_world_volume():
    """The viewport's LiveScene: a volume-only absorbing box over a white floor under a white
    world holding an absorbing world medium: e^(−σ_box·1 m) × e^(−σ_world·path) exactly."""
    from drt.interactive import LiveScene
    from drt.scene import CameraSpec, MeshData, RenderSettings

    pos, tri = box_mesh(3.0, 1.0)
    box = MeshData("box", pos.astype(np.float64), tri.astype(np.int64), np.zeros(len(tri), np.int64))
    live = LiveScene(RenderSettings(width=8, height=8, spp=2),
                     [dict(FOG_ONLY, volume={"scatter": [0, 0, 0], "absorption": [0.5, 1.0, 2.0],
                                             "emission": [0, 0, 0], "anisotropy": 0.0})], [], (1.0, 1.0, 1.0))
    live.set_object("box", "box", box, np.eye(4))
    live.set_world((1.0, 1.0, 1.0), {"scatter": [0, 0, 0], "absorption": [0.1, 0.1, 0.1],
                                     "emission": [0, 0, 0], "anisotropy": 0.0})
    m = np.eye(4)
    m[:3, 3] = (0, 0, 3.0)
    cam = CameraSpec(type="ORTHO", matrix=m, ortho_scale=1.0, clip_start=0.01, clip_end=10.0)
    scene, ctx = live.context(cam, 8, 8, spp=2)
    img = render(scene, spp=2, context=ctx, threads=1).combined[..., :3]
    # camera rays that miss run to infinity in the absorbing world medium (Cycles: black, also
    # past clip_end): nothing of the world is left
    assert np.all(img == 0.0)
    live.set_world((1.0, 1.0, 1.0), None)
    scene, ctx = live.context(cam, 8, 8, spp=2)
    img = render(scene, spp=2, context=ctx, threads=1).combined[..., :3]
    np.testing.assert_allclose(img.reshape(-1, 3), np.tile(np.exp(-SIGMA), (64, 1)), rtol=1e-4)


def test_emissive_absorbing_medium_integrates_emission_analytically():
    """A 1 m volume-only box emitting σe per metre with absorption σa, black world: radiance
    σe·(1 − e^(−σa))/σa per channel (a channel without absorption: σe·1 m)."""
    h = base_header(8, 8, 2, world=(0, 0, 0), camera=ortho_down(1.0))
    a = {}
    sigma_a = np.array([0.0, 1.0, 3.0])
    h["materials"].append(dict(FOG_ONLY, volume={"absorption": sigma_a.tolist(), "emission": [2.0, 2.0, 2.0]}))
    add_mesh(h, a, "slab", *box_mesh(2.0, 1.0), material=0, matrix=translation(0, 0, -0.5))
    expected = np.array([2.0, 2.0 * (1 - math.exp(-1.0)), 2.0 * (1 - math.exp(-3.0)) / 3.0])
    np.testing.assert_allclose(_render(h, a).reshape(-1, 3), np.tile(expected, (64, 1)), rtol=1e-4)


def _haze_scene(world_volume, spp=64):
    """A diffuse floor and ball in a world medium, lit by a sun and a point light."""
    h = base_header(24, 16, spp, world=(0.2, 0.25, 0.35), volume_bounces=1,
                    camera={"type": "PERSP", "matrix_world": look_at((0, -5, 1.5), (0, 0.3, 0.6)), "lens": 35.0})
    h["world"]["volume"] = world_volume
    h["materials"].append({"name": "grey", "lobes": [{"type": "DIFFUSE", "color": [0.5, 0.5, 0.5]}]})
    a = {}
    add_mesh(h, a, "floor", np.array([[-8, -8, 0], [8, -8, 0], [8, 8, 0], [-8, 8, 0]], float),
             np.array([[0, 1, 2], [0, 2, 3]]), 0)
    pos, tri, nrm = uv_sphere(0.6, rings=8, segments=16)
    add_mesh(h, a, "ball", pos + [0.0, 0.5, 0.6], tri, 0, normals=nrm)
    h["lights"].append({"type": "SUN", "matrix_world": look_at((0, 0, 5), (1, 1, 0)), "color": [1, 1, 1],
                        "energy": 2.0, "angle": 0.03})
    h["lights"].append({"type": "POINT", "matrix_world": translation(0, -0.5, 2.0), "color": [1, 1, 1],
                        "energy": 150.0, "radius": 0.1})
    return scene_from_dict(h, a)


def test_world_medium_hides_the_sun_from_light_selection(monkeypatch):
    """A world medium with σt > 0 in every channel: nothing at infinity reaches any point
    (Cycles renders a sun-only haze black), so the sun is left out of light selection — the same
    image in expectation (means within 4 standard errors per channel), no samples wasted. A
    medium that leaves one channel clear keeps the sun."""
    import drt.render as render_mod
    from drt.volumes import media as media_mod

    haze = {"scatter": [0.06, 0.06, 0.06], "absorption": [0.0, 0.0, 0.0], "anisotropy": 0.5}
    ctx = prepare(_haze_scene(haze))
    assert ctx.integrator.lights.n_lights == 1  # the point light only
    clear_blue = {"scatter": [0.06, 0.06, 0.0], "absorption": [0.0, 0.0, 0.0], "anisotropy": 0.0}
    assert prepare(_haze_scene(clear_blue)).integrator.lights.n_lights == 2

    def pixel_means(seeds):
        return np.array([render(_haze_scene(haze), seed=s, threads=1).combined[..., :3].mean(axis=(0, 1))
                         for s in seeds])

    without_sun = pixel_means(range(4))
    monkeypatch.setattr(render_mod, "lights_reaching", lambda lights, md: lights)
    monkeypatch.setattr(render_mod, "world_blocks_infinity", lambda md: False)
    assert prepare(_haze_scene(haze)).integrator.lights.n_lights == 2
    with_sun = pixel_means(range(10, 14))
    assert media_mod.world_blocks_infinity(ctx.integrator.media)
    se = np.sqrt(without_sun.var(axis=0, ddof=1) / 4 + with_sun.var(axis=0, ddof=1) / 4)
    diff = np.abs(without_sun.mean(axis=0) - with_sun.mean(axis=0))
    assert without_sun.mean() > 0.01
    assert np.all(diff <= 4 * se + 1e-3 * with_sun.mean()), (diff, se)
