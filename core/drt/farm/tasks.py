"""What a Dask worker runs: one render task, a pure function of its inputs.

``render_task(scene, scene_key, settings, tile, sample_offset, sample_count)`` renders sample
range [sample_offset, sample_offset + sample_count) of the pixels in ``tile`` and returns the
tile's film sums as a dict of numpy arrays. Same inputs, same bits: a task can be retried on
any worker (Dask does so when a worker dies) and the image does not change.

The scene arrives once per worker (the client scatters it); the per-scene context (geometry,
BVH, material and light tables: ``render.prepare``) is built once per worker process and
reused by every task of that scene (``_context``), keyed by the scattered scene's Dask key.
This module imports no Dask: workers need ``drt`` and ``distributed``, tasks only ``drt``.
"""

from __future__ import annotations

import hashlib
import os
import threading
import time
from collections import OrderedDict

from .. import __version__

CONTEXTS_KEPT = 2  # scenes whose context a worker keeps (an animation moves frame by frame)
_contexts: OrderedDict = OrderedDict()
_lock = threading.Lock()
_building: dict = {}
_fingerprint: str | None = None


def fingerprint() -> str:
    """``version+hash`` of every ``drt`` source file: a client refuses workers whose DRT differs,
    since a different renderer would put different pixels into the same image."""
    global _fingerprint
    if _fingerprint is None:
        root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        h = hashlib.sha1()
        for dirpath, dirnames, files in os.walk(root):
            dirnames[:] = sorted(d for d in dirnames if d != "__pycache__")
            for f in sorted(files):
                if f.endswith(".py"):
                    path = os.path.join(dirpath, f)
                    h.update(os.path.relpath(path, root).replace(os.sep, "/").encode())
                    with open(path, "rb") as fh:
                        h.update(fh.read())
        _fingerprint = f"{__version__}+{h.hexdigest()[:12]}"
    return _fingerprint


def _as_scene(scene):
    """A ``Scene``, from a Scene or the exporter's ``(header, arrays)``."""
    if isinstance(scene, (tuple, list)):
        from ..scene import scene_from_dict

        return scene_from_dict(scene[0], scene[1])
    return scene


def _context(scene, scene_key: str, settings: dict):
    """(Scene, RenderContext) for this scene and settings, built once per worker process.
    Threads of one worker wait for the one that builds it instead of building it twice."""
    from ..render import prepare

    key = (scene_key, settings.get("seed"), settings.get("sampler"), settings.get("direct"),
           settings.get("indirect"))
    while True:
        with _lock:
            if key in _contexts:
                _contexts.move_to_end(key)
                return _contexts[key]
            event = _building.get(key)
            if event is None:
                event = _building[key] = threading.Event()
                break
        event.wait()
    try:
        sc = _as_scene(scene)
        ctx = prepare(sc, seed=settings.get("seed"), sampler=settings.get("sampler"),
                      direct=settings.get("direct"), indirect=settings.get("indirect"))
        with _lock:
            _contexts[key] = (sc, ctx)
            while len(_contexts) > CONTEXTS_KEPT:
                _contexts.popitem(last=False)
        return sc, ctx
    finally:
        with _lock:
            _building.pop(key, None)
        event.set()


def render_task(scene, scene_key: str, settings: dict, tile, sample_offset: int, sample_count: int) -> dict:
    """Render one task; see the module docstring.

    settings: {"spp", "seed", "sampler", "direct", "indirect", "adaptive_threshold",
    "adaptive_min_samples"} (None: the scene's). tile: (x0, y0, x1, y1) pixels, rows from the
    top, end exclusive. Returns {"tile", "sample_offset", "sample_count", "sum_rgba" (n, 4),
    "sum_lum2" (n,), "sum_normal" (n, 3), "sum_albedo" (n, 3), "min_depth" (n,), "count"
    (n,), "sum_mist" ((n,) or None: no Mist pass), "sum_data" ((n, 9) or None: no data
    passes), "sum_light" ((n, 9) or None: no light passes), "sum_crypto" ((n, slots, 2) or None:
    no Cryptomatte; with "crypto_layers" and "crypto_slots", drt.film.Film), "nan_samples", "camera_paths", "rays",
    "seconds", "meta"} with n the tile's pixels, row-major from its top row. One thread per task: Dask runs one task per worker thread.
    """
    from ..render import render

    t0 = time.perf_counter()
    sc, ctx = _context(scene, scene_key, settings)
    film = render(sc, spp=settings.get("spp"), seed=settings.get("seed"), threads=1,
                  sample_offset=int(sample_offset), sample_count=int(sample_count),
                  adaptive_threshold=settings.get("adaptive_threshold"),
                  adaptive_min_samples=settings.get("adaptive_min_samples"),
                  context=ctx, tile=tuple(int(v) for v in tile))
    st = film.stats
    meta = {k: v for k, v in film.meta.items() if k != "tile"}
    return {
        "tile": list(film.meta["tile"]),
        "sample_offset": int(sample_offset),
        "sample_count": int(sample_count),
        "sum_rgba": film.sum_rgba, "sum_lum2": film.sum_lum2, "sum_normal": film.sum_normal,
        "sum_albedo": film.sum_albedo, "min_depth": film.min_depth, "count": film.count,
        "sum_mist": film.sum_mist,
        "sum_data": film.sum_data,
        "sum_light": film.sum_light,
        "sum_crypto": film.sum_crypto, "crypto_layers": list(film.crypto_layers),
        "crypto_slots": int(film.crypto_slots), "crypto_names": dict(film.crypto_names),
        "nan_samples": int(film.nan_samples),
        "camera_paths": int(st.camera_paths),
        "rays": int(st.rays),
        "seconds": time.perf_counter() - t0,
        "meta": meta,
    }
