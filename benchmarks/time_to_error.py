"""DRT vs Cycles: time to equal error on the shipped scenes, whole processes, same run.

    python benchmarks/time_to_error.py [SCENE.npz ...] [--threads 2] [--ref-spp 1024]
                                       [--drt-spp 8,16,32,64,128,256] [--repeat 1] [--seeds 1]
                                       [--out bench_out/tte]

For each scene (default: every ``blend_scenes/*.npz`` with a ``.blend`` beside it):

1. a converged reference: Cycles at ``--ref-spp`` (another seed), not timed;
2. Cycles at 64 spp in its own process (``python -c`` with bpy, CPU, no denoising, no adaptive
   sampling, clamps off): its relMSE against the reference is the *target error*, its whole
   process wall time (bpy import, file load, BVH, render, EXR write) the Cycles time;
3. DRT as a user runs it, ``python -m drt render SCENE.npz -o OUT.exr --spp N`` for each N, whole
   process wall time (imports, kernel cache load, BVH, render, EXR write) and relMSE against the
   same reference;
4. the time DRT needs for the target error, by log-log interpolation between its runs
   (``drt.bench.time_to_reach``; "~" marks an extrapolation beyond the last run).

With ``--repeat N`` every timed process (Cycles at 64 spp, each DRT run) runs N times and the
fastest counts, both engines alike: on a shared machine one slow run (another job waking up)
otherwise decides a scene's ratio. Images do not depend on the repeat (fixed seeds).

With ``--seeds K`` every timed process runs once per seed (K seeds × N repeats, the fastest
counts) and the error of each engine at each sample count is the mean relMSE of its K images.
One image's relMSE is itself a noisy number: on sss_head (rare bright paths) single seeds at 64
spp spread ±15 % around their mean, so with one seed per engine a scene's ratio moved by as much
between runs. The reference stays one Cycles image (its noise adds to both engines alike).

Prints one row per scene and the ratio DRT time / Cycles time (≤ 1: DRT is faster), for whole
processes and for the render alone (Cycles: ``bpy.ops.render.render``; DRT: the time its CLI
reports, scene setup included, imports and EXR writing excluded). relMSE is Rousselle et al.'s
(``drt.bench.rel_mse``). Nothing is asserted: this is a measurement.
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import re
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)


#: environment of the timed processes (set by main): Python may cache bytecode, as in a user's
#: install; None: this process's own environment
ENV = None


def user_env(out: str) -> dict:
    """This environment, but with bytecode caching on (in ``out``/pycache): a pip install has
    ``.pyc`` files, while a shell with PYTHONDONTWRITEBYTECODE=1 (as on the development machine)
    would make every DRT process recompile the drt sources (~0.1-0.3 s) — bpy and numpy in
    site-packages keep their ``.pyc`` either way."""
    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    env["PYTHONPYCACHEPREFIX"] = os.path.abspath(os.path.join(out, "pycache"))
    return env


def _wall(cmd, env=None) -> tuple[float, subprocess.CompletedProcess]:
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env if env is not None else ENV)
    return time.perf_counter() - t0, proc


def cycles_run(blend: str, spp: int, seed: int, threads: int, width: int, height: int, out: str):
    """One whole Cycles process: (wall seconds, render-only seconds, image)."""
    from drt.bench import _CYCLES_SCRIPT, _read_rgba

    args = dict(blend=os.path.abspath(blend), seed=seed, threads=threads, width=width, height=height,
                jobs=[[spp, os.path.abspath(out)]], warmup=False)  # a user's process renders cold
    wall, proc = _wall([sys.executable, "-c", _CYCLES_SCRIPT, json.dumps(args)])
    line = [ln for ln in proc.stdout.splitlines() if ln.startswith("CYCLES_RESULT ")]
    if proc.returncode != 0 or not line:
        raise RuntimeError(f"Cycles failed on {blend}: {proc.stderr.strip()[-800:]}")
    render_s = json.loads(line[-1][len("CYCLES_RESULT "):])[0]["seconds"]
    return wall, render_s, _read_rgba(out)


def drt_run(scene: str, spp: int, seed, threads: int, out: str):
    """One whole DRT process (the CLI): (wall seconds, render-only seconds, image); seed None:
    the scene's own."""
    import numpy as np

    from drt.exr import read_exr

    seed_args = [] if seed is None else ["--seed", str(seed)]
    wall, proc = _wall([sys.executable, "-m", "drt", "render", scene, "-o", out, "--spp", str(spp),
                        "--threads", str(threads)] + seed_args)
    if proc.returncode != 0:
        raise RuntimeError(f"DRT failed on {scene}: {proc.stderr.strip()[-800:]}")
    ch, _ = read_exr(out)
    m = re.search(r" in ([0-9.]+)s:", proc.stdout)
    render_s = float(m.group(1)) if m else float("nan")
    return wall, render_s, np.stack([ch[c] for c in "RGBA"], axis=-1).astype(np.float64)


def _fastest(repeat: int, seeds, run, *args):
    """``run(seed, *args)`` (→ wall s, render s, image) ``repeat`` times for each of ``seeds``:
    the fastest wall and render times (each the minimum over all runs) and one image per seed
    (its last run's)."""
    walls, renders, images = [], [], []
    for seed in seeds:
        for _ in range(max(1, repeat)):
            wall, render_s, image = run(seed, *args)
            walls.append(wall)
            renders.append(render_s)
        images.append(image)
    return min(walls), min(renders), images


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scenes", nargs="*")
    ap.add_argument("--threads", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--ref-spp", type=int, default=1024)
    ap.add_argument("--cycles-spp", type=int, default=64)
    ap.add_argument("--drt-spp", default="8,16,32,64,128,256")
    ap.add_argument("--repeat", type=int, default=1, help="runs per timed process; the fastest counts")
    ap.add_argument("--seeds", type=int, default=1,
                    help="seeds per timed process: errors are the mean relMSE over them")
    ap.add_argument("--out", default=os.path.join("bench_out", "time_to_error"))
    args = ap.parse_args(argv)
    import numpy as np

    from drt.bench import rel_mse, time_to_reach
    from drt.scene_file import load_scene

    scenes = args.scenes or [p for p in sorted(glob.glob(os.path.join(REPO, "blend_scenes", "*.npz")))
                             if os.path.exists(os.path.splitext(p)[0] + ".blend")]
    os.makedirs(args.out, exist_ok=True)
    global ENV
    ENV = user_env(args.out)
    # untimed: writes the bytecode of drt, numba, bpy... into the prefix (a user's install has it)
    _wall([sys.executable, "-c", "import bpy, drt.cli, drt.render, drt.exr, drt.loaders, drt.farm.cli"])
    spp_list = [int(s) for s in args.drt_spp.split(",")]
    rows = []
    print(f"threads {args.threads}; target = Cycles's relMSE at {args.cycles_spp} spp; reference = Cycles at "
          f"{args.ref_spp} spp; times are whole processes (wall clock)", flush=True)
    print(f"{'scene':16s} {'size':>9s} {'target':>9s} {'Cycles s':>9s} {'(render)':>9s} {'DRT s':>9s} {'(render)':>9s} "
          f"{'DRT/Cycles':>11s} {'(render)':>11s}  DRT runs (spp: whole-process s, relMSE)")
    for scene_path in scenes:
        name = os.path.splitext(os.path.basename(scene_path))[0]
        blend = os.path.splitext(scene_path)[0] + ".blend"
        r = load_scene(scene_path).render
        w, h = r.width, r.height
        base = os.path.join(args.out, name)
        _, _, ref = cycles_run(blend, args.ref_spp, 7, args.threads, w, h, base + "_ref.exr")
        c_wall, c_render, c_imgs = _fastest(
            args.repeat, range(args.seeds),
            lambda seed, *a: cycles_run(blend, args.cycles_spp, seed, *a, base + f"_cycles_s{seed}.exr"),
            args.threads, w, h)
        target = float(np.mean([rel_mse(c[..., :3], ref[..., :3]) for c in c_imgs]))
        secs, render_secs, errs, runs = [], [], [], []
        for spp in spp_list:
            d_wall, d_render, d_imgs = _fastest(
                args.repeat, [None] + [1000 + k for k in range(1, args.seeds)],
                lambda seed, *a: drt_run(scene_path, spp, seed, *a, base + f"_drt_{spp}_s{seed}.exr"), args.threads)
            e = float(np.mean([rel_mse(np.asarray(d, dtype=np.float64)[..., :3], ref[..., :3]) for d in d_imgs]))
            secs.append(d_wall)
            render_secs.append(d_render)
            errs.append(e)
            runs.append(f"{spp}: {d_wall:.2f}, {e:.2e}")
            if e < 0.5 * target:
                break
        t, extrapolated = time_to_reach(secs, errs, target)
        ratio = t / c_wall if t is not None else float("nan")
        t_r, _ = time_to_reach(render_secs, errs, target)
        render_ratio = t_r / c_render if t_r is not None else float("nan")
        mark = "~" if extrapolated else " "
        rows.append(dict(scene=name, width=w, height=h, target=target, cycles_wall=c_wall, cycles_render=c_render,
                         drt_seconds=t, extrapolated=extrapolated, ratio=ratio,
                         drt_render_seconds=t_r, render_ratio=render_ratio,
                         drt_runs=[dict(spp=s, seconds=a, relmse=b) for s, a, b in zip(spp_list, secs, errs)]))
        print(f"{name:16s} {w:4d}x{h:<4d} {target:9.2e} {c_wall:9.2f} {c_render:9.2f} {mark}{(t or float('nan')):8.2f} "
              f"{(t_r or float('nan')):9.2f} {ratio:11.2f} {render_ratio:11.2f}  " + "; ".join(runs), flush=True)
    with open(os.path.join(args.out, "time_to_error.json"), "w") as f:
        json.dump(dict(threads=args.threads, ref_spp=args.ref_spp, cycles_spp=args.cycles_spp, seeds=args.seeds,
                       repeat=args.repeat, rows=rows), f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
