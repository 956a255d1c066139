"""The ``.blend`` scene loader the core's command line uses (``python -m drt render X.blend``).

Registered as the ``blend`` entry point of the group ``drt.scene_loaders`` (pyproject.toml), so
the core finds it without importing the add-on by name: the dependency points from the
Blender side to the core, never back. It opens the file with the bpy module and exports it with
the same exporter F12 uses, so the CLI renders exactly the scene Blender renders.
"""

import os

import bpy


def read_blend(path: str, frame=None):
    """Open ``path`` (replacing bpy's current file) and export its scene at ``frame`` (default:
    the file's current frame): returns (header, arrays, warnings) as ``drt.loaders`` expects."""
    from . import register, unregister
    from .export.blend import export_blend_file

    # Register for the export only (so a .blend saved with the DRT engine opens with it), and
    # leave Blender as we found it: a process that also loads the add-on itself keeps its own.
    registered_here = not hasattr(bpy.types.Scene, "drt")
    if registered_here:
        register()
    try:
        result = export_blend_file(os.path.abspath(path), frame=frame)
    finally:
        if registered_here and hasattr(bpy.types.Scene, "drt"):
            unregister()
    return result.header, result.arrays, list(getattr(result, "warnings", []))
