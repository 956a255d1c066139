"""Motion blur: a cube translating 1 unit per frame with linear keys, a spinning bar, a
deforming (twisting) column, and static objects (which must get no motion data).

Shutter 0.5 frames centred on the frame (Blender's defaults), rendered at frame 5.
"""

import os
import sys

import bpy

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common as C  # noqa: E402

FINISH = dict(resolution=(128, 72), samples=16)


def build():
    scene = C.reset()
    bpy.context.preferences.edit.keyframe_new_interpolation_type = "LINEAR"
    C.set_world(scene.world, (0.2, 0.2, 0.2), 1.0)
    grey = C.diffuse("Grey", (0.6, 0.6, 0.6))
    C.quad("Floor", (0, 0, 0), 10.0, grey)
    mover = C.box("Mover", (0.5, 0.5, 0.5), (-1.5, 0.0, 0.5), C.diffuse("Orange", (0.8, 0.4, 0.1)))
    for f, x in ((1, -1.5 - 4.0 * 0.25), (9, -1.5 + 4.0 * 0.25)):
        mover.location.x = x
        mover.keyframe_insert("location", index=0, frame=f)
    spinner = C.box("Spinner", (1.2, 0.15, 0.15), (0.5, 0.0, 1.2), C.diffuse("Blue", (0.1, 0.2, 0.8)))
    for f, a in ((1, 0.0), (9, C.deg(8 * 30))):
        spinner.rotation_euler.y = a
        spinner.keyframe_insert("rotation_euler", index=1, frame=f)
    column = C.box("Twister", (0.3, 0.3, 1.5), (1.8, 0.5, 0.75), C.diffuse("Green", (0.2, 0.7, 0.3)))
    # Subdivide the column along its height so the twist bends it.
    bpy.context.view_layer.objects.active = column
    mod_sub = column.modifiers.new("Subdiv", "SUBSURF")
    mod_sub.subdivision_type = "SIMPLE"
    mod_sub.levels = mod_sub.render_levels = 3
    twist = column.modifiers.new("Twist", "SIMPLE_DEFORM")
    twist.deform_method = "TWIST"
    twist.deform_axis = "Z"
    for f, a in ((1, 0.0), (9, C.deg(8 * 20))):
        twist.angle = a
        twist.keyframe_insert("angle", frame=f)
    for idblock in (mover, spinner, column):
        C.make_linear(idblock)
    C.box("Static", (0.4, 0.4, 0.4), (-0.5, 1.2, 0.2), grey)
    C.light("Key", "POINT", (1.0, -2.0, 4.0), energy=600.0, shadow_soft_size=0.3)
    C.camera((0.0, -6.0, 2.5), (0.0, 0.0, 0.6), lens=35.0)
    scene.frame_start, scene.frame_end = 1, 9
    scene.frame_set(5)
    scene.render.use_motion_blur = True
    scene.render.motion_blur_shutter = 0.5
    scene.render.motion_blur_position = "CENTER"
    return scene


if __name__ == "__main__":
    C.finish(build(), "motion_blur", **FINISH)
