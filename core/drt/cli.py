"""Command line: ``python -m drt render | merge | export | bench``.

Bad input ends with a one-line message on stderr and a non-zero exit code, never a traceback
(exit 2: bad arguments or scene; 1: a failure while rendering; 130: interrupted, the partial
image is still written). The progress bar is shown only on a terminal.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
import time

EXIT_OK, EXIT_FAILURE, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130


class CliError(Exception):
    """A user-facing error: printed as one line, exit code ``code``."""

    def __init__(self, message: str, code: int = EXIT_USAGE):
        super().__init__(message)
        self.code = code


class _Parser(argparse.ArgumentParser):
    """argparse with DRT's error format: one line ``drt: error: ...`` on stderr, exit code 2
    (argparse's default prints the whole usage block first). ``--help`` is unchanged."""

    def error(self, message):
        sys.stderr.write(f"drt: error: {message} (see: {self.prog} --help)\n")
        sys.exit(EXIT_USAGE)


def _prog() -> str:
    """``drt`` when run through the console script, ``python -m drt`` otherwise."""
    return "drt" if os.path.basename(sys.argv[0] or "") in ("drt", "drt.exe") else "python -m drt"


def _choice(*names: str):
    """argparse type + choices for an option whose values are shown in lower case and accepted
    in any case (``--sampler SOBOL`` and ``--sampler sobol`` are the same); the parsed value is
    the upper-case name the core uses."""
    allowed = {n.lower(): n for n in names}

    def parse(text: str) -> str:
        key = text.lower()
        if key not in allowed:
            raise argparse.ArgumentTypeError(f"invalid choice {text!r} (choose from {', '.join(allowed)})")
        return allowed[key]

    return dict(type=parse, metavar="{" + ",".join(allowed) + "}")


def _resolution(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, e.g. 640x480, got {text!r}") from None
    if not (1 <= w <= 65536 and 1 <= h <= 65536):
        raise argparse.ArgumentTypeError(f"resolution must be between 1x1 and 65536x65536, got {text}")
    return w, h


def _int_at_least(lo: int):
    """argparse type: a whole number >= lo, with a one-line message otherwise."""

    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
        if v < lo:
            raise argparse.ArgumentTypeError(f"must be at least {lo}, got {v}")
        return v

    return parse


_positive = _int_at_least(1)
_non_negative = _int_at_least(0)


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog=_prog(), description="DRT: a distribution ray tracer for Blender scenes")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND (render, merge, export, bench)")

    r = sub.add_parser("render", help="render a scene (.npz export or .blend) to an EXR")
    r.add_argument("scene", help="scene file: .npz (DRT export) or .blend (needs the bpy module)")
    r.add_argument("-o", "--output", required=True, help="output EXR path")
    r.add_argument("--spp", type=_positive, help="samples per pixel (default: the scene's)")
    r.add_argument("--seed", type=_non_negative, help="random seed (default: the scene's)")
    r.add_argument("--threads", type=_positive, help="worker threads (default: all cores; at most 4 per core)")
    r.add_argument("--resolution", type=_resolution, help="override WIDTHxHEIGHT (keeps the camera's framing)")
    r.add_argument("--sampler", **_choice("SOBOL", "STRATIFIED", "RANDOM"),
                   help="how sample positions are spread over pixel, lens, time and lights (default sobol)")
    r.add_argument("--direct", **_choice("MIS_POWER", "MIS_BALANCE", "LIGHT", "BSDF"),
                   help="how light from lamps is found: sample lights, sample the material, or both "
                   "combined (mis_power, the default)")
    r.add_argument("--indirect", **_choice("BSDF", "COSINE", "UNIFORM"),
                   help="how bounce directions are chosen (default bsdf: follow the material)")
    r.add_argument("--adaptive-threshold", type=float, help="stop pixels whose relative standard error is below this (0: off)")
    r.add_argument("--adaptive-min-samples", type=_non_negative, help="samples before a pixel may stop (0: automatic)")
    r.add_argument("--sample-offset", type=_non_negative, default=0, help="first sample number (farm splitting)")
    r.add_argument("--sample-count", type=_positive, help="number of samples to render from --sample-offset")
    r.add_argument("--frame", type=int, help="frame to render (.blend only)")
    r.add_argument("--png", help="also write an 8-bit sRGB PNG preview here")
    _add_denoise_args(r, "denoise the image with Open Image Denoise (albedo + normal guides); the noisy "
                         "image is kept as the EXR layer Noisy (needs the denoise extra)")
    from .farm.cli import add_arguments as add_farm_arguments  # --frames, --cluster (no Dask import)

    add_farm_arguments(r)

    m = sub.add_parser("merge", help="merge EXRs of disjoint sample ranges into one image")
    m.add_argument("inputs", nargs="+", help="EXR files written by `drt render --sample-offset/--sample-count`")
    m.add_argument("-o", "--output", required=True)
    _add_denoise_args(m, "denoise the merged image once (the noisy one is kept as the layer Noisy)")

    e = sub.add_parser("export", help="export a .blend to a DRT scene file (needs the bpy module)")
    e.add_argument("scene", help=".blend file")
    e.add_argument("-o", "--output", required=True, help="output .npz")
    e.add_argument("--frame", type=int)
    b = sub.add_parser("bench", help="error against time for each estimator/sampler (and Cycles)")
    b.add_argument("scene", help="scene file: .npz (DRT export) or .blend (needs the bpy module)")
    b.add_argument("-o", "--output", required=True, help="output directory (bench.csv, bench.json, bench.png)")
    b.add_argument("--reference", help="reference EXR (default: render one at --reference-spp)")
    b.add_argument("--reference-spp", type=_positive, default=1024, help="samples of the rendered reference (default 1024)")
    b.add_argument("--methods", nargs="+", help="presets (mis_power mis_balance light bsdf cosine uniform random "
                   "stratified sobol adaptive) or direct/indirect/sampler[/threshold], e.g. mis_power/bsdf/sobol")
    b.add_argument("--spp-list", nargs="+", type=_positive, help="sample counts (default 1 4 16 64)")
    b.add_argument("--cycles", action="store_true", help="also render with Cycles through bpy (needs the .blend)")
    b.add_argument("--threads", type=_positive, help="threads for DRT and Cycles (default: all cores)")
    b.add_argument("--resolution", type=_resolution, help="override WIDTHxHEIGHT")
    b.add_argument("--seed", type=_non_negative, default=0)
    b.add_argument("--point", action="store_true", help="compare the direct-light estimators at the one "
                   "surface point the image centre sees, instead of whole renders")
    b.add_argument("--no-chart", action="store_true", help="skip the PNG chart")
    b.add_argument("--denoise", action="store_true", help="add denoised curves: the first method + OIDN "
                   "(needs the denoise extra) and, with --cycles, Cycles + its OpenImageDenoise")
    return p


def _add_denoise_args(p, help_text):
    p.add_argument("--denoise", action="store_true", help=help_text)
    p.add_argument("--denoise-quality", **_choice("HIGH", "BALANCED", "FAST"),
                   help="denoiser quality (default high, as in Cycles)")
    p.add_argument("--denoise-prefilter", **_choice("ACCURATE", "FAST", "NONE"),
                   help="how the albedo/normal guides are cleaned first (default accurate, as in Cycles)")


# ------------------------------------------------------------------------- denoising hooks


def _check_denoise(args) -> None:
    """Before any work: the denoise options are consistent and OIDN loads (exit 2 otherwise)."""
    if not args.denoise:
        if args.denoise_quality or args.denoise_prefilter:
            raise CliError("--denoise-quality and --denoise-prefilter need --denoise")
        return
    from .denoise import DenoiserUnavailable, require_backend

    try:
        require_backend()
    except DenoiserUnavailable as e:
        raise CliError(str(e)) from None


def _denoise(args, film):
    """(denoised RGB or None, summary note, EXR metadata) for a finished film."""
    if not args.denoise:
        return None, "", {}
    from .denoise import DEFAULT_PREFILTER, DEFAULT_QUALITY, denoise_film

    img, info = denoise_film(film, quality=args.denoise_quality or DEFAULT_QUALITY,
                             prefilter=args.denoise_prefilter or DEFAULT_PREFILTER,
                             threads=getattr(args, "threads", None))
    fixed = f", {info.replaced_pixels} non-finite pixels filled" if info.replaced_pixels else ""
    note = f", denoised ({info.quality.lower()}, prefilter {info.prefilter.lower()}) in {info.seconds:.2f}s{fixed}"
    return img, note, {"denoised": f"{info.backend}; quality {info.quality}; prefilter {info.prefilter}"}


# ------------------------------------------------------------------------- progress display


class Progress:
    """A one-line progress bar on a terminal; silent otherwise."""

    def __init__(self, stream=sys.stderr, clock=time.perf_counter):
        self.stream = stream
        self.enabled = stream.isatty()
        self.clock = clock
        self.last = 0.0
        self.first = None  # (time, fraction) of the first finished batch

    def eta(self, fraction: float) -> float:
        """Seconds left, from the rate measured since the first finished batch: scene setup and
        the first batch (loading kernels) are one-off costs, so extrapolating from the whole
        elapsed time overestimated early ETAs 2-3x."""
        now = self.clock()
        if self.first is None:
            self.first = (now, fraction)
            return float("nan")
        t0, f0 = self.first
        if fraction <= f0 or now <= t0:
            return float("nan")
        return (1.0 - fraction) * (now - t0) / (fraction - f0)

    def __call__(self, fraction, stats):
        eta = self.eta(fraction)
        if not self.enabled:
            return
        now = self.clock()
        if now - self.last < 0.1 and fraction < 1:
            return
        self.last = now
        bar = "#" * int(fraction * 30)
        eta_text = f"{eta:6.1f}s" if eta == eta else "    ..."
        self.stream.write(
            f"\r[{bar:<30}] {fraction * 100:5.1f}%  ETA {eta_text}  {stats.rays_per_second / 1e6:6.2f} Mrays/s "
        )
        self.stream.flush()

    def done(self):
        if self.enabled:
            self.stream.write("\n")
            self.stream.flush()


# ------------------------------------------------------------------------- commands


def _load(args):
    from .loaders import LoaderError, is_plugin_format, load_scene
    from .scene import SceneError

    path = args.scene
    if not os.path.exists(path):
        raise CliError(f"scene file not found: {path}")
    if os.path.isdir(path):
        raise CliError(f"the scene is a directory, not a file: {path}")
    plugin = is_plugin_format(path)
    if args.frame is not None and not plugin:
        raise CliError(f"--frame applies to animated scene files (.blend); {path} holds one exported frame")
    try:
        return load_scene(path, frame=args.frame, warn=lambda w: print(f"drt: warning: {w}", file=sys.stderr))
    except LoaderError as e:
        raise CliError(str(e)) from None
    except SceneError as e:
        if plugin:
            raise CliError(f"{path} exported an invalid scene: {e}", EXIT_FAILURE) from None
        raise CliError(f"invalid scene {path}: {e}") from None


def _check_output(path: str, ext: str = ".exr"):
    d = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(d):
        raise CliError(f"output directory does not exist: {d}")
    if not path.lower().endswith(ext):
        raise CliError(f"output must end in {ext}: {path}")


class _Loading(threading.Thread):
    """``_load(args)`` on a thread: an exported scene is read and checked while the main thread
    imports the renderer (the compiler and the kernel modules, ~0.35 s). zlib inflates the arrays
    without the GIL, so on two cores a big scene's read (0.7 s for 1M triangles) mostly hides
    behind the imports. ``result()`` returns the scene or raises what ``_load`` raised."""

    def __init__(self, args):
        super().__init__(name="drt-load-scene", daemon=True)
        self.args, self.scene, self.error = args, None, None
        self.start()

    def run(self):
        try:
            self.scene = _load(self.args)
        except BaseException as e:  # noqa: BLE001 - re-raised in the main thread by result()
            self.error = e

    def result(self):
        self.join()
        if self.error is not None:
            raise self.error
        return self.scene


def cmd_render(args) -> int:
    from .scene import SceneError

    _check_output(args.output)
    if args.png:
        _check_output(args.png, ".png")
    _check_denoise(args)
    if args.adaptive_threshold is not None and not (0 <= args.adaptive_threshold <= 1):
        raise CliError(f"--adaptive-threshold must be within [0, 1], got {args.adaptive_threshold}")
    from .farm import cli as farm_cli

    if farm_cli.wants_farm_path(args):  # animations and Dask clusters (docs/farm.md)
        return farm_cli.cmd_render(args, load=_load, error_cls=CliError, progress_cls=Progress)
    # only exported scenes: .blend files load through bpy, which stays on the main thread
    loading = _Loading(args) if os.path.splitext(args.scene)[1].lower() == ".npz" else None
    from .exr import write_exr
    from .render import render

    scene = loading.result() if loading is not None else _load(args)
    spp, count = apply_render_args(args, scene)

    stop = threading.Event()
    previous = signal.getsignal(signal.SIGINT)

    def on_sigint(signum, frame):
        if stop.is_set():  # a second Ctrl-C: give up at once
            raise KeyboardInterrupt
        stop.set()

    signal.signal(signal.SIGINT, on_sigint)
    from .kernels import COMPILING_NOTICE, kernels_compiled, scene_kernel_variant

    if not kernels_compiled(scene_kernel_variant(scene)):
        print(f"drt: {COMPILING_NOTICE}", file=sys.stderr, flush=True)
    bar = Progress()
    try:
        film = render(
            scene, spp=spp, seed=args.seed, threads=args.threads, sampler=args.sampler,
            direct=args.direct, indirect=args.indirect, adaptive_threshold=args.adaptive_threshold,
            adaptive_min_samples=args.adaptive_min_samples,
            sample_offset=args.sample_offset, sample_count=count, tick=bar, cancel=stop.is_set,
        )
    except SceneError as e:
        raise CliError(f"invalid scene {args.scene}: {e}") from None
    finally:
        signal.signal(signal.SIGINT, previous)
        bar.done()
    st = film.stats
    denoised, dn_note, dn_meta = _denoise(args, film) if not st.cancelled else (None, ", not denoised", {})
    write_exr(args.output, film, dn_meta, denoised=denoised, threads=args.threads)
    if args.png:
        from .preview import write_png

        write_png(args.png, film.combined if denoised is None else denoised)
    w, h = scene.render.width, scene.render.height
    nan_note = f", {st.nan_samples} NaN/Inf samples dropped" if st.nan_samples else ""
    state = "cancelled after" if st.cancelled else "rendered"
    print(
        f"drt: {state} {w}x{h} at {spp_summary(st)} in {st.seconds:.2f}s: "
        f"{st.camera_paths / max(st.seconds, 1e-9) / 1e3:.1f} k samples/s, {st.rays_per_second / 1e6:.2f} Mrays/s, "
        f"{100 * st.embree_seconds / max(st.seconds * st.threads, 1e-9):.0f}% of thread time in Embree{nan_note}{dn_note} -> {args.output}"
    )
    return EXIT_INTERRUPTED if st.cancelled else EXIT_OK


def apply_render_args(args, scene) -> tuple[int, int]:
    """Apply ``render``'s --resolution to a loaded scene and check, before any rendering work,
    the sample range, --denoise and the film's memory: (spp, sample count to render). Shared by
    the one-process path and drt.farm (clusters, --frames); raises CliError (exit 2)."""
    from dataclasses import replace

    if args.resolution:
        scene.render = replace(scene.render, width=args.resolution[0], height=args.resolution[1])
    _check_film_memory(scene.render.width, scene.render.height)
    spp = args.spp or scene.render.spp
    if args.sample_offset >= spp:
        raise CliError(f"--sample-offset {args.sample_offset} must be below the sample count {spp}")
    count = args.sample_count if args.sample_count is not None else spp - args.sample_offset
    if args.sample_offset + count > spp:
        raise CliError(f"--sample-offset + --sample-count ({args.sample_offset + count}) exceeds --spp {spp}")
    if args.denoise and count < spp:
        # a denoiser is not linear: denoising each range and averaging is not denoising the image
        raise CliError("--denoise renders the whole image only: render the sample ranges without it, "
                       "then `drt merge ... --denoise` denoises the merged image once")
    return spp, count


def spp_summary(st) -> str:
    """The samples per pixel the film holds: ``16 spp`` when every pixel has the same count,
    else mean and range (adaptive sampling, or a pass cut short by Ctrl-C)."""
    if st.spp_min == st.spp_max:
        return f"{st.spp_max} spp"
    return f"{st.spp_mean:.1f} spp mean ({st.spp_min}-{st.spp_max} per pixel)"


def _check_film_memory(width: int, height: int) -> None:
    """Refuse, before any rendering work, a film that cannot fit in the memory available."""
    from .render import FILM_BYTES_PER_PIXEL, film_memory_bytes
    from .scene_file import _available_memory

    need, avail = film_memory_bytes(width, height), _available_memory()
    if avail is not None and need > avail:
        gb = 1024.0**3
        raise CliError(f"a {width}x{height} render needs {need / gb:.1f} GB of memory ({FILM_BYTES_PER_PIXEL} bytes "
                       f"per pixel) but {avail / gb:.1f} GB are available: use a smaller --resolution")


def cmd_merge(args) -> int:
    from .exr import film_from_exr, write_exr
    from .render import merge_films

    _check_output(args.output)
    _check_denoise(args)
    films = []
    for path in args.inputs:
        if not os.path.exists(path):
            raise CliError(f"input not found: {path}")
        try:
            films.append(film_from_exr(path))
        except Exception as e:  # any unreadable file is a user error here
            raise CliError(f"cannot read {path} as a DRT EXR: {e}") from None
    ranges = sorted((int(f.meta.get("sample_offset", 0)), int(f.meta.get("sample_count", 0)), p) for f, p in zip(films, args.inputs))
    for (o1, c1, p1), (o2, _, p2) in zip(ranges, ranges[1:]):
        if o1 + c1 > o2:
            raise CliError(f"sample ranges of {p1} and {p2} overlap: merging would count samples twice")
    try:
        merged = merge_films(films)
    except ValueError as e:
        raise CliError(str(e)) from None
    denoised, dn_note, dn_meta = _denoise(args, merged)
    write_exr(args.output, merged, dn_meta, denoised=denoised)
    print(f"drt: merged {len(films)} renders ({merged.meta['sample_count']} samples per pixel){dn_note} -> {args.output}")
    return EXIT_OK


def cmd_export(args) -> int:
    from .loaders import LoaderError, is_plugin_format, read_scene_arrays
    from .scene import SceneError, scene_from_dict
    from .scene_file import save_scene

    if not os.path.exists(args.scene):
        raise CliError(f"scene file not found: {args.scene}")
    if os.path.isdir(args.scene):
        raise CliError(f"the scene is a directory, not a file: {args.scene}")
    if not is_plugin_format(args.scene):
        raise CliError(f"export reads .blend files (with the add-on package installed), not {args.scene}")
    _check_output(args.output, ".npz")
    try:
        header, arrays, warnings = read_scene_arrays(args.scene, frame=args.frame)
        for w in warnings:
            print(f"drt: warning: {w}", file=sys.stderr)
        scene_from_dict(header, arrays)  # never write a file the loader would refuse
    except LoaderError as e:
        raise CliError(str(e)) from None
    except SceneError as e:
        raise CliError(f"{args.scene} exported an invalid scene: {e}", EXIT_FAILURE) from None
    save_scene(args.output, header, arrays)
    print(f"drt: exported {args.scene} -> {args.output}")
    return EXIT_OK


def cmd_bench(args) -> int:
    from . import bench
    from .loaders import LoaderError

    if not os.path.exists(args.scene):
        raise CliError(f"scene file not found: {args.scene}")
    if args.reference and not os.path.exists(args.reference):
        raise CliError(f"reference not found: {args.reference}")
    parent = os.path.dirname(os.path.abspath(args.output))
    if not os.path.isdir(parent):
        raise CliError(f"output directory's parent does not exist: {parent}")
    if args.denoise:
        if args.point:
            raise CliError("--denoise has no meaning with --point (no image to denoise)")
        _check_denoise(args)
    try:
        for m in args.methods or ():
            if not args.point:
                bench.parse_method(m)
        if args.point:
            bench.bench_point(args.scene, args.output, methods=args.methods,
                              spp_list=args.spp_list or (4, 16, 64, 256, 1024), chart=not args.no_chart)
        else:
            bench.bench(args.scene, args.output, reference=args.reference,
                        methods=args.methods or bench.DEFAULT_METHODS, spp_list=args.spp_list or bench.DEFAULT_SPP,
                        reference_spp=args.reference_spp, cycles=args.cycles, threads=args.threads,
                        resolution=args.resolution, seed=args.seed, chart=not args.no_chart, denoise=args.denoise)
    except ValueError as e:  # bad method names, sizes, invalid scenes (SceneError)
        raise CliError(str(e)) from None
    except RuntimeError as e:  # a failed Cycles render
        raise CliError(str(e), EXIT_FAILURE) from None
    except LoaderError as e:
        raise CliError(str(e)) from None
    return EXIT_OK


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    handlers = {"render": cmd_render, "merge": cmd_merge, "export": cmd_export, "bench": cmd_bench}
    try:
        return handlers[args.command](args)
    except CliError as e:
        print(f"drt: error: {e}", file=sys.stderr)
        return e.code
    except KeyboardInterrupt:
        print("drt: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except MemoryError:
        print("drt: error: out of memory (try a smaller --resolution or fewer --threads)", file=sys.stderr)
        return EXIT_FAILURE
    except OSError as e:
        print(f"drt: error: {e}", file=sys.stderr)
        return EXIT_FAILURE


#: modules whose own exit handlers must run: Dask closes its connections and Blender (bpy,
#: loaded for .blend input) removes its session's temporary folder
_NEEDS_TEARDOWN = ("distributed", "bpy")


#: environment variables that size the BLAS library's thread pool (OpenBLAS in pip's numpy,
#: MKL in conda's), read once when numpy is first imported
_BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def _single_threaded_blas() -> None:
    """Ask for a one-thread BLAS before numpy is imported, unless the user chose a size.

    The renderer never calls BLAS on a large array (docs/decisions.md, "No BLAS in the render
    loop"), but OpenBLAS starts a thread per core and allocates each a buffer as numpy is
    imported: ~0.1 s of system CPU time in every CLI process (``import numpy``: 0.12 → 0.02 s
    system time on this machine), spent while the render's own threads start. Only the CLI
    sets it: a library import must not change its host's BLAS (Blender, a user's script)."""
    if "numpy" in sys.modules:  # too late to matter (a script that imported numpy calls run)
        return
    for name in _BLAS_THREAD_VARIABLES:
        os.environ.setdefault(name, "1")


def run() -> None:
    """The command-line entry point (``drt``, ``python -m drt``): ``main`` and exit with its code.

    A finished command has closed its files (outputs are written to a temporary name and renamed
    into place), so what is left at exit is the interpreter's teardown — mostly the kernel
    compiler's and LLVM's objects freed one by one: ~50–70 ms of every render from a shell or a
    farm script, as much as a small frame's tracing. When no module that needs its exit handlers
    was loaded (``_NEEDS_TEARDOWN``), the process leaves at once after flushing its output."""
    _single_threaded_blas()
    code = main()
    if any(name in sys.modules for name in _NEEDS_TEARDOWN):
        sys.exit(code)
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except (OSError, ValueError):  # a closed or broken pipe: nothing more to say
        pass
    os._exit(int(code or 0))
