"""Export helpers for bpy scripts and command lines (no RenderEngine involved).

``export_current()`` exports the open file's scene through the viewport depsgraph, moving time
with ``scene.frame_set`` for motion blur. Objects hidden in the viewport are not in that
depsgraph; objects hidden for rendering are skipped as in a render.
"""

import json
import os

import bpy
import numpy as np

from . import ExportResult, export_depsgraph


def export_current(scene=None, frame: int | None = None, preview: bool = False) -> ExportResult:
    scene = scene or bpy.context.scene
    if frame is not None:
        scene.frame_set(int(frame))

    def frame_set(f, subframe=0.0):
        scene.frame_set(int(f), subframe=float(subframe))

    depsgraph = bpy.context.evaluated_depsgraph_get()
    return export_depsgraph(depsgraph, frame_set=frame_set, preview=preview)


def export_blend_file(path: str, frame: int | None = None) -> ExportResult:
    """Open a .blend (replacing the current file) and export its scene.

    Blender raises when a file opens *with errors* (a linked library it could not read): the
    file is open then, with placeholders the exporter reports as warnings, so the export goes
    on, as F12 and ``blender -b`` do. A file that did not open at all stays an error."""
    try:
        bpy.ops.wm.open_mainfile(filepath=str(path))
    except RuntimeError:
        if not _is_open(path):
            raise
    from .. import register  # scene.drt must exist for the settings
    if not hasattr(bpy.types.Scene, "drt"):
        register()
    return export_current(frame=frame)


def _is_open(path) -> bool:
    current = bpy.data.filepath
    return bool(current) and os.path.normcase(os.path.realpath(current)) == \
        os.path.normcase(os.path.realpath(str(path)))


def save_npz(path: str, header: dict, arrays: dict) -> None:
    """Write a DRT scene file; the core's writer when importable, the same format otherwise."""
    try:
        from ..compat import core_module
        core_module("scene_file").save_scene(path, header, arrays)
    except ImportError:
        payload = {"header": np.frombuffer(json.dumps(header).encode("utf-8"), dtype=np.uint8)}
        payload.update(arrays)
        np.savez_compressed(path, **payload)
