"""Cutting frames into cluster tasks: tiles first, sample ranges only when tiles run out.

A task renders one tile (a pixel rectangle) over one sample range. Tiles over the full sample
range give an image bit-identical to the one-process render (each pixel gets the same samples
added in the same order, ``render(tile=...)``); sample ranges are summed afterwards, which
regroups the float64 sums (the result is within ~1e-15 relative of the local sums, so the
float32 image differs by at most one unit in the last place). So a frame is cut into tiles as
long as tiles keep at least ``MIN_TILE_PIXELS``, and only a small image with many samples is
also cut into sample ranges. Adaptive sampling never cuts sample ranges: a pixel's stopping
rule needs all of its samples in one task.

Task size: each task should take seconds (Dask's overhead per task is milliseconds, see
``benchmarks/farm_scaling.py``), estimated from the camera paths (pixels × samples) at
``PATHS_PER_SECOND`` per worker thread, a conservative figure for the shipped scenes (the
Cornell box traces ~0.45 M paths/s per thread on the 2-core test machine).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

PATHS_PER_SECOND = 250_000  # camera paths per second per worker thread (estimate)
TASK_SECONDS = 4.0  # target duration of one task
MIN_TILE_PIXELS = 32 * 32
MIN_TASK_PATHS = 1 << 14  # below this a task is all overhead
MAX_TILE_TASK_FACTOR = 4.0  # tile-only tasks may run this many times the target before
# sample ranges are cut (keeps the image bit-identical to the local render more often)


@dataclass(frozen=True)
class TaskSpec:
    """One task of one frame: ``tile`` (x0, y0, x1, y1), rows from the top, end exclusive;
    samples [sample_offset, sample_offset + sample_count)."""

    tile: tuple[int, int, int, int]
    sample_offset: int
    sample_count: int

    @property
    def paths(self) -> int:
        x0, y0, x1, y1 = self.tile
        return (x1 - x0) * (y1 - y0) * self.sample_count


def _edges(lo: int, hi: int, parts: int) -> list[int]:
    return [lo + (hi - lo) * i // parts for i in range(parts + 1)]


def plan_frame(bounds: tuple[int, int, int, int], sample_offset: int, sample_count: int, *,
               min_tasks: int = 1, task_seconds: float = TASK_SECONDS,
               split_samples: bool = True) -> list[TaskSpec]:
    """Tasks covering the pixel ``bounds`` (x0, y0, x1, y1) over the given sample range.

    At least ``min_tasks`` tasks (so every worker thread has work) unless tasks would drop
    below ``MIN_TASK_PATHS`` paths, and enough that none exceeds ``task_seconds`` at the
    estimated speed. Order: tiles row-major from the top, then sample ranges: the order in
    which the client sums them, which fixes the image's bits.
    """
    x0, y0, x1, y1 = bounds
    w, h = x1 - x0, y1 - y0
    npix = w * h
    total = npix * sample_count
    if total <= 0:
        return []
    target = max(task_seconds * PATHS_PER_SECOND, MIN_TASK_PATHS)
    n_tasks = max(math.ceil(total / target), min(min_tasks, total // MIN_TASK_PATHS), 1)
    n_tiles = max(1, min(n_tasks, npix // MIN_TILE_PIXELS))
    n_ranges = 1
    if split_samples and total / n_tiles > MAX_TILE_TASK_FACTOR * target:
        n_ranges = max(1, min(sample_count, math.ceil(n_tasks / n_tiles)))
    # a grid of about n_tiles near-square tiles
    side = math.sqrt(npix / n_tiles)
    cols = max(1, min(w, round(w / side)))
    rows = max(1, min(h, math.ceil(n_tiles / cols)))
    xe, ye = _edges(x0, x1, cols), _edges(y0, y1, rows)
    se = _edges(sample_offset, sample_offset + sample_count, n_ranges)
    return [TaskSpec((xe[i], ye[j], xe[i + 1], ye[j + 1]), se[k], se[k + 1] - se[k])
            for j in range(rows) for i in range(cols) for k in range(n_ranges)]
