"""Subsurface scattering (issue 14): Suzanne with a skin-like Principled BSDF (Subsurface Weight
1, Random Walk, radius (1, 0.2, 0.1) × scale 0.15 m) lit from behind by an area light, so light
bleeds red through the thin ears, plus a weak sun from the front-left and a dim world.
docs/subsurface.md.

Specular IOR Level is 0: this scene measures the subsurface walk; DRT's Principled specular
layer is still the simplified one (see textured.py). Suzanne is not a closed mesh (the eyes are
separate shells); Cycles's walk and DRT's treat the openings alike (a walk leaving through one
finds no surface and dies).
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common as C  # noqa: E402

import bpy  # noqa: E402

FINISH = dict(resolution=(128, 96), samples=64)


def skin_material(method="RANDOM_WALK"):
    mat, nodes, out = C._new_material("Skin")
    p = nodes.new("ShaderNodeBsdfPrincipled")
    p.inputs["Base Color"].default_value = (0.9, 0.62, 0.5, 1.0)
    p.inputs["Roughness"].default_value = 0.5
    p.inputs["Specular IOR Level"].default_value = 0.0
    p.inputs["Subsurface Weight"].default_value = 1.0
    p.inputs["Subsurface Radius"].default_value = (1.0, 0.2, 0.1)
    p.inputs["Subsurface Scale"].default_value = 0.15
    p.subsurface_method = method
    mat.node_tree.links.new(p.outputs[0], out.inputs["Surface"])
    mat.diffuse_color = (0.9, 0.62, 0.5, 1.0)
    return mat


def build():
    scene = C.reset()
    C.set_world(scene.world, (0.3, 0.35, 0.45), 0.15)
    bpy.ops.mesh.primitive_monkey_add(size=2.0, location=(0, 0, 0))
    head = bpy.context.object
    head.name = "Suzanne"
    head.data.materials.append(skin_material())
    head.data.polygons.foreach_set("use_smooth", [True] * len(head.data.polygons))
    head.data.update()
    # smooth geometry, not only smooth normals: where a low-poly facet's shading normal and its
    # geometric normal disagree, Cycles and DRT handle SSS exits differently (docs/subsurface.md)
    sub = head.modifiers.new("Subdivision", "SUBSURF")
    sub.levels, sub.render_levels = 2, 2
    # behind the head, facing the camera (−Y): its light passes through the ears
    C.light("Back", "AREA", (0.0, 2.2, 0.4), rotation=(C.deg(-90), 0.0, 0.0), energy=400.0, size=1.5)
    C.light("Sun", "SUN", (0, 0, 5), rotation=(C.deg(50), 0.0, C.deg(-35)), energy=1.0)
    C.camera((0.0, -5.5, 0.6), (0.0, 0.0, 0.1), lens=50.0)
    return scene


if __name__ == "__main__":
    C.finish(build(), "sss_head", **FINISH)
