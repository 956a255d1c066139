"""A light's node tree (Use Nodes) scales its light as in Cycles: folded at export to one RGB
factor (``addon.export.light_nodes``). A diffuse plane under a point light of radius 0 (a
delta light: exact at one sample in both engines), no bounces, against Cycles pixel by pixel."""

from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from node_parity import node, render_rgba_both, setup_scene  # noqa: E402

pytestmark = pytest.mark.blender


def _lit_plane(tree=None):
    """The scene: a white diffuse plane under a 100 W point light whose tree ``tree(nt, emission,
    output)`` edits (None: Use Nodes off)."""
    sc = setup_scene(1)
    sc.cycles.samples = sc.drt.samples = 4
    bpy.ops.mesh.primitive_plane_add(size=2.0, location=(0, 0, 0))
    mat = bpy.data.materials.new("white")
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (1, 1, 1, 1)
    bsdf.inputs["Specular IOR Level"].default_value = 0.0
    bpy.context.object.data.materials.append(mat)
    light = bpy.data.lights.new("lamp", "POINT")
    light.energy, light.shadow_soft_size = 100.0, 0.0
    obj = bpy.data.objects.new("lamp", light)
    obj.location = (0.2, -0.1, 0.9)
    sc.collection.objects.link(obj)
    if tree is not None:
        light.use_nodes = True
        nt = light.node_tree
        em = next(n for n in nt.nodes if n.bl_idname == "ShaderNodeEmission")
        out = next(n for n in nt.nodes if n.bl_idname == "ShaderNodeOutputLight")
        tree(nt, em, out)
    return sc


def _strength(nt, em, out):
    em.inputs["Strength"].default_value = 2.5


def _tinted(nt, em, out):
    em.inputs["Color"].default_value = (1.0, 0.5, 0.25, 1.0)


def _blackbody(nt, em, out):
    bb = node(nt, "ShaderNodeBlackbody", {"Temperature": 3000.0})
    nt.links.new(bb.outputs[0], em.inputs["Color"])
    value = node(nt, "ShaderNodeValue")
    value.outputs[0].default_value = 1.5
    nt.links.new(value.outputs[0], em.inputs["Strength"])


def _falloff(nt, em, out):  # Quadratic, Smooth 0: the light's own falloff, strength 3
    lf = node(nt, "ShaderNodeLightFalloff", {"Strength": 3.0})
    nt.links.new(lf.outputs["Quadratic"], em.inputs["Strength"])


def _mixed(nt, em, out):
    red = node(nt, "ShaderNodeEmission", {"Color": (1, 0, 0, 1), "Strength": 3.0})
    mix = node(nt, "ShaderNodeMixShader", {0: 0.25, 1: em.outputs[0], 2: red.outputs[0]})
    nt.links.new(mix.outputs[0], out.inputs["Surface"])


def _unlinked(nt, em, out):
    for link in list(out.inputs["Surface"].links):
        nt.links.remove(link)


@pytest.mark.parametrize("tree", [None, _strength, _tinted, _blackbody, _falloff, _mixed, _unlinked],
                         ids=["no nodes", "strength", "tinted", "blackbody", "falloff", "mixed", "unlinked"])
def test_light_node_tree_matches_cycles(tmp_path, tree):
    sc = _lit_plane(tree)
    cycles, drt = render_rgba_both(sc, tmp_path / "light_nodes.exr")
    c, d = cycles[..., :3], drt[..., :3]
    if tree is _unlinked:
        assert c.max() == 0.0 and d.max() == 0.0
        return
    assert c.min() > 0.01
    # per channel the image means agree to 0.1 %; single pixels to 1 % (each engine jitters
    # its samples inside the 0.01-pixel filter on its own: up to 0.8 % where the light peaks)
    np.testing.assert_allclose(d.mean((0, 1)), c.mean((0, 1)), rtol=1e-3)
    np.testing.assert_allclose(d, c, rtol=1e-2)


def test_a_varying_light_tree_warns_and_uses_constant_values():
    from addon.export import export_depsgraph

    def textured(nt, em, out):
        falloff = node(nt, "ShaderNodeLightFalloff", {"Strength": 40.0})
        nt.links.new(falloff.outputs["Linear"], em.inputs["Strength"])

    sc = _lit_plane(textured)
    res = export_depsgraph(bpy.context.evaluated_depsgraph_get())
    assert any("Light 'lamp' nodes" in w and "Light Falloff" in w for w in res.warnings), res.warnings
    lamp = next(lt for lt in res.header["lights"] if lt["name"] == "lamp")
    assert lamp["color"] == pytest.approx([1.0, 1.0, 1.0])  # the Strength socket's own value: 1
    assert sc.render.engine == "CYCLES"


def test_a_portal_emits_nothing_as_in_cycles(tmp_path):
    """An area light marked as a portal only guides Cycles's world sampling: a plane under a
    white world with a 1 kW portal above it is as bright as the world alone makes it."""
    sc = _lit_plane(None)
    bpy.data.objects.remove(bpy.data.objects["lamp"])
    sc.world.node_tree.nodes["Background"].inputs[0].default_value = (1, 1, 1, 1)
    sc.world.node_tree.nodes["Background"].inputs[1].default_value = 1.0
    sc.cycles.samples = sc.drt.samples = 64
    portal = bpy.data.lights.new("portal", "AREA")
    portal.energy, portal.size = 1000.0, 0.5
    portal.cycles.is_portal = True
    obj = bpy.data.objects.new("portal", portal)
    obj.location = (0.0, 0.0, 0.5)
    sc.collection.objects.link(obj)
    cycles, drt = render_rgba_both(sc, tmp_path / "portal.exr")
    c, d = cycles[..., :3].mean(), drt[..., :3].mean()
    assert 0.9 < c < 1.1  # the world's light on a white plane (a 1 kW light would add ~100)
    assert abs(d / c - 1) < 0.02, (c, d)


def test_light_settings_drt_ignores_are_named():
    """Light linking, shadow linking, a light's ray visibility and cast-shadow switch: DRT
    renders the light plainly and says so, naming the setting."""
    from addon.export import export_depsgraph

    sc = _lit_plane(None)
    lamp = bpy.data.objects["lamp"]
    lamp.visible_glossy = False
    lamp.visible_shadow = False
    coll = bpy.data.collections.new("lit")
    lamp.light_linking.receiver_collection = coll
    res = export_depsgraph(bpy.context.evaluated_depsgraph_get())
    warned = [w for w in res.warnings if "'lamp'" in w]
    assert len(warned) == 1, res.warnings
    for name in ("light linking", "invisible to glossy rays", "casts no shadow"):
        assert name in warned[0], warned[0]
    assert len(res.header["lights"]) == 1 and sc is not None
