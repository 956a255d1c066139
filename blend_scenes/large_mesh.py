"""Large mesh: a smooth-shaded UV sphere of ~1M triangles with a UV map, for export speed.

Generated, not committed (large_mesh.blend / .npz are git-ignored): run this script first.
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common as C  # noqa: E402

SEGMENTS, RINGS = 1024, 512  # 2·1024·(512 − 2) + 2·1024 = 1,046,528 triangles

FINISH = dict(resolution=(64, 64), samples=4)


def build():
    scene = C.reset()
    C.set_world(scene.world, (0.5, 0.5, 0.5), 1.0)
    C.uv_sphere("BigSphere", 1.0, (0, 0, 0), C.diffuse("Clay", (0.7, 0.6, 0.5)),
                segments=SEGMENTS, rings=RINGS)
    C.light("Sun", "SUN", (0, 0, 5), rotation=(0.6, 0.2, 0.0), energy=3.0)
    C.camera((0.0, -4.0, 0.0), (0.0, 0.0, 0.0), lens=50.0)
    return scene


if __name__ == "__main__":
    C.finish(build(), "large_mesh", **FINISH)
