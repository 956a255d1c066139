"""The render loop: progressive passes of samples over the image, batches over threads.

A *pass* adds a few samples to every pixel (1, 1, 2, 4, ... samples), so a viewer sees the whole
image refine. A pass is cut into *batches* of about ``BATCH_PATHS`` camera paths; worker threads
trace batches concurrently (Embree and large numpy operations release the GIL) and the film adds
finished batches in their fixed order, so the image is bit-identical for a seed whatever the
thread count or timing. Cancel is polled between batches (a batch takes well under a second).

Samples are numbered per pixel. Rendering sample range [offset, offset + count) gives exactly the
samples the full render would have made there, so disjoint ranges rendered on different machines
merge into the full image (``merge_films``).
"""

from __future__ import annotations

import os
import threading
import time
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout
from concurrent.futures import wait as futures_wait
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from . import __version__
from .camera import Camera
from .cryptomatte import scene_names, slot_count
from .film import Film, luminance
from .geometry import build_geometry
from .integrator import Integrator
from .kernels import mark_kernels_compiled, scene_kernel_variant
from .kernels.row_chunks import preparation_threads
from .compile_plan import mark_features_compiled, precompile, scene_features
from .lights import EmissiveTriangles, LightSet
from .materials import MaterialTable
from .sampling.pixel_filter import shared_pixel_filter
from .sampling.sequences import Sampler
from .scene import VIS_DIFFUSE, VIS_GLOSSY, VIS_TRANSMISSION, VIS_VOLUME_SCATTER, Scene, SceneError
from .trace import Tracer
from .volumes.media import lights_reaching, media_for_scene, world_blocks_infinity

#: camera paths per batch: on one thread, 16 384 — since the render loop reuses its arrays
#: (2026-12-07) smaller batches keep a thread's path state in cache and a new context's arrays
#: small: one thread 2–11 % faster than with 65 536 at 256², the same or 4 % faster at 512²
#: (docs/decisions.md); on several, 32 768 — threads share the last-level cache and the tail
#: of a render, and two threads were 1–12 % faster with it than with 65 536 on all ten scenes
#: measured (docs/kernels.md), while each batch costs some Python under the GIL, a cost that
#: grows with the thread count
BATCH_PATHS = 1 << 14
BATCH_PATHS_THREADED = 1 << 15
MIN_BATCH_PATHS = 1 << 12
#: how often cancel() is polled while a batch runs: a viewport edit waits at most this long
#: (plus the batches in flight) before its new image starts; 100 wake-ups/s cost nothing
CANCEL_POLL_SECONDS = 0.01
#: batches submitted per worker thread beyond the one each runs (plus one more in all):
#: collection is in submission order, so while the main thread waits for the oldest batch, a
#: worker that finishes a shorter one needs others already queued. With one queued batch in all
#: (threads + 1 in flight, until 2026-12-07) the two workers of a 256² all_lights render at 16
#: spp idled 38–55 ms of its ~0.19 s with nothing submitted (head-of-line blocking); with one
#: per thread 9–16 ms, with two 0–10 ms (render 0.187–0.189 → 0.164–0.169 s)
BATCHES_QUEUED_PER_THREAD = 2
#: worker threads per core at most: the kernels are CPU-bound, so threads beyond the cores only
#: cost memory (each holds a batch's path arrays, ~18 MB: a 512² render took 272 MB with 2
#: threads and 819 MB with 32 on 2 cores, and ran slower); a larger request (``--threads 999``)
#: is cut to this many per core
MAX_THREADS_PER_CORE = 4
#: how long a cancelled render waits for its batches already running before it leaves them to
#: finish on their own: a batch takes well under this, but the first batch of a fresh install
#: compiles the kernels (a minute or more), and a cancel must not wait for that
ABORT_WAIT_SECONDS = 0.5


#: bytes per pixel a render holds at its peak: the film's float64 accumulators (RGBA, luminance²,
#: normal, albedo, depth: 12 values + an int64 count = 104 B), the pixel index arrays (32 B) and
#: the float32 output passes with their float64 intermediates when the EXR is written (~84 B)
FILM_BYTES_PER_PIXEL = 220


def film_memory_bytes(width: int, height: int) -> int:
    """Peak bytes of the per-pixel state of a ``width`` x ``height`` render (the scene's own
    arrays and the per-batch path state, < 100 MB, come on top)."""
    return int(width) * int(height) * FILM_BYTES_PER_PIXEL


@dataclass
class RenderStats:
    seconds: float = 0.0
    samples_done: int = 0  # per pixel, completed passes
    samples_total: int = 0
    camera_paths: int = 0
    rays: int = 0
    embree_seconds: float = 0.0
    nan_samples: int = 0
    active_pixels: int = -1  # pixels still sampling (adaptive sampling); -1: all
    cancelled: bool = False
    threads: int = 1
    # samples per pixel the film holds, over the rendered pixels (adaptive sampling and a
    # cancelled pass make them differ from pixel to pixel)
    spp_min: int = 0
    spp_mean: float = 0.0
    spp_max: int = 0

    @property
    def rays_per_second(self) -> float:
        return self.rays / self.seconds if self.seconds > 0 else 0.0


@dataclass
class RenderContext:
    """Everything built once per scene (geometry, BVHs, tables); reusable across renders."""

    scene: Scene
    integrator: Integrator
    tracer: Tracer
    setup_seconds: float = 0.0
    warnings: list = field(default_factory=list)


def _emissive_triangles(scene: Scene, geom, materials: MaterialTable, programs=None,
                        material_dicts=None) -> EmissiveTriangles | None:
    """Static emissive triangles become lights (sampled by NEE); moving ones are only hit.
    With ``programs`` (the scene's ProgramData) textured emitters join them, weighted by their
    estimated average emission (``drt.lights.textured``); ``material_dicts``: the material
    list (default ``scene.materials``)."""
    if geom.static_count == 0:
        return None
    mat = geom.material[: geom.static_count]
    em = np.nonzero(materials.has_emission[mat])[0] if np.any(materials.has_emission) else np.zeros(0, np.int64)
    radiance = materials.emission[mat[em]]
    if programs is not None:
        from .lights.textured import textured_emitters

        dicts = material_dicts if material_dicts is not None else scene.materials
        no_light = np.array([isinstance(m, dict) and m.get("light") is False for m in dicts], bool)
        tex = textured_emitters(programs, geom.material, geom.static_count, no_light)
        if tex is not None:
            em = np.concatenate([em, tex[0]])
            radiance = np.concatenate([radiance, tex[1]])
    vis = getattr(geom, "visibility", None)
    if vis is not None and len(em):
        # as Cycles (object_usable_as_light): an object that no bounce ray sees is no light
        keep = (vis[em] & (VIS_DIFFUSE | VIS_GLOSSY | VIS_TRANSMISSION | VIS_VOLUME_SCATTER)) != 0
        em, radiance = em[keep], radiance[keep]
    if len(em) == 0:
        return None
    verts = geom.static_positions[geom.static_triangles[em]].astype(np.float64)
    return EmissiveTriangles(verts, radiance, em)


def _has_textured_emission(scene: Scene) -> bool:
    return textured_emission_in(scene.materials)


def textured_emission_in(materials) -> bool:
    """Whether a material list has program-driven emission (candidate textured emitters)."""
    return any(isinstance(m, dict) and m.get("program") and m.get("emission_reg") is not None
               for m in materials)


def _textured_world(scene: Scene, geom, materials: MaterialTable, camera: Camera):
    """(ProgramData with the world program appended, (its index, radiance register), importance
    map (wm_cond, wm_marg, average luminance) or None) of a scene whose world has a program."""
    from .integrator import program_data_for

    pd = program_data_for(materials, geom, camera, world=scene.world_program)
    return (pd,) + world_setup(scene.world_program, pd)


def world_setup(wp: dict, pd):
    """((index, radiance register), importance map or None) of world program ``wp`` appended to
    ``pd``: the map is built here, at load, by running the program over the map's directions
    (never stored); none when the world's ``map_size`` is (0, 0) (not importance-sampled)."""
    from .lights.world_map import build_world_map, shade_map, shade_map_corners
    from .materials.program_format import world_program_index

    index = world_program_index(pd)
    w, h = wp["map_size"]
    if w == 0:  # Cycles's World > Sampling: None: BSDF rays only
        return (index, wp["radiance_reg"]), None
    pixels = shade_map(pd, index, wp["radiance_reg"], wp["registers"], w, h)
    corners = shade_map_corners(pd, index, wp["radiance_reg"], wp["registers"], w, h)
    return (index, wp["radiance_reg"]), build_world_map(pixels, corners)


def prepare(scene: Scene, *, seed: int | None = None, sampler: str | None = None,
            direct: str | None = None, indirect: str | None = None,
            samples: int | None = None, threads: int | None = None) -> RenderContext:
    """Build the tracer, material table, lights and camera for ``scene``. Arguments that are
    not None override the scene's render settings. ``samples``: the camera samples the
    renders will trace (default: the frame's pixels × the scene's spp), a hint for the BVH
    build (``Tracer``): any number renders the same image. ``threads``: how many threads the
    per-triangle work may use (default: every core; ``drt.kernels.row_chunks``)."""
    with preparation_threads(threads):
        return _prepare(scene, seed, sampler, direct, indirect, samples)


def _prepare(scene, seed, sampler, direct, indirect, samples) -> RenderContext:
    t0 = time.perf_counter()
    overrides = {k: v for k, v in (("seed", seed), ("sampler", sampler), ("direct", direct), ("indirect", indirect)) if v is not None}
    settings = replace(scene.render, **overrides)
    geom = build_geometry(scene)
    try:
        materials = MaterialTable.from_scene(scene.materials, scene.images, scene.attributes,
                                             (settings.caustics_reflective, settings.caustics_refractive))
    except ValueError as e:
        raise SceneError("materials", str(e)) from None
    camera = Camera(scene.camera, settings, geom.origin_shift)
    programs, world_program, world_map, world_regs = None, None, None, 0
    if scene.world_program is not None:
        programs, world_program, world_map = _textured_world(scene, geom, materials, camera)
        world_regs = scene.world_program["registers"]
    media = media_for_scene(scene.materials, scene.world_volume, geom)
    # textured emitters are lights (NEE) except in scenes with media, whose light sampling
    # evaluates no programs (they keep the BSDF-hit-only path there)
    textured = _has_textured_emission(scene) and not media.enabled
    if textured and programs is None:
        from .integrator import program_data_for

        programs = program_data_for(materials, geom, camera)
    emissive = _emissive_triangles(scene, geom, materials, programs if textured else None)
    try:
        # a constant-colour world is found by BSDF rays only, as in Cycles (see LightSet); a
        # textured one is importance-sampled (drt.lights.world_map)
        # a world medium that attenuates every channel hides the sun and the world at infinity
        # (drt.volumes.media.world_blocks_infinity): they are not sampled as lights
        blocked = world_blocks_infinity(media)
        lights = LightSet(lights_reaching(scene.lights, media), scene.world_color, emissive,
                          origin_shift=geom.origin_shift, scene_radius=geom.scene_radius,
                          world_nee=world_map is not None and not blocked,
                          world_program=world_program, world_map=world_map)
    except ValueError as e:
        raise SceneError("lights", str(e)) from None
    if samples is None:
        x0, y0, x1, y1 = pixel_bounds(scene)
        samples = (x1 - x0) * (y1 - y0) * settings.spp
    tracer = Tracer(geom, expected_samples=samples)
    integ = Integrator(
        settings, geom, tracer, materials, lights, camera,
        Sampler(settings.sampler, settings.seed, settings.spp),
        shared_pixel_filter(settings.filter_type, settings.filter_width),
        direct=settings.direct,
        indirect=settings.indirect,
        media=media,
        programs=programs,
        world_registers=world_regs,
    )
    ctx = RenderContext(scene, integ, tracer, time.perf_counter() - t0)
    # (a moving emitter is no light, NEE samples static triangles only, but the camera sees it)
    emitters = (emissive is not None or _has_textured_emission(scene)
                or bool(len(geom.material) and np.any(materials.has_emission[geom.material])))
    if not scene.lights and not np.any(scene.world_color > 0) and not emitters and world_map is None:
        ctx.warnings.append("the scene has no lights, no emissive materials and a black world: the image will be black")
    return ctx


def _use_sampling_arguments(integ: Integrator, spp: int, seed, sampler, direct, indirect) -> None:
    """The integrator's sampler for this render: ``spp`` (stratified sampling needs the total,
    whatever range a render covers) and, with a prepared context, the seed and sampler kind
    ``render()`` names — the context renders with them from now on; before, it silently kept
    the seed it was prepared with, so seeds 0…7 of one context were one image. The direct and
    indirect strategies are built into the integrator: naming other ones than the context's is
    an error, not a silent no-op."""
    for name, value in (("direct", direct), ("indirect", indirect)):
        if value is not None and str(value).upper() != getattr(integ, name):
            raise ValueError(f"{name}={value!r} differs from the prepared context's "
                             f"{getattr(integ, name).lower()!r}: pass it to prepare() instead")
    new_seed = integ.s.seed if seed is None else int(seed)
    kind = integ.sampler.kind if sampler is None else str(sampler).upper()
    if new_seed != integ.s.seed or kind != integ.sampler.kind or spp != integ.sampler.spp:
        integ.sampler = Sampler(kind, new_seed, spp)
        integ.s = replace(integ.s, seed=new_seed, sampler=kind)


class _Cancelled(Exception):
    """Internal: the cancel callback said stop."""


#: batches that cancelled renders left running (``_ThreadWorkers.abort``), until they end
_ABANDONED: list = []
_ABANDONED_LOCK = threading.Lock()


def abandoned_batches() -> int:
    """How many batches of cancelled renders are still running (compiling, usually)."""
    with _ABANDONED_LOCK:
        _ABANDONED[:] = [f for f in _ABANDONED if not f.done()]
        return len(_ABANDONED)


def settle_abandoned_batches(cancel: Callable[[], bool] | None = None) -> bool:
    """Wait until the batches that cancelled renders left running have ended. Code that changes
    scene data a context shares with earlier renders (the viewport's edits) calls this first, and
    so does every render, whose first kernel call would wait for their compilation anyway.
    Returns False when ``cancel()`` turned True first."""
    while abandoned_batches():
        with _ABANDONED_LOCK:
            running = list(_ABANDONED)
        futures_wait(running, timeout=CANCEL_POLL_SECONDS)
        if cancel is not None and cancel():
            return False
    return True


class _ThreadWorkers:
    """Batches on threads sharing one context (used inside Blender and for small jobs)."""

    def __init__(self, ctx: RenderContext, threads: int):
        self.ctx = ctx
        self.pool = ThreadPoolExecutor(max_workers=threads)
        self.rays0 = ctx.tracer.rays_traced
        self.emb0 = ctx.tracer.embree_seconds
        self.in_flight: list = []

    def submit(self, x, row, first, k):
        """Samples first … first + k − 1 of pixels (x, row) (``Integrator.render_pixels``)."""
        future = self.pool.submit(self.ctx.integrator.render_pixels, x, row, first, k)
        self.in_flight = [f for f in self.in_flight if not f.done()]
        self.in_flight.append(future)
        return future

    def abort(self):
        """Stop now (cancel): queued batches are dropped; running ones get ABORT_WAIT_SECONDS to
        finish (a batch normally takes far less), and one still running then — compiling the
        kernels on a first render — is left to finish on its own thread: its compiled code
        lands in the cache, its samples are dropped (``settle_abandoned_batches``)."""
        self.pool.shutdown(wait=False, cancel_futures=True)
        running = [f for f in self.in_flight if not f.done()]
        if running:
            futures_wait(running, timeout=ABORT_WAIT_SECONDS)
        left = [f for f in running if not f.done()]
        if left:
            with _ABANDONED_LOCK:
                _ABANDONED.extend(left)
        else:  # every batch ended: join the idle threads, so none outlives the render
            self.pool.shutdown(wait=True)
        self.in_flight = []

    def counters(self) -> tuple[int, float]:
        return self.ctx.tracer.rays_traced - self.rays0, self.ctx.tracer.embree_seconds - self.emb0

    def close(self):
        self.pool.shutdown(wait=True)


def pixel_bounds(scene: Scene) -> tuple[int, int, int, int]:
    """(x0, y0, x1, y1): the pixels to render, columns [x0, x1) from the left and rows [y0, y1)
    from the top (the border region, or the whole frame)."""
    w, h = scene.render.width, scene.render.height
    x0, y0, x1, y1 = 0, 0, w, h
    if scene.render.border is not None:
        bx0, by0, bx1, by1 = scene.render.border  # fractions, y up
        x0, x1 = int(np.floor(bx0 * w)), max(int(np.ceil(bx1 * w)), int(np.floor(bx0 * w)) + 1)
        r0, r1 = int(np.floor((1 - by1) * h)), max(int(np.ceil((1 - by0) * h)), int(np.floor((1 - by1) * h)) + 1)
        y0, y1 = r0, r1
    return x0, y0, x1, y1


def _pixel_region(scene: Scene, tile: tuple[int, int, int, int] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Columns (from the left) and rows (from the top) of the pixels to render (border aware),
    within ``tile`` (x0, y0, x1, y1; rows from the top) when one is given."""
    x0, y0, x1, y1 = pixel_bounds(scene)
    if tile is not None:
        x0, y0, x1, y1 = max(x0, tile[0]), max(y0, tile[1]), min(x1, tile[2]), min(y1, tile[3])
    xs, ys = np.meshgrid(np.arange(x0, max(x0, x1)), np.arange(y0, max(y0, y1)))
    return xs.reshape(-1).astype(np.int64), ys.reshape(-1).astype(np.int64)


def _film_for(scene: Scene, xs: np.ndarray, ys: np.ndarray, tile) -> tuple[Film, tuple | None]:
    """The film a render of pixels (xs, ys) fills: the frame's, or with ``tile`` one of just
    the tile (a 4K frame's full film is ~0.8 GB per task), and the (frame width, x0, y0, tile
    width) that maps frame pixels into it (None: the whole frame)."""
    layers = tuple(getattr(scene.render, "cryptomatte", ()))
    crypto = dict(crypto_layers=layers,
                  crypto_slots=slot_count(scene.render.cryptomatte_levels) if layers else 0,
                  crypto_names=scene_names(scene, layers))
    if tile is None:
        return Film(scene.render.width, scene.render.height, exposure=scene.render.exposure, **crypto), None
    fx0, fy0 = (int(xs.min()), int(ys.min())) if len(xs) else (tile[0], tile[1])
    fx1, fy1 = (int(xs.max()) + 1, int(ys.max()) + 1) if len(xs) else (tile[0], tile[1])
    film = Film(fx1 - fx0, fy1 - fy0, exposure=scene.render.exposure, **crypto)
    film.meta["tile"] = [fx0, fy0, fx1, fy1]
    return film, (scene.render.width, fx0, fy0, fx1 - fx0)


def pass_schedule(count: int) -> list[int]:
    """Samples per pixel in each progressive pass: 1, 1, 2, 4, ... (at most 64), summing to count."""
    out, step, done = [], 1, 0
    while done < count:
        k = min(step, count - done)
        out.append(k)
        done += k
        if len(out) >= 2:
            step = min(step * 2, 64)
    return out


def render(
    scene: Scene,
    *,
    spp: int | None = None,
    seed: int | None = None,
    threads: int | None = None,
    sample_offset: int = 0,
    sample_count: int | None = None,
    sampler: str | None = None,
    direct: str | None = None,
    indirect: str | None = None,
    adaptive_threshold: float | None = None,
    adaptive_min_samples: int | None = None,
    progress: Callable[[Film, int, int], None] | None = None,
    tick: Callable[[float, RenderStats], None] | None = None,
    cancel: Callable[[], bool] | None = None,
    context: RenderContext | None = None,
    parallel: str = "auto",
    tile: tuple[int, int, int, int] | None = None,
    max_batch_paths: int | None = None,
) -> Film:
    """Render ``scene`` and return its ``Film`` (``film.stats`` holds a ``RenderStats``).

    spp: samples per pixel of the *whole* render (default: the scene's); the samples rendered
    here are numbers [sample_offset, sample_offset + sample_count) (default: all of them).
    progress(film, samples_done, samples_total) after each pass; tick(fraction, stats) after each
    batch; cancel() -> bool polled between batches: when it returns True the partial film is
    returned with ``stats.cancelled`` set.

    Adaptive sampling (``adaptive_threshold`` > 0): once every pixel has
    ``adaptive_min_samples``, a pixel stops receiving samples when the relative standard error
    of its mean luminance falls below the threshold (``film.sample_count`` records what each
    pixel took). Stopping depends only on the pixel's own samples, so it stays deterministic.

    parallel: "threads" (or "auto", the same): batches run on ``threads`` Python threads of this
    process; the compiled kernels and Embree release the GIL, so threads use every core (the
    ``drt.worker`` subprocess pool they replaced is gone, see docs/decisions.md). The image is
    bit-identical for any thread count: batches are added to the film in a fixed order.

    tile: (x0, y0, x1, y1) in pixels, columns from the left and rows from the top, end
    exclusive: render only those pixels (within the border region) and return a film of just
    that rectangle (``film.meta["tile"]``; the frame's size in ``meta["width"/"height"]``).
    Every pixel gets exactly the samples, in the same order, that the whole-frame render
    gives it, so tiles placed side by side are bit-identical to the whole frame (the cluster
    renderer, ``drt.farm``, relies on this).

    max_batch_paths: camera paths per batch (default ``BATCH_PATHS`` on one thread,
    ``BATCH_PATHS_THREADED`` on more); the viewport uses
    smaller batches so that cancelling (an edit) waits less for the batches in flight.
    """
    t0 = time.perf_counter()
    spp = int(spp or scene.render.spp)
    if spp < 1:
        raise SceneError("spp", f"must be >= 1, got {spp}")
    count = spp - sample_offset if sample_count is None else int(sample_count)
    if sample_offset < 0 or count < 0 or sample_offset + count > spp:
        raise SceneError("sample range", f"[{sample_offset}, {sample_offset + count}) is not within [0, {spp})")
    xs_all, ys_all = _pixel_region(scene, tile)
    threads = min(max(1, int(threads or os.cpu_count() or 1)), MAX_THREADS_PER_CORE * (os.cpu_count() or 1))
    # the first render of a kind of scene compiles the kernels, on every core (compile_plan);
    # a cancel meanwhile (or while an earlier render's batch still compiles) returns at once
    if not (settle_abandoned_batches(cancel) and precompile(scene_kernel_variant(scene), cancel, scene_features(scene))):
        film, _ = _film_for(scene, xs_all, ys_all, tile)
        film.stats = RenderStats(samples_total=count, threads=threads, cancelled=True,
                                 seconds=time.perf_counter() - t0)
        film.meta.update({"version": __version__, "seed": scene.render.seed if seed is None else seed,
                          "sampler": sampler or scene.render.sampler, "spp": spp,
                          "sample_offset": sample_offset, "sample_count": 0,
                          "width": scene.render.width, "height": scene.render.height})
        return film
    ctx = context or prepare(scene, seed=seed, sampler=sampler, direct=direct, indirect=indirect,
                             samples=len(xs_all) * count, threads=threads)
    integ = ctx.integrator
    _use_sampling_arguments(integ, spp, seed, sampler, direct, indirect)
    xs, ys = xs_all, ys_all
    film, to_film = _film_for(scene, xs, ys, tile)
    film.reserve(mist=integ.mist_pass, light=integ.light_passes, data=bool(integ.data_passes),
                 crypto=integ.cryptomatte)
    stats = RenderStats(samples_total=count, threads=threads)
    threshold = scene.render.adaptive_threshold if adaptive_threshold is None else float(adaptive_threshold)
    min_samples = scene.render.adaptive_min_samples if adaptive_min_samples is None else int(adaptive_min_samples)
    if min_samples <= 0:
        min_samples = max(16, spp // 16)
    npix = len(xs)
    total_paths = max(npix * count, 1)
    batch_paths = int(max_batch_paths or (BATCH_PATHS if threads == 1 else BATCH_PATHS_THREADED))

    def batches(first: int, k: int):
        """(x, row, first, k) of one pass's batches: slices of the pixel list (the worker
        expands them into its own arrays, ``Integrator.render_pixels``), at most batch_paths
        paths, and small enough that every thread gets work in the early, small passes (at
        least two batches per thread, of at least MIN_BATCH_PATHS paths). Each pixel's samples
        of a pass stay in one batch, so the film adds them in the same order whatever the cut:
        the image does not depend on the thread count."""
        npix = len(xs)
        k = max(k, 1)
        spread = max(MIN_BATCH_PATHS // k, -(-npix // (2 * threads)))
        per = max(1, min(batch_paths // k, spread))
        for start in range(0, npix, per):
            sl = slice(start, start + per)
            yield xs[sl], ys[sl], first, k

    done = sample_offset
    cancelled = False
    if parallel not in ("threads", "auto"):
        raise ValueError(f"parallel must be 'threads' or 'auto', got {parallel!r}")
    workers = _ThreadWorkers(ctx, threads)

    def collect(future):
        """Wait for a batch, polling cancel meanwhile (so Esc/Ctrl-C, or a viewport edit, is
        seen within CANCEL_POLL_SECONDS)."""
        while True:
            try:
                batch = future.result(timeout=CANCEL_POLL_SECONDS)
                break
            except FutureTimeout:
                if cancel is not None and cancel():
                    raise _Cancelled from None
        _collect(batch, film, stats, tick, total_paths, workers, t0, to_film)

    # Passes follow each other without a barrier: the next pass's batches are submitted while
    # the last ones of this pass still run (``in_flight`` batches: each thread's own and
    # BATCHES_QUEUED_PER_THREAD more per thread), so no thread idles at a pass's end. Batches
    # are collected in submission order, so the film adds every pixel's samples in pass order
    # whatever the timing (same image at any thread count), and
    # when a pass's last batch is collected the film holds exactly the passes up to it: the
    # progress callback, the cancel check and adaptive sampling see it then. A pass whose
    # pixels adaptive sampling chooses from the film waits for the passes before it.
    stop = False  # cancelled, or adaptive sampling found every pixel converged
    pending: deque = deque()  # (future, samples per pixel of the pass it ends, or 0)
    in_flight = threads * (1 + BATCHES_QUEUED_PER_THREAD) + 1

    def end_of_pass(k: int) -> None:
        nonlocal xs, ys, cancelled, done, stop
        done += k
        stats.samples_done = done - sample_offset
        if threshold > 0 and stats.samples_done >= min_samples:
            fx, fy = (xs, ys) if to_film is None else (xs - to_film[1], ys - to_film[2])
            keep = adaptive_active(film, fx, fy, threshold)
            xs, ys = xs[keep], ys[keep]
            stats.active_pixels = int(len(xs))
            if len(xs) == 0:
                stats.samples_done = count
                if progress is not None:
                    progress(film, count, count)
                stop = True
                return
        if progress is not None:
            progress(film, stats.samples_done, count)
        if cancel is not None and cancel():
            cancelled = stats.samples_done < count
            stop = True

    def finish_one() -> None:
        future, ends_pass = pending.popleft()
        collect(future)
        if ends_pass and not stop:
            end_of_pass(ends_pass)

    def drain() -> None:
        """Collect every batch in flight (the film then holds every pass submitted so far)."""
        while pending and not stop:
            finish_one()

    aborted = False
    try:
        try:
            first = done  # first sample number of the next pass to submit
            for k in pass_schedule(count):
                if threshold > 0 and first - sample_offset >= min_samples:
                    drain()  # adaptive: this pass's pixels come from the film so far
                if stop:
                    break
                cut = list(batches(first, k))
                if not cut:  # no pixels (an empty tile): the pass ends once the film is current
                    drain()
                    if not stop:
                        end_of_pass(k)
                for j, b in enumerate(cut):
                    if cancel is not None and cancel():
                        raise _Cancelled
                    pending.append((workers.submit(*b), k if j == len(cut) - 1 else 0))
                    while len(pending) >= in_flight and not stop:
                        finish_one()
                    if stop:
                        break
                if stop:
                    break
                first += k
            drain()
        except _Cancelled:  # during a submission or while waiting for a batch
            cancelled = True
            stop = True
            aborted = True
        if pending:  # stopped at a pass's end (cancel) with the next pass's batches in flight
            aborted = True
        if aborted:
            workers.abort()  # batches in flight are dropped: the film keeps finished ones
    finally:
        if not aborted:
            workers.close()
    stats.cancelled = cancelled
    if stats.samples_done:
        mark_kernels_compiled(ctx.integrator.kernel_variant)
        integ = ctx.integrator
        mark_features_compiled(f for f in scene_features(scene)
                               if (f == "sss" and integ.sss is not None and integ.sss.walks) or (f == "motion" and integ.motion))
    stats.seconds = time.perf_counter() - t0
    stats.rays, stats.embree_seconds = workers.counters()
    stats.nan_samples = film.nan_samples
    ox, oy = (0, 0) if to_film is None else (to_film[1], to_film[2])
    held = film.count[(ys_all - oy) * film.width + (xs_all - ox)]
    if len(held):
        stats.spp_min, stats.spp_mean, stats.spp_max = int(held.min()), float(held.mean()), int(held.max())
    film.meta.update(
        {
            "version": __version__,
            "seed": integ.s.seed,
            "sampler": integ.sampler.kind,
            "spp": spp,
            "sample_offset": sample_offset,
            "sample_count": stats.samples_done,
            "width": scene.render.width,
            "height": scene.render.height,
        }
    )
    film.stats = stats
    return film


def adaptive_active(film: Film, xs: np.ndarray, ys: np.ndarray, threshold: float) -> np.ndarray:
    """(n,) bool for the given pixels: is the relative standard error of the mean luminance
    still above ``threshold``? The denominator is floored at 1e-3 so black pixels converge."""
    flat = ys * film.width + xs
    n = film.count[flat].astype(np.float64)
    mean = luminance(film.sum_rgba[flat, :3]) / np.maximum(n, 1)
    m2 = film.sum_lum2[flat] / np.maximum(n, 1)
    var_mean = np.maximum(m2 - mean**2, 0.0) / np.maximum(n - 1, 1)
    return np.sqrt(var_mean) > threshold * np.maximum(mean, 1e-3)


def _collect(batch, film, stats, tick, total_paths, workers, t0, to_film=None):
    if to_film is not None:  # frame pixel ids -> ids in the tile's film
        width, fx0, fy0, fw = to_film
        row, col = np.divmod(batch.pixel, width)
        batch = replace(batch, pixel=(row - fy0) * fw + (col - fx0))
        if batch.data_pixel is not None:
            row, col = np.divmod(batch.data_pixel, width)
            batch = replace(batch, data_pixel=(row - fy0) * fw + (col - fx0))
    film.add(batch)
    stats.camera_paths += len(batch.pixel) + batch.nan_count
    if batch.release is not None:  # the film holds its sums: the arrays can serve a later batch
        batch.release()
    if tick is not None:
        stats.seconds = time.perf_counter() - t0
        stats.rays, stats.embree_seconds = workers.counters()
        tick(min(stats.camera_paths / total_paths, 1.0), stats)


def merge_films(films: list[Film]) -> Film:
    """Sum films of disjoint sample ranges of the same render into one."""
    if not films:
        raise ValueError("nothing to merge")
    out = Film(films[0].width, films[0].height)
    for f in films:
        if (f.width, f.height) != (out.width, out.height):
            raise ValueError(f"cannot merge a {f.width}x{f.height} image into a {out.width}x{out.height} one")
        out.merge(f)
    out.meta = dict(films[0].meta)
    out.meta["sample_count"] = int(sum(int(f.meta.get("sample_count", 0)) for f in films))
    out.meta["sample_offset"] = min(int(f.meta.get("sample_offset", 0)) for f in films)
    return out
