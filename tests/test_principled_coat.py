"""Principled coat and sheen, Sheen BSDF (issue 11): the SHEEN (microfiber LTC) and VELVET
(Ashikhmin) lobes, chained layers (diffuse under specular under coat under sheen) with the coat
tint's absorption, against sampling/eval checks and against Cycles under a delta sun."""

import math

import numpy as np
import pytest

from drt.materials.table import MaterialTable

from stats_util import material_chi_square


def _wo(mu, n):
    return np.tile([math.sqrt(1 - mu * mu), 0.0, mu], (n, 1))


def _uniform_dirs(rng, n):
    z = rng.random(n)
    ph = 2 * np.pi * rng.random(n)
    r = np.sqrt(1 - z * z)
    return np.stack([r * np.cos(ph), r * np.sin(ph), z], 1)


SHEEN = {"type": "SHEEN", "color": [1, 1, 1], "roughness": 0.5}
VELVET = {"type": "VELVET", "color": [1, 1, 1], "roughness": 0.4}


def _stack(sheen_w=0.6, coat_w=1.0, tint=(1, 1, 1), base=(1, 1, 1), coat_r=0.3, sheen_r=0.5):
    """A Principled-like chain, top first: sheen → coat → specular → diffuse."""
    return {"name": "stack", "lobes": [
        {"type": "SHEEN", "color": [sheen_w] * 3, "roughness": sheen_r, "layer_weight": sheen_w},
        {"type": "DIELECTRIC_SPECULAR", "color": [coat_w] * 3, "roughness": coat_r, "ior": 1.5,
         "layer": 0, "layer_weight": coat_w, "coat_tint": list(tint)},
        {"type": "DIELECTRIC_SPECULAR", "color": [1, 1, 1], "roughness": 0.5, "ior": 1.45, "layer": 1},
        {"type": "DIFFUSE", "color": list(base), "layer": 2}]}


def _chi_square(t, mat, mu, seed):
    n = 200_000
    p, valid, mass, _ = material_chi_square(t, mat, _wo(mu, n), n, np.random.default_rng(seed))
    assert p > 1e-3, p
    # directions lost below the horizon (the LTC's mass there) are exactly the invalid samples
    assert abs(valid - mass) < 0.01, (valid, mass)


@pytest.mark.parametrize("mu", [0.15, 0.7])
def test_sampling_chi_square(mu):
    """Directions sampled from a sheen, a velvet and the full coat/sheen chain follow the pdf
    eval reports (chi-square over a cos θ × φ grid)."""
    t = MaterialTable.from_scene([{"name": "s", "lobes": [SHEEN]}, {"name": "v", "lobes": [VELVET]},
                                  _stack(base=(0.5, 0.3, 0.2))])
    for mat in range(3):
        _chi_square(t, mat, mu, 17 + mat)


@pytest.mark.parametrize("mu", [0.2, 0.6, 0.95])
def test_sample_weight_matches_eval_and_furnace(mu):
    """E[sample weight] = ∫ f cos (eval integrated uniformly) per channel, for sheen, velvet and
    the chain; a white chain reflects ≤ 1 (energy conserving layering) and ≥ 0.9 (the layers
    pass on what they do not reflect); a sheen's weight is its tabulated albedo A(r, mu)."""
    from drt.materials.sheen import sheen_albedo

    t = MaterialTable.from_scene([{"name": "s", "lobes": [SHEEN]}, {"name": "v", "lobes": [VELVET]},
                                  _stack(), _stack(tint=(0.9, 0.5, 0.2), sheen_w=1.0, coat_r=0.05)])
    n = 200_000
    rng = np.random.default_rng(int(mu * 100))
    for mat in range(4):
        s = t.sample(np.full(n, mat), _wo(mu, n), rng.random(n), rng.random((n, 2)))
        f, pdf = t.eval(np.full(n, mat), _wo(mu, n), _uniform_dirs(rng, n))
        a, b = s.weight.mean(0), (f * 2 * np.pi).mean(0)
        tol = 3 * np.hypot(s.weight.std(0), (f * 2 * np.pi).std(0)) / math.sqrt(n) + 1e-4
        assert np.all(np.abs(a - b) < tol), (mat, a, b, tol)
        if mat == 0:
            assert abs(a[0] - sheen_albedo(0.25, mu)) < 1e-9
        if mat == 2:
            assert 0.9 < a[0] <= 1.0 + tol[0], a
        assert np.all(a <= 1.0 + tol)


def test_chain_layer_weights_are_products():
    """Per hit, a lobe's scale is the product over the layers above it of 1 − k·albedo(wo), and
    a tinted coat's absorption mix(1, tint^(1/cos θt), k): eval of the diffuse at the bottom of
    sheen → coat → specular equals Lambert × those factors."""
    from drt.materials.dielectric_specular import layer_weight
    from drt.materials.sheen import sheen_albedo

    tint = (0.8, 0.5, 0.1)
    ks, kc = 0.6, 0.7
    t = MaterialTable.from_scene([_stack(sheen_w=ks, coat_w=kc, tint=tint, base=(1, 1, 1))])
    # isolate the diffuse: zero the colours of the layers (their albedo estimates stay)
    t.data.lobe_color[0, :3] = 0.0
    for mu in (0.3, 0.8):
        wo = (math.sqrt(1 - mu * mu), 0.0, mu)
        wi = np.array([[0.3, 0.2, math.sqrt(1 - 0.13)]])
        f, _ = t.eval([0], np.array([wo]), wi)
        ws = 1 - ks * sheen_albedo(0.25, mu)
        wc = 1 - kc * (1 - layer_weight(0.09, 1.5, (0.04, 0.04, 0.04), True, mu))
        wsp = layer_weight(0.25, 1.45, (((1.45 - 1) / 2.45) ** 2,) * 3, True, mu)
        cos_t = math.sqrt(1 - (1 - mu * mu) / 1.5 ** 2)
        absorb = 1 + kc * (np.array(tint) ** (1 / cos_t) - 1)
        np.testing.assert_allclose(f[0], wi[0, 2] / math.pi * ws * wc * wsp * absorb, rtol=1e-9)


def test_dropped_layer_passes_its_lobes_up_and_validation():
    """A black (dropped) layer in the middle of the chain: the lobes under it lie under the
    layer above it. Loops, layers naming non-layer lobes and misplaced layer fields fail with
    the field named."""
    t = MaterialTable.from_scene([{"name": "x", "lobes": [
        dict(SHEEN, layer_weight=0.5),
        {"type": "DIELECTRIC_SPECULAR", "color": [0, 0, 0], "roughness": 0.3, "ior": 1.5, "layer": 0},
        {"type": "DIFFUSE", "color": [1, 1, 1], "layer": 1}]}])
    assert list(t.data.lobe_layer[0, :2]) == [-1, 0] and t.data.has_layers[0]
    with pytest.raises(ValueError, match="lobe 0: layer chain loops"):
        MaterialTable.from_scene([{"name": "x", "lobes": [dict(SHEEN, layer=1), dict(SHEEN, layer=0)]}])
    with pytest.raises(ValueError, match="layer must be the index of a DIELECTRIC_SPECULAR or SHEEN"):
        MaterialTable.from_scene([{"name": "x", "lobes": [VELVET, dict(SHEEN, layer=0)]}])
    with pytest.raises(ValueError, match="coat_tint is only allowed"):
        MaterialTable.from_scene([{"name": "x", "lobes": [dict(SHEEN, coat_tint=[1, 1, 1])]}])
    with pytest.raises(ValueError, match="layer_weight must be >= 0"):
        MaterialTable.from_scene([{"name": "x", "lobes": [dict(SHEEN, layer_weight=-1)]}])
    # sheen and velvet are never delta, even at roughness 0 (Cycles clamps them)
    t = MaterialTable.from_scene([{"name": "s", "lobes": [dict(SHEEN, roughness=0.0), dict(VELVET, roughness=0.0)]}])
    assert not t.data.lobe_delta[0].any()


def _principled(base, rough=0.5, coat=0.0, coat_r=0.03, coat_ior=1.5, coat_tint=(1, 1, 1, 1),
                sheen=0.0, sheen_r=0.5, sheen_tint=(1, 1, 1, 1), metal=0.0, textured=False, emission=0.0):
    from node_parity import node

    def case(nt, uv):
        inputs = {"Base Color": base, "Roughness": rough, "Metallic": metal, "Coat Weight": coat,
                  "Coat Roughness": coat_r, "Coat IOR": coat_ior, "Coat Tint": coat_tint,
                  "Sheen Weight": sheen, "Sheen Roughness": sheen_r, "Sheen Tint": sheen_tint,
                  "Emission Color": (0.6, 0.5, 0.4, 1), "Emission Strength": emission}
        if textured:  # checker-driven base colour and coat / sheen roughness (per-hit lobe data)
            ck = node(nt, "ShaderNodeTexChecker", {"Vector": uv, "Scale": 3.0, "Color1": (0.9, 0.3, 0.1, 1),
                                                   "Color2": (0.1, 0.3, 0.8, 1)})
            r = node(nt, "ShaderNodeMapRange", {0: ck.outputs["Fac"], 3: 0.1, 4: 0.6})
            inputs.update({"Base Color": ck.outputs["Color"], "Coat Roughness": r.outputs[0],
                           "Sheen Roughness": r.outputs[0]})
        if textured == "layers":  # and the coat / sheen weights and tints
            ck2 = node(nt, "ShaderNodeTexChecker", {"Vector": uv, "Scale": 5.0, "Color1": (1.0, 0.4, 0.2, 1),
                                                    "Color2": (0.3, 0.8, 1.0, 1)})
            w = node(nt, "ShaderNodeMapRange", {0: ck2.outputs["Fac"], 3: 0.3, 4: 1.0})
            inputs.update({"Coat Weight": w.outputs[0], "Sheen Weight": w.outputs[0],
                           "Coat Tint": ck2.outputs["Color"], "Sheen Tint": ck2.outputs["Color"]})
        return node(nt, "ShaderNodeBsdfPrincipled", inputs).outputs[0]
    return case


def _sheen_node(col, r, dist="MICROFIBER"):
    from node_parity import node

    def case(nt, uv):
        return node(nt, "ShaderNodeBsdfSheen", {"Color": col, "Roughness": r}, distribution=dist).outputs[0]
    return case


def _compare(cases, n, tmp_path, tol, sun=(3.0, (0.6, 0.2, 0.3))):
    from node_parity import render_tiles, tile

    cycles, drt, res = render_tiles(cases, n, tmp_path, shader=True, sun=sun, shape="sphere", tag=f"tiles{n}")
    assert not res.warnings, res.warnings
    means = np.array([tile(cycles, k, n).reshape(-1, 3).mean(0) for k in range(len(cases))])
    errs = np.array([tile(drt, k, n).reshape(-1, 3).mean(0) for k in range(len(cases))]) / means - 1
    print("Cycles tile means:\n", np.round(means, 4), "\nper-tile channel mean errors (%):\n",
          np.round(100 * errs, 2))
    assert means.min() > 1e-3, means
    assert np.all(np.abs(errs).max(axis=1) < tol), np.round(100 * errs, 2)
    return res


def test_coat_sheen_spheres_match_cycles(tmp_path):
    """A coated, a sheened and a coated + sheened metal Principled sphere, a Sheen BSDF and a
    Principled whose coat / sheen weights, tints and roughnesses are textured, under a delta
    sun, no bounces: tile channel means within 1 % of Cycles's (measured ≤ 0.14 %); the export
    chains the layers (sheen → coat → metal / specular → diffuse). An emissive Principled under
    a tinted coat and a sheen, alone: its emission attenuated per view angle as Cycles (0.00 %)."""
    pytest.importorskip("bpy")
    cases = [_principled((0.8, 0.3, 0.1, 1), coat=1.0, coat_r=0.2, coat_tint=(0.4, 0.7, 1, 1)),
             _principled((0.8, 0.3, 0.1, 1), sheen=1.0, sheen_r=0.4, sheen_tint=(0.3, 0.6, 1, 1)),
             _principled((0.9, 0.6, 0.3, 1), rough=0.4, metal=0.5, coat=0.8, coat_r=0.2, sheen=0.7),
             _sheen_node((0.8, 0.8, 0.8, 1), 0.5),
             _principled((0.8, 0.3, 0.1, 1), coat=1.0, coat_r=0.2, sheen=1.0, textured="layers"),
             # a coat of weight 1, untinted, alone over a metal: a single plain layer (has_layers
             # 1) over a METALLIC lobe, which must still be attenuated
             _principled((0.1, 0.25, 0.7, 1), rough=0.4, metal=1.0, coat=1.0, coat_r=0.05)]
    res = _compare(cases, 3, tmp_path, 0.01)
    mats = {m["name"]: m for m in res.header["materials"]}
    lobes = mats["case2"]["lobes"]
    assert [lb["type"] for lb in lobes] == ["SHEEN", "DIELECTRIC_SPECULAR", "METALLIC", "DIELECTRIC_SPECULAR",
                                            "DIFFUSE"]
    assert [lb.get("layer") for lb in lobes] == [None, 0, 1, 1, 3]
    assert lobes[0]["layer_weight"] == pytest.approx(0.7) and lobes[1]["layer_weight"] == pytest.approx(0.8)
    # emission seen by the camera (no light: an emitter beside the sun would make light
    # selection noisy at 1 spp), attenuated by a tinted coat and a sheen: exact
    emissive = _principled((0.1, 0.1, 0.1, 1), coat=1.0, coat_r=0.3, coat_tint=(0.5, 0.8, 1, 1), sheen=0.8,
                           emission=1.0)
    res = _compare([emissive], 1, tmp_path, 0.01, sun=None)
    assert res.header["materials"][0]["emission_layer"] == 1  # the coat, under the sheen


def _coat_normal_case(normal, coat_normal, base=(0.8, 0.3, 0.1, 1), rough=0.5, metal=0.0, coat=1.0,
                      coat_r=0.15, sheen=0.0, textured_coat=False):
    """A coated Principled whose Normal / Coat Normal are the tilted map ("map"), the same map
    node for both ("same": one source) or unlinked (None)."""
    from node_parity import node

    def case(nt, uv):
        ins = {"Base Color": base, "Roughness": rough, "Metallic": metal, "Coat Weight": coat,
               "Coat Roughness": coat_r, "Sheen Weight": sheen, "Sheen Roughness": 0.4}
        if textured_coat:
            ck = node(nt, "ShaderNodeTexChecker", {"Vector": uv, "Scale": 4.0})
            ins["Coat Weight"] = node(nt, "ShaderNodeMapRange", {0: ck.outputs["Fac"], 3: 0.3, 4: 1.0}).outputs[0]
        from test_shading_inputs import _normal_map  # tilts up to ~35° over the UVs

        nm = _normal_map()(nt, uv) if "map" in (normal, coat_normal) or normal == "same" else None
        if normal in ("map", "same"):
            ins["Normal"] = nm
        if coat_normal == "map" or normal == "same":
            ins["Coat Normal"] = nm
        return node(nt, "ShaderNodeBsdfPrincipled", ins).outputs[0]
    return case


def test_coat_normal_apart_from_normal_matches_cycles(tmp_path):
    """Coat Normal apart from Normal (issue 11): the coat is shaded about its own normal and the
    sheen about their mix, as Cycles. Sphere tiles under a delta sun, no bounces, each beside a
    twin whose Coat Normal and Normal share one source: a normal map on the base under a
    smooth coat (dielectric, metal, under a sheen, textured coat weight), a normal map on the
    coat only. Tile channel means within 1 % of Cycles's (measured ≤ 0.13 %), the twins within
    2 %; each pair differs in Cycles by more than 2 % (what DRT rendered before, with the
    warning, was the twin)."""
    pytest.importorskip("bpy")
    from node_parity import render_tiles, tile

    cases = [_coat_normal_case("map", None), _coat_normal_case("same", None),
             _coat_normal_case(None, "map"), _coat_normal_case(None, None),
             _coat_normal_case("map", None, coat=0.6, sheen=0.8), _coat_normal_case("same", None, coat=0.6, sheen=0.8),
             _coat_normal_case("map", None, base=(0.9, 0.6, 0.3, 1), rough=0.4, metal=1.0, coat_r=0.05),
             _coat_normal_case("same", None, base=(0.9, 0.6, 0.3, 1), rough=0.4, metal=1.0, coat_r=0.05),
             _coat_normal_case("map", None, sheen=0.5, textured_coat=True)]
    n = 3
    cycles, drt, res = render_tiles(cases, n, tmp_path, shader=True, sun=(3.0, (0.6, 0.2, 0.3)), shape="sphere",
                                    tag="coat_normal")
    assert not res.warnings, res.warnings
    cm = np.array([tile(cycles, k, n).reshape(-1, 3).mean(0) for k in range(len(cases))])
    dm = np.array([tile(drt, k, n).reshape(-1, 3).mean(0) for k in range(len(cases))])
    errs = dm / cm - 1
    effect = cm[0:8:2] / cm[1:8:2] - 1
    print("Cycles tile means:\n", np.round(cm, 4), "\nchannel mean errors (%):\n", np.round(100 * errs, 3),
          "\ncase vs one-source twin in Cycles (%):\n", np.round(100 * effect, 2))
    assert cm.min() > 1e-3, cm
    # the twins (one source for both normals) within 2 %: the sheen twin is 1.9 % dark in blue
    # (measured 2026-12-02; the coat-normal tiles ≤ 0.13 %): a sheen about a normal map tilted
    # away from the viewer (cos θo < 0 at the silhouette) reads Cycles's albedo table at 0,
    # DRT's at |cos θo| (docs/materials.md, "Coat Normal")
    tol = np.array([0.01, 0.02] * 4 + [0.01])
    assert np.all(np.abs(errs).max(axis=1) < tol), np.round(100 * errs, 3)
    # each pair differs in Cycles by more than twice the 1 % value tolerance, so the twin DRT
    # rendered before (within 0.1 % of Cycles's twin) would fail the value check; the metal
    # pair is the closest (2.2 %: the metal base dominates its tile)
    assert np.all(np.abs(effect).max(axis=1) > 0.02), np.round(100 * effect, 2)
    mats = {m["name"]: m for m in res.header["materials"]}
    assert mats["case0"]["coat_normal"] == "SMOOTH" and "coat_normal_reg" in mats["case2"]
    assert "coat_normal" not in mats["case1"] and "coat_normal_reg" not in mats["case1"]


@pytest.mark.slow
def test_coat_sheen_sweep_matches_cycles(tmp_path):
    """The sweep: coat weight 0 / 0.5 / 1 × coat roughness 0.05 / 0.3 / 0.8, coat IOR and tint,
    sheen weight 0.5 / 1 × roughness 0.2 / 0.5 / 1 × tint, coat + sheen + metal, textured base
    and coat / sheen roughness, Sheen BSDF Microfiber and Ashikhmin: tile channel means within
    1 % of Cycles's (measured ≤ 0.12 %), 2 % for the near-black smooth (0.2) white Sheen BSDF
    (tile mean 0.003, lit at grazing angles only: −1.4 %)."""
    pytest.importorskip("bpy")
    b = (0.8, 0.3, 0.1, 1)
    cases = [_principled(b, coat=w, coat_r=r) for w in (0.5, 1.0) for r in (0.05, 0.3, 0.8)]
    cases += [_principled(b, coat=0.0), _principled((0.2, 0.5, 0.8, 1), coat=1.0, coat_r=0.1, coat_ior=2.2),
              _principled((0.2, 0.5, 0.8, 1), coat=1.0, coat_r=0.4, coat_ior=1.2),
              _principled((0.9, 0.9, 0.9, 1), coat=0.6, coat_r=0.3, coat_tint=(0.2, 0.6, 1.0, 1))]
    cases += [_principled(b, sheen=w, sheen_r=r) for w in (0.5, 1.0) for r in (0.2, 0.5, 1.0)]
    cases += [_principled((0.1, 0.1, 0.1, 1), sheen=1.0, sheen_r=0.3, sheen_tint=(1.0, 0.4, 0.6, 1)),
              _principled((0.9, 0.6, 0.3, 1), rough=0.3, metal=1.0, coat=1.0, coat_r=0.1, sheen=0.8, sheen_r=0.6),
              _principled((0.5, 0.5, 0.5, 1), rough=0.6, metal=0.3, coat=0.5, coat_r=0.5, sheen=0.4,
                          coat_tint=(0.8, 0.9, 0.5, 1), sheen_tint=(0.5, 1.0, 0.5, 1)),
              _principled(b, coat=1.0, coat_r=0.2, sheen=1.0, textured=True),
              _sheen_node((0.8, 0.8, 0.8, 1), 0.2), _sheen_node((0.9, 0.4, 0.2, 1), 1.0),
              _sheen_node((0.8, 0.8, 0.8, 1), 0.3, "ASHIKHMIN"), _sheen_node((0.2, 0.9, 0.4, 1), 0.8, "ASHIKHMIN")]
    _compare(cases, 5, tmp_path, np.where(np.arange(len(cases)) == 20, 0.02, 0.01))


@pytest.mark.slow
def test_coat_sheen_spheres_in_a_white_world_match_cycles(tmp_path):
    """Indirect light: coated / sheened Principled spheres and Sheen BSDFs in a uniform white
    world with bounces, equal samples (DRT_TEST_SPP, default 256): per-tile channel means within
    2 % of Cycles's (BSDF sampling of the new lobes, MIS with the world, the per-hit layer chain
    at every bounce). Measured (2048 spp, converged): −0.2 … −1.5 %, always darker; a plain
    Lambert sphere of colour (0.8, 0.3, 0.1) shows −0.1 / −0.9 / −1.5 % in the same setup (and
    test_principled_layering's world test −0.1 … −1.3 %), so the residual is the setup (dark
    spheres against the white world: silhouettes), not the coat / sheen lobes."""
    pytest.importorskip("bpy")
    import os

    import bpy
    from addon.export import export_depsgraph
    from drt.render import render
    from drt.scene import scene_from_dict
    from node_parity import TILE, _add_shape, _material, setup_scene, tile
    import _common as C

    n = 3
    spp = int(os.environ.get("DRT_TEST_SPP", 256))
    b = (0.8, 0.3, 0.1, 1)
    cases = [_principled(b, coat=1.0, coat_r=0.05), _principled(b, coat=1.0, coat_r=0.5, coat_tint=(0.4, 0.7, 1, 1)),
             _principled((0.2, 0.5, 0.8, 1), coat=0.5, coat_r=0.2, coat_ior=2.0),
             _principled(b, sheen=1.0, sheen_r=0.3), _principled((0.1, 0.1, 0.1, 1), sheen=1.0, sheen_r=0.8),
             _principled((0.9, 0.6, 0.3, 1), rough=0.3, metal=1.0, coat=1.0, coat_r=0.1, sheen=0.8, sheen_r=0.6),
             _principled(b, coat=1.0, coat_r=0.2, sheen=1.0, textured="layers"),
             _sheen_node((0.8, 0.8, 0.8, 1), 0.5), _sheen_node((0.8, 0.8, 0.8, 1), 0.4, "ASHIKHMIN")]
    sc = setup_scene(n)
    size = 2.0 / n
    for k, case in enumerate(cases):
        row, col = divmod(k, n)
        _add_shape("sphere", size, (-1 + (col + 0.5) * size, 1 - (row + 0.5) * size, 0))
        bpy.context.object.data.materials.append(_material(f"w{k}", case, True))
    C.reference_settings(sc, samples=spp)
    sc.cycles.filter_width = 0.01  # both engines read Cycles's pixel filter
    sc.render.resolution_x = sc.render.resolution_y = n * TILE
    sc.cycles.use_light_tree = False
    sc.world.node_tree.nodes["Background"].inputs[1].default_value = 1.0
    sc.drt.samples = spp
    sc.drt.max_bounces = 12
    path = str(tmp_path / "world.exr")
    sc.render.filepath = path
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(path)
    w = n * TILE
    cycles = np.array(img.pixels[:], dtype=np.float64).reshape(w, w, 4)[::-1, :, :3]
    res = export_depsgraph(bpy.context.evaluated_depsgraph_get())
    assert not res.warnings, res.warnings
    drt = np.asarray(render(scene_from_dict(res.header, res.arrays), threads=2).combined, np.float64)[..., :3]
    errs = np.array([tile(drt, k, n).reshape(-1, 3).mean(0) / tile(cycles, k, n).reshape(-1, 3).mean(0) - 1
                     for k in range(len(cases))])
    print("per-tile channel mean errors (%):\n", np.round(100 * errs, 2))
    assert np.abs(errs).max() < 0.02, np.round(100 * errs, 2)


def test_export_coat_normal_frames_and_emission():
    """Coat Normal and Normal from one source export as before (no frames); apart, the coat
    lobe gets frame COAT and the material names the coat normal: an unlinked Coat Normal under
    a mapped Normal is the smooth normal ("SMOOTH"), a linked one a register; a sheen over such
    a coat gets frame SHEEN. An IOR-1 tinted coat warns; emission under a coat names its layer;
    a coat-free Principled exports as before."""
    bpy = pytest.importorskip("bpy")
    from addon.export.materials import MaterialExporter

    def principled(link_normal, link_coat, coat=0.5, emission=0.0, coat_ior=1.5, tint=(1, 1, 1, 1), sheen=0.0):
        mat = bpy.data.materials.new("m")
        nt = mat.node_tree
        p = nt.nodes["Principled BSDF"]
        p.inputs["Coat Weight"].default_value = coat
        p.inputs["Coat IOR"].default_value = coat_ior
        p.inputs["Coat Tint"].default_value = tint
        p.inputs["Sheen Weight"].default_value = sheen
        p.inputs["Emission Strength"].default_value = emission
        p.inputs["Emission Color"].default_value = (1, 1, 1, 1)
        nm = nt.nodes.new("ShaderNodeNormalMap")
        if link_normal:
            nt.links.new(nm.outputs[0], p.inputs["Normal"])
        if link_coat:
            nt.links.new(nm.outputs[0], p.inputs["Coat Normal"])
        ex = MaterialExporter()
        out = ex.convert(mat)
        return out, " ".join(ex.warnings)

    out, warn = principled(True, True)
    assert warn == "" and [lb["type"] for lb in out["lobes"]] == ["DIELECTRIC_SPECULAR", "DIELECTRIC_SPECULAR",
                                                                 "DIFFUSE"]
    assert not any("frame" in lb for lb in out["lobes"]) and "coat_normal" not in out
    out, warn = principled(True, False, sheen=0.5)  # a normal map on the base only
    assert warn == "" and [lb.get("frame") for lb in out["lobes"]] == ["SHEEN", "COAT", None, None]
    assert out["coat_normal"] == "SMOOTH" and "normal_reg" in out and "program" in out
    out, warn = principled(False, True)  # a normal map on the coat only
    assert warn == "" and [lb.get("frame") for lb in out["lobes"]] == ["COAT", None, None]
    assert "coat_normal_reg" in out and "normal_reg" not in out and "program" in out
    assert principled(False, False)[1] == ""
    out, warn = principled(True, False, coat=0.0)  # no coat: nothing to differ
    assert warn == "" and not any("frame" in lb for lb in out["lobes"])
    out, warn = principled(False, False, emission=2.0)  # emission under the coat: attenuated by it
    assert warn == "" and out["emission_layer"] == 0
    out, warn = principled(False, False, coat_ior=1.0, tint=(0.5, 0.5, 1, 1))
    assert "Coat IOR 1" in warn and [lb["type"] for lb in out["lobes"]] == ["DIELECTRIC_SPECULAR", "DIFFUSE"]
    out, warn = principled(False, False, coat=0.0)
    assert warn == "" and all("layer_weight" not in lb and "coat_tint" not in lb for lb in out["lobes"])


def test_coat_frame_validation_and_identity():
    """A lobe ``frame`` is COAT on a DIELECTRIC_SPECULAR or SHEEN on a SHEEN lobe, nothing else;
    with the coat normal equal to the shading normal (NO_BUMP) a framed material evaluates and
    samples exactly as its frameless twin."""
    with pytest.raises(ValueError, match="frame must be"):
        MaterialTable.from_scene([{"name": "x", "lobes": [dict(SHEEN, frame="COAT")]}])
    with pytest.raises(ValueError, match="frame must be"):
        MaterialTable.from_scene([{"name": "x", "lobes": [{"type": "DIFFUSE", "color": [1, 1, 1], "frame": "SHEEN"}]}])
    plain = _stack(base=(0.5, 0.3, 0.2))
    framed = _stack(base=(0.5, 0.3, 0.2))
    framed["lobes"][0]["frame"], framed["lobes"][1]["frame"] = "SHEEN", "COAT"
    framed["name"] = "framed"
    t = MaterialTable.from_scene([plain, framed])
    # the glossy lobes of a material with a diffuse lobe: the valid-reflection frame (3)
    assert list(t.data.lobe_frame[1, :4]) == [2, 1, 3, 0] and list(t.data.lobe_frame[0, :4]) == [0, 3, 3, 0]
    rng = np.random.default_rng(3)
    n = 2000
    wo, wi = _uniform_dirs(rng, n), _uniform_dirs(rng, n) * [1, 1, -1] ** rng.integers(0, 2, (n, 1))
    u, u2 = rng.random(n), rng.random((n, 2))
    f0, p0 = t.eval(np.zeros(n, int), wo, wi)
    f1, p1 = t.eval(np.ones(n, int), wo, wi)
    assert np.array_equal(f0, f1) and np.array_equal(p0, p1)
    s0, s1 = t.sample(np.zeros(n, int), wo, u, u2), t.sample(np.ones(n, int), wo, u, u2)
    for field in ("wi", "weight", "pdf", "lobe_kind", "is_delta", "valid"):
        assert np.array_equal(getattr(s0, field), getattr(s1, field)), field


@pytest.mark.parametrize("mu", [0.3, 0.8])
def test_tilted_coat_samples_follow_its_pdf(mu):
    """With the coat normal tilted 30° from the shading normal (and the sheen mixed toward it),
    directions sampled from the sheen → coat → specular → diffuse chain follow the pdf eval
    reports over the whole sphere (chi-square), every valid non-delta sample's pdf is eval's,
    and the sample weight's mean is ∫ f cos (eval integrated uniformly), per channel."""
    framed = _stack(base=(0.5, 0.3, 0.2), coat_r=0.3, coat_w=0.8)
    framed["lobes"][0]["frame"], framed["lobes"][1]["frame"] = "SHEEN", "COAT"
    t = MaterialTable.from_scene([framed])
    nc = np.array([math.sin(math.radians(30)), 0.0, math.cos(math.radians(30))])
    wo = np.array([math.sqrt(1 - mu * mu), 0.3 * mu, mu])
    wo /= np.linalg.norm(wo)
    n = 200_000
    rng = np.random.default_rng(5)
    p, valid, mass, _ = material_chi_square(t, 0, np.tile(wo, (n, 1)), n, rng, z_lo=-1.0, coat_normal=nc)
    assert p > 1e-3, p
    assert abs(valid - mass) < 0.01, (valid, mass)
    s = t.sample(np.zeros(n, int), np.tile(wo, (n, 1)), rng.random(n), rng.random((n, 2)), coat_normal=nc)
    ok = s.valid & ~s.is_delta
    _, pdf = t.eval(np.zeros(int(ok.sum()), int), np.tile(wo, (int(ok.sum()), 1)), s.wi[ok], coat_normal=nc)
    assert np.allclose(pdf, s.pdf[ok], rtol=1e-9)
    est = s.weight.sum(axis=0) / n
    m = 1_000_000
    d = _uniform_dirs(rng, m)
    d[m // 2:, 2] *= -1  # the whole sphere
    f, _ = t.eval(np.zeros(m, int), np.tile(wo, (m, 1)), d, coat_normal=nc)
    ref = f.mean(axis=0) * 4 * np.pi
    se = f.std(axis=0) * 4 * np.pi / math.sqrt(m) + s.weight.std(axis=0) / math.sqrt(n)
    assert np.all(np.abs(est - ref) < 4 * se), (est, ref, se)
    # and the tilt matters: the same chain about the shading normal reflects differently
    f0, _ = t.eval(np.zeros(m, int), np.tile(wo, (m, 1)), d)
    assert np.abs(f0.mean(axis=0) * 4 * np.pi - ref).max() > 10 * se.max()


def test_layer_levels_keep_the_plain_principled_fast_path():
    """``has_layers`` 1 (the scalar fast path) only for single untinted k = 1 specular layers;
    a coat, a sheen, a chain, a tint or a weight register make it 2, and both paths agree."""
    spec = {"type": "DIELECTRIC_SPECULAR", "color": [1, 1, 1], "roughness": 0.4, "ior": 1.5}
    diffuse = {"type": "DIFFUSE", "color": [0.7, 0.4, 0.2], "layer": 0}
    mats = [{"name": "plain", "lobes": [spec, diffuse]},
            {"name": "k", "lobes": [dict(spec, layer_weight=1.0, coat_tint=[1, 1, 0.999999]), diffuse]},
            {"name": "reg", "lobes": [dict(spec, layer_weight_reg=0), diffuse]},
            _stack(), {"name": "none", "lobes": [{"type": "DIFFUSE", "color": [1, 1, 1]}]}]
    t = MaterialTable.from_scene(mats)
    assert list(t.data.has_layers) == [1, 2, 2, 2, 0]
    t.data.has_layers[2] = 1  # same data, other path: the same numbers
    rng = np.random.default_rng(5)
    n = 1000
    wo, wi = _uniform_dirs(rng, n), _uniform_dirs(rng, n)
    f1, p1 = t.eval(np.full(n, 2), wo, wi)
    f0, p0 = t.eval(np.zeros(n, int), wo, wi)
    np.testing.assert_allclose(f1, f0, rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(p1, p0)


@pytest.mark.parametrize("mu", [0.05, 0.2, 0.5, 0.9])
def test_lobe_choice_follows_the_view(mu):
    """A near-mirror coat over a white diffuse is picked with probability its albedo at wo (as
    Cycles's sample weights: the coat's albedo, the base's 1 − albedo), so every sample weight
    stays near 1 at every view. A constant, cosine-averaged choice picks the coat 9 % of the time
    and returns it with weight 9.4 at mu = 0.05: the fireflies at a coated sphere's rim."""
    from drt.materials.dielectric_specular import f0_from_ior, layer_albedo_max
    from drt.materials.table import LOBE_GLOSSY

    t = MaterialTable.from_scene([{"name": "coat", "lobes": [
        {"type": "DIELECTRIC_SPECULAR", "color": [1, 1, 1], "roughness": 0.03, "ior": 1.5},
        {"type": "DIFFUSE", "color": [1, 1, 1], "layer": 0}]}])
    n = 100_000
    rng = np.random.default_rng(int(mu * 100))
    s = t.sample(np.zeros(n, int), _wo(mu, n), rng.random(n), rng.random((n, 2)))
    f0 = f0_from_ior(1.5)
    albedo = layer_albedo_max(0.03 ** 2, 1.5, (f0, f0, f0), False, mu)
    share = np.mean(s.lobe_kind == LOBE_GLOSSY)
    assert abs(share - albedo) < 4 * math.sqrt(albedo * (1 - albedo) / n) + 1e-3, (share, albedo)
    assert s.valid.mean() > 0.999
    assert s.weight[s.valid].max() < 1.2
    assert abs(s.weight[:, 0].mean() - 1.0) < 0.01  # white over white: albedo ≈ 1


@pytest.mark.parametrize("coat_normal", [None, (0.3, -0.2, 0.93)])
def test_the_light_samples_lobe_weights_pick_the_same_lobe(coat_normal):
    """The integrator evaluates a vertex's light sample first and lets the BSDF sample pick its
    lobe from the weights that evaluation computed (``bsdf_eval_weights``): the samples must be
    the very ones the sample's own weighing gives, for layered stacks of up to four lobes and
    for a five-lobe one (which weighs again), on both sides and at grazing views."""
    five = _stack()
    five = dict(five, name="five", lobes=five["lobes"] + [
        {"type": "GLOSSY", "color": [0.3, 0.3, 0.3], "roughness": 0.2}])
    metal = {"name": "metal", "lobes": [
        {"type": "DIELECTRIC_SPECULAR", "color": [1, 1, 1], "roughness": 0.05, "ior": 1.5, "layer_weight": 1.0},
        {"type": "METALLIC", "color": [0.9, 0.6, 0.2], "roughness": 0.3, "layer": 0, "weight": 1.0}]}
    t = MaterialTable.from_scene([_stack(), _stack(sheen_w=0.0, tint=(0.8, 0.5, 0.3), coat_r=0.02), metal, five,
                                  {"name": "plain", "lobes": [
                                      {"type": "DIELECTRIC_SPECULAR", "color": [1, 1, 1], "roughness": 0.4,
                                       "ior": 1.5},
                                      {"type": "DIFFUSE", "color": [0.7, 0.2, 0.2], "layer": 0}]}])
    assert t.data.has_layers.min() > 0 and t.data.lobe_count.max() == 5
    rng = np.random.default_rng(11)
    n = 40_000
    mat = rng.integers(0, 5, n)
    wo = _uniform_dirs(rng, n) * rng.choice([-1.0, 1.0], (n, 1))
    wo[: n // 8, 2] *= 0.01  # grazing
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    light_wi = _uniform_dirs(rng, n)
    u_lobe, u2 = rng.random(n), rng.random((n, 2))
    own = t.sample(mat, wo, u_lobe, u2, coat_normal=coat_normal)
    reused = t.sample(mat, wo, u_lobe, u2, coat_normal=coat_normal, light_wi=light_wi)
    for field in ("wi", "weight", "pdf", "lobe_kind", "is_delta", "valid"):
        np.testing.assert_array_equal(getattr(reused, field), getattr(own, field), err_msg=field)
    assert own.valid.mean() > 0.5 and len(np.unique(own.lobe_kind[own.valid])) >= 2
