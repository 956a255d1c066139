"""Scene loaders by file suffix: the core reads its own ``.npz`` scenes; other formats come from
plugins.

The core never imports Blender or the add-on. A ``.blend`` file is read by a loader that the
Blender-side package (``drt_blender``, the add-on) registers under the entry-point group
``drt.scene_loaders`` (see pyproject.toml); the command line asks this registry for the loader
of a suffix and never knows who provides it. Code can also register a loader at run time with
``register_loader`` (tests, other front-ends).

A loader is a callable ``read(path, frame=None) -> (header, arrays, warnings)``: the scene
dictionary pair of ``docs/scene-format.md`` and a list of human-readable warnings. Exceptions
it raises are reported to the user as "cannot read PATH: message".
"""

from __future__ import annotations

import os
from typing import Callable

from .scene import Scene, scene_from_dict

ENTRY_POINT_GROUP = "drt.scene_loaders"

#: what to install when a plugin cannot be imported, by the missing module's name
_INSTALL_HINTS = {
    "bpy": "Blender as a Python module: pip install 'bpy==5.0.1' (Python 3.11)",
}

Loader = Callable[..., tuple]
_registered: dict[str, Loader] = {}


class LoaderError(Exception):
    """A scene file could not be read; the message is for the user (one line)."""


def register_loader(suffix: str, read: Loader) -> None:
    """Make ``read`` the loader of files ending in ``suffix`` (e.g. ``".blend"``)."""
    _registered[_normal_suffix(suffix)] = read


def _normal_suffix(suffix: str) -> str:
    suffix = suffix.lower()
    return suffix if suffix.startswith(".") else "." + suffix


def _entry_point(suffix: str):
    from importlib.metadata import entry_points

    for ep in entry_points(group=ENTRY_POINT_GROUP):
        if _normal_suffix(ep.name) == suffix:
            return ep
    return None


def loader_for(path: str) -> Loader | None:
    """The loader of ``path``'s suffix: registered at run time, else from an installed plugin;
    None for DRT's own ``.npz`` files (and for suffixes nobody reads)."""
    suffix = _normal_suffix(os.path.splitext(path)[1] or ".")
    if suffix == ".npz":
        return None
    if suffix in _registered:
        return _registered[suffix]
    ep = _entry_point(suffix)
    if ep is None:
        return None
    try:
        read = ep.load()
    except ImportError as e:
        missing = getattr(e, "name", None)
        hint = _INSTALL_HINTS.get(missing or "", f"the module {missing!r}" if missing else str(e))
        raise LoaderError(f"reading {suffix} files needs {hint}") from None
    _registered[suffix] = read
    return read


def is_plugin_format(path: str) -> bool:
    """Is ``path`` read by a plugin (``.blend``...) rather than being a DRT ``.npz`` scene?"""
    suffix = _normal_suffix(os.path.splitext(path)[1] or ".")
    return suffix != ".npz" and (suffix in _registered or _entry_point(suffix) is not None)


def read_scene_arrays(path: str, frame: int | None = None) -> tuple[dict, dict, list]:
    """(header, arrays, warnings) of a plugin-format file such as a ``.blend``."""
    read = loader_for(path)
    if read is None:
        suffix = os.path.splitext(path)[1] or "(none)"
        raise LoaderError(f"no loader for {suffix} files (DRT reads .npz scenes, and .blend files "
                          f"when the add-on package drt_blender is installed)")
    try:
        header, arrays, warnings = read(os.path.abspath(path), frame=frame)
    except LoaderError:
        raise
    except Exception as e:  # noqa: BLE001 - a plugin's failure is a user-facing error here
        raise LoaderError(f"cannot read {path}: {e}") from None
    return header, arrays, list(warnings)


def load_scene(path: str, frame: int | None = None, warn: Callable[[str], None] | None = None) -> Scene:
    """A ``Scene`` from any supported file: DRT's ``.npz`` directly, other suffixes through their
    loader. ``frame`` applies to animated formats (.blend); ``warn`` receives each warning."""
    if loader_for(path) is None:  # DRT's own format (or a file it will refuse with a reason)
        from .scene_file import load_scene as load_npz

        return load_npz(path)
    header, arrays, warnings = read_scene_arrays(path, frame)
    for w in warnings:
        if warn is not None:
            warn(w)
    return scene_from_dict(header, arrays)
