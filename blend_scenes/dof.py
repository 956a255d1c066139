"""Depth of field: five diffuse spheres receding along a floor, focus on the middle one.

The camera focuses through ``dof.focus_object`` (an empty at the middle sphere) with a
six-bladed aperture at f/0.8, so both the focus-object path and polygonal bokeh are exercised.
"""

import os
import sys

import bpy

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common as C  # noqa: E402

FINISH = dict(resolution=(128, 72), samples=16)


def build():
    scene = C.reset()
    C.set_world(scene.world, (0.05, 0.06, 0.08), 1.0)
    floor = C.diffuse("Floor", (0.5, 0.5, 0.5))
    C.quad("Floor", (0, 3, 0), 12.0, floor)
    colors = [(0.8, 0.2, 0.2), (0.8, 0.6, 0.2), (0.3, 0.7, 0.3), (0.2, 0.4, 0.8), (0.6, 0.3, 0.7)]
    for i, col in enumerate(colors):
        C.uv_sphere(f"Ball{i}", 0.3, (-0.9 + 0.45 * i, 1.5 * i, 0.3), C.diffuse(f"Ball{i}", col))
    target = bpy.data.objects.new("Focus", None)
    scene.collection.objects.link(target)
    target.location = (0.0, 3.0, 0.3)
    C.light("Sun", "SUN", (0, 0, 5), rotation=(C.deg(40), C.deg(10), C.deg(30)),
            energy=3.0, angle=C.deg(5))
    cam = C.camera((0.0, -3.0, 1.0), (0.0, 3.0, 0.3), lens=50.0)
    dof = cam.data.dof
    dof.use_dof = True
    dof.focus_object = target
    dof.aperture_fstop = 0.8
    dof.aperture_blades = 6
    dof.aperture_rotation = C.deg(10)
    return scene


if __name__ == "__main__":
    C.finish(build(), "dof", **FINISH)
