"""Linked data that did not load → one warning per library (the render goes on without it).

When a library .blend is missing, unreadable, or no longer holds a linked data-block, Blender
still opens the file and puts an empty placeholder where the linked data would be: an object
becomes an empty, a collection and a mesh hold nothing, a material has no node tree (DRT renders
it as the default gray diffuse), other data gets default settings. DRT renders what is there and
names, per library, what is missing.

Blender 4.0+ flags placeholders with ``ID.is_missing`` (also on the Library itself). 3.4 has no
flag: there a library whose file does not exist counts as not loaded, with all its data.
"""

import os

import bpy

MAX_NAMES = 6
# Placeholders of these kinds contribute nothing to the image; the others render with defaults.
_GEOMETRY = ("Object", "Collection", "Mesh", "Curve", "Curves", "MetaBall", "PointCloud", "Volume")


def library_path(lib) -> str:
    """Absolute path of a library file (a nested library's path is relative to its parent's)."""
    parent = getattr(lib, "parent", None)
    return os.path.normpath(bpy.path.abspath(lib.filepath, library=parent))


def _library_missing(lib) -> bool:
    missing = getattr(lib, "is_missing", None)
    if missing is None:  # 3.4
        return not os.path.isfile(library_path(lib))
    return bool(missing)


def _names(ids) -> str:
    names = sorted(f"{i.bl_rna.name} '{i.name}'" for i in ids)
    text = ", ".join(names[:MAX_NAMES])
    if len(names) > MAX_NAMES:
        text += f" and {len(names) - MAX_NAMES} more"
    return text


def missing_link_warnings(depsgraph) -> list[str]:
    """Warnings for the linked data-blocks of this render that are placeholders."""
    if len(bpy.data.libraries) == 0:
        return []
    lib_missing: dict = {}  # library pointer -> the whole file failed to load
    missing: dict = {}  # library pointer -> (library, [original IDs])
    for id_eval in depsgraph.ids:
        orig = id_eval.original
        lib = orig.library
        if lib is None:
            continue
        key = lib.as_pointer()
        if key not in lib_missing:
            lib_missing[key] = _library_missing(lib)
        flag = getattr(orig, "is_missing", None)
        if lib_missing[key] if flag is None else flag:
            missing.setdefault(key, (lib, []))[1].append(orig)

    warnings = []
    for key, (lib, ids) in sorted(missing.items(), key=lambda kv: kv[1][0].name):
        if lib_missing[key]:
            head = f"Library '{lib.name}' could not be loaded ({library_path(lib)})"
        else:
            head = f"Library '{lib.name}' ({library_path(lib)}) lacks linked data"
        geometry = tuple(getattr(bpy.types, t) for t in _GEOMETRY if hasattr(bpy.types, t))
        gone = [i for i in ids if isinstance(i, geometry)]
        default = [i for i in ids if not isinstance(i, geometry)]
        parts = []
        if gone:
            parts.append(f"missing from the render: {_names(gone)}")
        if default:
            parts.append(f"rendered with default settings: {_names(default)}")
        warnings.append(f"{head}: " + "; ".join(parts))
    return warnings
