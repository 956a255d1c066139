"""A world volume: the world's Volume output holds a thin Volume Scatter haze (forward
scattering) lit by a sun and a point light, around diffuse objects on a floor; the camera and
everything else sit in the haze. Volume bounces 2 (multiple scattering).
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common as C  # noqa: E402

FINISH = dict(resolution=(96, 64), samples=64)


def build():
    scene = C.reset()
    C.set_world(scene.world, (0.2, 0.25, 0.35), 1.0)
    nodes = scene.world.node_tree.nodes
    out = next(n for n in nodes if n.bl_idname == "ShaderNodeOutputWorld")
    haze = nodes.new("ShaderNodeVolumeScatter")
    haze.inputs["Color"].default_value = (0.8, 0.85, 0.9, 1.0)
    haze.inputs["Density"].default_value = 0.06
    haze.inputs["Anisotropy"].default_value = 0.5
    scene.world.node_tree.links.new(haze.outputs[0], out.inputs["Volume"])
    C.quad("Floor", (0, 0, 0), 8.0, C.diffuse("Floor", (0.5, 0.5, 0.5)))
    C.uv_sphere("Ball", 0.6, (-0.8, 0.5, 0.6), C.diffuse("Ball", (0.8, 0.3, 0.2)))
    C.box("Block", (0.8, 0.8, 1.4), (0.9, 0.8, 0.7), C.diffuse("Block", (0.3, 0.6, 0.8)))
    C.light("Sun", "SUN", (0, 0, 5), rotation=(C.deg(50), 0, C.deg(30)), energy=2.0, angle=C.deg(2))
    C.light("Lamp", "POINT", (0.0, -0.5, 2.0), energy=150.0, shadow_soft_size=0.1)
    C.camera((0.0, -5.0, 1.5), (0.0, 0.3, 0.6), lens=35.0)
    if C._ensure_addon():
        scene.drt.volume_bounces = 2
    return scene


if __name__ == "__main__":
    C.finish(build(), "volume_world", **FINISH)
