"""Fog lit by a spot light (blend_scenes/volume_fog): time to relMSE 0.01 for DRT and Cycles,
whole processes, same machine and threads; prints the ratio DRT / Cycles (≤ 1: DRT is faster).

    python benchmarks/volume_fog.py [--threads 2] [--ref-spp 2048] [--spp 4,8,16,32,64,128]
                                    [--target 0.01] [--out bench_out/volume_fog]

A converged Cycles render (another seed) is the reference; both renderers run at each spp of
the list (stopping once below half the target) and the time to reach the target is interpolated
log-log (drt.bench.time_to_reach; "~" marks an extrapolation). Render-only times are printed
too (Cycles: bpy.ops.render.render; DRT: what its CLI reports). Asserts nothing.
"""

from __future__ import annotations

import argparse
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, HERE)

from time_to_error import cycles_run, drt_run  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", default=os.path.join(REPO, "blend_scenes", "volume_fog.npz"))
    ap.add_argument("--threads", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--ref-spp", type=int, default=2048)
    ap.add_argument("--spp", default="4,8,16,32,64,128,256")
    ap.add_argument("--target", type=float, default=0.01)
    ap.add_argument("--out", default=os.path.join("bench_out", "volume_fog"))
    args = ap.parse_args(argv)
    import numpy as np

    from drt.bench import rel_mse, time_to_reach
    from drt.scene_file import load_scene

    blend = os.path.splitext(args.scene)[0] + ".blend"
    r = load_scene(args.scene).render
    os.makedirs(args.out, exist_ok=True)
    base = os.path.join(args.out, "volume_fog")
    _, _, ref = cycles_run(blend, args.ref_spp, 7, args.threads, r.width, r.height, base + "_ref.exr")
    result = {}
    for engine in ("Cycles", "DRT"):
        walls, renders, errs, runs = [], [], [], []
        for spp in (int(s) for s in args.spp.split(",")):
            out = base + f"_{engine.lower()}_{spp}.exr"
            if engine == "Cycles":
                wall, rnd, img = cycles_run(blend, spp, 0, args.threads, r.width, r.height, out)
            else:
                wall, rnd, img = drt_run(args.scene, spp, args.threads, out)
            e = rel_mse(np.asarray(img, dtype=np.float64)[..., :3], ref[..., :3])
            walls.append(wall)
            renders.append(rnd)
            errs.append(e)
            runs.append(f"{spp}: {wall:.2f} s ({rnd:.2f}), {e:.2e}")
            if e < 0.5 * args.target:
                break
        t, ext = time_to_reach(walls, errs, args.target)
        t_r, ext_r = time_to_reach(renders, errs, args.target)
        result[engine] = (t, t_r)
        print(f"{engine:6s}: relMSE {args.target} in {'~' if ext else ''}{t:.2f} s whole process, "
              f"{'~' if ext_r else ''}{t_r:.2f} s render  [" + "; ".join(runs) + "]", flush=True)
    (dt, dr), (ct, cr) = result["DRT"], result["Cycles"]
    print(f"ratio DRT/Cycles: {dt / ct:.2f} whole process, {dr / cr:.2f} render only "
          f"({args.threads} threads, {r.width}x{r.height})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
