"""Per-sample error of DRT and Cycles at equal samples, and where it lives in the image.

    python benchmarks/per_sample_error.py SCENE.npz [--spp 64] [--seeds 4] [--ref-spp 4096]
                                          [--threads 1] [--out bench_out/per_sample]

For one shipped scene (a ``.blend`` beside the ``.npz``):

1. a Cycles reference at ``--ref-spp`` (seed 7), cached on disk (``<out>/<scene>_ref.exr``);
2. Cycles and DRT at ``--spp`` for seeds 0 … ``--seeds``−1 (Cycles's images are cached too);
3. prints, per engine, relMSE against the reference (``drt.bench.rel_mse``): mean over seeds ±
   its standard error, the per-seed values, and the relMSE with the top 0.1 % of pixel errors
   removed (fireflies against broad noise);
4. writes ``<scene>_map_<engine>.png``: the per-pixel relMSE (mean over seeds), log10 from
   1e-4 (black) to 1 (white).

Nothing is timed or asserted: this measures sample quality only (docs/estimators.md).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))


def pixel_rel_mse(x: np.ndarray, ref: np.ndarray, eps: float = 0.01) -> np.ndarray:
    """(H, W) relMSE per pixel, the mean over RGB of (x − ref)² / (ref² + eps)."""
    d = x[..., :3] - ref[..., :3]
    return np.mean(d * d / (ref[..., :3] ** 2 + eps), axis=-1)


def trimmed(e: np.ndarray, frac: float = 0.001) -> float:
    """Mean of the per-pixel errors with the largest ``frac`` of them counted as 0."""
    f = np.sort(e.ravel())
    return float(f[: int(round(len(f) * (1.0 - frac)))].sum() / len(f))


def save_map(e: np.ndarray, path: str) -> None:
    from drt.preview import encode_png

    v = np.clip((np.log10(e + 1e-6) + 4.0) / 4.0, 0.0, 1.0)
    v = np.repeat(np.repeat(v, 4, 0), 4, 1)
    with open(path, "wb") as f:
        f.write(encode_png((np.stack([v, v * v, 0.3 * v], -1) * 255).astype(np.uint8)))


def cycles_image(blend: str, spp: int, seed: int, threads: int, w: int, h: int, path: str) -> np.ndarray:
    from drt.bench import _CYCLES_SCRIPT, _read_rgba

    if not os.path.exists(path):
        args = dict(blend=os.path.abspath(blend), seed=seed, threads=threads, width=w, height=h,
                    jobs=[[spp, os.path.abspath(path)]], warmup=False)
        proc = subprocess.run([sys.executable, "-c", _CYCLES_SCRIPT, json.dumps(args)], capture_output=True, text=True)
        if proc.returncode != 0:
            raise RuntimeError(f"Cycles failed on {blend}: {proc.stderr.strip()[-800:]}")
    return _read_rgba(path)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene")
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--ref-spp", type=int, default=4096)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", default=os.path.join("bench_out", "per_sample"))
    args = ap.parse_args(argv)
    from drt.bench import rel_mse
    from drt.render import render
    from drt.scene_file import load_scene

    name = os.path.splitext(os.path.basename(args.scene))[0]
    blend = os.path.splitext(args.scene)[0] + ".blend"
    os.makedirs(args.out, exist_ok=True)
    scene = load_scene(args.scene)
    w, h = scene.render.width, scene.render.height
    base = os.path.join(args.out, name)
    ref = cycles_image(blend, args.ref_spp, 7, args.threads, w, h, f"{base}_ref{args.ref_spp}.exr")
    runs = {"cycles": [cycles_image(blend, args.spp, s, args.threads, w, h, f"{base}_cycles{args.spp}_s{s}.exr")
                       for s in range(args.seeds)],
            "drt": [render(scene, spp=args.spp, seed=s, threads=args.threads).combined.astype(np.float64)
                    for s in range(args.seeds)]}
    print(f"{name}: {args.spp} spp, {args.seeds} seeds, Cycles reference {args.ref_spp} spp")
    for engine, imgs in runs.items():
        errs = [rel_mse(x[..., :3], ref[..., :3]) for x in imgs]
        maps = [pixel_rel_mse(x, ref) for x in imgs]
        se = np.std(errs, ddof=1) / np.sqrt(len(errs)) if len(errs) > 1 else float("nan")
        print(f"  {engine:6s} relMSE {np.mean(errs):.3e} ± {se:.1e}   without top 0.1 % pixels "
              f"{np.mean([trimmed(m) for m in maps]):.3e}   per seed " + " ".join(f"{e:.2e}" for e in errs))
        save_map(np.mean(maps, axis=0), f"{base}_map_{engine}.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
