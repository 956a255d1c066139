"""``python -m drt render`` with ``--cluster`` and/or ``--frames`` (hooked from ``drt.cli``).

Without ``--cluster`` (nor ``DRT_CLUSTER``) this module imports no Dask: ``--frames`` then
renders the frames one after another in this process, on its threads.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading

CLUSTER_ENV = "DRT_CLUSTER"


def _seconds(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected seconds, got {text!r}") from None
    if not (0 < v <= 86400):
        raise argparse.ArgumentTypeError(f"must be within (0, 86400] seconds, got {text}")
    return v


def add_arguments(r: argparse.ArgumentParser) -> None:
    """The animation and cluster options of ``render``."""
    from .client import DEFAULT_TIMEOUT
    from .plan import TASK_SECONDS

    r.add_argument("--frames", help="render frames A-B (or 1,5,10-20) of a .blend; OUT_####.exr is "
                   "numbered like Blender (no # : frame number before the extension)")
    g = r.add_argument_group("cluster (Dask; see docs/farm.md)")
    g.add_argument("--cluster", metavar="ADDRESS", help=f"render on the Dask scheduler at tcp://HOST:PORT or "
                   f"tls://HOST:PORT (default: ${CLUSTER_ENV}; none: this machine)")
    g.add_argument("--cluster-timeout", type=_seconds, default=DEFAULT_TIMEOUT, metavar="SECONDS",
                   help=f"give up when the scheduler does not answer, or the cluster has no worker, for this "
                   f"long (default {DEFAULT_TIMEOUT:g})")
    g.add_argument("--tls-ca-file", help="CA certificate that signed the scheduler's (tls://)")
    g.add_argument("--tls-cert", help="this client's certificate (tls://)")
    g.add_argument("--tls-key", help="this client's private key, if not in --tls-cert (tls://)")
    g.add_argument("--task-seconds", type=_seconds, default=TASK_SECONDS, metavar="SECONDS",
                   help=f"estimated duration of one cluster task (default {TASK_SECONDS:g})")


def wants_farm_path(args) -> bool:
    return bool(args.frames or cluster_address(args))


def cluster_address(args) -> str | None:
    return args.cluster or os.environ.get(CLUSTER_ENV) or None


def cmd_render(args, *, load, error_cls, progress_cls) -> int:
    """``render`` with --frames and/or a cluster. load(args) -> Scene is the CLI's loader;
    error_cls(message, code) its one-line error; progress_cls(stream) its progress bar.
    Denoising (--denoise) runs here on the client, on each whole frame."""
    from ..cli import _denoise, apply_render_args
    from ..exr import write_exr
    from ..frames import frame_path, parse_frames
    from ..loaders import is_plugin_format
    from ..scene import SceneError

    address = cluster_address(args)
    frames = [None]
    if args.frames:
        try:
            frames = parse_frames(args.frames)
        except ValueError as e:
            raise error_cls(f"--frames: {e}", 2) from None
        if args.frame is not None:
            raise error_cls("give --frame or --frames, not both", 2)
        if not os.path.exists(args.scene):
            raise error_cls(f"scene file not found: {args.scene}", 2)
        if not is_plugin_format(args.scene):
            raise error_cls(f"--frames needs an animated scene file (.blend); {args.scene} holds one "
                            "exported frame", 2)
    sec = None
    if address:
        if args.threads:
            raise error_cls("--threads does not apply to --cluster (each worker runs one task per thread)", 2)
        from .client import FarmError, check_address, security

        try:
            address = check_address(address)
            sec = security(address, args.tls_ca_file, args.tls_cert, args.tls_key)
        except FarmError as e:
            raise error_cls(str(e), e.code) from None

    def out_path(pattern, frame):
        return pattern if frame is None else frame_path(pattern, frame)

    def load_frame(frame):
        ns = args if frame is None else argparse.Namespace(**{**vars(args), "frame": frame})
        scene = load(ns)
        apply_render_args(args, scene)  # the client holds whole frames: the memory check applies
        return scene

    written, notes = [], []

    def write(frame, film):
        path = out_path(args.output, frame)
        denoised, note, meta = _denoise(args, film) if not stop.is_set() else (None, "", {})
        notes.append(note)
        write_exr(path, film, meta, denoised=denoised)
        if args.png:
            from ..preview import write_png

            write_png(out_path(args.png, frame), film.combined if denoised is None else denoised)
        written.append(path)

    stop = threading.Event()
    previous = signal.getsignal(signal.SIGINT)

    def on_sigint(signum, frame):
        if stop.is_set():  # a second Ctrl-C: give up at once
            raise KeyboardInterrupt
        stop.set()

    signal.signal(signal.SIGINT, on_sigint)
    bar = progress_cls(sys.stderr)
    try:
        if address:
            stats, first = _render_cluster(args, address, sec, frames, load_frame, write, bar, stop, error_cls)
        else:
            stats, first = _render_local(args, frames, load_frame, write, bar, stop)
    except SceneError as e:
        raise error_cls(f"invalid scene {args.scene}: {e}", 2) from None
    finally:
        signal.signal(signal.SIGINT, previous)
        bar.done()
    if first is None:
        return 130 if stop.is_set() else 0
    w, h = first.render.width, first.render.height
    where = (f"on {stats.workers} workers ({stats.threads} threads), {stats.tasks_done} tasks"
             if address else f"on {getattr(stats, 'threads', 1)} threads")
    what = f"{len(written)} frames" if args.frames else f"{w}x{h}"
    state = "cancelled after" if stop.is_set() else "rendered"
    target = args.output if not args.frames else f"{written[0]} .. {written[-1]}" if written else "nothing"
    note = notes[-1] if len(notes) == 1 else (f", {len(notes)} frames denoised" if args.denoise and notes else "")
    print(f"drt: {state} {what} {where} in {stats.seconds:.2f}s: "
          f"{stats.camera_paths / max(stats.seconds, 1e-9) / 1e3:.1f} k samples/s{note} -> {target}")
    return 130 if stop.is_set() else 0


class _LocalStats:
    def __init__(self):
        self.seconds = 0.0
        self.camera_paths = 0
        self.threads = 1


def _render_local(args, frames, load_frame, write, bar, stop):
    """Frames one after another in this process (no Dask)."""
    import time

    from ..kernels import COMPILING_NOTICE, kernels_compiled, scene_kernel_variant
    from ..render import render

    t0 = time.perf_counter()
    total = _LocalStats()
    first = None
    for i, frame in enumerate(frames):
        if stop.is_set():
            break
        scene = load_frame(frame)
        first = first or scene
        if not kernels_compiled(scene_kernel_variant(scene)):
            print(f"drt: {COMPILING_NOTICE}", file=sys.stderr, flush=True)

        def tick(fraction, st, i=i):
            bar((i + fraction) / len(frames), _Elapsed(time.perf_counter() - t0, st.rays_per_second))

        spp = args.spp or scene.render.spp
        count = args.sample_count if args.sample_count is not None else spp - args.sample_offset
        film = render(scene, spp=spp, seed=args.seed, threads=args.threads, sampler=args.sampler,
                      direct=args.direct, indirect=args.indirect, adaptive_threshold=args.adaptive_threshold,
                      adaptive_min_samples=args.adaptive_min_samples, sample_offset=args.sample_offset,
                      sample_count=count, tick=tick, cancel=stop.is_set)
        write(frame, film)
        total.camera_paths += film.stats.camera_paths
        total.threads = film.stats.threads
    total.seconds = time.perf_counter() - t0
    return total, first


class _Elapsed:
    """What the CLI's progress bar reads: elapsed seconds and a ray rate."""

    def __init__(self, seconds, rays_per_second):
        self.seconds = seconds
        self.rays_per_second = rays_per_second


def _render_cluster(args, address, sec, frames, load_frame, write, bar, stop, error_cls):
    from .client import FarmError, connect, quiet_dask_logs, render_frames

    first = []

    def load(frame):
        scene = load_frame(frame)
        if not first:
            first.append(scene)
        return scene, scene

    settings = dict(spp=args.spp, seed=args.seed, sampler=args.sampler, direct=args.direct,
                    indirect=args.indirect, adaptive_threshold=args.adaptive_threshold,
                    adaptive_min_samples=args.adaptive_min_samples)
    try:
        client = connect(address, timeout=args.cluster_timeout, sec=sec)
        try:
            with quiet_dask_logs():
                stats = render_frames(client, frames, load, settings, on_frame=write,
                                      timeout=args.cluster_timeout, task_seconds=args.task_seconds,
                                      progress=bar, cancel=stop.is_set, sample_offset=args.sample_offset,
                                      sample_count=args.sample_count)
        finally:
            with quiet_dask_logs():
                client.close(timeout=min(args.cluster_timeout, 10))
    except FarmError as e:
        raise error_cls(str(e), e.code) from None
    return stats, (first[0] if first else None)
