"""Arrays one thread reuses from call to call instead of allocating them afresh.

A render traces a batch's rays bounce after bounce, and each bounce's queries need the same
few arrays of about the same length (float32 rays for Embree, the hits in float64). Fresh numpy
arrays of that size are not free: glibc serves them from memory it has just given back to the
kernel (a worker thread's arena is trimmed with ``madvise(MADV_DONTNEED)`` once its free top
passes the trim threshold, the main arena with ``brk``), so every 4 KB page costs a fault and a
zeroed page when it is written again, and each trim interrupts the other cores to flush their
TLBs. Measured on dof (256²): ~12 000 page faults a render at 16 spp and ~33 000 at 64 spp on
one thread, 2–8 % of the render's time (docs/kernels.md, "The render loop stops re-faulting its
memory").

A ``Scratch`` belongs to one thread (it is not locked). ``take`` hands out a view of the first
n rows of a buffer kept under a name; the buffer grows when a longer view is asked for. A view
stays valid until the next ``take`` of the same name: callers use it within one query and
copy whatever must outlive it. ``FRESH`` has the same method and allocates every time (the
default for callers that keep their results).
"""

from __future__ import annotations

import numpy as np


class Scratch:
    """Named buffers of one thread, reused by ``take``."""

    def __init__(self):
        self._buffers: dict[str, np.ndarray] = {}

    def take(self, name: str, n: int, tail: tuple = (), dtype=np.float64) -> np.ndarray:
        """An uninitialised, C-contiguous (n, *tail) array of ``dtype``: the first n rows of
        the buffer called ``name``, valid until the next ``take`` of that name."""
        buf = self._buffers.get(name)
        if buf is None or buf.shape[0] < n or buf.shape[1:] != tuple(tail) or buf.dtype != dtype:
            buf = self._buffers[name] = np.empty((n,) + tuple(tail), dtype=dtype)
        return buf[:n]


class _Fresh:
    """``Scratch``'s interface, allocating a new array at every ``take``."""

    @staticmethod
    def take(name: str, n: int, tail: tuple = (), dtype=np.float64) -> np.ndarray:
        return np.empty((n,) + tuple(tail), dtype=dtype)


#: allocate afresh: results the caller may keep
FRESH = _Fresh()
