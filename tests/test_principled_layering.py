"""Principled v2 dielectric layering (issue 11): the DIELECTRIC_SPECULAR lobe (GGX × dielectric
Fresnel, multiscatter compensation) and the per-hit 1 − E(wo) weight of the layers below it,
against analytic/Monte Carlo checks and against Cycles under a delta sun."""

import math

import numpy as np
import pytest

from drt.materials.table import MaterialTable

from stats_util import material_chi_square


def _table(rough=0.5, ior=1.5, tint=(1, 1, 1), ms=True, base=(1, 1, 1)):
    return MaterialTable.from_scene([{"name": "p", "lobes": [
        {"type": "DIELECTRIC_SPECULAR", "color": [1, 1, 1], "roughness": rough, "ior": ior,
         "tint": list(tint), "multiscatter": ms},
        {"type": "DIFFUSE", "color": list(base), "layer": 0}]},
        {"name": "spec", "lobes": [
            {"type": "DIELECTRIC_SPECULAR", "color": [1, 1, 1], "roughness": rough, "ior": ior,
             "tint": list(tint), "multiscatter": ms}]}])


def _wo(mu, n):
    return np.tile([math.sqrt(1 - mu * mu), 0.0, mu], (n, 1))


@pytest.mark.parametrize("rough", [0.1, 0.5, 0.9])
@pytest.mark.parametrize("mu", [0.15, 0.6, 0.95])
def test_white_furnace_layered_energy(rough, mu):
    """A white diffuse under the specular layer reflects ≤ 1 and, with multiscatter, close to 1
    (Cycles's albedo estimate is what the base loses); sample() and eval() agree."""
    t = _table(rough)
    n = 200_000
    rng = np.random.default_rng(7)
    s = t.sample(np.zeros(n, int), _wo(mu, n), rng.random(n), rng.random((n, 2)))
    a = s.weight[:, 0].mean()
    err = 3 * s.weight[:, 0].std() / math.sqrt(n)
    z = rng.random(n)
    ph = 2 * np.pi * rng.random(n)
    r = np.sqrt(1 - z * z)
    f, pdf = t.eval(np.zeros(n, int), _wo(mu, n), np.stack([r * np.cos(ph), r * np.sin(ph), z], 1))
    b = (f[:, 0] * 2 * np.pi).mean()
    # (≤ 1 up to the albedo tables' interpolation: 1.0002 at rough 0.1, mu 0.6 by quadrature)
    assert a <= 1.0 + err + 5e-4
    assert a > 0.95, a  # table estimate vs exact albedo: within a few %
    assert abs(a - b) < err + 3 * (f[:, 0] * 2 * np.pi).std() / math.sqrt(n)
    assert (pdf * 2 * np.pi).mean() <= 1.0 + 0.02


def test_absorbing_base_keeps_only_the_specular_layer():
    """Black base: the furnace albedo is the specular layer's own (multiscatter GGX with Fresnel,
    ≈ Fss for IOR 1.5 ~ 0.09 at normal incidence, more at grazing), = 1 − absorbed."""
    from drt.materials.dielectric_specular import layer_weight

    t = _table(0.5, base=(0, 0, 0))
    n = 200_000
    rng = np.random.default_rng(3)
    f0 = 0.04
    for mu, lo, hi in ((0.95, 0.035, 0.05), (0.2, 0.08, 0.25)):
        s = t.sample(np.zeros(n, int), _wo(mu, n), rng.random(n), rng.random((n, 2)))
        spec = t.sample(np.ones(n, int), _wo(mu, n), rng.random(n), rng.random((n, 2)))
        a, b = s.weight[:, 0].mean(), spec.weight[:, 0].mean()
        assert lo < a < hi, (mu, a)
        assert abs(a - b) < 0.005, (a, b)
        # the albedo the lower layers lose is Cycles's tabulated estimate (darkening × the mean
        # Fresnel remap over visible normals): close to the layer's actual albedo
        est = 1.0 - layer_weight(0.25, 1.5, (f0, f0, f0), True, mu)
        assert abs(est / a - 1) < 0.07, (mu, est, a)


def test_multiscatter_vs_ggx():
    """f0·tint = 1 (a white mirror-like Fresnel): multiscatter GGX keeps all the energy
    (furnace 1), single-scatter GGX its directional albedo E(r, mu) from the table; with the
    plain dielectric Fresnel (F0 0.04) the compensation adds little (multiple bounces mostly
    refract), as in Cycles."""
    from drt.materials.dielectric_specular import GGX_E, table_2d

    n = 200_000
    rng = np.random.default_rng(5)
    for rough, mu in ((0.9, 0.7), (0.5, 0.3)):
        out = {}
        for ms in (True, False):
            t = _table(rough, ms=ms, tint=(25, 25, 25), base=(0, 0, 0))
            w = t.sample(np.ones(n, int), _wo(mu, n), rng.random(n), rng.random((n, 2))).weight[:, 0]
            out[ms] = (w.mean(), 3 * w.std() / math.sqrt(n))
        assert abs(out[True][0] - 1.0) < out[True][1] + 0.01, out
        assert abs(out[False][0] - table_2d(GGX_E, rough, mu)) < out[False][1] + 0.01, out
    t = {ms: _table(0.9, ms=ms, base=(0, 0, 0)) for ms in (True, False)}
    a = {ms: t[ms].sample(np.ones(n, int), _wo(0.7, n), rng.random(n), rng.random((n, 2))).weight[:, 0].mean()
         for ms in (True, False)}
    assert 1.02 < a[True] / a[False] < 1.15, a


def test_sampling_chi_square():
    """Directions sampled from the layered material follow its pdf (chi-square over a
    θ×φ grid, expected counts from eval's pdf)."""
    t = _table(0.4, base=(0.5, 0.3, 0.2))
    n = 200_000
    p, valid, mass, _ = material_chi_square(t, 0, _wo(0.5, n), n, np.random.default_rng(11), refine=64)
    assert p > 1e-3, p
    assert abs(valid - mass) < 0.01


@pytest.mark.parametrize("ms", [True, False])
def test_metallic_lobe_energy_and_consistency(ms):
    """METALLIC (F82-tint): a white F0 with Multiscatter GGX keeps all energy (furnace 1), GGX
    keeps E(r, mu); a coloured one with a tint: sample() agrees with eval() integrated
    uniformly, and the tint darkens grazing reflection only."""
    from drt.materials.dielectric_specular import GGX_E, table_2d

    n = 200_000
    rng = np.random.default_rng(13)
    t = MaterialTable.from_scene([
        {"name": "w", "lobes": [{"type": "METALLIC", "color": [1, 1, 1], "weight": 1.0, "roughness": 0.8,
                                 "multiscatter": ms}]},
        {"name": "c", "lobes": [{"type": "METALLIC", "color": [0.45, 0.3, 0.15], "weight": 0.5, "roughness": 0.4,
                                 "tint": [0.5, 0.8, 1.0], "multiscatter": ms}]}])
    w = t.sample(np.zeros(n, int), _wo(0.6, n), rng.random(n), rng.random((n, 2))).weight[:, 0]
    expect = 1.0 if ms else table_2d(GGX_E, 0.8, 0.6)
    assert abs(w.mean() - expect) < 3 * w.std() / math.sqrt(n) + 0.01, (w.mean(), expect)
    for mu in (0.9, 0.2):
        s = t.sample(np.ones(n, int), _wo(mu, n), rng.random(n), rng.random((n, 2)))
        z = rng.random(n)
        ph = 2 * np.pi * rng.random(n)
        r = np.sqrt(1 - z * z)
        f, _ = t.eval(np.ones(n, int), _wo(mu, n), np.stack([r * np.cos(ph), r * np.sin(ph), z], 1))
        a, b = s.weight.mean(0), (f * 2 * np.pi).mean(0)
        assert np.all(np.abs(a - b) < 3 * (f * 2 * np.pi).std(0) / math.sqrt(n) + 1e-3), (a, b)
        assert np.all(a <= 0.5 + 1e-3)  # weight 0.5 × an albedo ≤ 1


def test_validation_and_no_layer_tables():
    with pytest.raises(ValueError, match="lobe 1: layer must be"):
        MaterialTable.from_scene([{"name": "x", "lobes": [
            {"type": "DIFFUSE", "color": [1, 1, 1]}, {"type": "DIFFUSE", "color": [1, 1, 1], "layer": 0}]}])
    with pytest.raises(ValueError, match="ior is missing"):
        MaterialTable.from_scene([{"name": "x", "lobes": [
            {"type": "DIELECTRIC_SPECULAR", "color": [1, 1, 1], "roughness": 0.5}]}])
    t = MaterialTable.from_scene([{"name": "d", "lobes": [{"type": "DIFFUSE", "color": [0.5, 0.5, 0.5]}]}])
    assert not t.data.has_layers.any() and t.data.pure_diffuse[0]


@pytest.mark.slow
def test_principled_spheres_under_a_sun_match_cycles(tmp_path):
    """Principled spheres (no bounces, a delta sun: direct light is exact at one sample in both
    engines): base colours, roughness 0.05–1, specular IOR levels, IORs, tints, GGX and
    Multiscatter GGX, a textured base colour and roughness, a Mix with a Diffuse, metals. Each
    tile's channel means within 1 % of Cycles's (measured ≤ 0.6 %)."""
    pytest.importorskip("bpy")
    from node_parity import node, render_tiles, tile

    def principled(base, rough, ior=1.5, level=0.5, tint=(1, 1, 1, 1), dist="MULTI_GGX", metal=0.0):
        def case(nt, uv):
            n = node(nt, "ShaderNodeBsdfPrincipled", {"Base Color": base, "Roughness": rough, "IOR": ior,
                                                      "Specular IOR Level": level, "Specular Tint": tint,
                                                      "Metallic": metal})
            n.distribution = dist
            return n.outputs[0]
        return case

    def textured(nt, uv):  # a program-driven base colour and roughness (per-hit lobe data)
        ck = node(nt, "ShaderNodeTexChecker", {"Vector": uv, "Scale": 3.0, "Color1": (0.9, 0.3, 0.1, 1),
                                               "Color2": (0.1, 0.3, 0.8, 1)})
        rough = node(nt, "ShaderNodeMapRange", {0: ck.outputs["Fac"], 3: 0.2, 4: 0.7})
        return node(nt, "ShaderNodeBsdfPrincipled", {"Base Color": ck.outputs["Color"],
                                                     "Roughness": rough.outputs[0]}).outputs[0]

    def mixed(nt, uv):  # the layered pair inside a Mix shader with a Diffuse
        p = principled((0.8, 0.8, 0.1, 1), 0.35)(nt, uv)
        d = node(nt, "ShaderNodeBsdfDiffuse", {"Color": (0.2, 0.6, 0.9, 1)})
        return node(nt, "ShaderNodeMixShader", {0: 0.4, 1: p, 2: d.outputs[0]}).outputs[0]

    cases = [principled((0.8, 0.1, 0.1, 1), 0.1), principled((0.1, 0.5, 0.8, 1), 0.3),
             principled((0.9, 0.9, 0.9, 1), 0.5), principled((0.05, 0.05, 0.05, 1), 0.7),
             principled((0.3, 0.7, 0.2, 1), 0.9), principled((0.8, 0.6, 0.2, 1), 0.4, level=1.0),
             principled((0.2, 0.3, 0.8, 1), 0.4, level=0.2), principled((0.5, 0.5, 0.5, 1), 0.3, ior=2.2),
             principled((0.6, 0.2, 0.6, 1), 0.5, ior=1.2), principled((0.7, 0.7, 0.2, 1), 0.6,
                                                                      tint=(1.0, 0.5, 0.2, 1)),
             principled((0.1, 0.1, 0.1, 1), 0.9, dist="GGX"), principled((0.8, 0.4, 0.1, 1), 0.2, dist="GGX"),
             principled((0.02, 0.02, 0.02, 1), 0.25), principled((0.4, 0.4, 0.4, 1), 0.05),
             principled((0.9, 0.5, 0.3, 1), 1.0), principled((0.3, 0.3, 0.3, 1), 0.5, level=0.0),
             textured, mixed, principled((0.5, 0.8, 0.9, 1), 0.8, ior=1.33, level=0.8, dist="GGX"),
             principled((0.2, 0.2, 0.6, 1), 0.85, tint=(0.3, 1.0, 0.6, 1)),
             # metallic (F82-tint Fresnel, multiscatter): was up to −59 % with the GLOSSY stand-in
             principled((0.9, 0.6, 0.3, 1), 0.5, metal=1.0), principled((0.9, 0.6, 0.3, 1), 0.9, metal=1.0),
             principled((0.8, 0.2, 0.2, 1), 0.4, metal=0.5),
             principled((0.9, 0.9, 0.9, 1), 0.3, metal=1.0, tint=(0.5, 0.7, 1.0, 1)),
             principled((0.95, 0.95, 0.95, 1), 1.0, metal=1.0)]
    cycles, drt, res = render_tiles(cases, 5, tmp_path, shader=True, sun=(3.0, (0.6, 0.2, 0.3)),
                                    shape="sphere")
    assert not res.warnings, res.warnings
    errs = []
    for k in range(len(cases)):
        a, b = tile(cycles, k, 5), tile(drt, k, 5)
        assert a.mean() > 0.01
        errs.append(b.reshape(-1, 3).mean(0) / a.reshape(-1, 3).mean(0) - 1)
    errs = np.array(errs)
    print("per-tile channel mean errors (%):\n", np.round(100 * errs, 2))
    assert np.abs(errs).max() < 0.01, np.round(100 * errs, 2)


@pytest.mark.slow
def test_principled_spheres_in_a_white_world_match_cycles(tmp_path):
    """Indirect light: Principled spheres (and the ground between them) in a uniform white world
    with bounces, equal samples (256): per-tile channel means within 2 % of Cycles's. Exercises
    BSDF sampling, MIS with the world and the per-hit layering at every bounce. Measured (2048
    spp, converged): −0.1 … −1.3 %, always darker; the same scene with the plain Glossy BSDF
    (a lobe this work does not touch) is −0.2 … −1.7 % darker, so the residual is not the
    layering (likely Cycles's specular-normal correction at smooth silhouettes, which DRT applies
    only to normal-mapped hits). Before Principled v2 (constant F_avg split) the same test gave
    up to −3.1 %."""
    pytest.importorskip("bpy")
    from drt.render import render
    from drt.scene import scene_from_dict
    from addon.export import export_depsgraph
    from node_parity import TILE, _add_shape, _material, node, setup_scene, tile
    import _common as C

    n = 3
    SPP = int(__import__("os").environ.get("DRT_TEST_SPP", 256))
    cases = [(0.8, 0.1, 0.1, 0.2), (0.1, 0.5, 0.8, 0.5), (0.9, 0.9, 0.9, 0.9), (0.05, 0.05, 0.05, 0.3),
             (0.3, 0.7, 0.2, 0.05), (0.8, 0.6, 0.2, 0.7), (0.5, 0.5, 0.5, 0.4), (0.9, 0.4, 0.6, 1.0),
             (0.2, 0.2, 0.2, 0.15)]
    sc = setup_scene(n)
    size = 2.0 / n
    for k, (r, g, b, rough) in enumerate(cases):
        row, col = divmod(k, n)
        _add_shape("sphere", size, (-1 + (col + 0.5) * size, 1 - (row + 0.5) * size, 0))

        def case(nt, uv, base=(r, g, b, 1), rough=rough):
            return node(nt, "ShaderNodeBsdfPrincipled", {"Base Color": base, "Roughness": rough}).outputs[0]
        bpy_obj = __import__("bpy").context.object
        bpy_obj.data.materials.append(_material(f"w{k}", case, True))
    C.reference_settings(sc, samples=SPP)
    sc.cycles.filter_width = 0.01  # both engines read Cycles's pixel filter
    sc.render.resolution_x = sc.render.resolution_y = n * TILE
    sc.cycles.use_light_tree = False
    sc.world.node_tree.nodes["Background"].inputs[1].default_value = 1.0
    sc.drt.samples = SPP
    sc.drt.max_bounces = 12
    path = str(tmp_path / "world.exr")
    sc.render.filepath = path
    import bpy

    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(path)
    w = n * TILE
    cycles = np.array(img.pixels[:], dtype=np.float64).reshape(w, w, 4)[::-1, :, :3]
    res = export_depsgraph(bpy.context.evaluated_depsgraph_get())
    drt = np.asarray(render(scene_from_dict(res.header, res.arrays), threads=2).combined, np.float64)[..., :3]
    assert not res.warnings, res.warnings
    errs = np.array([tile(drt, k, n).reshape(-1, 3).mean(0) / tile(cycles, k, n).reshape(-1, 3).mean(0) - 1
                     for k in range(len(cases))])
    print("per-tile channel mean errors (%):\n", np.round(100 * errs, 2))
    assert np.abs(errs).max() < 0.02, np.round(100 * errs, 2)


@pytest.mark.slow
def test_subsurface_under_the_specular_layer_matches_cycles(tmp_path):
    """Principled subsurface (Random Walk) with Specular IOR Level 0.5: the SSS lobe lies under
    the specular layer (scaled per hit by 1 − E(wo)); lit-disk channel means at 256 spp within
    1.5 % of Cycles's."""
    pytest.importorskip("bpy")
    import os
    import sys

    sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scripts"))
    from test_subsurface_cycles import _render_both, sss_scene

    scene = sss_scene("RANDOM_WALK", spec=0.5)
    drt, cyc = _render_both(scene, tmp_path, 256)
    y, x = np.mgrid[0:48, 0:48]
    disk = (x - 23.5) ** 2 + (y - 23.5) ** 2 < 14 ** 2
    ratio = drt[disk].mean(0) / cyc[disk].mean(0)
    print("SSS under the specular layer, DRT / Cycles:", ratio)
    assert np.all(np.abs(ratio - 1) < 0.015), ratio


@pytest.mark.slow
def test_textured_metal_under_a_sun_matches_cycles(tmp_path):
    """A metal whose base colour and roughness come from a checker (F0 = colour register /
    weight per hit) and a half-metal with a textured base: tile means within 1 % of Cycles's."""
    pytest.importorskip("bpy")
    from node_parity import node, render_tiles, tile

    def textured(metal):
        def case(nt, uv):
            ck = node(nt, "ShaderNodeTexChecker", {"Vector": uv, "Scale": 3.0, "Color1": (0.95, 0.7, 0.3, 1),
                                                   "Color2": (0.6, 0.6, 0.65, 1)})
            rough = node(nt, "ShaderNodeMapRange", {0: ck.outputs["Fac"], 3: 0.25, 4: 0.75})
            return node(nt, "ShaderNodeBsdfPrincipled", {"Base Color": ck.outputs["Color"], "Metallic": metal,
                                                         "Roughness": rough.outputs[0]}).outputs[0]
        return case

    cases = [textured(1.0), textured(0.6)]
    cycles, drt, res = render_tiles(cases, 2, tmp_path, shader=True, sun=(3.0, (0.6, 0.2, 0.3)), shape="sphere")
    assert not res.warnings, res.warnings
    errs = np.array([tile(drt, k, 2).reshape(-1, 3).mean(0) / tile(cycles, k, 2).reshape(-1, 3).mean(0) - 1
                     for k in range(len(cases))])
    print("textured metal errors (%):", np.round(100 * errs, 2))
    assert np.abs(errs).max() < 0.01, np.round(100 * errs, 2)
