"""Peak memory (RSS) of large jobs: a 3840×2160 frame at 1 spp, the same at higher spp on a
smaller frame (memory must not grow with samples), a multi-million-triangle mesh, and a 4K
frame of a 1M-triangle mesh.

    python benchmarks/memory.py [--cases 4k,spp1,spp16,tris,4ktris] [--threads 2]
                                [--triangles 4000000]

Each case runs in a fresh Python process (so ``ru_maxrss`` is that case's own peak) and prints
one line: RSS after imports, after loading/building the scene and the peak during the render
(one process: batches run on threads). Never asserts anything; the budget is stated in
docs/robustness.md.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests"))


def rss_mb() -> float:
    """Current RSS (MB) from /proc, falling back to the peak."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    return peak_mb()


def peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def grid_mesh(n: int):
    """An n×n-quad height field (2n² triangles), vectorised."""
    import numpy as np

    xs = np.linspace(-1, 1, n + 1)
    X, Y = np.meshgrid(xs, xs)
    Z = 0.05 * np.sin(9 * X) * np.cos(7 * Y)
    pos = np.stack([X.ravel(), Y.ravel(), Z.ravel()], 1).astype(np.float32)
    j, i = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    a = (j * (n + 1) + i).ravel()
    b, c, d = a + 1, a + n + 2, a + n + 1
    tri = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]).astype(np.int32)
    return pos, tri


def run_case(case: str, threads: int, triangles: int) -> dict:
    import numpy as np

    from drt.render import prepare, render
    from drt.scene import scene_from_dict
    from scene_builders import add_material, add_mesh, base_header, cornell_box, look_at, translation

    out = {"case": case, "rss_imports_mb": rss_mb()}
    if case == "4k":
        h, a = cornell_box(3840, 2160, 1)
    elif case.startswith("spp"):
        h, a = cornell_box(480, 270, int(case[3:]))
    elif case in ("tris", "4ktris"):
        if case == "4ktris":
            triangles, (w, hh) = 1_000_000, (3840, 2160)
        else:
            w, hh = 640, 360
        n = int(round((triangles / 2) ** 0.5))
        h = base_header(w, hh, 1, world=(0.2, 0.2, 0.2),
                        camera={"type": "PERSP", "matrix_world": look_at((0, -2.5, 1.5), (0, 0, 0)), "lens": 35.0})
        a = {}
        m = add_material(h, "white", [{"type": "DIFFUSE", "color": [0.8, 0.8, 0.8]}])
        pos, tri = grid_mesh(n)
        add_mesh(h, a, "field", pos, tri, material=m)
        h["lights"].append({"type": "AREA", "matrix_world": translation(0, 0, 2), "power": 200.0, "size": 1.0})
        out["triangles"] = int(len(tri))
    else:
        raise SystemExit(f"unknown case {case}")
    scene = scene_from_dict(h, a)
    del a
    out["rss_scene_mb"] = rss_mb()
    t0 = time.perf_counter()
    ctx = prepare(scene)
    out["prepare_s"] = time.perf_counter() - t0
    out["rss_prepared_mb"] = rss_mb()
    t0 = time.perf_counter()
    film = render(scene, context=ctx, threads=threads)
    out["render_s"] = time.perf_counter() - t0
    out["pixels"] = scene.render.width * scene.render.height
    out["spp"] = film.stats.samples_done
    out["peak_mb"] = peak_mb()
    assert np.all(np.isfinite(film.combined))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cases", default="4k,spp1,spp16,tris,4ktris")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--triangles", type=int, default=4_000_000)
    ap.add_argument("--case", help=argparse.SUPPRESS)  # internal: run one case here, print JSON
    args = ap.parse_args(argv)
    if args.case:
        print(json.dumps(run_case(args.case, args.threads, args.triangles)))
        return
    print(f"{'case':8} {'pixels':>9} {'spp':>4} {'tris':>9} {'imports':>8} {'scene':>8} {'prepared':>9} "
          f"{'peak':>8} {'render s':>9}   (MB)")
    for case in args.cases.split(","):
        r = subprocess.run([sys.executable, __file__, "--case", case, "--threads", str(args.threads),
                            "--triangles", str(args.triangles)],
                           capture_output=True, text=True)
        if r.returncode != 0:
            print(f"{case:8} failed: {r.stderr.strip().splitlines()[-1] if r.stderr.strip() else r.returncode}")
            continue
        d = json.loads(r.stdout.strip().splitlines()[-1])
        print(f"{case:8} {d['pixels']:9d} {d['spp']:4d} {d.get('triangles', 34):9d} {d['rss_imports_mb']:8.0f} "
              f"{d['rss_scene_mb']:8.0f} {d['rss_prepared_mb']:9.0f} {d['peak_mb']:8.0f} "
              f"{d['render_s']:9.1f}", flush=True)


if __name__ == "__main__":
    main()
