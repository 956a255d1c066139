"""The client side of cluster rendering: connect, scatter scenes, submit tasks, merge films.

Everything Dask lives here and is imported only when a cluster is named, so ``import drt`` and
one-process renders never import ``distributed``.

Time-outs (``timeout`` seconds, the CLI's ``--cluster-timeout``, default ``DEFAULT_TIMEOUT``):
connecting to the scheduler; waiting for the first worker to join; the cluster having no
worker at all mid-render; the scheduler being unreachable mid-render. Each ends the render
with a ``FarmError`` instead of waiting forever. A task's own duration is not limited (the
first task on a fresh worker may compile the kernels for half a minute).

A worker that dies loses only its running tasks: Dask runs them again elsewhere, and since a
task is a pure function of (scene, settings, tile, sample range) the image does not change.
"""

from __future__ import annotations

import logging
import os
import time
import uuid
from concurrent.futures import CancelledError
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from ..film import DATA_WIDTH, LIGHT_WIDTH, Film
from .plan import TASK_SECONDS, TaskSpec, plan_frame

DEFAULT_TIMEOUT = 30.0  # seconds
POLL_SECONDS = 0.05  # how often the client looks at finished tasks, cancel and the cluster
HEALTH_SECONDS = 1.0  # how often it asks the scheduler how many workers it has
TASK_FUNCTION = "render_task"  # in drt.farm.tasks, called through _remote.call
FINGERPRINT_FUNCTION = "fingerprint"


class FarmError(Exception):
    """A cluster problem, for the user in one line; ``code`` is the CLI exit code
    (2: cannot start — unreachable, no workers, TLS, mismatched workers; 1: failed mid-render)."""

    def __init__(self, message: str, code: int = 1):
        super().__init__(message)
        self.code = code


@contextmanager
def quiet_dask_logs():
    """Dask logs connection retries and lost workers at WARNING/ERROR on stderr; DRT reports
    those itself in one line, so Dask's own loggers are held at CRITICAL meanwhile."""
    loggers = [logging.getLogger(n) for n in ("distributed", "distributed.client", "distributed.comm",
                                               "distributed.core", "distributed.batched", "tornado")]
    levels = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        for lg, lv in zip(loggers, levels):
            lg.setLevel(lv)


def security(address: str, tls_ca_file: str | None = None, tls_cert: str | None = None,
             tls_key: str | None = None):
    """Dask ``Security`` for a ``tls://`` address: the given files (CA, client certificate,
    its key), else Dask's configuration (``distributed.comm.tls.*`` in ~/.config/dask or
    ``DASK_DISTRIBUTED__COMM__TLS__...`` variables). None for ``tcp://``."""
    files = {"--tls-ca-file": tls_ca_file, "--tls-cert": tls_cert, "--tls-key": tls_key}
    given = [k for k, v in files.items() if v]
    if not address.startswith("tls://"):
        if given:
            raise FarmError(f"{', '.join(given)} need a tls:// scheduler address, got {address}", 2)
        return None
    for k, v in files.items():
        if v and not os.path.isfile(v):
            raise FarmError(f"{k} file not found: {v}", 2)
    from distributed.security import Security

    if not given:
        return Security()
    if not (tls_ca_file and tls_cert):
        raise FarmError("tls:// needs --tls-ca-file and --tls-cert (and --tls-key unless the "
                        "certificate file holds the key)", 2)
    return Security(tls_ca_file=tls_ca_file, tls_client_cert=tls_cert,
                    tls_client_key=tls_key or None, require_encryption=True)


def check_address(address: str) -> str:
    address = address.strip()
    if not (address.startswith("tcp://") or address.startswith("tls://")) or len(address) <= 6:
        raise FarmError(f"a cluster address is tcp://HOST:PORT or tls://HOST:PORT, got {address!r}", 2)
    return address


def connect(address: str, *, timeout: float = DEFAULT_TIMEOUT, sec=None):
    """A ``distributed.Client`` of the scheduler at ``address`` with at least one worker, whose
    workers all run this client's DRT (``tasks.fingerprint``). FarmError (code 2) otherwise,
    within about ``timeout`` seconds for each of: connecting, the first worker joining."""
    check_address(address)
    try:
        from distributed import Client
    except ImportError:
        raise FarmError("rendering on a cluster needs Dask: pip install 'drt-renderer[farm]' "
                        "(the distributed package)", 2) from None
    import dask

    with quiet_dask_logs():
        try:
            # connect time-out for every comm; no dashboard, no listening port on the client
            # the connect time-out of every later call too (cancel, scatter), so none hangs
            dask.config.set({"distributed.comm.timeouts.connect": f"{timeout}s"})
            client = Client(address, timeout=timeout, security=sec, set_as_default=False,
                            name="drt-client")
        except Exception as e:  # OSError, TimeoutError, TLS errors: all "cannot reach"
            why = str(e).splitlines()[0] if str(e) else e.__class__.__name__
            if "timed out" in why.lower() or isinstance(e, TimeoutError):
                why = f"no answer within {timeout:g} s"
            raise FarmError(f"cannot reach the Dask scheduler at {address}: {why}", 2) from None
        try:
            try:
                client.wait_for_workers(1, timeout=timeout)
            except Exception:
                raise FarmError(f"the Dask scheduler at {address} has no workers "
                                f"(none joined within {timeout:g} s)", 2) from None
            check_workers(client)
        except BaseException:
            client.close(timeout=min(timeout, 5))
            raise
    return client


def _remote_call():
    from . import _remote

    return _remote.call


def check_workers(client) -> None:
    """Refuse workers without DRT or with another DRT than this client (FarmError, code 2)."""
    from .tasks import fingerprint

    mine = fingerprint()
    answers = client.run(_remote_call(), FINGERPRINT_FUNCTION, on_error="return")
    for worker, fp in sorted(answers.items()):
        if isinstance(fp, BaseException):
            raise FarmError(f"worker {worker} cannot run DRT ({fp}); install the same "
                            "drt-renderer on every worker", 2)
        if fp != mine:
            raise FarmError(f"worker {worker} runs DRT {fp}, this client {mine}: install the "
                            "same drt-renderer on every worker", 2)


@dataclass
class FarmStats:
    """Progress of a cluster render: what ``progress(fraction, stats)`` receives."""

    seconds: float = 0.0
    tasks_total: int = 0
    tasks_done: int = 0
    frames_done: int = 0
    camera_paths: int = 0
    rays: int = 0
    task_seconds: float = 0.0  # summed over finished tasks (worker time)
    workers: int = 0
    threads: int = 0
    nan_samples: int = 0
    cancelled: bool = False
    resubmitted: int = 0  # tasks sent again after the scene was lost with its workers
    samples_done: int = 0  # of the last frame (per pixel)
    embree_seconds: float = 0.0

    @property
    def rays_per_second(self) -> float:
        return self.rays / self.seconds if self.seconds > 0 else 0.0


@dataclass
class _Frame:
    index: int
    number: int | None
    width: int
    height: int
    specs: list[TaskSpec]
    scene_future: object
    sample_offset: int
    sample_count: int
    payload: object = None  # kept to send again if every worker holding the scene is lost
    settings: dict = field(default_factory=dict)
    attempts: int = 0
    futures: dict = field(default_factory=dict)  # unfinished task's key -> task index
    handles: dict = field(default_factory=dict)  # unfinished task's key -> its Future
    parts: dict = field(default_factory=dict)  # task index -> result dict
    preview: Film | None = None

    @property
    def paths(self) -> int:
        return sum(s.paths for s in self.specs)


def _add_part(film: Film, part: dict) -> None:
    """Add a task's tile sums into a whole-frame film (exact for a tile's first sample range:
    0 + x is x, min(inf, x) is x)."""
    x0, y0, x1, y1 = part["tile"]
    h, w = y1 - y0, x1 - x0
    rows = slice(y0, y1)
    cols = slice(x0, x1)
    for name, ch in (("sum_rgba", 4), ("sum_lum2", 0), ("sum_normal", 3), ("sum_albedo", 3), ("count", 0)):
        dst = getattr(film, name).reshape((film.height, film.width) + ((ch,) if ch else ()))
        dst[rows, cols] += part[name].reshape((h, w) + ((ch,) if ch else ()))
    md = film.min_depth.reshape(film.height, film.width)
    md[rows, cols] = np.minimum(md[rows, cols], part["min_depth"].reshape(h, w))
    if part.get("sum_mist") is not None:  # (the Mist pass, when the scene asks for it)
        if film.sum_mist is None:
            film.sum_mist = np.zeros(film.width * film.height)
        film.sum_mist.reshape(film.height, film.width)[rows, cols] += part["sum_mist"].reshape(h, w)
    if part.get("sum_light") is not None:  # (the Emission and Environment passes)
        if film.sum_light is None:
            film.sum_light = np.zeros((film.width * film.height, LIGHT_WIDTH))
        film.sum_light.reshape(film.height, film.width, LIGHT_WIDTH)[rows, cols] += \
            part["sum_light"].reshape(h, w, LIGHT_WIDTH)
    if part.get("sum_data") is not None:  # (the data passes, when the scene asks for them)
        if film.sum_data is None:
            film.sum_data = np.zeros((film.width * film.height, DATA_WIDTH))
        film.sum_data.reshape(film.height, film.width, DATA_WIDTH)[rows, cols] += \
            part["sum_data"].reshape(h, w, DATA_WIDTH)
    if part.get("sum_crypto") is not None:  # (Cryptomatte: slots merge by id, not by sum)
        layers, n_slots = tuple(part["crypto_layers"]), int(part["crypto_slots"])
        if film.sum_crypto is None:
            film.crypto_layers, film.crypto_slots = layers, n_slots
            film.sum_crypto = np.zeros((film.width * film.height, len(layers) * n_slots, 2), np.float32)
        whole = film.sum_crypto.reshape(film.height, film.width, -1, 2)
        block = np.ascontiguousarray(whole[rows, cols]).reshape(h * w, -1, 2)
        tile_film = Film(w, h, sum_crypto=block, crypto_layers=film.crypto_layers, crypto_slots=film.crypto_slots)
        tile_film.merge_crypto(part["sum_crypto"], layers, n_slots, part.get("crypto_names"))
        whole[rows, cols] = tile_film.sum_crypto.reshape(h, w, -1, 2)
        film.crypto_names = {k: tuple(sorted(set(film.crypto_names.get(k, ())) | set(v)))
                             for k, v in {**film.crypto_names, **tile_film.crypto_names}.items()}
    film.nan_samples += int(part["nan_samples"])


def _frame_film(fr: _Frame, parts: Sequence[dict]) -> Film:
    film = Film(fr.width, fr.height)
    for p in parts:
        _add_part(film, p)
    meta = dict(parts[0]["meta"]) if parts else {}
    if len(parts) == len(fr.specs):
        count = fr.sample_count
    else:  # cancelled: the samples every pixel of the frame has (0 where a tile is missing)
        per_tile: dict = {}
        for p in parts:
            per_tile[tuple(p["tile"])] = per_tile.get(tuple(p["tile"]), 0) + p["sample_count"]
        tiles = {s.tile for s in fr.specs}
        count = min(per_tile.get(t, 0) for t in tiles)
    meta.update(sample_offset=fr.sample_offset, sample_count=count, width=fr.width, height=fr.height)
    film.meta = meta
    return film


def render_frames(
    client,
    frames: Sequence,
    load: Callable[[object], tuple],
    settings: dict,
    *,
    on_frame: Callable[[object, Film], None],
    timeout: float = DEFAULT_TIMEOUT,
    task_seconds: float = TASK_SECONDS,
    progress: Callable[[float, FarmStats], None] | None = None,
    preview: Callable[[object, Film], None] | None = None,
    cancel: Callable[[], bool] | None = None,
    sample_offset: int = 0,
    sample_count: int | None = None,
) -> FarmStats:
    """Render ``frames`` on the cluster behind ``client``; returns the stats.

    load(frame) -> (scene, payload): the ``Scene`` (for its size, border and samples) and what
    the workers receive (the Scene itself, or the exporter's ``(header, arrays)``); called on
    the client when the frame is scheduled, so a .blend animation is exported frame by frame.
    settings: spp, seed, sampler, direct, indirect, adaptive_threshold, adaptive_min_samples
    (None: the scene's). Frames overlap: the next frame's tasks are submitted while the
    cluster still has fewer than two tasks per worker thread queued, so a small cluster stays
    busy across frame boundaries; earlier frames have priority.

    on_frame(frame, film) when a frame is complete (its tasks summed in plan order: the same
    bits whatever order tasks finished in); preview(frame, film) after each finished task with
    the frame's partial sum (for live display); progress(fraction, stats) after each task, the
    fraction counted in camera paths. cancel() -> True cancels the cluster's tasks and returns
    (``stats.cancelled``); the unfinished frame is passed to on_frame with what was done.
    Raises FarmError on task failures and on the time-outs in the module docstring.
    """
    from distributed import as_completed

    from ..render import pixel_bounds

    t0 = time.perf_counter()
    stats = FarmStats()
    stats.workers, stats.threads = _cluster_size(client)
    run_id = uuid.uuid4().hex[:8]
    pending_frames = list(frames)
    active: dict[int, _Frame] = {}
    by_key: dict[str, _Frame] = {}
    ac = as_completed([], with_results=False, loop=client.loop)
    outstanding = 0
    paths_done = 0
    paths_known = 0
    frames_total = len(pending_frames)
    next_index = 0
    last_health = time.perf_counter()
    no_workers_since = None
    lost_since = None
    adaptive = settings.get("adaptive_threshold")

    def submit_frame():
        nonlocal next_index, outstanding, paths_known
        number = pending_frames.pop(0)
        scene, payload = load(number)
        spp = int(settings.get("spp") or scene.render.spp)
        count = spp - sample_offset if sample_count is None else int(sample_count)
        if sample_offset < 0 or count < 1 or sample_offset + count > spp:
            raise FarmError(f"sample range [{sample_offset}, {sample_offset + count}) is not within [0, {spp})", 2)
        ad = scene.render.adaptive_threshold if adaptive is None else adaptive
        specs = plan_frame(pixel_bounds(scene), sample_offset, count, min_tasks=2 * max(stats.threads, 1),
                           task_seconds=task_seconds, split_samples=not (ad and ad > 0))
        fr = _Frame(next_index, number, scene.render.width, scene.render.height, specs, None,
                    sample_offset, count, payload, dict(settings, spp=spp))
        fr.scene_future = scatter(fr)
        fr.preview = Film(fr.width, fr.height) if preview is not None else None
        for i in range(len(specs)):
            submit_task(fr, i)
        active[fr.index] = fr
        outstanding += len(specs)
        stats.tasks_total += len(specs)
        paths_known += fr.paths
        next_index += 1

    def scatter(fr: _Frame):
        """Send the frame's scene to every worker (hash=False: a fresh key per frame;
        broadcast: one copy per worker now, not one per task)."""
        try:
            (fut,) = client.scatter([fr.payload], broadcast=True, hash=False, timeout=timeout)
        except TimeoutError:
            if client.status == "running" and _cluster_size(client)[0] == 0:
                raise FarmError(_no_workers_message()) from None
            raise FarmError(f"could not send the scene to the workers within {timeout:g} s") from None
        return fut

    def submit_task(fr: _Frame, i: int):
        sp = fr.specs[i]
        fut = fr.scene_future
        f = client.submit(_remote_call(), TASK_FUNCTION, fut, fut.key, fr.settings, sp.tile, sp.sample_offset,
                          sp.sample_count, key=f"drt-render-{run_id}-{fr.index}-{i}-{fr.attempts}",
                          priority=-fr.index, pure=False)
        fr.futures[f.key] = i
        fr.handles[f.key] = f
        by_key[f.key] = fr
        ac.add(f)

    def resubmit(fr: _Frame, lost: list[int]):
        """Dask cancels tasks whose input is gone: every worker holding the frame's scene
        died. Send the scene again and submit those tasks again (same inputs, same pixels)."""
        fr.attempts += 1
        if fr.attempts > 10:
            raise FarmError("the workers holding the scene kept dying; giving up")
        if fr.scene_future.status != "finished":
            fr.scene_future.release()
            fr.scene_future = scatter(fr)
        for i in lost:
            submit_task(fr, i)
        stats.resubmitted += len(lost)

    def _no_workers_message():
        return (f"all workers left the cluster and none came back within {timeout:g} s "
                f"({stats.tasks_done} of {stats.tasks_total} tasks done)")

    def fill():
        while pending_frames and (not active or outstanding < 2 * max(stats.threads, 1)):
            submit_frame()

    def finish_frame(fr: _Frame, partial: bool = False):
        parts = [fr.parts[i] for i in sorted(fr.parts)]
        film = _frame_film(fr, parts)
        del active[fr.index]
        fr.scene_future.release()
        if parts or not partial:
            on_frame(fr.number, film)
        stats.frames_done += 0 if partial else 1

    def health(force: bool = False):
        """Raise FarmError when the scheduler or every worker has been gone ``timeout`` s."""
        nonlocal last_health, no_workers_since, lost_since
        now = time.perf_counter()
        if now - last_health < (POLL_SECONDS * 4 if force else HEALTH_SECONDS):
            return
        last_health = now
        if client.status != "running":
            lost_since = lost_since or now
            if now - lost_since > timeout:
                raise FarmError(f"lost the connection to the Dask scheduler for more than {timeout:g} s "
                                f"({stats.tasks_done} of {stats.tasks_total} tasks done)")
            return
        lost_since = None
        stats.workers, stats.threads = _cluster_size(client)
        if stats.workers == 0:
            no_workers_since = no_workers_since or now
            if now - no_workers_since > timeout:
                raise FarmError(_no_workers_message())
        else:
            no_workers_since = None

    try:
        fill()
        while active:
            if cancel is not None and cancel():
                stats.cancelled = True
                break
            done = ac.next_batch(block=False) if ac.has_ready() else []
            if not done:
                time.sleep(POLL_SECONDS)
                health()
                continue
            lost: dict[int, list[int]] = {}
            if all(f.status in ("pending", "lost") for f in done):
                time.sleep(POLL_SECONDS)  # only recomputations under way: do not spin
                health()
            for f in done:
                if f.status in ("pending", "lost"):  # its worker died: Dask computes it again
                    ac.add(f)
                    continue
                fr = by_key.pop(f.key)
                if f.status == "cancelled":  # by the scheduler (we cancel only on leaving)
                    lost.setdefault(fr.index, []).append(fr.futures.pop(f.key))
                    fr.handles.pop(f.key)
                    continue
                if f.status != "finished":
                    raise _task_error(f)
                try:  # fetched from the worker; Dask recomputes it if that worker just died
                    part = f.result(timeout=timeout)
                except TimeoutError:
                    # its worker left before the result was fetched, and Dask found no other to
                    # compute it again on: say so when that is because every worker is gone
                    if _cluster_size(client)[0] == 0:
                        raise FarmError(_no_workers_message()) from None
                    raise FarmError(f"a finished task's result did not arrive within {timeout:g} s") from None
                except CancelledError:
                    # its worker died after it finished, with the only copy of the frame's scene:
                    # Dask cannot recompute it and cancels it; send both again (as above)
                    lost.setdefault(fr.index, []).append(fr.futures.pop(f.key))
                    fr.handles.pop(f.key)
                    continue
                fr.parts[fr.futures.pop(f.key)] = part
                fr.handles.pop(f.key)
                outstanding -= 1
                stats.tasks_done += 1
                stats.camera_paths += part["camera_paths"]
                stats.rays += part["rays"]
                stats.task_seconds += part["seconds"]
                stats.nan_samples += part["nan_samples"]
                x0, y0, x1, y1 = part["tile"]
                paths_done += (x1 - x0) * (y1 - y0) * part["sample_count"]
                f.release()
                if fr.preview is not None:
                    _add_part(fr.preview, part)
                    preview(fr.number, fr.preview)
                if not fr.futures:
                    stats.samples_done = fr.sample_count
                    finish_frame(fr)
            for index, tasks in lost.items():
                if client.status == "running":
                    stats.workers, stats.threads = _cluster_size(client)
                while stats.workers == 0 or client.status != "running":  # wait (time-out) for workers
                    time.sleep(POLL_SECONDS)
                    health(force=True)
                resubmit(active[index], tasks)
            fill()
            stats.seconds = time.perf_counter() - t0
            if progress is not None:
                # frames not scheduled yet are assumed as costly as the ones that are
                per_frame = paths_known / max(next_index, 1)
                total = paths_known + per_frame * (frames_total - next_index)
                progress(min(paths_done / max(total, 1), 1.0), stats)
    finally:
        left = [f for fr in active.values() for f in fr.handles.values()]
        if left and client.status == "running":
            client.cancel(left)
    if stats.cancelled:
        for fr in sorted(active.values(), key=lambda fr: fr.index):
            finish_frame(fr, partial=True)
    stats.seconds = time.perf_counter() - t0
    return stats


def _cluster_size(client) -> tuple[int, int]:
    """(workers, threads) the scheduler has now (one round trip)."""
    try:
        info = client.scheduler_info(n_workers=0)  # totals only (distributed >= 2025)
    except TypeError:
        info = client.scheduler_info()
    if "n_workers" in info:
        return int(info["n_workers"]), int(info.get("total_threads", 0))
    workers = info.get("workers", {})
    return len(workers), sum(int(w.get("nthreads", 0)) for w in workers.values())


def _task_error(future) -> FarmError:
    """A one-line FarmError for a failed task (the render error, or Dask's KilledWorker)."""
    try:
        exc = future.exception(timeout=5)
    except Exception as e:  # noqa: BLE001 -- cancelled or lost futures
        exc = e
    name = exc.__class__.__name__
    msg = str(exc).splitlines()[0] if str(exc) else name
    if name == "KilledWorker":
        return FarmError(f"a render task killed every worker it ran on; giving up ({msg})")
    if name in ("CancelledError", "FutureCancelledError"):
        return FarmError("the scheduler cancelled a render task (did it restart?)")
    code = 2 if msg.startswith("SceneError") else 1
    return FarmError(f"a render task failed on the cluster: {msg}", code)
