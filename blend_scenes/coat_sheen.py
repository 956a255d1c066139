"""Coat and sheen: Principled spheres with a clear coat (smooth and rough, over plastic and over
a rough metal: car paint), a tinted coat, sheen over a dark fabric, coat + sheen over a
checker-textured base, and Sheen BSDFs (Microfiber and Ashikhmin), over a diffuse floor under an
area light and a dim world (docs/materials.md, "Principled coat and sheen").
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common as C  # noqa: E402


def principled(name, checker=False, **inputs):
    mat, nodes, out = C._new_material(name)
    n = nodes.new("ShaderNodeBsdfPrincipled")
    for k, v in inputs.items():
        n.inputs[k].default_value = v
    if checker:  # a textured base colour under the coat and sheen
        ck = nodes.new("ShaderNodeTexChecker")
        ck.inputs["Scale"].default_value = 6.0
        ck.inputs["Color1"].default_value = (0.8, 0.15, 0.05, 1.0)
        ck.inputs["Color2"].default_value = (0.9, 0.8, 0.6, 1.0)
        mat.node_tree.links.new(ck.outputs["Color"], n.inputs["Base Color"])
    mat.node_tree.links.new(n.outputs[0], out.inputs["Surface"])
    return mat


def sheen(name, color, roughness, distribution):
    mat, nodes, out = C._new_material(name)
    n = nodes.new("ShaderNodeBsdfSheen")
    n.distribution = distribution
    n.inputs["Color"].default_value = C._rgba(color)
    n.inputs["Roughness"].default_value = roughness
    mat.node_tree.links.new(n.outputs[0], out.inputs["Surface"])
    return mat


FINISH = dict(resolution=(192, 108), samples=16)


def build():
    scene = C.reset()
    C.set_world(scene.world, (0.3, 0.35, 0.4), 0.5)
    C.quad("Floor", (0, 0, 0), 12.0, C.diffuse("Floor", (0.45, 0.45, 0.45)))
    C.quad("Back", (0, 2.5, 2.0), (12.0, 4.0), C.diffuse("Back", (0.3, 0.5, 0.6)),
           rotation=(C.deg(90), 0, 0))
    specs = [
        ("CoatPlastic", principled("CoatPlastic", **{"Base Color": (0.7, 0.05, 0.05, 1.0), "Roughness": 0.5,
                                                      "Coat Weight": 1.0, "Coat Roughness": 0.03})),
        ("CarPaint", principled("CarPaint", **{"Base Color": (0.1, 0.25, 0.7, 1.0), "Metallic": 1.0,
                                                "Roughness": 0.4, "Coat Weight": 1.0, "Coat Roughness": 0.05})),
        ("TintedCoat", principled("TintedCoat", **{"Base Color": (0.8, 0.8, 0.8, 1.0), "Roughness": 0.3,
                                                    "Coat Weight": 0.8, "Coat Roughness": 0.3,
                                                    "Coat IOR": 1.6, "Coat Tint": (1.0, 0.6, 0.2, 1.0)})),
        ("Fabric", principled("Fabric", **{"Base Color": (0.05, 0.05, 0.2, 1.0), "Roughness": 0.9,
                                            "Sheen Weight": 1.0, "Sheen Roughness": 0.3,
                                            "Sheen Tint": (0.8, 0.8, 1.0, 1.0)})),
        ("CoatSheen", principled("CoatSheen", checker=True, **{"Roughness": 0.6, "Coat Weight": 0.5,
                                                               "Coat Roughness": 0.2, "Sheen Weight": 0.6,
                                                               "Sheen Roughness": 0.5})),
        ("Microfiber", sheen("Microfiber", (0.9, 0.9, 0.9), 0.5, "MICROFIBER")),
        ("Velvet", sheen("Velvet", (0.9, 0.5, 0.3), 0.4, "ASHIKHMIN")),
    ]
    for i, (name, mat) in enumerate(specs):
        x = -2.7 + i * 0.9
        C.uv_sphere(name, 0.42, (x, 0.0, 0.42), mat, segments=48, rings=24)
    C.light("Softbox", "AREA", (0.0, -1.5, 3.5), rotation=(C.deg(25), 0, 0),
            shape="RECTANGLE", size=3.0, size_y=1.0, energy=300.0)
    C.camera((0.0, -6.4, 1.7), (0.0, 0.0, 0.4), lens=38.0)
    return scene


if __name__ == "__main__":
    C.finish(build(), "coat_sheen", **FINISH)
