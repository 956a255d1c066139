"""Reading and writing the ``.npz`` scene file (format in ``docs/scene-format.md``).

The file is a NumPy zip archive; the JSON header is stored as a uint8 array named ``header``.
Loading uses ``allow_pickle=False`` and refuses object arrays, so a scene file can never run
code. Every failure becomes a ``SceneError`` with the field (or the file) named.
"""

from __future__ import annotations

import json
import os
import zipfile

import numpy as np

from .scene import Scene, SceneError, scene_from_dict

MAX_HEADER_BYTES = 64 << 20


def encode_header(header: dict) -> np.ndarray:
    """The header as the uint8 array stored under ``header``."""
    return np.frombuffer(json.dumps(header, separators=(",", ":")).encode("utf-8"), dtype=np.uint8)


def save_scene(path: str | os.PathLike, header: dict, arrays: dict[str, np.ndarray], compress: bool = True) -> None:
    """Write a scene file. ``arrays`` maps names like ``mesh0.positions`` to numeric arrays."""
    payload = {"header": encode_header(header)}
    for name, a in arrays.items():
        a = np.asarray(a)
        if a.dtype.kind not in "biuf":
            raise SceneError(name, f"cannot store dtype {a.dtype} (numeric arrays only)")
        payload[name] = a
    tmp = f"{os.fspath(path)}.tmp"
    with open(tmp, "wb") as f:
        (np.savez_compressed if compress else np.savez)(f, **payload)
    os.replace(tmp, path)  # never leave a half-written scene behind


def read_scene_arrays(path: str | os.PathLike) -> tuple[dict, dict[str, np.ndarray]]:
    """Read the header dict and arrays without validating their meaning."""
    p = os.fspath(path)
    if not os.path.isfile(p):
        raise SceneError("file", f"{p} does not exist")
    try:
        with np.load(p, allow_pickle=False) as z:
            names = list(z.files)
            if "header" not in names:
                raise SceneError("header", f"{p} has no 'header' entry (is it a DRT scene file?)")
            arrays = {}
            for name in names:
                try:
                    a = z[name]
                except ValueError as e:  # object arrays need pickle: refused
                    raise SceneError(name, f"cannot be loaded without pickle ({e})") from None
                arrays[name] = a
    except SceneError:
        raise
    except (zipfile.BadZipFile, EOFError, OSError, ValueError, KeyError, RuntimeError) as e:
        raise SceneError("file", f"{p} is not a readable scene archive ({type(e).__name__}: {e})") from None
    raw = arrays.pop("header")
    if raw.dtype != np.uint8 or raw.ndim != 1:
        raise SceneError("header", f"must be a 1-D uint8 array of UTF-8 JSON, got {raw.dtype} {raw.shape}")
    if raw.size > MAX_HEADER_BYTES:
        raise SceneError("header", f"is larger than {MAX_HEADER_BYTES} bytes")
    try:
        header = json.loads(raw.tobytes().decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise SceneError("header", f"is not valid UTF-8 JSON ({e})") from None
    if not isinstance(header, dict):
        raise SceneError("header", "must be a JSON object")
    return header, arrays


def load_scene(path: str | os.PathLike) -> Scene:
    """Load and validate a scene file."""
    header, arrays = read_scene_arrays(path)
    try:
        return scene_from_dict(header, arrays)
    except SceneError:
        raise
    except RecursionError:
        raise SceneError("header", "is nested too deeply") from None
