"""Glossy and glass: GGX glossy spheres (sharp and rough), a clear and a frosted glass sphere,
a Principled metal and a Principled plastic, a Mix Shader, over a diffuse floor under an area
light and a dim world.
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common as C  # noqa: E402


def principled(name, **inputs):
    mat, nodes, out = C._new_material(name)
    n = nodes.new("ShaderNodeBsdfPrincipled")
    for k, v in inputs.items():
        n.inputs[k].default_value = v
    mat.node_tree.links.new(n.outputs[0], out.inputs["Surface"])
    return mat

FINISH = dict(resolution=(128, 72), samples=16)


def build():
    scene = C.reset()
    C.set_world(scene.world, (0.3, 0.35, 0.4), 0.5)
    C.quad("Floor", (0, 0, 0), 12.0, C.diffuse("Floor", (0.45, 0.45, 0.45)))
    C.quad("Back", (0, 2.5, 2.0), (12.0, 4.0), C.diffuse("Back", (0.3, 0.5, 0.6)),
           rotation=(C.deg(90), 0, 0))
    specs = [
        ("GlossySharp", C.glossy("GlossySharp", (0.9, 0.9, 0.9), 0.05)),
        ("GlossyRough", C.glossy("GlossyRough", (0.9, 0.7, 0.4), 0.4)),
        ("Glass", C.glass("Glass", (1.0, 1.0, 1.0), 0.0, 1.5)),
        ("Frosted", C.glass("Frosted", (0.9, 1.0, 0.95), 0.3, 1.45)),
        ("Metal", principled("Metal", **{"Base Color": (0.95, 0.64, 0.54, 1.0),
                                          "Metallic": 1.0, "Roughness": 0.25})),
        ("Mix", C.mix("Mix", 0.3,
                      {"node": "ShaderNodeBsdfDiffuse", "Color": (0.7, 0.1, 0.1, 1.0)},
                      {"node": "ShaderNodeBsdfGlass", "Color": (1.0, 1.0, 1.0, 1.0), "IOR": 1.5})),
    ]
    for i, (name, mat) in enumerate(specs):
        x = -2.5 + i * 1.0
        C.uv_sphere(name, 0.42, (x, 0.0, 0.42), mat, segments=48, rings=24)
    C.light("Softbox", "AREA", (0.0, -1.5, 3.5), rotation=(C.deg(25), 0, 0),
            shape="RECTANGLE", size=3.0, size_y=1.0, energy=300.0)
    C.camera((0.0, -5.5, 1.6), (0.0, 0.0, 0.45), lens=40.0)
    return scene


if __name__ == "__main__":
    C.finish(build(), "glossy_glass", **FINISH)
