"""``python -m drt bench``: error against time for each estimator and sample generator, and
for Cycles at matched settings.

For a scene (.npz export, or .blend through bpy) the bench

1. takes a reference image (``--reference REF.exr``) or renders one with the default method at
   ``reference_spp``;
2. renders with each method at increasing sample counts, timing the render (scene setup —
   BVH, tables — is excluded and reported separately);
3. optionally renders with Cycles through bpy in a subprocess (CPU, same threads and
   resolution, no denoising, adaptive sampling off, clamps 0, blur_glossy 0), against Cycles's
   own high-sample reference (each renderer is measured against its own converged image; the
   relMSE between the two references is reported as their agreement);
4. with ``denoise``: adds denoised curves, ``<method>+oidn`` for the first DRT method (the same
   renders, then ``drt.denoise`` with Cycles's defaults: prefilter ACCURATE, quality HIGH; its
   time is render + denoise) and ``cycles+oidn`` (Cycles's own OpenImageDenoise with albedo and
   normal, prefilter ACCURATE, quality HIGH; its time includes the denoise); each against its
   renderer's converged reference. The summary then also has the time each curve needs to reach
   the relMSE Cycles+OIDN reaches at 16 spp (or the nearest measured count);
5. writes ``bench.csv`` and ``bench.json`` of (method, spp, seconds, RMSE, relMSE), a log-log
   chart ``bench.png`` of relMSE against seconds (matplotlib, imported only here), and the time
   each method needs to reach relMSE 0.01 (log-log interpolation between measured points; a
   value beyond the last point is extrapolated along the last segment's slope and flagged).

relMSE = mean over pixels and RGB of (x − ref)² / (ref² + 0.01) (Rousselle et al.'s relative
MSE; the 0.01 keeps black pixels from dominating). RMSE is over pixels and RGB.

Methods are presets (``METHODS``) or ``DIRECT/INDIRECT/SAMPLER`` triples, e.g.
``LIGHT/BSDF/RANDOM``; ``adaptive`` is the default method with adaptive sampling (its "spp" is
the cap; the mean samples a pixel took is recorded). ``point`` mode (``bench_point``) runs the
lecture's direct-light estimators (`drt.estimators`) at the shading point the image centre
sees, against a high-sample reference.
"""

from __future__ import annotations

import inspect
import json
import math
import os
import subprocess
import sys
import time
from dataclasses import asdict, dataclass, replace

import numpy as np

TARGET_RELMSE = 0.01
DEFAULT_METHODS = ("mis_power", "mis_balance", "light", "bsdf", "cosine", "random", "stratified", "adaptive")
DEFAULT_SPP = (1, 4, 16, 64)

#: presets: name -> (direct, indirect, sampler, adaptive threshold)
METHODS = {
    "mis_power": ("MIS_POWER", "BSDF", "SOBOL", 0.0),
    "mis_balance": ("MIS_BALANCE", "BSDF", "SOBOL", 0.0),
    "light": ("LIGHT", "BSDF", "SOBOL", 0.0),
    "bsdf": ("BSDF", "BSDF", "SOBOL", 0.0),
    "cosine": ("BSDF", "COSINE", "SOBOL", 0.0),      # lecture: cosine-weighted hemisphere, no NEE
    "uniform": ("BSDF", "UNIFORM", "SOBOL", 0.0),    # lecture: uniform hemisphere, no NEE
    "random": ("MIS_POWER", "BSDF", "RANDOM", 0.0),
    "stratified": ("MIS_POWER", "BSDF", "STRATIFIED", 0.0),
    "sobol": ("MIS_POWER", "BSDF", "SOBOL", 0.0),
    "adaptive": ("MIS_POWER", "BSDF", "SOBOL", 0.01),
}


def parse_method(name: str) -> tuple[str, str, str, float]:
    """A preset name or ``DIRECT/INDIRECT/SAMPLER[/THRESHOLD]`` → (direct, indirect, sampler,
    adaptive threshold). Raises ValueError naming what is wrong."""
    from .sampling.sequences import SAMPLER_KINDS
    from .scene import DIRECT_STRATEGIES, INDIRECT_STRATEGIES

    if name.lower() in METHODS:
        return METHODS[name.lower()]
    parts = name.upper().split("/")
    if len(parts) not in (3, 4):
        raise ValueError(f"unknown method {name!r}: use a preset ({', '.join(METHODS)}) or DIRECT/INDIRECT/SAMPLER")
    d, i, s = parts[:3]
    for value, allowed, what in ((d, DIRECT_STRATEGIES, "direct"), (i, INDIRECT_STRATEGIES, "indirect"), (s, SAMPLER_KINDS, "sampler")):
        if value not in allowed:
            raise ValueError(f"method {name!r}: {what} must be one of {', '.join(allowed)}, got {value}")
    return d, i, s, float(parts[3]) if len(parts) == 4 else 0.0


# ------------------------------------------------------------------------------ error metrics


def rmse(x: np.ndarray, ref: np.ndarray) -> float:
    """Root mean square error over pixels and RGB. x, ref: (H, W, ≥3)."""
    d = x[..., :3].astype(np.float64) - ref[..., :3]
    return float(np.sqrt(np.mean(d * d)))


def rel_mse(x: np.ndarray, ref: np.ndarray, eps: float = 0.01) -> float:
    """mean((x − ref)² / (ref² + eps)) over pixels and RGB."""
    r = ref[..., :3].astype(np.float64)
    d = x[..., :3].astype(np.float64) - r
    return float(np.mean(d * d / (r * r + eps)))


def time_to_reach(seconds, errors, target: float = TARGET_RELMSE) -> tuple[float | None, bool]:
    """Seconds at which the error curve reaches ``target``, interpolating log-log between the
    measured points (sorted by time). Returns (seconds, extrapolated): beyond the last point the
    last segment's slope is extended (extrapolated = True); None if the curve never falls."""
    pts = sorted((float(t), float(e)) for t, e in zip(seconds, errors) if t > 0 and e > 0)
    if not pts:
        return None, False
    if pts[0][1] <= target:
        return pts[0][0], False
    for (t0, e0), (t1, e1) in zip(pts, pts[1:]):
        if e1 <= target < e0:
            f = (math.log(target) - math.log(e0)) / (math.log(e1) - math.log(e0))
            return math.exp(math.log(t0) + f * (math.log(t1) - math.log(t0))), False
    if len(pts) >= 2:
        (t0, e0), (t1, e1) = pts[-2], pts[-1]
        if e1 < e0 and t1 > t0:
            slope = (math.log(e1) - math.log(e0)) / (math.log(t1) - math.log(t0))
            return math.exp(math.log(t1) + (math.log(target) - math.log(e1)) / slope), True
    return None, False


@dataclass
class BenchRow:
    method: str
    spp: int
    seconds: float
    rmse: float
    relmse: float
    mean_spp: float
    renderer: str = "drt"


# ------------------------------------------------------------------------------ DRT side


def load_scene(path: str, frame: int | None = None):
    """A Scene from a .npz or (through bpy) a .blend."""
    from .loaders import load_scene as _load

    return _load(path, frame=frame, warn=lambda w: print(f"drt: warning: {w}", file=sys.stderr))


def _render(scene, ctx, spp, threads, seed, threshold, min_samples=None):
    from .render import render

    kw = dict(spp=spp, seed=seed, threads=threads, context=ctx, adaptive_threshold=threshold,
              adaptive_min_samples=min_samples)
    if "parallel" in inspect.signature(render).parameters:
        kw["parallel"] = "threads"  # one context, no worker start-up in the timings
    return render(scene, **kw)


def render_reference(scene, spp: int, threads: int, seed: int = 1234, log=print) -> np.ndarray:
    """(H, W, 4) image with the default method at ``spp`` (a different seed from the runs)."""
    from .render import prepare

    ctx = prepare(scene, seed=seed, sampler="SOBOL", direct="MIS_POWER", indirect="BSDF")
    film = _render(scene, ctx, spp, threads, seed, 0.0)
    log(f"bench: DRT reference {spp} spp in {film.stats.seconds:.1f} s")
    return film.combined.astype(np.float64)


DENOISED_SUFFIX = "+oidn"


def run_drt(scene, ref, methods, spp_list, threads, seed=0, log=print, denoise=()) -> list[BenchRow]:
    """Rows for each method and spp; for methods in ``denoise`` also a ``<method>+oidn`` row
    per render (seconds = render + OIDN, error of the denoised image)."""
    from .render import prepare

    if denoise:
        from .denoise import denoise_film

        warm = prepare(scene, seed=seed)  # OIDN's first filter also loads its weights: not timed
        denoise_film(_render(scene, warm, 1, threads, seed, 0.0), threads=threads)
    rows = []
    for name in methods:
        direct, indirect, sampler, threshold = parse_method(name)
        ctx = prepare(scene, seed=seed, sampler=sampler, direct=direct, indirect=indirect)
        for spp in spp_list:
            min_samples = max(4, spp // 8) if threshold > 0 else None
            film = _render(scene, ctx, spp, threads, seed, threshold, min_samples)
            img = film.combined
            row = BenchRow(name, int(spp), film.stats.seconds, rmse(img, ref), rel_mse(img, ref),
                           float(film.sample_count.mean()))
            rows.append(row)
            log(f"bench: {name:>12} {spp:5d} spp  {row.seconds:8.2f} s  RMSE {row.rmse:.4g}  relMSE {row.relmse:.4g}"
                + (f"  (mean {row.mean_spp:.1f} spp)" if threshold > 0 else ""))
            if name in denoise:
                den, info = denoise_film(film, threads=threads)
                d = BenchRow(name + DENOISED_SUFFIX, int(spp), film.stats.seconds + info.seconds, rmse(den, ref),
                             rel_mse(den, ref), row.mean_spp)
                rows.append(d)
                log(f"bench: {d.method:>12} {spp:5d} spp  {d.seconds:8.2f} s  RMSE {d.rmse:.4g}  relMSE {d.relmse:.4g}"
                    f"  (OIDN {info.seconds:.2f} s)")
    return rows


# ------------------------------------------------------------------------------ Cycles side

_CYCLES_SCRIPT = r"""
import json, sys, time
import bpy
args = json.loads(sys.argv[1])
bpy.ops.wm.open_mainfile(filepath=args["blend"])
sc = bpy.context.scene
sc.render.engine = "CYCLES"
cy = sc.cycles
cy.device = "CPU"
cy.use_adaptive_sampling = False
cy.use_denoising = False
cy.sample_clamp_direct = 0.0
cy.sample_clamp_indirect = 0.0
cy.blur_glossy = 0.0
cy.seed = args["seed"]
cy.denoiser = "OPENIMAGEDENOISE"
cy.denoising_prefilter = "ACCURATE"
cy.denoising_quality = "HIGH"
cy.denoising_input_passes = "RGB_ALBEDO_NORMAL"
cy.denoising_use_gpu = False
for vl in sc.view_layers:
    if hasattr(vl, "cycles") and hasattr(vl.cycles, "use_denoising"):
        vl.cycles.use_denoising = True  # the scene setting below decides
sc.render.threads_mode = "FIXED"
sc.render.threads = args["threads"]
sc.render.resolution_x, sc.render.resolution_y = args["width"], args["height"]
sc.render.resolution_percentage = 100
sc.render.use_border = False
im = sc.render.image_settings
im.file_format = "OPEN_EXR"
im.color_depth = "32"
im.color_mode = "RGBA"
# warm-up: the first render of a process also initialises Cycles's device and kernels, which
# would make the first timed job look slower than a later, larger one
if args.get("warmup", True):
    cy.samples = 1
    cy.use_denoising = any(len(j) > 2 and j[2] for j in args["jobs"])  # OIDN's first run loads weights
    bpy.ops.render.render(write_still=False)
out = []
for job in args["jobs"]:
    spp, path = job[:2]
    cy.use_denoising = len(job) > 2 and bool(job[2])
    cy.samples = spp
    sc.render.filepath = path
    t0 = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    out.append({"spp": spp, "path": path, "seconds": time.perf_counter() - t0, "denoised": cy.use_denoising})
print("CYCLES_RESULT " + json.dumps(out))
"""


def _read_rgba(path: str) -> np.ndarray:
    import OpenEXR

    with OpenEXR.File(path, separate_channels=True) as f:
        ch = {k: np.array(v.pixels, dtype=np.float64) for k, v in f.channels().items()}
    names = {k.split(".")[-1]: k for k in ch}
    h, w = ch[names["R"]].shape
    return np.stack([ch[names[c]] if c in names else np.ones((h, w)) for c in "RGBA"], axis=-1)


def run_cycles(blend: str, spp_list, ref_spp: int, width: int, height: int, threads: int, outdir: str,
               seed: int = 0, log=print, denoise: bool = False) -> tuple[list[dict], np.ndarray]:
    """Render ``blend`` with Cycles at each spp (and, with ``denoise``, again with its
    OpenImageDenoise) and at ``ref_spp`` (the reference, another seed, never denoised) in one
    subprocess. Returns ([{spp, seconds, denoised, image}], reference image)."""
    jobs = [[int(s), os.path.abspath(os.path.join(outdir, f"cycles_{s:05d}.exr")), False] for s in spp_list]
    if denoise:
        jobs += [[int(s), os.path.abspath(os.path.join(outdir, f"cycles_oidn_{s:05d}.exr")), True] for s in spp_list]
    ref_path = os.path.abspath(os.path.join(outdir, f"cycles_reference_{ref_spp}.exr"))
    results = []
    for job_seed, job_list in ((seed + 7, [[ref_spp, ref_path]]), (seed, jobs)):
        args = dict(blend=os.path.abspath(blend), seed=job_seed, threads=threads, width=width, height=height, jobs=job_list)
        proc = subprocess.run([sys.executable, "-c", _CYCLES_SCRIPT, json.dumps(args)], capture_output=True, text=True)
        line = [ln for ln in proc.stdout.splitlines() if ln.startswith("CYCLES_RESULT ")]
        if proc.returncode != 0 or not line:
            raise RuntimeError(f"Cycles render failed: {proc.stderr.strip()[-500:]}")
        results.append(json.loads(line[-1][len("CYCLES_RESULT "):]))
    ref_info = results[0][0]
    log(f"bench: Cycles reference {ref_spp} spp in {ref_info['seconds']:.1f} s")
    ref = _read_rgba(ref_info["path"])
    runs = [dict(r, image=_read_rgba(r["path"])) for r in results[1]]
    return runs, ref


# ------------------------------------------------------------------------------ the whole bench


def _blend_for(scene_path: str) -> str | None:
    if scene_path.lower().endswith(".blend"):
        return scene_path
    stem = os.path.splitext(scene_path)[0]
    return stem + ".blend" if os.path.exists(stem + ".blend") else None


def bench(scene_path: str, outdir: str, *, reference: str | None = None, methods=DEFAULT_METHODS,
          spp_list=DEFAULT_SPP, reference_spp: int = 1024, cycles: bool = False, threads: int | None = None,
          resolution: tuple[int, int] | None = None, seed: int = 0, chart: bool = True, log=print,
          denoise: bool = False) -> dict:
    """Run the bench; write bench.csv, bench.json (and bench.png) into ``outdir``; return the
    summary dict (also in bench.json)."""
    from .exr import read_exr

    os.makedirs(outdir, exist_ok=True)
    threads = int(threads or os.cpu_count() or 1)
    scene = load_scene(scene_path)
    if resolution:
        scene.render = replace(scene.render, width=resolution[0], height=resolution[1], border=None)
    w, h = scene.render.width, scene.render.height
    spp_list = sorted({int(s) for s in spp_list})
    methods = list(methods)
    for m in methods:
        parse_method(m)

    if reference:
        ch, _ = read_exr(reference)
        ref = np.stack([ch[c] for c in "RGB"] + [ch.get("A", np.ones_like(ch["R"]))], axis=-1).astype(np.float64)
        if ref.shape[:2] != (h, w):
            raise ValueError(f"reference {reference} is {ref.shape[1]}x{ref.shape[0]}, the render {w}x{h}")
        ref_note = reference
    else:
        ref = render_reference(scene, reference_spp, threads, log=log)
        ref_note = f"DRT mis_power/SOBOL at {reference_spp} spp"

    rows = run_drt(scene, ref, methods, spp_list, threads, seed=seed, log=log,
                   denoise=(methods[0],) if denoise else ())

    cycles_note = "not requested"
    agreement = None
    if cycles:
        blend = _blend_for(scene_path)
        if blend is None:
            cycles_note = "skipped: an .npz scene with no .blend beside it (nothing is built for Cycles)"
            log(f"bench: Cycles {cycles_note}")
        else:
            runs, cref = run_cycles(blend, spp_list, reference_spp, w, h, threads, outdir, seed=seed, log=log,
                                    denoise=denoise)
            for r in runs:
                name = "cycles" + (DENOISED_SUFFIX if r.get("denoised") else "")
                row = BenchRow(name, r["spp"], r["seconds"], rmse(r["image"], cref), rel_mse(r["image"], cref),
                               float(r["spp"]), renderer="cycles")
                rows.append(row)
                log(f"bench: {name:>12} {row.spp:5d} spp  {row.seconds:8.2f} s  RMSE {row.rmse:.4g}  relMSE {row.relmse:.4g}")
            agreement = rel_mse(ref, cref)
            cycles_note = (f"{blend}, CPU, {threads} threads, adaptive off, clamps 0, blur_glossy 0"
                           + (", without and with OpenImageDenoise (albedo+normal, ACCURATE, HIGH); " if denoise else
                              ", no denoising; ") +
                           f"measured against its own {reference_spp}-spp reference (times include Cycles's scene sync)")

    summary = summarize(rows)
    summary.update(scene=scene_path, resolution=[w, h], threads=threads, reference=ref_note, cycles=cycles_note,
                   reference_agreement_relmse=agreement, spp_list=spp_list)
    write_outputs(rows, summary, outdir, chart=chart, title=os.path.basename(scene_path))
    for m, t in summary["time_to_relmse_0.01"].items():
        sec, extra = t["seconds"], t["extrapolated"]
        log(f"bench: time to relMSE {TARGET_RELMSE}: {m:>12} " + ("never" if sec is None else f"{sec:.2f} s" + (" (extrapolated)" if extra else "")))
    for m, t in summary.get("time_to_cycles_oidn_16spp", {}).get("seconds", {}).items():
        log(f"bench: time to Cycles+OIDN's {summary['time_to_cycles_oidn_16spp']['spp']}-spp relMSE "
            f"{summary['time_to_cycles_oidn_16spp']['relmse']:.3g}: {m:>12} "
            + ("never" if t["seconds"] is None else f"{t['seconds']:.2f} s" + (" (extrapolated)" if t["extrapolated"] else "")))
    if summary.get("drt_over_cycles") is not None:
        log(f"bench: DRT ({summary['drt_method_for_ratio']}) / Cycles time to relMSE {TARGET_RELMSE}: {summary['drt_over_cycles']:.2f}")
    return summary


def summarize(rows: list[BenchRow]) -> dict:
    by = {}
    for r in rows:
        by.setdefault(r.method, []).append(r)
    reach = {}
    for m, rs in by.items():
        sec, extra = time_to_reach([r.seconds for r in rs], [r.relmse for r in rs])
        reach[m] = {"seconds": sec, "extrapolated": extra}
    out = {"rows": [asdict(r) for r in rows], "time_to_relmse_0.01": reach}
    oidn16 = [r for r in by.get("cycles" + DENOISED_SUFFIX, [])]
    if oidn16:
        # the bar: Cycles + its denoiser at 16 spp (the nearest measured count if 16 was not run)
        anchor = min(oidn16, key=lambda r: (abs(math.log(r.spp / 16)), r.spp))
        out["time_to_cycles_oidn_16spp"] = {"spp": anchor.spp, "relmse": anchor.relmse, "seconds": {
            m: dict(zip(("seconds", "extrapolated"), time_to_reach([r.seconds for r in rs], [r.relmse for r in rs],
                                                                   anchor.relmse)))
            for m, rs in by.items()}}
    drt = {m: v["seconds"] for m, v in reach.items()
           if m != "cycles" and not m.endswith(DENOISED_SUFFIX) and v["seconds"] is not None}
    cyc = reach.get("cycles", {}).get("seconds")
    if drt and cyc:
        pick = "mis_power" if "mis_power" in drt else min(drt, key=drt.get)
        out["drt_method_for_ratio"] = pick
        out["drt_over_cycles"] = drt[pick] / cyc
        best = min(drt, key=drt.get)
        out["best_drt_method"] = best
        out["best_drt_over_cycles"] = drt[best] / cyc
    return out


def write_outputs(rows, summary, outdir, chart=True, title=""):
    import csv

    with open(os.path.join(outdir, "bench.csv"), "w", newline="") as f:
        wr = csv.writer(f)
        wr.writerow(["renderer", "method", "spp", "mean_spp", "seconds", "rmse", "relmse"])
        for r in rows:
            wr.writerow([r.renderer, r.method, r.spp, f"{r.mean_spp:.3f}", f"{r.seconds:.4f}", f"{r.rmse:.6g}", f"{r.relmse:.6g}"])
    with open(os.path.join(outdir, "bench.json"), "w") as f:
        json.dump(summary, f, indent=1)
    if chart:
        plot(rows, os.path.join(outdir, "bench.png"), title)


def plot(rows, path, title=""):
    """Log-log relMSE against seconds, one line per method (matplotlib, the bench extra)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("bench: matplotlib is not installed, so no chart (pip install matplotlib; in a DRT checkout: "
              "pip install -e '.[bench]')", file=sys.stderr)
        return
    fig, ax = plt.subplots(figsize=(6.4, 4.4), dpi=90)
    by = {}
    for r in rows:
        by.setdefault(r.method, []).append(r)
    for m, rs in by.items():
        rs = sorted(rs, key=lambda r: r.seconds)
        style = dict(color="black", linestyle="--", linewidth=2) if m == "cycles" else {}
        if m.endswith(DENOISED_SUFFIX):  # denoised curves: dash-dot, Cycles's in black
            style = dict(linestyle="-.", linewidth=2, **({"color": "black"} if m.startswith("cycles") else {}))
        ax.loglog([r.seconds for r in rs], [r.relmse for r in rs], marker="o", markersize=3, label=m, **style)
    ax.axhline(TARGET_RELMSE, color="grey", linewidth=0.8, linestyle=":")
    ax.set_xlabel("render time (s)")
    ax.set_ylabel("relMSE")
    ax.set_title(f"error vs time: {title}")
    ax.grid(True, which="both", linewidth=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


# ------------------------------------------------------------------------------ point mode


def bench_point(scene_path: str, outdir: str, *, methods=None, spp_list=(4, 16, 64, 256, 1024),
                pixel: tuple[int, int] | None = None, trials: int = 64, reference_spp: int = 65536,
                chart: bool = True, log=print) -> dict:
    """The lecture's direct-light estimators at the surface point one pixel sees (default the
    image centre): RMSE over ``trials`` independent estimates against a LIGHT-sampling
    reference, per method and sample count, with time per estimate. Writes point.csv,
    point.json and point.png."""
    from .estimators import METHODS as EST_METHODS, RAYS_PER_SAMPLE, DirectLight, ShadingPoints
    from .render import prepare

    scene = load_scene(scene_path)
    ctx = prepare(scene)
    integ = ctx.integrator
    w, h = scene.render.width, scene.render.height
    px, py = pixel or (w // 2, h // 2)
    rays = integ.camera.generate(np.array([px + 0.5]), np.array([h - py - 0.5]), np.full((1, 2), 0.5), np.zeros(1))
    hits = ctx.tracer.intersect(rays.o, rays.d, np.zeros(1), rays.tmax)
    if not hits.hit[0]:
        raise ValueError(f"pixel {px},{py} sees no surface")
    ng = hits.ng[0]
    wo = -rays.d[0]
    n = ng if ng @ wo >= 0 else -ng
    mat = int(integ.geom.material[hits.prim[0]])
    from .trace import offset_origin

    p = offset_origin(hits.p[:1], n[None], n[None])[0]

    def occluded(o, d, tmax):
        return ctx.tracer.occluded(o, d, tmax, np.zeros(len(o)))

    dl = DirectLight(integ.lights, integ.materials, occluded)
    methods = list(methods or EST_METHODS)
    ref_pts = ShadingPoints(np.tile(p, (16, 1)), n, wo, mat)
    ref = float(dl.estimate_direct("MIS_POWER", ref_pts, reference_spp // 16, seed=99).mean(axis=0) @ [0.2126, 0.7152, 0.0722])
    pts = ShadingPoints(np.tile(p, (trials, 1)), n, wo, mat)
    rows = []
    for m in methods:
        for spp in spp_list:
            t0 = time.perf_counter()
            est = dl.estimate_direct(m, pts, spp) @ np.array([0.2126, 0.7152, 0.0722])
            sec = (time.perf_counter() - t0) / trials
            err = float(np.sqrt(np.mean((est - ref) ** 2)))
            rows.append(BenchRow(m, int(spp), sec, err, err * err / (ref * ref + 0.01), float(spp * RAYS_PER_SAMPLE[m])))
            log(f"bench point: {m:>12} {spp:5d} samples  RMSE {err:.4g}")
    summary = summarize(rows)
    summary.update(scene=scene_path, pixel=[px, py], reference=ref, point=p.tolist(), normal=n.tolist(), material=mat)
    os.makedirs(outdir, exist_ok=True)
    write_outputs(rows, summary, outdir, chart=False)
    for name in ("bench.csv", "bench.json"):
        os.replace(os.path.join(outdir, name), os.path.join(outdir, name.replace("bench", "point")))
    if chart:
        plot(rows, os.path.join(outdir, "point.png"), f"direct light at pixel {px},{py} of {os.path.basename(scene_path)}")
    return summary
