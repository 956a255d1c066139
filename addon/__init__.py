"""DRT for Blender: a distribution ray tracer as a render engine (bl_idname 'DRT').

Blender 4.2+ reads ``blender_manifest.toml`` (extension); older Blender reads ``bl_info``
(legacy add-on). The core renderer is bundled as the sub-package ``drt`` in both builds
(``scripts/build_extension.py``); in a development checkout the pip-installed ``drt`` is used.
"""

bl_info = {
    "name": "DRT",
    "author": "DRT contributors",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "Properties > Render > Render Engine > DRT",
    "description": "Distribution ray tracer (numpy + Embree) as a render engine",
    "category": "Render",
}

import os
import sys


def _add_vendor_path() -> None:
    """Legacy builds carry third-party packages (embreex) in ``_vendor``; use them last."""
    vendor = os.path.join(os.path.dirname(__file__), "_vendor")
    if os.path.isdir(vendor) and vendor not in sys.path:
        sys.path.append(vendor)


_add_vendor_path()

import bpy  # noqa: E402

from . import engine, properties, ui  # noqa: E402

_classes = properties.classes + (engine.DRTRenderEngine,) + ui.classes


def register():
    for cls in _classes:
        bpy.utils.register_class(cls)
    ui.add_compat_engines()


def unregister():
    ui.remove_compat_engines()
    for cls in reversed(_classes):
        bpy.utils.unregister_class(cls)
