"""Denoised error-vs-time curves on the shipped scenes: DRT, DRT + OIDN, Cycles, Cycles + OIDN.

Runs ``drt bench --cycles --denoise`` (default method mis_power) on every shipped scene that has
a .blend, prints the time each curve needs to reach the relMSE Cycles + OIDN reaches at 16 spp,
and draws one chart with a panel per scene (docs/img/denoise_curves.png).

    python benchmarks/denoise_curves.py [--reference-spp 2048] [--out /tmp/denoise_bench]
"""

import argparse
import glob
import json
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
SPP = (1, 2, 4, 8, 16, 32, 64, 128, 256)


def chart(results: dict, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(results)
    cols = min(n, 3)
    rows = (n + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.4 * rows), dpi=80, squeeze=False)
    styles = {"mis_power": dict(color="tab:blue"), "mis_power+oidn": dict(color="tab:blue", linestyle="-."),
              "cycles": dict(color="black", linestyle="--"), "cycles+oidn": dict(color="black", linestyle="-.")}
    labels = {"mis_power": "DRT", "mis_power+oidn": "DRT + OIDN", "cycles": "Cycles", "cycles+oidn": "Cycles + OIDN"}
    for ax, (name, summary) in zip(axes.flat, results.items()):
        by = {}
        for r in summary["rows"]:
            by.setdefault(r["method"], []).append(r)
        for m, rs in by.items():
            rs = sorted(rs, key=lambda r: r["spp"])  # in sample order: timings on a shared machine jitter
            ax.loglog([r["seconds"] for r in rs], [r["relmse"] for r in rs], marker="o", markersize=2.5,
                      linewidth=1.6, label=labels.get(m, m), **styles.get(m, {}))
        bar = summary.get("time_to_cycles_oidn_16spp")
        if bar:
            ax.axhline(bar["relmse"], color="grey", linewidth=0.8, linestyle=":")
        w, h = summary["resolution"]
        ax.set_title(f"{name} ({w}x{h})", fontsize=9)
        ax.set_xlabel("seconds (render + denoise)", fontsize=8)
        ax.set_ylabel("relMSE", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(True, which="both", linewidth=0.3)
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=7)
    fig.suptitle("relMSE vs time (points 1, 2, 4, ... 256 spp); dotted: Cycles + OIDN at 16 spp", fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scenes", nargs="*", help="default: blend_scenes/*.npz with a .blend beside them")
    ap.add_argument("--reference-spp", type=int, default=2048)
    ap.add_argument("--threads", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--out", default="/tmp/denoise_bench")
    ap.add_argument("--chart", default=os.path.join(REPO, "docs", "img", "denoise_curves.png"))
    ap.add_argument("--from-json", help="only redraw the chart from a denoise_curves.json")
    args = ap.parse_args(argv)
    if args.from_json:
        with open(args.from_json) as f:
            chart(json.load(f), args.chart)
        return 0
    from drt import bench

    scenes = args.scenes or sorted(p for p in glob.glob(os.path.join(REPO, "blend_scenes", "*.npz"))
                                   if os.path.exists(p[:-4] + ".blend"))
    results = {}
    for scene in scenes:
        name = os.path.splitext(os.path.basename(scene))[0]
        out = os.path.join(args.out, name)
        print(f"== {name}", flush=True)
        results[name] = bench.bench(scene, out, methods=["mis_power"], spp_list=SPP, reference_spp=args.reference_spp,
                                    cycles=True, threads=args.threads, denoise=True, chart=False,
                                    log=lambda s: print(s, flush=True))
    with open(os.path.join(args.out, "denoise_curves.json"), "w") as f:
        json.dump(results, f, indent=1)
    print("\nseconds to reach the relMSE of Cycles + OIDN at 16 spp (x: extrapolated beyond the last point)")
    curves = ("mis_power", "mis_power+oidn", "cycles", "cycles+oidn")
    print(f"{'scene':>14} {'target':>8} " + " ".join(f"{c:>15}" for c in curves) + "  ref agreement")
    for name, s in results.items():
        bar = s["time_to_cycles_oidn_16spp"]
        cells = []
        for c in curves:
            t = bar["seconds"].get(c, {})
            sec = t.get("seconds")
            cells.append(f"{'never' if sec is None else f'{sec:.3f}' + ('x' if t.get('extrapolated') else ''):>15}")
        print(f"{name:>14} {bar['relmse']:8.4f} " + " ".join(cells) + f"  {s['reference_agreement_relmse']:.2g}")
    chart(results, args.chart)
    print(f"chart: {args.chart}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
