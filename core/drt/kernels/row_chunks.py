"""Row-wise kernels of scene preparation, run over chunks of their rows on several threads.

Preparing a large mesh for rendering runs a few kernels over every triangle (world-space
normals, the shadow terminator's corners, the geometric normals): ~40 ms for a million
triangles on one core, paid on every F12 before the first sample. Each row of their output
depends only on the same row of their inputs, so contiguous row ranges can run side by side:
the kernels release the GIL, and the result is the same bytes whatever the split.

How many threads: those of the render being prepared (``preparation_threads``, which
``drt.render.prepare`` sets from its ``threads`` argument, so a render limited to one thread
prepares on one), else every core.
"""

from __future__ import annotations

import contextvars
import os
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager

#: fewer rows than this per thread are not worth a thread's start (~0.1 ms)
MIN_ROWS_PER_THREAD = 65_536

_THREADS: contextvars.ContextVar[int | None] = contextvars.ContextVar("drt_preparation_threads", default=None)


@contextmanager
def preparation_threads(threads: int | None):
    """Within the block, ``over_rows`` uses at most ``threads`` threads (None: every core)."""
    token = _THREADS.set(None if threads is None else max(1, int(threads)))
    try:
        yield
    finally:
        _THREADS.reset(token)


def over_rows(kernel, args: tuple, sliced: tuple) -> list:
    """``kernel(*args)`` with the arguments at positions ``sliced`` cut to row ranges [lo, hi)
    that together cover their rows, in order; returns the calls' results in row order.
    ``args[i]`` for i in ``sliced``: arrays with the same number of rows (the kernel's per-row
    inputs and outputs); the others are passed whole (tables the rows index into)."""
    rows = len(args[sliced[0]])
    threads = _THREADS.get() or os.cpu_count() or 1
    parts = max(1, min(threads, rows // MIN_ROWS_PER_THREAD))
    if parts == 1:
        return [kernel(*args)]
    bounds = [rows * k // parts for k in range(parts + 1)]
    calls = [tuple(a[lo:hi] if i in sliced else a for i, a in enumerate(args))
             for lo, hi in zip(bounds, bounds[1:])]
    with ThreadPoolExecutor(parts - 1, thread_name_prefix="drt-prepare") as pool:
        futures = [pool.submit(kernel, *call) for call in calls[1:]]
        first = kernel(*calls[0])  # the calling thread takes a share too
        return [first] + [f.result() for f in futures]
