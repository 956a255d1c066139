"""Cycles's Caustics switches (Light Paths > Caustics > Reflective / Refractive): off, a hit right
after a diffuse bounce is shaded without the closures the switch names (drt.materials.caustics).

Lobe level: a material's twin row evaluates and samples as the material without those lobes —
a dropped specular layer no longer darkens the lobes under it, a dropped coat still tints them,
a glass keeps exactly its refraction or its reflection. Renderer: the floor in a glass ball's
and a mirror ball's shadows is lit only through them, and each switch takes away exactly its
own caustic. (bpy) The exporter reads Cycles's settings, and the same scene renders as Cycles's.
"""

import dataclasses
import math

import numpy as np
import pytest

from drt.materials.caustics import caustics_twin, with_caustics_twins
from drt.materials.table import BSDF_COAT_TINT, BSDFSample, MaterialTable
from drt.render import render
from drt.scene import SceneError, scene_from_dict
from scene_builders import with_render
from test_filter_glossy import _blender_caustic_scene, _caustic_scene, add_low_point_light

_FIELDS = [f.name for f in dataclasses.fields(BSDFSample)]
SWITCHES = [(False, True), (True, False), (False, False)]


def _rows(n, seed):
    rng = np.random.default_rng(seed)
    wo = rng.normal(size=(n, 3))
    wo /= np.linalg.norm(wo, axis=1)[:, None]
    wo[:, 2] = np.abs(wo[:, 2]) + 0.05
    wo /= np.linalg.norm(wo, axis=1)[:, None]
    wi = rng.normal(size=(n, 3))
    wi /= np.linalg.norm(wi, axis=1)[:, None]
    return wo, wi, rng.random(n), rng.random((n, 2))


def _twin_table(material, switches):
    """The table of [material, its twin] and the twin's row."""
    t = MaterialTable.from_scene([material], caustics=switches)
    assert t.data.caustic_row.shape == (len(t.names),)
    return t, int(t.data.caustic_row[0])


PRINCIPLED = {"name": "plastic", "lobes": [
    {"type": "DIELECTRIC_SPECULAR", "color": [1, 1, 1], "roughness": 0.3, "ior": 1.5},
    {"type": "DIFFUSE", "color": [0.8, 0.5, 0.3], "layer": 0}]}


@pytest.mark.parametrize("switches", SWITCHES)
def test_a_dropped_specular_layer_leaves_the_diffuse_undarkened(switches):
    """Reflective off: the Principled's specular layer goes, and the diffuse under it is the
    whole Lambert (Cycles attenuates lower layers only by a closure it built); refractive off
    alone changes nothing (no twin)."""
    t, twin = _twin_table(PRINCIPLED, switches)
    if switches[0]:
        assert twin == -1 and len(t.names) == 1
        return
    lambert = MaterialTable.from_scene([{"name": "d", "lobes": [{"type": "DIFFUSE", "color": [0.8, 0.5, 0.3]}]}])
    n = 4000
    wo, wi, u_lobe, u2 = _rows(n, 1)
    f_t, p_t = t.eval(np.full(n, twin), wo, wi)
    f_d, p_d = lambert.eval(np.zeros(n, int), wo, wi)
    assert np.array_equal(f_t, f_d) and np.array_equal(p_t, p_d)
    s_t = t.sample(np.full(n, twin), wo, u_lobe, u2)
    s_d = lambert.sample(np.zeros(n, int), wo, u_lobe, u2)
    assert all(np.array_equal(getattr(s_t, k), getattr(s_d, k)) for k in _FIELDS)
    # the material's own row keeps its specular layer, which darkens the diffuse
    f_o, _ = t.eval(np.zeros(n, int), wo, wi)
    lit = wi[:, 2] > 0
    assert (f_o.sum(axis=1) != f_t.sum(axis=1))[lit].all() and (f_t[~lit] == 0).all()


def test_a_dropped_coat_still_tints_what_lies_under_it():
    """Reflective off: a tinted coat (weight k, tint c, IOR η) reflects nothing but still absorbs,
    mix(1, c^(1/cos θt), k) with θt the view direction refracted into the coat; the specular
    layer under it goes too, and the Lambert at the bottom is lit in full."""
    k, tint, eta = 0.7, np.array([0.4, 0.7, 1.0]), 1.6
    coated = {"name": "coated", "lobes": [
        {"type": "DIELECTRIC_SPECULAR", "color": [1, 1, 1], "roughness": 0.2, "ior": eta, "layer_weight": k,
         "coat_tint": tint.tolist()},
        {"type": "DIELECTRIC_SPECULAR", "color": [1, 1, 1], "roughness": 0.4, "ior": 1.5, "layer": 0},
        {"type": "DIFFUSE", "color": [0.8, 0.5, 0.3], "layer": 1}]}
    t, twin = _twin_table(coated, (False, True))
    assert list(t.lobe_type[twin, :2]) == [BSDF_COAT_TINT, 1]
    n = 4000
    wo, wi, u_lobe, u2 = _rows(n, 2)
    f, pdf = t.eval(np.full(n, twin), wo, wi)
    cos_t = np.sqrt(1 - (1 - wo[:, 2] ** 2) / eta**2)
    absorb = 1 + k * (tint[None, :] ** (1 / cos_t[:, None]) - 1)
    lit = wi[:, 2] > 0
    expected = np.where(lit[:, None], np.array([0.8, 0.5, 0.3]) * absorb * wi[:, 2:3] / math.pi, 0.0)
    assert np.allclose(f, expected, rtol=1e-12, atol=1e-15)
    assert np.allclose(pdf, np.where(lit, wi[:, 2] / math.pi, 0.0), rtol=1e-12, atol=0)
    s = t.sample(np.full(n, twin), wo, u_lobe, u2)
    assert s.valid.all() and (s.lobe_kind == 1).all()  # (only the Lambert is ever picked)
    # an untinted coat is dropped outright: the twin is the Lambert alone
    plain = {**coated, "lobes": [{**coated["lobes"][0], "coat_tint": [1, 1, 1]}] + coated["lobes"][1:]}
    t2, twin2 = _twin_table(plain, (False, True))
    assert list(t2.lobe_type[twin2]) == [1, 0, 0] and t2.data.has_layers[twin2] == 0


@pytest.mark.parametrize("switches", SWITCHES)
@pytest.mark.parametrize("principled", [False, True])
def test_glass_keeps_the_half_its_switch_leaves(switches, principled):
    """A rough glass (Glass BSDF, or the Principled's with its untinted reflection weight):
    reflective off keeps exactly its refraction, refractive off exactly its reflection (a Glass
    BSDF's tinted by its colour's mean), both off drop it; the pdf is the glass's own either
    way (it still samples both halves)."""
    glass = {"type": "GLASS", "color": [0.9, 0.9, 0.9], "roughness": 0.4, "ior": 1.45}
    if principled:
        glass["reflection_weight"] = 0.8
    t, twin = _twin_table({"name": "g", "lobes": [glass]}, switches)
    if switches == (False, False):
        assert t.data.lobe_count[twin] == 0
        return
    n = 6000
    wo, wi, _, _ = _rows(n, 3)
    f_o, p_o = t.eval(np.zeros(n, int), wo, wi)
    f_t, p_t = t.eval(np.full(n, twin), wo, wi)
    refl = wi[:, 2] > 0
    kept = ~refl if not switches[0] else refl
    assert np.array_equal(p_t, p_o)
    assert not f_t[~kept].any()
    assert np.allclose(f_t[kept], f_o[kept], rtol=1e-12, atol=0)
    assert (f_t[kept] > 0).mean() > 0.5


def test_delta_glass_samples_carry_only_the_kept_half():
    """Smooth glass, reflective off: a sampled refraction weighs what it did, a reflection 0."""
    glass = {"type": "GLASS", "color": [1, 1, 1], "roughness": 0.0, "ior": 1.5}
    t, twin = _twin_table({"name": "g", "lobes": [glass]}, (False, True))
    n = 4000
    wo, _, u_lobe, u2 = _rows(n, 4)
    s_o = t.sample(np.zeros(n, int), wo, u_lobe, u2)
    s_t = t.sample(np.full(n, twin), wo, u_lobe, u2)
    refr = s_o.lobe_kind == 3
    assert 0.8 < refr.mean() < 0.99
    assert np.array_equal(s_t.weight[refr], s_o.weight[refr])
    assert not s_t.weight[~refr].any()


def test_twins_are_made_only_where_a_switch_drops_something():
    mats = [{"name": "d", "lobes": [{"type": "DIFFUSE", "color": [0.5, 0.5, 0.5]},
                                    {"type": "SHEEN", "color": [0.5, 0.5, 0.5], "roughness": 0.3}]},
            {"name": "m", "lobes": [{"type": "GLOSSY", "color": [1, 1, 1], "roughness": 0.1}]},
            {"name": "r", "lobes": [{"type": "REFRACTION", "color": [1, 1, 1], "roughness": 0.1, "ior": 1.3}]}]
    for switches, rows in (((True, True), None), ((False, True), [-1, 3, -1, -1]),
                           ((True, False), [-1, -1, 3, -1]), ((False, False), [-1, 3, 4, -1, -1])):
        t = MaterialTable.from_scene(mats, caustics=switches)
        if rows is None:
            assert t.data.caustic_row.shape == (0,) and len(t.names) == 3
        else:
            assert t.data.caustic_row.tolist() == rows, switches
    assert caustics_twin(mats[0], False, False) is None
    # an IOR-1 glass is the Transparent BSDF / alpha (drt.materials.transparency): never dropped
    cutout = {"name": "leaf", "lobes": [{"type": "DIFFUSE", "color": [0.2, 0.6, 0.1]},
                                        {"type": "GLASS", "color": [0.5, 0.5, 0.5], "roughness": 0.0, "ior": 1.0}]}
    assert caustics_twin(cutout, False, False) is None
    out, twin_of = with_caustics_twins(mats, False, True)
    assert [m["name"] for m in out] == ["d", "m", "r", "m (caustics)"] and twin_of.tolist() == [-1, 3, -1, -1]


@pytest.mark.parametrize("bad", [
    {"name": "x", "lobes": [{"type": "GLOSSY", "roughness": 0.2}]},  # no colour
    {"name": "x", "lobes": ["glossy"]},
    {"name": "x", "lobes": [{"type": "DIELECTRIC_SPECULAR", "color": [1, 1, 1], "roughness": 0.2, "ior": 1.5,
                             "coat_tint": "blue"}]},
    {"name": "x", "lobes": [{"type": "GLASS", "color": [1, 1, 1], "roughness": 0.0, "ior": "glass"}]},
])
def test_a_bad_material_fails_the_same_way_with_the_switches_off(bad):
    """The twins are read off the scene's descriptions before the table checks them: a bad one
    gets no twin, and the table's own error (naming the material and field) as with the
    switches on."""
    with pytest.raises(ValueError) as on:
        MaterialTable.from_scene([bad])
    with pytest.raises(ValueError) as off:
        MaterialTable.from_scene([bad], caustics=(False, False))
    assert str(off.value) == str(on.value)


def test_a_textured_twin_keeps_its_program_on_the_lobes_it_keeps():
    """A Principled whose diffuse colour is textured: the twin runs the same program, its
    textured colour lands on the twin's Lambert slot (the specular slot before it is gone)."""
    from drt.materials.program_format import build_program_data

    mat = {"name": "tex", "program": {"registers": 2, "ops": np.zeros((0, 12), np.int64),
                                      "constants": np.zeros((0, 4)), "data": np.zeros(0)},
           "lobes": [{"type": "DIELECTRIC_SPECULAR", "color": [1, 1, 1], "roughness": 0.3, "ior": 1.5,
                      "roughness_reg": 0},
                     {"type": "DIFFUSE", "color": [1, 1, 1], "layer": 0, "color_reg": 1}]}
    t = MaterialTable.from_scene([mat], caustics=(False, True))
    twin = int(t.data.caustic_row[0])
    pd = build_program_data(t.program_source[0], t, [], None, None, None)
    assert pd.prog_of[twin] >= 0
    assert pd.lobe_color_reg[0].tolist()[:2] == [-1, 1] and pd.lobe_rough_reg[0, 0] == 0
    assert pd.lobe_color_reg[twin, 0] == 1 and pd.lobe_rough_reg[twin, 0] == -1


# ------------------------------------------------------------------------------ renders
def _render(h, arrays, switches, spp=None):
    h = with_render(h, caustics_reflective=switches[0], caustics_refractive=switches[1],
                    **({"spp": spp} if spp else {}))
    return np.asarray(render(scene_from_dict(h, arrays), threads=2).combined, np.float64)[..., :3].mean(axis=-1)


def test_each_switch_takes_away_its_own_caustic():
    """The caustic scene with rough (0.3) glass and mirror balls under a point light: the floor
    in their shadows is lit only through them, and a diffuse floor's path to the light through
    a ball is exactly what a switch drops. Glass shadow: refractive off takes away the
    refraction caustic (measured at 256 samples: 0.0169 → 0.0006), reflective off leaves it
    (0.0164); mirror shadow: reflective off takes most of it away (0.0019 → 0.0006; the rest
    comes through the glass ball), refractive off leaves most (0.0014). Both off: the shadows'
    cores are black; the balls seen from the camera and the lit floor barely change (they are
    seen before any diffuse bounce)."""
    h, arrays = _caustic_scene(spp=256, glossy_roughness=0.3, glass_roughness=0.3)
    on = _render(h, arrays, (True, True))
    refl_off, refr_off, both_off = (_render(h, arrays, s) for s in SWITCHES)
    glass_shadow, mirror_shadow = (slice(5, 12), slice(20, 32)), (slice(21, 32), slice(20, 32))
    for name, img in (("on", on), ("reflective off", refl_off), ("refractive off", refr_off), ("both", both_off)):
        print(name, img[glass_shadow].mean(), img[mirror_shadow].mean(), img.mean())
    assert refr_off[glass_shadow].mean() < 0.1 * on[glass_shadow].mean()
    assert refl_off[glass_shadow].mean() > 0.8 * on[glass_shadow].mean()
    assert refl_off[mirror_shadow].mean() < 0.5 * on[mirror_shadow].mean()
    assert refr_off[mirror_shadow].mean() > 0.5 * on[mirror_shadow].mean()
    # the shadows' cores (lit through the balls only, black with both switches off) hold most
    # of the light in those regions
    core = (both_off == 0) & (on > 0)
    for region in (glass_shadow, mirror_shadow):
        assert core[region].sum() >= 20
        assert on[region][core[region]].sum() > 0.7 * on[region].sum()
    assert abs(both_off.mean() / on.mean() - 1) < 0.1


def test_switches_change_nothing_without_glossy_lobes_after_a_diffuse_bounce():
    """A scene of a glossy ball over a black world (no diffuse surface anywhere): no path has a
    diffuse bounce, so every switch setting renders the same image bit for bit."""
    h, arrays = _caustic_scene(spp=8, glossy_roughness=0.3, glass_roughness=0.3)
    h = {**h, "materials": [{**m, "lobes": [{"type": "GLOSSY", "color": [0.5, 0.5, 0.5], "roughness": 0.6}]}
                            if m["name"] == "floor" else m for m in h["materials"]]}
    images = [_render(h, arrays, s) for s in [(True, True)] + SWITCHES]
    assert all(np.array_equal(images[0], img) for img in images[1:])


def test_the_viewport_follows_the_switches():
    """LiveScene (the rendered viewport): switching Refractive Caustics off and on again gives
    the final render's image each time (the material table is rebuilt with or without twins)."""
    from dataclasses import replace

    from drt.interactive import LiveScene
    from drt.scene import MeshData

    h, arrays = _caustic_scene(spp=16, glossy_roughness=0.3, glass_roughness=0.3)
    scene = scene_from_dict(h, arrays)
    live = LiveScene(scene.render, scene.materials, h["lights"], scene.world_color)
    for k, m in enumerate(scene.meshes):
        live.set_object(k, m.name, MeshData(m.name, m.positions, m.triangles, m.material_index), np.eye(4))
    for switches in ((True, False), (True, True)):
        settings = replace(scene.render, caustics_reflective=switches[0], caustics_refractive=switches[1])
        live.set_settings(settings)
        s, ctx = live.context(scene.camera, 32, 32, spp=16)
        got = np.asarray(render(s, spp=16, context=ctx, threads=1).combined)
        want = np.asarray(render(replace(scene, render=settings), threads=1).combined)
        np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-9)


def test_switches_are_read_and_checked():
    h, arrays = _caustic_scene(spp=1)
    r = scene_from_dict(h, arrays).render
    assert (r.caustics_reflective, r.caustics_refractive) == (True, True)
    r = scene_from_dict(with_render(h, caustics_refractive=False), arrays).render
    assert (r.caustics_reflective, r.caustics_refractive) == (True, False)
    for bad in (0, "off", 1.0):
        with pytest.raises(SceneError, match="caustics_reflective"):
            scene_from_dict(with_render(h, caustics_reflective=bad), arrays)


# ------------------------------------------------------------------------------ Blender
def test_caustics_switches_are_cycles_settings():
    """The exporter writes Cycles's Reflective / Refractive Caustics when off (nothing when on,
    a new file's state), for the render and the viewport, and warns of nothing."""
    pytest.importorskip("bpy")
    import bpy

    from addon.export import export_depsgraph
    from addon.export.scene_parts import render_settings

    sc = _blender_caustic_scene(None, 1)
    assert sc.cycles.caustics_reflective and sc.cycles.caustics_refractive
    for refl, refr in [(True, True)] + SWITCHES:
        sc.cycles.caustics_reflective, sc.cycles.caustics_refractive = refl, refr
        res = export_depsgraph(bpy.context.evaluated_depsgraph_get())
        assert not res.warnings, res.warnings
        for r in (res.header["render"], render_settings(sc, preview=True)):
            assert r.get("caustics_reflective", True) is refl and r.get("caustics_refractive", True) is refr
            assert "caustics_reflective" in r or refl
        s = scene_from_dict(res.header, res.arrays).render
        assert (s.caustics_reflective, s.caustics_refractive) == (refl, refr)


def _blender_principled_scene(spp, switches):
    """node_parity's orthographic view down on a Principled floor with a Principled glass ball, a
    Principled gold metal ball under a tinted coat and a red wall under a blue-tinted coat beside
    them (edge on), a point light low on the left; Cycles's Caustics switches as given."""
    import bpy

    from node_parity import setup_scene

    sc = setup_scene(2)
    sc.cycles.samples = sc.drt.samples = spp
    sc.cycles.max_bounces = sc.drt.max_bounces = 8
    sc.cycles.sample_clamp_indirect = 0.0
    sc.cycles.caustics_reflective, sc.cycles.caustics_refractive = switches

    def principled(name, **inputs):
        mat = bpy.data.materials.new(name)
        bsdf = mat.node_tree.nodes["Principled BSDF"]
        for key, value in inputs.items():
            bsdf.inputs[key].default_value = value
        return mat

    bpy.ops.mesh.primitive_plane_add(size=2.2, location=(0, 0, -1))
    bpy.context.object.data.materials.append(principled("floor", **{"Base Color": (0.8, 0.8, 0.8, 1),
                                                                      "Roughness": 0.5}))
    glass = principled("glass", **{"Transmission Weight": 1.0, "Roughness": 0.25, "IOR": 1.45})
    metal = principled("metal", **{"Base Color": (0.9, 0.7, 0.4, 1), "Metallic": 1.0, "Roughness": 0.25,
                                   "Coat Weight": 0.6, "Coat Tint": (0.6, 0.8, 1.0, 1), "Coat Roughness": 0.1})
    for mat, y in ((glass, 0.45), (metal, -0.45)):
        bpy.ops.mesh.primitive_uv_sphere_add(radius=0.3, location=(0, y, -0.5), segments=48, ring_count=24)
        bpy.ops.object.shade_smooth()
        bpy.context.object.data.materials.append(mat)
    bpy.ops.mesh.primitive_plane_add(size=2.0, location=(0.9, 0, -0.2), rotation=(0, math.pi / 2, 0))
    bpy.context.object.data.materials.append(principled("wall", **{
        "Base Color": (0.8, 0.2, 0.1, 1), "Roughness": 0.3, "Coat Weight": 0.5, "Coat Tint": (0.3, 0.5, 1.0, 1)}))
    add_low_point_light(sc)
    return sc


def test_caustics_switches_match_cycles(tmp_path):
    """Principled glass, coated metal and a coated wall over a Principled floor: with each
    setting of the switches, DRT's floor in the balls' shadows is within 4 % of Cycles's and
    the whole image within 1.5 %, and the light a setting takes away (the image with both on
    minus with it) within 10 % of what it takes away in Cycles (measured at 1024 samples:
    reflective off 0.0101 vs 0.0101, refractive off 0.0187 vs 0.0183, both 0.0289 vs 0.0285;
    regions within 2.7 %)."""
    pytest.importorskip("bpy")
    from node_parity import render_rgba_both

    regions = {"glass shadow": (slice(4, 15), slice(20, 32)), "metal shadow": (slice(18, 28), slice(20, 32)),
               "image": (slice(None), slice(None))}
    images = {}
    for switches in [(True, True)] + SWITCHES:
        sc = _blender_principled_scene(512, switches)
        cycles, drt = (img[..., :3] for img in render_rgba_both(sc, tmp_path / f"{switches}.exr"))
        images[switches] = cycles, drt
        for name, r in regions.items():
            a, b = cycles[r].mean(), drt[r].mean()
            print(switches, name, "Cycles", a, "DRT", b)
            assert abs(b / a - 1) < (0.015 if name == "image" else 0.04), (switches, name, a, b)
    for switches in SWITCHES:
        removed = [(images[(True, True)][k] - images[switches][k]).mean() for k in (0, 1)]
        print(switches, "removed: Cycles", removed[0], "DRT", removed[1])
        assert removed[0] > 0.005 and abs(removed[1] / removed[0] - 1) < 0.1, (switches, removed)


def test_the_light_paths_and_passes_panels_show_the_switches_and_the_mist_pass():
    """DRT's Light Paths panel edits Cycles's Caustics switches, its Data passes panel the Mist
    pass, and Blender's World > Mist Pass panel shows for DRT."""
    pytest.importorskip("bpy")
    import bpy

    from addon import ui
    from test_addon import FakeLayout, ensure_registered

    ensure_registered()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    drawn = {}
    for cls in (ui.DRT_RENDER_PT_light_paths, ui.DRT_VIEWLAYER_PT_passes_data):
        panel = type("FakePanel", (), {"layout": FakeLayout()})()
        cls.draw(panel, bpy.context)
        drawn[cls.__name__] = panel.layout.props
    assert {"blur_glossy", "caustics_reflective", "caustics_refractive"} <= set(drawn["DRT_RENDER_PT_light_paths"])
    assert "use_pass_mist" in drawn["DRT_VIEWLAYER_PT_passes_data"]
    assert ui.ENGINE in bpy.types.EEVEE_WORLD_PT_mist.COMPAT_ENGINES
