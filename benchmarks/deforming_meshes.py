"""Deforming meshes of growing size: closest-hit cost of Embree's motion-blur scene (two vertex
time steps, queried from a kernel at each ray's time) against the exact per-ray-time intersector
behind cluster boxes (the fallback without Embree's C handles, and the only path before
2026-12-03). A UV sphere that grows 10 % and moves over the shutter, 65 536 rays from a sphere
around it toward its middle at random times; process CPU time, one thread, best of 3.

    python benchmarks/deforming_meshes.py

Prints one row per mesh size; asserts nothing (docs/kernels.md records the figures).
"""

from __future__ import annotations

import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "tests"))

from drt.geometry import build_geometry  # noqa: E402
from drt.scene import scene_from_dict  # noqa: E402
from drt.trace import Tracer  # noqa: E402
from scene_builders import add_material, add_mesh, base_header, translation, uv_sphere  # noqa: E402


def tracers(rings: int, segments: int):
    """(Tracer on Embree's motion blur, the same on the exact intersector, triangles)."""
    import copy

    h, a = base_header(), {}
    m = add_material(h, "m", [{"type": "DIFFUSE", "color": [1, 1, 1]}])
    pos, tri, _ = uv_sphere(1.0, center=(0, 0, 0), rings=rings, segments=segments)
    motion = {"matrix_open": translation(0, 0, 0), "matrix_close": translation(0.2, 0, 0)}
    add_mesh(h, a, "blob", pos, tri, material=m, motion=motion, positions_close=pos * 1.1)
    h["render"]["shutter"] = [0.0, 1.0]
    h["camera"]["matrix_world"] = translation(0, 0, 0)
    tr = Tracer(build_geometry(scene_from_dict(h, a)))
    exact = copy.copy(tr)
    exact.moving = [copy.copy(obj) for obj in tr.moving]
    for obj in exact.moving:
        obj.direct = None
    return tr, exact, len(tri)


def main() -> int:
    rng = np.random.default_rng(0)
    n = 65536
    o = rng.normal(size=(n, 3))
    o = 4.0 * o / np.linalg.norm(o, axis=1, keepdims=True)
    d = rng.uniform(-0.8, 0.8, (n, 3)) - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    tau = rng.random(n)
    for rings, segments in ((16, 24), (64, 96), (192, 288)):
        tr, exact, triangles = tracers(rings, segments)
        row = {}
        for name, t in (("embree", tr), ("exact", exact)):
            t.intersect(o[:64], d[:64], tau=tau[:64])  # kernels loaded
            best = np.inf
            for _ in range(3):
                c = time.process_time()
                hits = t.intersect(o, d, tau=tau)
                best = min(best, time.process_time() - c)
            row[name] = (best, hits.hit.mean())
        used = "yes" if tr.moving[0].direct is not None else "no (handles not confirmed: both rows are the exact path)"
        print(f"{triangles:7d} triangles: Embree motion blur {row['embree'][0] * 1e3:7.1f} ms, exact intersector "
              f"{row['exact'][0] * 1e3:8.1f} ms per {n} rays (hit fraction {row['embree'][1]:.3f} / "
              f"{row['exact'][1]:.3f}); Embree path used: {used}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
