"""Fog lit by a spot light (god rays): a room-sized box of Principled Volume fog that also holds
the camera (camera inside a volume), a spot light shining down through a slatted blocker onto a
diffuse floor, a dim world. Cycles's default Volume bounces (0: single scattering).
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common as C  # noqa: E402

FINISH = dict(resolution=(96, 64), samples=64)


def build():
    scene = C.reset()
    C.set_world(scene.world, (0.05, 0.06, 0.08), 1.0)
    C.quad("Floor", (0, 0, 0), 12.0, C.diffuse("Floor", (0.5, 0.5, 0.5)))
    fog = C.volume_material("Fog", Color=(0.9, 0.9, 0.9), Density=0.12, Anisotropy=0.3)
    C.box("FogBox", (10.0, 10.0, 6.0), (0, 0, 2.99), fog)
    slats = C.diffuse("Slats", (0.2, 0.2, 0.2))
    for i in range(4):
        C.box(f"Slat{i}", (0.25, 3.0, 0.1), (-0.9 + 0.6 * i, 0.0, 3.0), slats)
    C.light("Spot", "SPOT", (0.0, 0.0, 4.5), spot_size=C.deg(50), spot_blend=0.15, energy=1500.0,
            shadow_soft_size=0.05)
    C.camera((0.0, -4.5, 1.4), (0.0, 0.0, 1.6), lens=28.0)
    return scene


if __name__ == "__main__":
    C.finish(build(), "volume_fog", **FINISH)
