"""An absorbing coloured liquid in glass: a clear glass box (Glass BSDF surface) filled with a
Volume Absorption medium, beside a glass box holding a Principled Volume with scattering
(milky), on a tiled floor (a Checker texture into a Diffuse BSDF) under an area light and a dim
world. Homogeneous media and a texture, no procedural node: the scene the compile plan of the
"media-programs" kernel variant is recorded from (drt.compile_plan).
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common as C  # noqa: E402

FINISH = dict(resolution=(96, 64), samples=64)


def tiled(name, color1, color2, scale):
    """A Diffuse BSDF whose colour is a Checker texture on the Generated coordinates."""
    mat, nodes, out = C._new_material(name)
    n = nodes.new("ShaderNodeBsdfDiffuse")
    ck = nodes.new("ShaderNodeTexChecker")
    ck.inputs["Scale"].default_value = scale
    ck.inputs["Color1"].default_value = C._rgba(color1)
    ck.inputs["Color2"].default_value = C._rgba(color2)
    mat.node_tree.links.new(ck.outputs["Color"], n.inputs["Color"])
    mat.node_tree.links.new(n.outputs[0], out.inputs["Surface"])
    mat.diffuse_color = C._rgba(color1)
    return mat


def build():
    scene = C.reset()
    C.set_world(scene.world, (0.3, 0.32, 0.35), 0.6)
    C.quad("Floor", (0, 0, 0), 12.0, tiled("Floor", (0.6, 0.6, 0.6), (0.35, 0.35, 0.35), 24.0))
    glass = {"node": "ShaderNodeBsdfGlass", "Color": (1.0, 1.0, 1.0, 1.0), "Roughness": 0.0, "IOR": 1.33}
    wine = C.volume_material("Wine", node="ShaderNodeVolumeAbsorption", surface=glass,
                             Color=(0.9, 0.2, 0.1), Density=1.5)
    milk = C.volume_material("Milk", surface=dict(glass, IOR=1.35), Color=(0.9, 0.85, 0.7),
                             Density=3.0, Absorption_Color=(0.6, 0.6, 0.6))
    C.box("Wine", (0.8, 0.8, 1.2), (-0.6, 0.0, 0.6001), wine)
    C.box("Milk", (0.8, 0.8, 1.2), (0.6, 0.3, 0.6001), milk)
    C.light("Softbox", "AREA", (0.5, -1.5, 3.0), rotation=(C.deg(30), 0, 0), size=2.0, energy=400.0)
    C.camera((0.0, -4.0, 1.5), (0.0, 0.0, 0.6), lens=40.0)
    return scene


if __name__ == "__main__":
    C.finish(build(), "volume_liquid", **FINISH)
