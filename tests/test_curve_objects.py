"""Curves, text, NURBS surfaces and metaballs render once, as in Cycles: Blender presents their
evaluated geometry as a mesh instance of the object, and only that instance is exported
(``addon.export.objects_presented_as_meshes``). Before, the object was exported as well, so
every such surface was doubled: transparent ones covered twice, emissive ones lit twice."""

from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from node_parity import node, render_rgba_both, setup_scene  # noqa: E402

pytestmark = pytest.mark.blender


def _curve_like_objects(strength=1.0):
    """A bevelled Bézier circle, a text, a metaball and a NURBS sphere, in [−1, 1]² seen from
    above, each with an emissive material of ``strength``."""
    mat = bpy.data.materials.new("emitter")
    nt = mat.node_tree
    nt.nodes.clear()
    em = node(nt, "ShaderNodeEmission", {"Color": (0.2, 0.6, 1.0, 1), "Strength": strength})
    nt.links.new(em.outputs[0], nt.nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
    bpy.ops.curve.primitive_bezier_circle_add(radius=0.3, location=(-0.5, 0.5, -1))
    bpy.context.object.data.bevel_depth = 0.08
    bpy.ops.object.text_add(location=(0.05, 0.35, -1))
    bpy.context.object.data.size = 0.5
    bpy.ops.object.metaball_add(radius=0.5, location=(-0.5, -0.5, -1))
    bpy.ops.surface.primitive_nurbs_surface_sphere_add(radius=0.35, location=(0.5, -0.5, -1))
    objs = [o for o in bpy.context.scene.objects if o.type in ("CURVE", "FONT", "META", "SURFACE")]
    for o in objs:
        o.data.materials.append(mat)
    return objs


def test_each_curve_like_object_is_exported_once():
    from addon.export import export_depsgraph

    setup_scene(2)
    objs = _curve_like_objects()
    res = export_depsgraph(bpy.context.evaluated_depsgraph_get())
    names = [o["name"] for o in res.header["objects"]]
    assert len(names) == len(objs) == 4, names
    for o in objs:
        assert sum(n.split("@")[0] == o.name for n in names) == 1, (o.name, names)


def test_curve_like_emitters_light_a_floor_as_in_cycles(tmp_path):
    """The objects as emitters over a diffuse floor: the floor's light against Cycles (with
    every emitter doubled, next-event estimation sampled both copies and the floor came out
    17 % brighter than Cycles's)."""
    sc = setup_scene(4)
    sc.cycles.samples = sc.drt.samples = 64
    sc.cycles.max_bounces = sc.drt.max_bounces = 1
    for o in _curve_like_objects(strength=20.0):
        o.location.z = -0.7
    bpy.ops.mesh.primitive_plane_add(size=2.0, location=(0, 0, -1.0))
    floor = bpy.data.materials.new("floor")
    floor.node_tree.nodes["Principled BSDF"].inputs["Specular IOR Level"].default_value = 0.0
    bpy.context.object.data.materials.append(floor)
    cycles, drt = render_rgba_both(sc, tmp_path / "curves.exr")
    bare = cycles[..., 2] < 5.0  # floor pixels (an emitter's own blue is 20)
    lit_c, lit_d = cycles[bare][:, :3].mean(0), drt[bare][:, :3].mean(0)
    assert bare.mean() > 0.3 and lit_c.min() > 0.01
    print("floor light, Cycles / DRT", lit_c, lit_d)
    np.testing.assert_allclose(lit_d, lit_c, rtol=0.03)  # measured 1 %
