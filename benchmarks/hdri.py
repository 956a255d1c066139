"""HDRI world convergence: time to relMSE 0.01 for DRT and for Cycles on blend_scenes/hdri
(a sunny generated HDRI is the only light; issue 11's target: DRT within 1.5× of Cycles).

    python benchmarks/hdri.py [--threads 2] [--ref-spp 4096] [--spp 16,32,64,128,256]
                              [--target 0.01] [--out bench_out/hdri]

1. reference: Cycles at ``--ref-spp`` (seed 7), not timed;
2. Cycles and DRT each in their own processes at every ``--spp`` (whole-process wall time and
   the render-only time each reports: Cycles ``bpy.ops.render.render``, DRT the CLI's own
   figure, scene setup — the importance map included — counted);
3. each renderer's time to reach ``--target`` relMSE (Rousselle et al., ``drt.bench.rel_mse``)
   by log-log interpolation between its runs (``drt.bench.time_to_reach``, "~" = extrapolated).

Prints the per-run errors and the DRT/Cycles ratios. A measurement, nothing asserted; on a
shared machine the absolute times vary, the ratio less so.
"""

from __future__ import annotations

import argparse
import json
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, HERE)


def main(argv=None) -> int:
    import numpy as np

    from drt.bench import rel_mse, time_to_reach
    from drt.scene_file import load_scene
    from time_to_error import cycles_run, drt_run

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", default=os.path.join(REPO, "blend_scenes", "hdri.npz"))
    ap.add_argument("--threads", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--ref-spp", type=int, default=4096)
    ap.add_argument("--spp", default="16,32,64,128,256")
    ap.add_argument("--target", type=float, default=0.01)
    ap.add_argument("--out", default=os.path.join("bench_out", "hdri"))
    args = ap.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    blend = os.path.splitext(args.scene)[0] + ".blend"
    r = load_scene(args.scene).render
    w, h = r.width, r.height
    base = os.path.join(args.out, "hdri")
    _, _, ref = cycles_run(blend, args.ref_spp, 7, args.threads, w, h, base + "_ref.exr")
    ref = ref[..., :3]
    result = {"threads": args.threads, "ref_spp": args.ref_spp, "target": args.target}
    times = {}
    for name in ("Cycles", "DRT"):
        walls, renders, errs = [], [], []
        for spp in (int(s) for s in args.spp.split(",")):
            out = base + f"_{name.lower()}_{spp}.exr"
            if name == "Cycles":
                wall, rend, img = cycles_run(blend, spp, 0, args.threads, w, h, out)
            else:
                wall, rend, img = drt_run(args.scene, spp, args.threads, out)
            e = rel_mse(np.asarray(img, dtype=np.float64)[..., :3], ref)
            walls.append(wall)
            renders.append(rend)
            errs.append(e)
            print(f"{name:6s} {spp:5d} spp: whole {wall:7.2f} s, render {rend:7.2f} s, relMSE {e:.3e}", flush=True)
        t_wall, x_wall = time_to_reach(walls, errs, args.target)
        t_rend, x_rend = time_to_reach(renders, errs, args.target)
        times[name] = (t_wall, t_rend)
        result[name] = dict(runs=[dict(seconds=a, render_seconds=b, relmse=c) for a, b, c in zip(walls, renders, errs)],
                            time_to_target=t_wall, render_time_to_target=t_rend,
                            extrapolated=bool(x_wall or x_rend))
        mark = "~" if (x_wall or x_rend) else ""
        print(f"{name}: relMSE {args.target} after {mark}{t_wall or float('nan'):.2f} s whole process, "
              f"{mark}{t_rend or float('nan'):.2f} s render", flush=True)
    (cw, cr), (dw, dr) = times["Cycles"], times["DRT"]
    ratio = dw / cw if dw and cw else float("nan")
    render_ratio = dr / cr if dr and cr else float("nan")
    result.update(ratio=ratio, render_ratio=render_ratio)
    print(f"DRT/Cycles time to relMSE {args.target}: {ratio:.2f} (whole process), {render_ratio:.2f} (render)")
    with open(base + ".json", "w") as f:
        json.dump(result, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
