"""``.blend`` input for the command line, through the bpy module and the add-on's exporter.

This is the only core module that reaches Blender, and only when a ``.blend`` is given: it is
imported lazily by the CLI. The exporter is the add-on's own (``addon/export``), so a scene
rendered from the command line is exactly the scene F12 renders. The add-on package is found in
the source checkout next to ``core/`` (or as an installed ``drt_blender`` module).
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import sys

from .scene import Scene, scene_from_dict

ADDON_MODULE = "drt_blender"


class BlendError(Exception):
    """A .blend could not be exported; the message is for the user."""


def _load_addon():
    if ADDON_MODULE in sys.modules:
        return sys.modules[ADDON_MODULE]
    try:
        import bpy  # noqa: F401
    except ImportError:
        raise BlendError("reading .blend files needs the bpy module: pip install 'bpy==5.0.1' (Python 3.11)") from None
    here = os.path.dirname(os.path.abspath(__file__))
    addon_dir = os.path.normpath(os.path.join(here, "..", "..", "addon"))
    init = os.path.join(addon_dir, "__init__.py")
    if os.path.isfile(init):
        spec = importlib.util.spec_from_file_location(ADDON_MODULE, init, submodule_search_locations=[addon_dir])
        module = importlib.util.module_from_spec(spec)
        sys.modules[ADDON_MODULE] = module
        spec.loader.exec_module(module)
        return module
    try:
        return importlib.import_module(ADDON_MODULE)
    except ImportError:
        raise BlendError("the DRT add-on (addon/) was not found next to the core; run from a source checkout") from None


def export_blend_arrays(path: str, frame: int | None = None) -> tuple[dict, dict, list]:
    """Open ``path`` with bpy and export its scene: (header, arrays, warnings)."""
    addon = _load_addon()
    blend = importlib.import_module(f"{addon.__name__}.export.blend")
    import bpy

    # Register for the export only (so a .blend saved with the DRT engine opens with it), and
    # leave Blender as we found it: a process that also loads the add-on itself keeps its own.
    registered_here = not hasattr(bpy.types.Scene, "drt")
    if registered_here:
        addon.register()
    try:
        result = blend.export_blend_file(os.path.abspath(path), frame=frame)
    except Exception as e:  # bpy raises RuntimeError for unreadable files, ExportError for scenes
        raise BlendError(f"cannot export {path}: {e}") from None
    finally:
        if registered_here and hasattr(bpy.types.Scene, "drt"):
            addon.unregister()
    return result.header, result.arrays, list(getattr(result, "warnings", []))


def scene_from_blend(path: str, frame: int | None = None) -> Scene:
    header, arrays, warnings = export_blend_arrays(path, frame)
    for w in warnings:
        print(f"drt: warning: {w}", file=sys.stderr)
    return scene_from_dict(header, arrays)


def export_blend(path: str, output: str, frame: int | None = None) -> None:
    from .scene_file import save_scene

    header, arrays, warnings = export_blend_arrays(path, frame)
    for w in warnings:
        print(f"drt: warning: {w}", file=sys.stderr)
    scene_from_dict(header, arrays)  # never write a file the loader would refuse
    save_scene(output, header, arrays)
