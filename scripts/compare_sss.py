"""DRT vs Cycles on a shipped scene, with per-block confidence: the issue-14 acceptance check.

    python scripts/compare_sss.py blend_scenes/sss_head.blend [--spp 1024] [--png docs/img/x.png]

Cycles renders the .blend (reference settings, scripts/compare_cycles.py); DRT renders the
scene file exported next to it (same name, .npz) through the core, which also gives each
pixel's variance. Criteria (issue 14): channel means within 1 %; ≥ 95 % of 16×16 blocks whose
mean is within 3 % of Cycles's — or within 3σ, σ the standard error of the block difference,
estimated from DRT's per-pixel luminance variance (scaled per channel by the block's colour,
×√2 for Cycles's own noise at equal samples).
"""

import argparse
import os
import sys
import time

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(REPO, "scripts"))


def blocks(img, b=16):
    h, w = (s // b * b for s in img.shape[:2])
    return img[:h, :w].reshape(h // b, b, w // b, b, *img.shape[2:]).mean((1, 3))


def criteria(drt, cyc, var_lum, b=16, tol=0.03):
    """(per-channel mean ratio, fraction of blocks within tol, within tol or 3σ)."""
    ratio = drt.mean((0, 1)) / np.maximum(cyc.mean((0, 1)), 1e-12)
    a, c = blocks(drt, b), blocks(cyc, b)
    lum = a @ np.array([0.2126, 0.7152, 0.0722])
    # standard error of a block's mean luminance: sqrt(Σ σ²/N) / pixels
    se_lum = np.sqrt(blocks(var_lum, b) / (b * b))
    se = se_lum[..., None] * a / np.maximum(lum[..., None], 1e-12) * np.sqrt(2.0)
    floor = 0.01 * cyc.mean()
    diff = np.abs(a - c)
    ok_tol = (diff <= tol * np.maximum(c, floor)).all(-1)
    ok = (ok_tol | (diff <= 3 * se).all(-1))
    return ratio, float(ok_tol.mean()), float(ok.mean())


def side_by_side(drt, cyc, path):
    """DRT left, Cycles right, both scaled by Cycles's 99.5th percentile, ×3 nearest-neighbour,
    as an 8-bit sRGB PNG (drt.preview's writer: no imaging library needed)."""
    from drt.preview import write_png

    img = np.concatenate([drt, np.full((drt.shape[0], 4, 3), 1.0), cyc], 1)
    img = np.clip(img / np.percentile(cyc, 99.5), 0, 1)
    write_png(path, np.repeat(np.repeat(img, 3, axis=0), 3, axis=1))


def main(argv=None):
    p = argparse.ArgumentParser()
    p.add_argument("blend")
    p.add_argument("--spp", type=int, default=1024)
    p.add_argument("--out", default="/tmp/drt-compare")
    p.add_argument("--png")
    opts = p.parse_args(argv)
    os.makedirs(opts.out, exist_ok=True)
    name = os.path.splitext(os.path.basename(opts.blend))[0]
    import bpy
    from compare_cycles import render as bpy_render
    bpy.ops.wm.open_mainfile(filepath=os.path.abspath(opts.blend))
    t0 = time.perf_counter()
    cyc = bpy_render(bpy.context.scene, "CYCLES", opts.spp, os.path.join(opts.out, f"{name}_cycles.exr"))
    t_cyc = time.perf_counter() - t0
    from drt.render import render
    from drt.scene_file import load_scene
    scene = load_scene(os.path.splitext(opts.blend)[0] + ".npz")
    t0 = time.perf_counter()
    film = render(scene, spp=opts.spp)
    t_drt = time.perf_counter() - t0
    drt = film.combined[..., :3].astype(np.float64)
    ratio, frac, frac_sigma = criteria(drt, cyc, film.variance.astype(np.float64))
    good = bool(np.all(np.abs(ratio - 1) <= 0.01) and frac_sigma >= 0.95)
    print(f"{name} at {opts.spp} spp: mean ratio R {ratio[0]:.4f} G {ratio[1]:.4f} B {ratio[2]:.4f}; "
          f"blocks within 3%: {100 * frac:.1f}%, within 3% or 3σ: {100 * frac_sigma:.1f}% -> "
          f"{'OK' if good else 'DIFFERS'} (Cycles {t_cyc:.0f} s, DRT {t_drt:.0f} s)", flush=True)
    if opts.png:
        side_by_side(drt, cyc, opts.png)
    return int(not good)


if __name__ == "__main__":
    sys.exit(main())
