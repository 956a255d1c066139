"""DRT vs Cycles on the shipped volume scenes (issue 14 acceptance), at equal samples.

    python scripts/compare_volumes.py blend_scenes/volume_fog.blend [...] [--spp 256] [--png DIR]

For each .blend: Cycles renders once with the reference settings (compare_cycles.py); DRT renders
twice with different seeds at spp/2 each (their mean is the spp image, their difference gives
DRT's per-block noise σ, and Cycles's is taken to be the same). Prints the DRT/Cycles channel
mean ratios (target within 1 %) and the fraction of 16×16 blocks within 3 % or 3σ of Cycles
(target ≥ 95 %). With --png, writes DRT | Cycles | |difference|×8 as <name>_drt_vs_cycles.png.
"""

import argparse
import os
import sys

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(REPO, "scripts"))
sys.path.insert(0, os.path.join(REPO, "blend_scenes"))


def blocks(img, block=16):
    h, w = (s // block * block for s in img.shape[:2])
    return img[:h, :w].reshape(h // block, block, w // block, block, 3).mean((1, 3))


def judge(drt_a, drt_b, cyc, tol=0.03):
    """(channel mean ratios, fraction of blocks within tol or 3σ)."""
    drt = 0.5 * (drt_a + drt_b)
    ratio = drt.mean((0, 1)) / np.maximum(cyc.mean((0, 1)), 1e-12)
    a, b = blocks(drt), blocks(cyc)
    # σ of one spp/2 block mean ≈ |A − B|/√2; of the spp mean /√2 again; DRT − Cycles: ×√2
    sigma = np.abs(blocks(drt_a) - blocks(drt_b)) / np.sqrt(2.0)
    floor = 0.01 * cyc.mean()
    ok = (np.abs(a - b) <= tol * np.maximum(b, floor)) | (np.abs(a - b) <= 3.0 * sigma)
    return ratio, float(ok.all(axis=-1).mean())


def main(argv=None):
    p = argparse.ArgumentParser()
    p.add_argument("blends", nargs="+")
    p.add_argument("--spp", type=int, default=256)
    p.add_argument("--out", default=os.path.join(REPO, "out", "compare_volumes"))
    p.add_argument("--png", help="folder for the side-by-side PNGs")
    opts = p.parse_args(argv)
    import bpy
    import compare_cycles as cc

    import addon
    addon.register()
    os.makedirs(opts.out, exist_ok=True)
    worst = 0
    for blend in opts.blends:
        name = os.path.splitext(os.path.basename(blend))[0]
        bpy.ops.wm.open_mainfile(filepath=os.path.abspath(blend))
        scene = bpy.context.scene
        cyc = cc.render(scene, "CYCLES", opts.spp, os.path.join(opts.out, f"{name}_cycles.exr"))
        runs = []
        for seed in (1, 2):
            scene.drt.seed = seed
            runs.append(cc.render(scene, "DRT", opts.spp // 2, os.path.join(opts.out, f"{name}_drt{seed}.exr")))
        ratio, frac = judge(runs[0], runs[1], cyc)
        drt = 0.5 * (runs[0] + runs[1])
        bad = not np.all(np.isfinite(drt))
        good = bool(np.all(np.abs(ratio - 1) <= 0.01) and frac >= 0.95 and not bad)
        worst |= not good
        print(f"{name}: {opts.spp} spp; mean ratio R {ratio[0]:.4f} G {ratio[1]:.4f} B {ratio[2]:.4f}; "
              f"blocks within 3% or 3 sigma: {100 * frac:.1f}% -> {'OK' if good else 'DIFFERS'}", flush=True)
        if opts.png:
            from drt.preview import write_png

            gap = np.ones((drt.shape[0], 4, 3))
            side = np.concatenate([drt, gap, cyc, gap, np.abs(drt - cyc) * 8.0], axis=1)
            os.makedirs(opts.png, exist_ok=True)
            write_png(os.path.join(opts.png, f"{name}_drt_vs_cycles.png"), side)
    return int(worst)


if __name__ == "__main__":
    sys.exit(main())
