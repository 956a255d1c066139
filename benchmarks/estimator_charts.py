"""Charts for docs/estimators.md from the point estimators (drt.estimators): RMSE against
sample count for each estimator and generator on the rectangle light, and per-plate variance
on Veach's plates. Writes docs/img/estimators_convergence.png and docs/img/veach_plates.png.

    python benchmarks/estimator_charts.py
"""

import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests"))

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from failure_scenes import PLATE_ROUGHNESS, veach_points  # noqa: E402
from test_estimators import LUM, rectangle_setup  # noqa: E402

OUT = os.path.join(HERE, "..", "docs", "img")


def convergence():
    dl, pts, expected = rectangle_setup(128)
    counts = [4, 16, 64, 256, 1024]
    fig, ax = plt.subplots(figsize=(6.4, 4.4), dpi=80)
    for method, sampler in [("UNIFORM", "RANDOM"), ("STRATIFIED", "RANDOM"), ("COSINE", "RANDOM"),
                            ("LIGHT", "RANDOM"), ("LIGHT", "STRATIFIED"), ("LIGHT", "SOBOL"), ("MIS_POWER", "SOBOL")]:
        errs = []
        for n in counts:
            est = dl.estimate_direct(method, pts, n, sampler=sampler, seed=3) @ LUM
            errs.append(np.sqrt(np.mean((est - expected) ** 2)) / expected)
        slope = np.polyfit(np.log(counts), np.log(errs), 1)[0]
        ax.loglog(counts, errs, marker="o", markersize=3, label=f"{method}/{sampler} (slope {slope:.2f})")
    mid = []
    for m in (1, 2, 4, 8, 16):
        est = dl.estimate_direct("MIDPOINT", pts, 0, grid=(m, 4 * m)) @ LUM
        mid.append(abs(est[0] - expected) / expected)
    ax.loglog([4 * m * m for m in (1, 2, 4, 8, 16)], mid, "k--", marker="x", label="MIDPOINT (deterministic)")
    ax.set_xlabel("samples per estimate")
    ax.set_ylabel("relative RMSE")
    ax.set_title("direct light from a 1×0.5 m rectangle at a diffuse point")
    ax.grid(True, which="both", linewidth=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(OUT, "estimators_convergence.png"))


def veach():
    methods = ["LIGHT", "BSDF", "MIS_BALANCE", "MIS_POWER"]
    v = np.zeros((len(PLATE_ROUGHNESS), len(methods)))
    for k in range(len(PLATE_ROUGHNESS)):
        setup = veach_points(k)
        for j, m in enumerate(methods):
            x = setup.direct().direct_samples(m, setup.points, 4096) @ LUM
            v[k, j] = x.var(axis=1, ddof=1).sum()
    fig, ax = plt.subplots(figsize=(6.4, 3.8), dpi=80)
    w = 0.2
    for j, m in enumerate(methods):
        ax.bar(np.arange(len(PLATE_ROUGHNESS)) + (j - 1.5) * w, v[:, j], w, label=m)
    ax.set_yscale("log")
    ax.set_xticks(range(len(PLATE_ROUGHNESS)), [f"roughness {r}" for r in PLATE_ROUGHNESS])
    ax.set_ylabel("per-sample variance (sum over 4 points)")
    ax.set_title("Veach's plates: light sampling fails on sharp plates, BSDF on small lights")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(OUT, "veach_plates.png"))
    return v


if __name__ == "__main__":
    os.makedirs(OUT, exist_ok=True)
    convergence()
    print(veach())
