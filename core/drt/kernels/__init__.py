"""Compiled kernels: the one decorator every per-sample function of the renderer uses.

DRT's per-sample work (camera rays, BSDFs, lights, MIS, film accumulation) is written as scalar
Python functions compiled by numba. ``@kernel`` is ``numba.njit`` with the project's fixed
choices:

- ``nogil=True``: a compiled call releases the GIL, so the render loop's Python threads run
  kernels on every core of one process (also inside Blender, where worker processes cannot be
  spawned).
- ``cache=True``: machine code is cached on disk, so only the very first render of an install
  compiles (tens of seconds); later processes load it in well under a second. The cache lives in
  a per-user directory (``cache_dir()``), never beside the sources: an installed Blender
  extension's folder may be read-only.
- ``error_model="numpy"``: division by zero gives inf/nan as numpy does instead of raising, so
  kernels keep the numpy code's IEEE semantics (and skip a branch per division).
- no ``fastmath``: NaN checks and the order of floating-point operations must survive compilation
  (renders are bit-identical for a seed).

Conventions shared by all kernels (see docs/kernels.md): a 3-vector is a tuple ``(x, y, z)`` of
float64 (``drt.kernels.vec3``); per-scene read-only data (materials, lights, camera, sampler) is
a namedtuple of numpy arrays built once in Python and passed as the first argument.
"""

from __future__ import annotations

import os
import sys


def cache_dir() -> str:
    """The per-user directory of numba's compiled-kernel cache: ``$DRT_CACHE_DIR`` if set, else
    the platform's user cache folder (``$XDG_CACHE_HOME`` or ``~/.cache`` on Linux,
    ``~/Library/Caches`` on macOS, ``%LOCALAPPDATA%`` on Windows) + ``drt/numba``."""
    explicit = os.environ.get("DRT_CACHE_DIR")
    if explicit:
        return os.path.join(explicit, "numba")
    if sys.platform == "win32":
        base = os.environ.get("LOCALAPPDATA") or os.path.expanduser("~\\AppData\\Local")
    elif sys.platform == "darwin":
        base = os.path.expanduser("~/Library/Caches")
    else:
        base = os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache")
    return os.path.join(base, "drt", "numba")


def _configure_numba_cache() -> None:
    """Point numba's cache at ``cache_dir()`` unless the user chose one (NUMBA_CACHE_DIR)."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        return
    path = cache_dir()
    try:
        os.makedirs(path, exist_ok=True)
    except OSError:
        return  # numba falls back to its own locations (beside the sources or the user dir)
    os.environ["NUMBA_CACHE_DIR"] = path
    if "numba" in sys.modules:  # imported earlier (another add-on in Blender): set it live
        import numba.core.config as _config

        _config.CACHE_DIR = path


_configure_numba_cache()

import numba  # noqa: E402  (after the cache location is set)

KERNEL_OPTIONS = dict(nogil=True, cache=True, error_model="numpy")


def kernel(fn=None, **overrides):
    """``numba.njit`` with DRT's options (see the module docstring). Use as ``@kernel``."""
    opts = {**KERNEL_OPTIONS, **overrides}
    if fn is None:
        return lambda f: numba.njit(**opts)(f)
    return numba.njit(**opts)(fn)
