"""Light selection that fits the scene: by estimated contribution (power / distance²) with many
lights, nothing at all with one; pdfs that `sample` and `intersect` / `emissive_pdf` /
`world_pdf` agree on (MIS needs both sides to see the same selection probability)."""

import math

import numpy as np
import pytest

from drt.lights import EmissiveTriangles, LightSet
from failure_scenes import many_lights_points
from scene_builders import translation

LUM = np.array([0.2126, 0.7152, 0.0722])


def sphere(x, y, z, r=0.05, power=10.0):
    return {"type": "POINT", "matrix_world": translation(x, y, z), "color": [1, 1, 1], "power": power,
            "radius": r, "soft_falloff": False}


def test_one_light_spends_nothing():
    ls = LightSet([sphere(0, 0, 1)])
    assert not ls._per_point  # no per-point work at all
    p = np.random.default_rng(0).normal(size=(50, 3))
    assert np.all(ls.selection_pmf(p) == 1.0)
    s = ls.sample(p, None, np.random.default_rng(1).random(50), np.random.default_rng(2).random((50, 2)))
    h = ls.intersect(p, s.wi, np.inf)
    assert np.allclose(h.pdf[s.valid & h.hit], s.pdf[s.valid & h.hit], rtol=1e-9)


def test_nearer_light_is_chosen_more_often():
    ls = LightSet([sphere(-2, 0, 0.5), sphere(2, 0, 0.5)])
    pmf = ls.selection_pmf(np.array([[-1.5, 0, 0], [0, 0, 0], [1.5, 0, 0]]))
    assert pmf[0, 0] > 0.9 and np.allclose(pmf[1], 0.5) and pmf[2, 1] > 0.9
    assert np.allclose(pmf.sum(axis=1), 1.0)


def test_one_sided_area_light_is_never_chosen_from_behind():
    area = {"type": "AREA", "matrix_world": translation(0, 0, 1), "power": 50, "size": 1.0}
    ls = LightSet([area, sphere(0, 0, 3)])
    pmf = ls.selection_pmf(np.array([[0, 0, 2.0], [0, 0, 0.0]]))
    assert pmf[0, 0] == 0.0 and pmf[1, 0] > 0.5


def test_power_and_uniform_modes():
    ls = LightSet([sphere(-2, 0, 0.5, power=1.0), sphere(2, 0, 0.5, power=3.0)], selection="POWER")
    assert np.allclose(ls.selection_pmf(np.zeros((2, 3))), [0.25, 0.75])
    ls = LightSet([sphere(-2, 0, 0.5, power=1.0), sphere(2, 0, 0.5, power=3.0)], selection="UNIFORM")
    assert np.allclose(ls.selection_pmf(np.zeros((2, 3))), 0.5)
    with pytest.raises(ValueError, match="unknown light selection"):
        LightSet([sphere(0, 0, 1)], selection="NEAREST")


def test_sample_and_intersect_pdfs_agree_with_many_lights():
    setup = many_lights_points(count=2000)
    ls = setup.lights
    rng = np.random.default_rng(3)
    p = setup.points.p
    s = ls.sample(p, setup.points.n, rng.random(len(p)), rng.random((len(p), 2)))
    h = ls.intersect(p, s.wi, np.inf)
    ok = s.valid & h.hit & (h.light == s.light)
    assert ok.mean() > 0.95
    assert np.allclose(h.pdf[ok], s.pdf[ok], rtol=1e-9)


def test_emissive_and_world_pdfs_use_the_same_selection():
    v = np.array([[[-0.5, -0.5, 1.0], [0.5, -0.5, 1.0], [0.5, 0.5, 1.0]]])
    tris = EmissiveTriangles(v, np.array([[4.0, 4.0, 4.0]]), np.array([7]))
    ls = LightSet([sphere(3, 0, 0.5)], (0.2, 0.2, 0.2), tris)
    assert ls._per_point
    rng = np.random.default_rng(5)
    m = 5000
    p = np.concatenate([rng.uniform(-2, 4, size=(m, 2)), np.zeros((m, 1))], axis=1)
    n = np.tile([0.0, 0.0, 1.0], (m, 1))
    s = ls.sample(p, n, rng.random(m), rng.random((m, 2)))
    em = s.valid & (s.light == ls.emissive_index)
    ng = np.tile([0.0, 0.0, -1.0], (em.sum(), 1))
    assert np.allclose(ls.emissive_pdf(s.prim[em], p[em], p[em] + s.wi[em] * s.dist[em, None], ng), s.pdf[em], rtol=1e-9)
    w = s.valid & (s.light == ls.world_index)
    assert np.allclose(ls.world_pdf(p[w], n[w], s.wi[w]), s.pdf[w], rtol=1e-9)


def _irradiance_exact(setup):
    """Σ over sphere lights fully above the plane: E = π L (r/d)² cos θ = P cos θ/(4π d²)."""
    e = np.zeros(len(setup.points))
    for lt in setup.lights.lights:
        rel = lt.position[None, :] - setup.points.p
        d2 = (rel ** 2).sum(axis=1)
        cos = rel[:, 2] / np.sqrt(d2)
        e += float(lt.intensity @ LUM) * cos / d2
    return 0.8 / math.pi * e


def test_distance_selection_beats_power_selection_with_many_lights():
    """64 lights low over a floor: the unbiased estimates agree with the closed form in both
    modes, and selecting by power/distance² cuts the variance several times."""
    var = {}
    for mode in ("DISTANCE", "POWER"):
        setup = many_lights_points(count=32, selection=mode)
        dl = setup.direct()
        s = dl.direct_samples("LIGHT", setup.points, 512, seed=1) @ LUM
        expected = _irradiance_exact(setup)
        est = s.mean(axis=1)
        se = s.std(axis=1, ddof=1) / math.sqrt(s.shape[1])
        assert np.all(np.abs(est - expected) < 5 * se + 1e-12), mode
        var[mode] = np.mean(s.var(axis=1, ddof=1) / expected ** 2)
    assert var["POWER"] > 4 * var["DISTANCE"], var



# ------------------------------------------------------------------ BSDF-aware selection


def _glossy_hint(m, roughness=0.1, wo=(0.0, -0.5, math.sqrt(0.75)), kd=0.0):
    from drt.lights.selection import ShadingHint
    return ShadingHint(np.tile([0.0, 0.0, 1.0], (m, 1)), np.tile(wo, (m, 1)), np.full(m, kd),
                       np.full(m, 0.8), np.full(m, roughness ** 4), np.zeros(m))


def test_glossy_point_picks_the_light_it_reflects():
    """Two equal lights at equal distance: a diffuse point picks each half the time; a glossy
    point picks the one in its mirror direction, but never less than the defensive share."""
    from drt.lights.selection import DEFENSIVE_SHARE
    mirror = np.array([0.0, 0.5, math.sqrt(0.75)])
    a, b = 3 * mirror, 3 * mirror * np.array([-1, 1, 1])  # b is mirrored across the plane x = 0
    ls = LightSet([sphere(*a), sphere(*b + [0.5, 0, 0])])
    p = np.zeros((1, 3))
    plain = ls.selection_pmf(p)
    guided = ls.selection_pmf(p, _glossy_hint(1))
    # nearly all of the guided share, plus half of the even (defensive) share
    assert guided[0, 0] > 0.95 * (1 - DEFENSIVE_SHARE) + 0.5 * DEFENSIVE_SHARE and np.isclose(guided.sum(), 1.0)
    assert plain[0, 1] > 0.0 and guided[0, 1] >= 0.5 * DEFENSIVE_SHARE * (1 - 1e-12)
    matte = _glossy_hint(1, kd=0.8)
    matte.kg[:] = 0.0
    diffuse = ls.selection_pmf(p, matte)
    assert abs(diffuse[0, 0] - diffuse[0, 1]) < 0.15


def test_a_weak_light_keeps_an_even_share_beside_a_strong_one():
    """Selection sees neither light's occlusion: a 1 W light beside a 4000 W one at the same
    distance above a diffuse point keeps ≥ DEFENSIVE_SHARE / 2 (the even share over the two
    lights reaching it), not a share of its 1/4001 of the irradiance — where the strong light is
    hidden (sss_head's back light behind the head) the weak one is all the light there is, and a
    rare pick of it came back as a firefly (it used to get 0.9·E·B-share + 0.1·E-share ≈ 0.03 %)."""
    from drt.lights.selection import DEFENSIVE_SHARE
    ls = LightSet([sphere(1.0, 0, 2.0, power=4000.0), sphere(-1.0, 0, 2.0, power=1.0)])
    matte = _glossy_hint(1, kd=0.8)
    matte.kg[:] = 0.0
    pmf = ls.selection_pmf(np.zeros((1, 3)), matte)
    assert np.isclose(pmf.sum(), 1.0)
    assert pmf[0, 1] >= 0.5 * DEFENSIVE_SHARE * (1 - 1e-12)
    assert pmf[0, 1] < 0.5 * DEFENSIVE_SHARE + 1e-3  # and the rest follows the estimate
    assert np.allclose(ls.selection_prob(np.zeros((1, 3)), [1], matte), pmf[0, 1])


def test_lights_below_the_horizon_lose_to_lights_above():
    from drt.lights.selection import DEFENSIVE_SHARE, KT_FLOOR
    ls = LightSet([sphere(0, 0, 2.0), sphere(0, 0, -2.0)])
    hint = _glossy_hint(1, roughness=1.0, kd=0.8)
    hint.kt[:] = KT_FLOOR  # (else the light below gets nothing at all: see the next test)
    pmf = ls.selection_pmf(np.zeros((1, 3)), hint)
    assert np.isclose(pmf[0, 1], DEFENSIVE_SHARE * 0.5)  # only the defensive share is left


def test_a_diffuse_point_gives_no_samples_to_a_light_below_its_horizon():
    """A point that only reflects (kt = 0), all its lobes about its normal, cannot reflect a light
    whose whole bounding cone lies below its horizon, so that light gets nothing, not even the
    defensive share (sss_head's SSS exits facing the camera spent 1/8 of their light samples on
    the back light behind the head). A light straddling the horizon keeps its share."""
    from drt.lights.selection import DEFENSIVE_SHARE
    above, below, straddling = sphere(0.3, 0, 2.0), sphere(0, 0.2, -2.0), sphere(2.0, 0, 0.05, r=0.2)
    matte = _glossy_hint(1, kd=0.8)
    matte.kg[:] = 0.0
    p = np.zeros((1, 3))
    pmf = LightSet([above, below]).selection_pmf(p, matte)
    assert pmf[0, 1] == 0.0 and pmf[0, 0] == 1.0
    assert LightSet([above, below]).selection_prob(p, [1], matte)[0] == 0.0
    pmf = LightSet([above, below, straddling]).selection_pmf(p, matte)
    assert pmf[0, 1] == 0.0 and np.isclose(pmf.sum(), 1.0)
    assert pmf[0, 2] >= 0.5 * DEFENSIVE_SHARE * (1 - 1e-12)
    glossy = _glossy_hint(1, roughness=1.0, kd=0.8)  # glossy lobes about n reflect nothing below it either
    assert LightSet([above, below]).selection_pmf(p, glossy)[0, 1] == 0.0


@pytest.mark.parametrize("lobes", ["matte", "glossy"])
def test_light_sampling_stays_unbiased_with_lights_about_the_horizon(lobes):
    """Matte and glossy points tilted every way under lights above, below and across their
    horizons: light sampling (which now skips the lights wholly below) agrees with BSDF
    sampling within 4 standard errors at every point."""
    from drt.estimators import ShadingPoints
    from failure_scenes import DIFFUSE, PointSetup, _materials, glossy
    lights = LightSet([sphere(0.3, 0, 1.5, r=0.3, power=40.0), sphere(0, 0.2, -1.5, r=0.3, power=40.0),
                       sphere(1.5, 0, 0.1, r=0.4, power=40.0)])
    tilt = np.radians([0.0, 30.0, 60.0, 85.0, 100.0, 150.0])
    n = np.stack([np.sin(tilt), np.zeros_like(tilt), np.cos(tilt)], axis=1)
    wo = np.stack([np.sin(tilt + 0.2), np.zeros_like(tilt), np.cos(tilt + 0.2)], axis=1)
    material = _materials(DIFFUSE if lobes == "matte" else DIFFUSE + glossy(0.4))
    setup = PointSetup(lights, material, ShadingPoints(np.zeros((len(tilt), 3)), n, wo, 0))
    x = {m: setup.direct().direct_samples(m, setup.points, 16384, seed=5) @ LUM for m in ("LIGHT", "BSDF")}
    se = np.hypot(x["LIGHT"].std(axis=1), x["BSDF"].std(axis=1)) / math.sqrt(16384)
    assert np.all(x["BSDF"].mean(axis=1) > 0)
    assert np.all(np.abs(x["LIGHT"].mean(axis=1) - x["BSDF"].mean(axis=1)) < 4 * se)


def test_a_tilted_point_keeps_the_defensive_share_below_its_horizon():
    """The hint of a point where a lobe is shaded about another normal than the hint's (a
    smooth mesh's silhouette, a valid-reflection or coat normal: ``path_stages.hint_code``)
    carries kt = KT_FLOOR, so lights below the horizon keep their even share there; the hint of
    any other point carries the material's own kt, and a summary that knows nothing stays so."""
    from drt.lights.selection import DEFENSIVE_SHARE, KT_FLOOR
    from drt.materials import MaterialTable
    from drt.path_stages import HINT_TILTED, hint_code, material_hint
    md = MaterialTable.from_scene([
        {"name": "glossy", "lobes": [{"type": "DIFFUSE", "color": [0.8] * 3},
                                     {"type": "GLOSSY", "color": [0.5] * 3, "roughness": 0.5}], "emission": [0, 0, 0]},
        {"name": "translucent", "lobes": [{"type": "DIFFUSE", "color": [0.8] * 3},
                                          {"type": "TRANSLUCENT", "color": [0.3] * 3}], "emission": [0, 0, 0]},
        {"name": "mirror", "lobes": [{"type": "GLOSSY", "color": [0.9] * 3, "roughness": 0.0}], "emission": [0, 0, 0]},
    ]).data
    n, wo = (0.0, 0.0, 1.0), (0.0, 0.6, 0.8)
    assert hint_code(0, False) == 0 and hint_code(0, True) == HINT_TILTED and hint_code(-1, True) == -1
    assert material_hint(md, hint_code(0, False), n, wo)[5] == 0.0
    assert material_hint(md, hint_code(0, True), n, wo)[5] == KT_FLOOR
    assert material_hint(md, hint_code(1, True), n, wo)[5] == material_hint(md, 1, n, wo)[5] > 0.1
    assert material_hint(md, -1, n, wo)[2:] == (0.0, 0.0, 0.0, 0.0)
    # a summary that knows nothing (a mirror: no lobe NEE can reach) stays unknown when tilted
    mirror = material_hint(md, hint_code(2, True), n, wo)
    assert mirror[2] + mirror[3] + mirror[5] == 0.0
    ls = LightSet([sphere(0.3, 0, 2.0), sphere(0, 0.2, -2.0)])
    tilted = _glossy_hint(1, roughness=1.0, kd=0.8)
    tilted.kt[:] = KT_FLOOR
    assert np.isclose(ls.selection_pmf(np.zeros((1, 3)), tilted)[0, 1], 0.5 * DEFENSIVE_SHARE)


def test_guided_sample_and_intersect_pdfs_agree():
    """MIS needs the pdf a BSDF-sampled ray sees (intersect from the offset origin, with the
    shading point and hint) to be the one light sampling used."""
    setup = many_lights_points(count=2000)
    ls = setup.lights
    rng = np.random.default_rng(7)
    p = setup.points.p
    hint = _glossy_hint(len(p), roughness=0.3, kd=0.2)
    s = ls.sample(p, setup.points.n, rng.random(len(p)), rng.random((len(p), 2)), hint)
    o = p + 1e-4 * setup.points.n
    h = ls.intersect(o, s.wi, np.inf, origin=p, hint=hint)
    ok = s.valid & h.hit & (h.light == s.light)
    assert ok.mean() > 0.95
    assert np.allclose(h.pdf[ok], s.pdf[ok], rtol=1e-4)
    # without the hint the selection differs, so the pdfs would not agree
    h0 = ls.intersect(o, s.wi, np.inf, origin=p)
    assert not np.allclose(h0.pdf[ok], s.pdf[ok], rtol=1e-4)


def test_guided_selection_is_unbiased_on_veachs_plates():
    """Light sampling with the guided selection agrees with BSDF sampling (which never
    selects a light) within 4 standard errors at every point of every plate."""
    from failure_scenes import PLATE_ROUGHNESS, veach_points
    for plate in range(len(PLATE_ROUGHNESS)):
        setup = veach_points(plate)
        x = {m: setup.direct().direct_samples(m, setup.points, 8192, seed=3) @ LUM for m in ("LIGHT", "BSDF", "MIS_POWER")}
        ref = x["BSDF"].mean(axis=1)
        for m in ("LIGHT", "MIS_POWER"):
            se = np.hypot(x[m].std(axis=1), x["BSDF"].std(axis=1)) / math.sqrt(8192)
            assert np.all(np.abs(x[m].mean(axis=1) - ref) < 4 * se), (plate, m)


def test_guided_pdfs_agree_for_suns_world_and_emissive_triangles():
    """With a hint, the selection of a sun (a direction), the world (hemisphere average) and the
    emissive group is the same function in `sample` as in `intersect` / `world_pdf` /
    `emissive_pdf`."""
    v = np.array([[[-0.5, -0.5, 1.0], [0.5, -0.5, 1.0], [0.5, 0.5, 1.0]]])
    tris = EmissiveTriangles(v, np.array([[4.0, 4.0, 4.0]]), np.array([7]))
    sun = {"type": "SUN", "matrix_world": translation(0, 0, 0), "strength": 3.0, "angle": 0.2}
    ls = LightSet([sphere(3, 0, 0.5), sun], (0.2, 0.2, 0.2), tris)
    rng = np.random.default_rng(11)
    m = 6000
    p = np.concatenate([rng.uniform(-2, 4, size=(m, 2)), np.zeros((m, 1))], axis=1)
    n = np.tile([0.0, 0.0, 1.0], (m, 1))
    hint = _glossy_hint(m, roughness=0.4, kd=0.3)
    s = ls.sample(p, n, rng.random(m), rng.random((m, 2)), hint)
    counts = np.bincount(s.light[s.valid], minlength=ls.count)
    assert np.all(counts > 100), counts  # every strategy is still chosen (defensive share)
    em = s.valid & (s.light == ls.emissive_index)
    ng = np.tile([0.0, 0.0, -1.0], (em.sum(), 1))
    assert np.allclose(ls.emissive_pdf(s.prim[em], p[em], p[em] + s.wi[em] * s.dist[em, None], ng,
                                       hint.subset(em)), s.pdf[em], rtol=1e-9)
    w = s.valid & (s.light == ls.world_index)
    assert np.allclose(ls.world_pdf(p[w], n[w], s.wi[w], hint.subset(w)), s.pdf[w], rtol=1e-9)
    su = s.valid & (s.light == 1)
    h = ls.intersect(p[su], s.wi[su], np.inf, hint=hint.subset(su))
    ok = h.light == 1
    assert ok.mean() > 0.9 and np.allclose(h.pdf[ok], s.pdf[su][ok], rtol=1e-9)


def test_constant_world_is_found_by_bsdf_rays_not_sampled():
    """As in Cycles, a constant-colour world is not a next-event strategy: BSDF rays find it with
    a pdf ∝ the diffuse integrand, and sampling it as a light only adds the variance of choosing
    between it and the sun. Same mean, and at least 3x less pixel variance (measured ~10x)."""
    from drt.render import prepare, render
    from drt.scene import scene_from_dict
    from scene_builders import add_material, add_mesh, base_header, look_at, quad

    h = base_header(16, 16, 64, world=(0.5, 0.5, 0.5),
                    camera={"type": "PERSP", "matrix_world": look_at((0, -3, 3), (0, 0, 0)), "lens": 50.0})
    a = {}
    m = add_material(h, "white", [{"type": "DIFFUSE", "color": [0.8, 0.8, 0.8]}])
    add_mesh(h, a, "floor", *quad((0, 0, 0), (3, 0, 0), (0, 3, 0)), material=m)
    h["lights"].append({"type": "SUN", "matrix_world": np.eye(4).tolist(), "strength": 3.0, "angle": 0.01})
    scene = scene_from_dict(h, a)
    ctx = prepare(scene)
    assert ctx.integrator.lights.count == 1  # the sun only
    without = render(scene, context=ctx, threads=1)
    geom = ctx.integrator.geom
    ctx.integrator.lights = LightSet(scene.lights, scene.world_color, None, origin_shift=geom.origin_shift,
                                     scene_radius=geom.scene_radius, world_nee=True)
    assert ctx.integrator.lights.count == 2
    with_world = render(scene, context=ctx, threads=1)
    a_mean, b_mean = without.combined[..., :3].mean(), with_world.combined[..., :3].mean()
    assert abs(a_mean / b_mean - 1) < 0.01
    assert without.variance.mean() < with_world.variance.mean() / 3


@pytest.mark.parametrize("count", [12, 20])
def test_cached_selection_walk_chooses_exactly_as_the_two_pass_walk(count):
    """`select_strategy` keeps each strategy's weights between its passes when there are at most
    CACHED_STRATEGIES (else it recomputes them): either way (index, probability, rescaled u)
    must equal, bit for bit, a walk over `strategy_prob` after `selection_totals`."""
    from drt.lights import selection as sel

    rng = np.random.default_rng(12)
    ls = LightSet([sphere(*rng.uniform(-3, 3, 3), power=float(rng.uniform(1, 20))) for _ in range(count)])
    ld = ls.data
    assert ld.per_point and ld.n_strategies == count
    for k in range(60):
        p = tuple(rng.uniform(-3, 3, 3))
        n = tuple(rng.normal(size=3) / 1.7)
        guided = k % 3 != 0
        hint = (n, (0.0, 0.6, 0.8), 0.3 if guided else 0.0, 0.5 if guided else 0.0, 0.2, 0.0)
        u = float(rng.random())
        totals = sel.selection_totals(ld, p, hint, sel.hint_known(hint))
        c, want = 0.0, None
        last = (-1, 0.0, 0.0)
        for j in range(count):
            pj = sel.strategy_prob(ld, j, p, hint, sel.hint_known(hint), totals)
            c += pj
            cj = 1.0 if j == count - 1 else c
            if u < cj or j == count - 1:
                want = sel._finish_select(u, j, pj, cj, *last)
                break
            if pj > 0.0:
                last = (j, pj, cj)
        assert sel.select_strategy(ld, p, hint, u) == want


def test_bsdf_factor_cone_bound_equals_the_angle_formula():
    """`bsdf_factor` bounds the cosine over a light's cone with cos θ cos θ_L + sin θ sin θ_L
    (θ > θ_L; else 1) instead of cos(acos(cos θ) − asin(sin θ_L)): the same function up to
    round-off, over directions above, at and below the horizon, small and huge cones, and the
    diffuse-only, glossy and glass summaries."""
    from drt.lights import selection as sel

    rng = np.random.default_rng(21)
    n = (0.0, 0.0, 1.0)
    wo = (0.6, 0.0, 0.8)
    checked = 0
    for k in range(3000):
        wi = rng.normal(size=3)
        wi /= np.linalg.norm(wi)
        if k % 10 == 0:  # exactly at the normal or at the horizon
            wi = np.array([0.0, 0.0, 1.0]) if k % 20 == 0 else np.array([1.0, 0.0, 0.0])
        dist = float(rng.uniform(0.1, 10.0))
        radius2 = float(rng.choice([0.0, 1e-6, 0.01, 1.0, 200.0]))  # 200 > dist²: θ_L = 90°
        kd, kg, alpha, kt = [(0.8, 0.0, 0.0, 0.0), (0.3, 0.5, 0.2, 0.0), (0.0, 0.0, 0.0, 0.9)][k % 3]
        to_light = tuple(float(x) for x in wi * dist)
        got = sel.bsdf_factor(to_light, radius2, (n, wo, kd, kg, alpha, kt))
        # the angle formula of the module docstring, in numpy
        sin_l = math.sqrt(min(radius2 / dist ** 2, 1.0))
        theta = math.acos(float(np.clip(wi[2], -1, 1))) - math.asin(sin_l)
        cos_bound = math.cos(theta) if theta > 0 else 1.0
        if kg > 0 and abs(cos_bound) < 1e-12:
            continue  # the cone's edge exactly on the horizon: cos(π/2) rounds to 6e-17 > 0
        want = kd / math.pi * max(cos_bound, 0.0) + kt / math.pi
        if kg > 0 and cos_bound > 0:
            h = wi + np.array(wo)
            cos_h = max(h[2] / np.linalg.norm(h), 0.0)
            a2 = alpha ** 2 + 0.25 * sin_l ** 2
            want += kg / (4 * max(wo[2], 1e-2)) * a2 / (math.pi * (cos_h ** 2 * (a2 - 1) + 1) ** 2)
        assert got == pytest.approx(want, rel=1e-9, abs=1e-12), (k, wi, radius2)
        checked += cos_bound < 1.0 and cos_bound > 0.0
    assert checked > 500  # the cone bound's formula itself was exercised, not only its clamps
