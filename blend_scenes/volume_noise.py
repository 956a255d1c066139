"""A heterogeneous cloud: a 2 m cube whose Principled Volume density is a thresholded Noise
Texture (Generated coordinates, Cycles's default for a volume), lit by a sun from the side and a
dim sky, above a grey floor. Cycles's default Volume bounces (0: single scattering).
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common as C  # noqa: E402

FINISH = dict(resolution=(96, 64), samples=64)


def cloud_material(name="Cloud", threshold=0.45, gain=12.0, scale=3.0, detail=2.0):
    """Principled Volume with Density = max(noise − threshold, 0) · gain."""
    mat = C.volume_material(name, Color=(0.9, 0.85, 0.8), Density=1.0, Anisotropy=0.2)
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    vol = next(n for n in nodes if n.bl_idname == "ShaderNodeVolumePrincipled")
    noise = nodes.new("ShaderNodeTexNoise")
    noise.inputs["Scale"].default_value = scale
    noise.inputs["Detail"].default_value = detail
    sub = nodes.new("ShaderNodeMath")
    sub.operation = "SUBTRACT"
    sub.inputs[1].default_value = threshold
    mx = nodes.new("ShaderNodeMath")
    mx.operation = "MAXIMUM"
    mx.inputs[1].default_value = 0.0
    mul = nodes.new("ShaderNodeMath")
    mul.operation = "MULTIPLY"
    mul.inputs[1].default_value = gain
    links.new(noise.outputs["Fac"], sub.inputs[0])
    links.new(sub.outputs[0], mx.inputs[0])
    links.new(mx.outputs[0], mul.inputs[0])
    links.new(mul.outputs[0], vol.inputs["Density"])
    return mat


def build():
    scene = C.reset()
    C.set_world(scene.world, (0.15, 0.18, 0.25), 1.0)
    C.quad("Floor", (0, 0, 0), 12.0, C.diffuse("Floor", (0.5, 0.5, 0.5)))
    C.box("Cloud", (2.0, 2.0, 2.0), (0, 0, 1.3), cloud_material())
    C.light("Sun", "SUN", (3.0, -2.0, 5.0), rotation=(C.deg(50.0), 0.0, C.deg(60.0)), energy=3.0,
            angle=C.deg(2.0))
    C.camera((0.0, -6.0, 2.0), (0.0, 0.0, 1.2), lens=40.0)
    return scene


if __name__ == "__main__":
    C.finish(build(), "volume_noise", **FINISH)
