"""Export helpers for bpy scripts and command lines.

``export_render()`` exports the open file's scene through a render-mode depsgraph, the one F12
renders (modifiers at render levels); ``export_blend_file()`` (the CLI's .blend loader) uses it.
``export_current()`` exports through the viewport depsgraph, moving time with
``scene.frame_set`` for motion blur (objects hidden in the viewport are not in that depsgraph;
objects hidden for rendering are skipped as in a render); the committed scene files were made
with it, and for them both give the same arrays.
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


class _RenderDepsgraphExporter(bpy.types.RenderEngine):
    """A render engine that renders nothing: its ``render()`` exports the depsgraph Blender
    hands it. Blender builds a *render-mode* depsgraph (modifiers at their render levels,
    objects hidden for rendering left out, as F12 sees the scene) only for a render, and Python
    cannot create one; so ``export_render`` runs ``bpy.ops.render.render`` with this engine.
    Registered for the duration of one export only (it never shows in Blender's UI)."""

    bl_idname = "DRT_RENDER_EXPORT"
    bl_label = "DRT (export)"
    result = None  # (ExportResult or None, exception or None) of the last render() call

    def render(self, depsgraph):
        try:
            type(self).result = (export_depsgraph(depsgraph, frame_set=self.frame_set), None)
        except Exception as exc:  # noqa: BLE001 -- handed back to export_render, raised there
            type(self).result = (None, exc)


def export_render(scene=None, frame: int | None = None) -> ExportResult:
    """Export ``scene`` (default: the current one) at ``frame`` through a render-mode
    depsgraph: exactly the scene F12 renders (``blender -b ... -E DRT`` and the add-on's own
    render() get the same depsgraph)."""
    from . import ExportError

    scene = scene or bpy.context.scene
    if scene.camera is None:  # bpy's render operator would say it less clearly
        raise ExportError("the scene has no active camera")
    if frame is not None:
        scene.frame_set(int(frame))
    engine = scene.render.engine
    bpy.utils.register_class(_RenderDepsgraphExporter)
    _RenderDepsgraphExporter.result = None
    try:
        scene.render.engine = _RenderDepsgraphExporter.bl_idname
        bpy.ops.render.render(write_still=False, scene=scene.name)
    finally:
        scene.render.engine = engine
        bpy.utils.unregister_class(_RenderDepsgraphExporter)
    result, error = _RenderDepsgraphExporter.result or (None, RuntimeError("Blender did not render"))
    _RenderDepsgraphExporter.result = None
    if error is not None:
        raise error
    return result


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
    return export_render(frame=frame)


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
