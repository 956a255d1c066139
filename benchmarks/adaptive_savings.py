"""Adaptive sampling against uniform sample counts on the mixed easy/hard scene: RMSE, mean
samples per pixel and seconds. Prints a table; asserts nothing (tests/test_adaptive.py asserts
the sample savings).

    python benchmarks/adaptive_savings.py [--size 32] [--threads 2]
"""

import argparse
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))

from drt.bench import rmse  # noqa: E402
from drt.render import prepare, render  # noqa: E402
from drt.scene import scene_from_dict  # noqa: E402
from failure_scenes import mixed_scene  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=int, default=32)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--reference-spp", type=int, default=2048)
    opts = ap.parse_args()
    h, a = mixed_scene(opts.size, opts.size)
    scene = scene_from_dict(h, a)
    ref = render(scene, spp=opts.reference_spp, seed=99, threads=opts.threads, parallel="threads").combined
    ctx = prepare(scene, seed=0)
    rows = []
    for spp in (16, 32, 64, 128, 256):
        f = render(scene, spp=spp, threads=opts.threads, context=ctx, parallel="threads")
        rows.append(("uniform", spp, float(f.sample_count.mean()), f.stats.seconds, rmse(f.combined, ref)))
    for thr in (0.2, 0.1, 0.05, 0.02):
        f = render(scene, spp=512, threads=opts.threads, context=ctx, adaptive_threshold=thr,
                   adaptive_min_samples=16, parallel="threads")
        rows.append((f"adaptive {thr}", 512, float(f.sample_count.mean()), f.stats.seconds, rmse(f.combined, ref)))
    print(f"{'method':>16} {'cap':>5} {'mean spp':>9} {'seconds':>8} {'RMSE':>8}")
    for r in rows:
        print(f"{r[0]:>16} {r[1]:5d} {r[2]:9.1f} {r[3]:8.2f} {r[4]:8.4f}")
    uni = [r for r in rows if r[0] == "uniform"]
    ls, le = np.log([r[2] for r in uni]), np.log([r[4] for r in uni])
    lt = np.log([r[3] for r in uni])
    k_spp = np.polyfit(le, ls, 1)
    k_t = np.polyfit(le, lt, 1)
    for r in rows:
        if r[0].startswith("adaptive"):
            need_spp = math.exp(np.polyval(k_spp, math.log(r[4])))
            need_t = math.exp(np.polyval(k_t, math.log(r[4])))
            print(f"{r[0]}: uniform needs ≈{need_spp:.0f} spp / {need_t:.2f} s for RMSE {r[4]:.4f}; "
                  f"adaptive used {r[2]:.0f} spp / {r[3]:.2f} s ({need_t / r[3]:.2f}x faster)")


if __name__ == "__main__":
    main()
