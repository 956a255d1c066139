"""Cornell box lit by a square area light (diffuse walls, two boxes).

Room: x ∈ [-1, 1], y ∈ [-1, 1], z ∈ [0, 2]; open towards −y, where the camera stands.
The walls are one mesh with per-face material slots (exercises slot → material mapping).
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common as C  # noqa: E402

FINISH = dict(resolution=(96, 96), samples=16)


def build():
    scene = C.reset()
    white = C.diffuse("White", (0.73, 0.73, 0.73))
    red = C.diffuse("Red", (0.65, 0.05, 0.05))
    green = C.diffuse("Green", (0.12, 0.45, 0.15))
    v = [(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0),
         (-1, -1, 2), (1, -1, 2), (1, 1, 2), (-1, 1, 2)]
    faces = [(0, 1, 2, 3),   # floor, facing +z
             (4, 7, 6, 5),   # ceiling, facing −z
             (3, 2, 6, 7),   # back wall, facing −y
             (0, 3, 7, 4),   # left wall (x = −1), facing +x
             (1, 5, 6, 2)]   # right wall (x = +1), facing −x
    C.mesh_object("Room", v, faces, [white, red, green], face_materials=[0, 0, 0, 1, 2])
    C.box("TallBox", (0.6, 0.6, 1.2), (-0.33, 0.3, 0.6), white, rotation_z=C.deg(17))
    C.box("ShortBox", (0.6, 0.6, 0.6), (0.35, -0.3, 0.3), white, rotation_z=C.deg(-17))
    C.light("Ceiling", "AREA", (0.0, 0.0, 1.98), shape="SQUARE", size=0.5, energy=40.0)
    C.camera((0.0, -3.9, 1.0), (0.0, 0.0, 1.0), lens=38.0)
    return scene


if __name__ == "__main__":
    C.finish(build(), "cornell_box", **FINISH)
