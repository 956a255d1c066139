"""Regenerate the pictures at the top of README.md (needs bpy for the Cycles side; matplotlib for
the chart).

    python scripts/make_readme_images.py [--spp 128] [--compare-spp 64] [--compare-scale 50]
        [--skip-showcase] [--skip-compare] [--skip-chart]

1. ``docs/img/showcase.png``: blend_scenes/showcase.npz rendered by the command line at its own
   resolution (1280x720), as a user would (``python -m drt render ... --png``).
2. ``docs/img/showcase_drt_vs_cycles.png``: the same .blend rendered by DRT and by Cycles (bpy,
   reference settings: no denoising, no clamping) at equal samples and ``--compare-scale`` %
   resolution, side by side with their absolute difference x8. Prints the per-channel mean ratio
   and the share of 16x16 blocks within 3 % (scripts/compare_cycles.py's measure).
3. ``docs/img/error_vs_time.png``: ``drt bench`` on the Cornell box with Cycles: relMSE against a
   1024-spp reference versus seconds, for DRT's default estimator and Cycles.

Each step prints the times it measured; PNGs are sRGB previews of scene-linear renders.
"""

import argparse
import os
import shutil
import subprocess
import sys
import time

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
IMG = os.path.join(REPO, "docs", "img")
WORK = os.path.join(REPO, "out", "readme")

COMPARE = r"""
import os, sys
sys.path.insert(0, {scripts!r})
import numpy as np
import bpy
import drt_blender
import compare_cycles as cc
drt_blender.register()
bpy.ops.wm.open_mainfile(filepath={blend!r})
scene = bpy.context.scene
scene.render.resolution_percentage = {scale}
import time
t = time.perf_counter(); cyc = cc.render(scene, "CYCLES", {spp}, {cyc_out!r}); tc = time.perf_counter() - t
t = time.perf_counter(); drt = cc.render(scene, "DRT", {spp}, {drt_out!r}); td = time.perf_counter() - t
ratio, frac = cc.compare(drt, cyc)
np.save({npy!r}, np.stack([drt, cyc]))
print(f"RESULT cycles {{tc:.1f}} s, drt {{td:.1f}} s; mean ratio R {{ratio[0]:.4f}} G {{ratio[1]:.4f}} "
      f"B {{ratio[2]:.4f}}; blocks within 3%: {{100 * frac:.1f}}%")
"""


def showcase(spp: int) -> None:
    png = os.path.join(IMG, "showcase.png")
    t = time.perf_counter()
    subprocess.run([sys.executable, "-m", "drt", "render", os.path.join(REPO, "blend_scenes", "showcase.npz"),
                    "-o", os.path.join(WORK, "showcase.exr"), "--spp", str(spp), "--png", png], check=True)
    print(f"showcase: {time.perf_counter() - t:.1f} s (whole process) -> {png}")


def compare(spp: int, scale: int) -> None:
    from drt.preview import write_png

    npy = os.path.join(WORK, "compare.npy")
    code = COMPARE.format(scripts=os.path.join(REPO, "scripts"), blend=os.path.join(REPO, "blend_scenes", "showcase.blend"),
                          scale=scale, spp=spp, cyc_out=os.path.join(WORK, "showcase_cycles.exr"),
                          drt_out=os.path.join(WORK, "showcase_drt.exr"), npy=npy)
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    if p.returncode != 0:
        raise SystemExit(p.stdout[-3000:] + p.stderr[-3000:])
    print("compare:", [ln for ln in p.stdout.splitlines() if ln.startswith("RESULT")][-1][7:])
    drt, cyc = np.load(npy)
    diff = np.abs(drt - cyc) * 8.0
    gap = np.ones((drt.shape[0], 8, 3))
    side = np.concatenate([drt, gap, cyc, gap, diff], axis=1)
    png = os.path.join(IMG, "showcase_drt_vs_cycles.png")
    write_png(png, side)
    print(f"compare: DRT | Cycles | |difference| x8, {spp} spp each -> {png}")


def chart() -> None:
    out = os.path.join(WORK, "bench")
    t = time.perf_counter()
    subprocess.run([sys.executable, "-m", "drt", "bench", os.path.join(REPO, "blend_scenes", "cornell_box.blend"),
                    "-o", out, "--cycles", "--methods", "mis_power", "--spp-list", "4", "16", "64", "256"], check=True)
    shutil.copyfile(os.path.join(out, "bench.png"), os.path.join(IMG, "error_vs_time.png"))
    print(f"chart: {time.perf_counter() - t:.1f} s -> docs/img/error_vs_time.png")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--spp", type=int, default=128, help="samples of the showcase render")
    p.add_argument("--compare-spp", type=int, default=64)
    p.add_argument("--compare-scale", type=int, default=50, help="resolution %% of the DRT/Cycles comparison")
    p.add_argument("--skip-showcase", action="store_true")
    p.add_argument("--skip-compare", action="store_true")
    p.add_argument("--skip-chart", action="store_true")
    opts = p.parse_args(argv)
    os.makedirs(WORK, exist_ok=True)
    if not opts.skip_showcase:
        showcase(opts.spp)
    if not opts.skip_compare:
        compare(opts.compare_spp, opts.compare_scale)
    if not opts.skip_chart:
        chart()
    return 0


if __name__ == "__main__":
    sys.exit(main())
