"""Throughput of the compiled renderer: rays/s against Embree's raw rate on the same rays, and
thread scaling in one process (the CLI's core, and inside Blender through the add-on).

    python benchmarks/kernel_throughput.py [SCENE.npz] [--resolution 256x256] [--spp 16]
                                           [--repeat 5] [--no-blender]

1. Renders the scene warm (kernels loaded) on 1 and 2 threads, alternated; prints samples/s,
   rays/s and the 2-thread speed-up (best of --repeat runs each: on a shared virtual machine
   single runs of the same render vary by ±15 %, and best of two put the same code's speed-up
   anywhere in 1.65–1.95×).
2. Records every ray batch the 1-thread render gave Embree (closest-hit and occlusion), replays
   exactly those batches through embreex alone on one thread, and prints Embree's raw rays/s and
   the renderer's rays/s (its best unrecorded 1-thread run) as a fraction of it, both in process
   CPU time (the rest of the time is DRT's own work).
3. Where the 1-thread time goes (best of three renders, process CPU time, each stage wrapped in
   a timer): the camera stage, `shade` (all per-hit work), Embree itself, DRT's glue around
   Embree (float32 rays, hit arrays, surface data), the subsurface walks if the scene has any
   (their own Embree calls included), and the rest (render loop, film).
4. Unless --no-blender: in a bpy subprocess with the add-on registered, F12-renders the .blend
   beside the scene with Performance > Threads fixed at 1 and at 2 (after a warm-up render) and
   prints the speed-up inside Blender; then renders it with Cycles on one thread at the same
   samples (no adaptive sampling, denoising or clamping) and prints its time beside DRT's, and
   DRT's ray count at Cycles's pace as a share of Embree's rate (Cycles does not report its own
   ray count; both engines trace about one ray and one shadow ray per vertex with the scene's
   bounce limits, but their roulette differs: a figure for scale, not a measurement of Cycles),
   and Cycles's own F12 speed-up from 1 to 2 threads (the yardstick for DRT's: both include
   Blender's fixed work per F12).
Nothing is asserted: it prints figures.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import time
from dataclasses import replace

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)

BLENDER_SCRIPT = r"""
import sys, time, bpy
sys.path.insert(0, sys.argv[1])
import addon
addon.register()
bpy.ops.wm.open_mainfile(filepath=sys.argv[2])
sc = bpy.context.scene
sc.render.engine = "DRT"
sc.render.resolution_x, sc.render.resolution_y = int(sys.argv[3]), int(sys.argv[4])
sc.render.resolution_percentage = 100
sc.drt.samples = int(sys.argv[5])
sc.render.threads_mode = "FIXED"
best = {}
bpy.ops.render.render()  # warm-up: kernels loaded, first-use allocations made
for threads in (1, 2) * int(sys.argv[6]):
    sc.render.threads = threads
    t0 = time.perf_counter()
    bpy.ops.render.render()
    best[threads] = min(best.get(threads, 1e9), time.perf_counter() - t0)
print("BLENDER_THREADS", best[1], best[2], flush=True)
# Cycles on the same file, samples and thread count, as the benchmarks set it up (no adaptive
# sampling, no denoising, no clamping): its pace on this scene, for scale
sc.render.engine = "CYCLES"
cy = sc.cycles
cy.device, cy.samples = "CPU", int(sys.argv[5])
cy.use_adaptive_sampling = cy.use_denoising = False
cy.sample_clamp_direct = cy.sample_clamp_indirect = cy.blur_glossy = 0.0
sc.render.threads = 1
bpy.ops.render.render()  # warm-up: Cycles's device and kernels
cycles = {}
for threads in (1, 2) * int(sys.argv[6]):
    sc.render.threads = threads
    t0 = time.perf_counter()
    bpy.ops.render.render()
    cycles[threads] = min(cycles.get(threads, 1e9), time.perf_counter() - t0)
print("BLENDER_CYCLES", cycles[1], cycles[2], flush=True)
"""


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene", nargs="?", default=os.path.join(REPO, "blend_scenes", "cornell_box.npz"))
    ap.add_argument("--resolution", default="256x256")
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--repeat", type=int, default=5, help="timed runs per thread count (best counts)")
    ap.add_argument("--no-blender", action="store_true")
    args = ap.parse_args(argv)
    import numpy as np

    from drt.render import prepare, render
    from drt.scene_file import load_scene

    w, h = (int(v) for v in args.resolution.split("x"))
    scene = load_scene(args.scene)
    scene = replace(scene, render=replace(scene.render, width=w, height=h))
    ctx = prepare(scene)
    render(scene, spp=1, threads=2, context=ctx)  # load (or compile) the kernels

    best, rays, cpu1, faults = {}, 0, 1e9, {}
    for threads in (1, 2) * max(args.repeat, 1):
        f0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
        t0, c0 = time.perf_counter(), time.process_time()
        film = render(scene, spp=args.spp, threads=threads, context=ctx)
        dt = time.perf_counter() - t0
        if threads == 1:
            cpu1 = min(cpu1, time.process_time() - c0)
        best[threads] = min(best.get(threads, 1e9), dt)
        # page faults of a render with the context warm: memory the render frees and writes
        # again (docs/kernels.md, "The render loop stops re-faulting its memory")
        faults[threads] = min(faults.get(threads, 1 << 62), resource.getrusage(resource.RUSAGE_SELF).ru_minflt - f0)
        rays = film.stats.rays
    paths = w * h * args.spp
    print(f"scene {os.path.basename(args.scene)} {w}x{h} at {args.spp} spp: {paths} camera paths, {rays} rays")
    for t in (1, 2):
        print(f"  {t} thread{'s' if t > 1 else ' '}: {best[t]:.3f} s, {paths / best[t] / 1e3:7.0f} k samples/s, "
              f"{rays / best[t] / 1e6:6.2f} Mrays/s")
    print(f"  thread scaling (2 vs 1): {best[1] / best[2]:.2f}x")
    print(f"  minor page faults a render (fewest): 1 thread {faults[1]}, 2 threads {faults[2]}")

    # record the batches Embree sees in a 1-thread render, then replay them through Embree alone
    tracer = ctx.tracer
    recorded = []
    original = tracer._run

    def recording(emb_scene, o, d, tfar, occluded=False, scratch=False):
        recorded.append((emb_scene, np.array(o, dtype=np.float32), np.array(d, dtype=np.float32),
                         np.array(tfar, dtype=np.float32), occluded))
        return original(emb_scene, o, d, tfar, occluded, scratch)

    # a scene of moving objects queries one Embree scene of instances from kernels instead
    # (drt.trace._Instances): its rays are recorded too, replayed by a plain rtcIntersect1 /
    # rtcOccluded1 loop
    import drt.trace as trace_mod
    from drt import embree_direct

    instanced = []
    kernels = trace_mod._instanced_hits, trace_mod._instanced_blocked

    def recording_hits(fn, handle, words, offsets, objects, motions, o, d, tau, tmax, *rest):
        instanced.append((fn, handle, o.copy(), d.copy(), tau.copy(),
                          tmax.copy() if len(tmax) else np.full(len(o), np.inf)))
        return kernels[0](fn, handle, words, offsets, objects, motions, o, d, tau, tmax, *rest)

    def recording_blocked(fn, handle, words, o, d, tau, tmax, blocked):
        instanced.append((fn, handle, o.copy(), d.copy(), tau.copy(), tmax.copy()))
        return kernels[1](fn, handle, words, o, d, tau, tmax, blocked)

    tracer._run = recording
    trace_mod._instanced_hits, trace_mod._instanced_blocked = recording_hits, recording_blocked
    try:
        render(scene, spp=args.spp, threads=1, context=ctx)
    finally:
        tracer._run = original
        trace_mod._instanced_hits, trace_mod._instanced_blocked = kernels
    n_rays = sum(len(r[1]) for r in recorded) + sum(len(r[2]) for r in instanced)
    words = embree_direct.scratch()
    answers = [tuple(np.empty(len(r[2]), dtype) for dtype in (np.float64, np.int64, np.float64, np.float64))
               for r in instanced]
    # both rates in process CPU time, best of two, one thread: on a shared machine wall time
    # measures the neighbours; the renderer's time is that of an unrecorded run (the recording
    # render above copies every batch, which is no part of the renderer)
    embree_seconds = 1e9
    for _ in range(2):
        c0 = time.process_time()
        for emb_scene, o, d, tfar, occluded in recorded:
            dists = tfar.copy()
            if occluded:
                emb_scene.run(o, d, dists=dists, query="OCCLUDED")
            else:
                emb_scene.run(o, d, dists=dists, output=1)
        for (fn, handle, o, d, tau, tmax), out in zip(instanced, answers):
            embree_direct.trace_rows_at(fn, handle, words, o, d, tmax, tau, *out)
        embree_seconds = min(embree_seconds, time.process_time() - c0)
    drt_rate, raw_rate = n_rays / cpu1, n_rays / embree_seconds
    print(f"  Embree alone on the same {n_rays} rays (1 thread, CPU time): {raw_rate / 1e6:.2f} Mrays/s; "
          f"DRT whole renderer (1 thread, CPU time): {drt_rate / 1e6:.2f} Mrays/s = {100 * drt_rate / raw_rate:.0f}% "
          f"of Embree's rate")

    stage_breakdown(scene, ctx, args.spp, n_rays)

    blend = os.path.splitext(args.scene)[0] + ".blend"
    if not args.no_blender and os.path.exists(blend):
        p = subprocess.run([sys.executable, "-c", BLENDER_SCRIPT, REPO, blend, str(w), str(h), str(args.spp),
                            str(max(args.repeat, 1))],
                           capture_output=True, text=True)
        line = [ln for ln in p.stdout.splitlines() if ln.startswith("BLENDER_THREADS")]
        if p.returncode != 0 or not line:
            print(f"  inside Blender: failed ({p.stderr.strip()[-300:]})")
        else:
            one, two = (float(v) for v in line[-1].split()[1:])
            print(f"  inside Blender (bpy, F12): 1 thread {one:.3f} s, 2 threads {two:.3f} s: {one / two:.2f}x")
            cyc = [ln for ln in p.stdout.splitlines() if ln.startswith("BLENDER_CYCLES")]
            if cyc:
                cycles, cycles2 = (float(v) for v in cyc[-1].split()[1:])
                # Cycles traces its own rays (its own roulette, light tree): how many is not
                # reported, so its pace is put as DRT's ray count in Cycles's time
                print(f"  Cycles (bpy, F12, 1 thread, same samples): {cycles:.3f} s against DRT's {one:.3f} s; "
                      f"DRT's rays at Cycles's pace: {100 * drt_rate * one / cycles / raw_rate:.0f}% of Embree's rate")
                # the same F12 includes Blender's own fixed work (depsgraph, result handling):
                # Cycles's scaling on it is the yardstick for DRT's
                print(f"  Cycles (bpy, F12): 1 thread {cycles:.3f} s, 2 threads {cycles2:.3f} s: "
                      f"{cycles / cycles2:.2f}x")
    return 0


def stage_breakdown(scene, ctx, spp, n_rays):
    """Per-stage process CPU time of 1-thread renders (best of three per stage)."""
    import drt.path_stages as stages
    from drt.render import render
    from drt.subsurface import SubsurfaceWalker

    tracer = ctx.tracer
    spent = {}

    def timed(name, fn):
        def wrapper(*a, **k):
            c0 = time.process_time()
            try:
                return fn(*a, **k)
            finally:
                spent[name] = spent.get(name, 0.0) + time.process_time() - c0
        return wrapper

    import drt.trace as trace_mod

    originals = dict(shade=stages.shade, camera_stage=stages.camera_stage, walk=SubsurfaceWalker.run,
                     hits=trace_mod._instanced_hits, blocked=trace_mod._instanced_blocked)
    patched_tracer = ("intersect", "occluded", "_run")
    best = {}
    try:
        # (the query kernels of a scene of instances: Embree plus writing the hits)
        trace_mod._instanced_hits = timed("_run", originals["hits"])
        trace_mod._instanced_blocked = timed("_run", originals["blocked"])
        stages.shade = timed("shade", originals["shade"])
        stages.camera_stage = timed("camera_stage", originals["camera_stage"])
        SubsurfaceWalker.run = timed("walk", originals["walk"])
        for name in patched_tracer:
            setattr(tracer, name, timed(name, getattr(tracer, name)))
        for _ in range(3):
            spent.clear()
            c0 = time.process_time()
            render(scene, spp=spp, threads=1, context=ctx)
            spent["total"] = time.process_time() - c0
            for k, v in spent.items():
                best[k] = min(best.get(k, 1e9), v)
    finally:
        stages.shade, stages.camera_stage = originals["shade"], originals["camera_stage"]
        trace_mod._instanced_hits, trace_mod._instanced_blocked = originals["hits"], originals["blocked"]
        SubsurfaceWalker.run = originals["walk"]
        for name in patched_tracer:
            tracer.__dict__.pop(name, None)
    rows = [("shade (per-hit work: emission, MIS, NEE, BSDF sampling)", best.get("shade", 0.0)),
            ("camera_stage", best.get("camera_stage", 0.0)),
            ("Embree itself (Tracer._run; instances: their query kernels)", best.get("_run", 0.0)),
            ("glue around Embree (intersect + occluded - Embree)",
             best.get("intersect", 0.0) + best.get("occluded", 0.0) - best.get("_run", 0.0))]
    if best.get("walk", 0.0) > 0.0:  # its Embree calls are inside, not in the rows above
        rows.append(("subsurface random walks (SubsurfaceWalker.run)", best["walk"]))
    rest = best["total"] - sum(v for _, v in rows)
    print(f"  where one thread's time goes (process CPU time, best of 3 per stage; {n_rays} rays):")
    for name, v in rows + [("render loop, film, the rest", rest), ("total", best["total"])]:
        print(f"    {name:58s} {v:7.3f} s {100 * v / best['total']:5.1f} %")


if __name__ == "__main__":
    sys.exit(main())
