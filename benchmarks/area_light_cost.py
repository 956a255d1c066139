"""ns per call of the area-light kernels next-event estimation uses (Cornell box light), optionally
against another version of ``drt/lights/area.py`` in the same process, interleaved.

    python benchmarks/area_light_cost.py [--old PATH/TO/OLD/area.py] [--n 400000]

A ``@njit`` loop over n shading points inside the Cornell box calls ``area_sample`` (solid-angle
sampling of the rectangle) or ``area_pdf`` (the MIS pdf of a BSDF ray hitting the light); process
CPU time, best of 7 rounds, versions alternated within each round. Prints figures, asserts nothing.
(An old file is executed as a module of ``drt.lights``: it must import only what the current
package provides.)
"""

from __future__ import annotations

import argparse
import os
import time
import types

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)


def _area_module(path, name):
    m = types.ModuleType("drt.lights." + name)
    m.__package__ = "drt.lights"
    m.__file__ = path
    with open(path) as f:
        exec(compile(f.read(), path, "exec"), m.__dict__)
    return m


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--old", help="another area.py to time beside the current one")
    ap.add_argument("--n", type=int, default=400_000)
    args = ap.parse_args(argv)
    import numpy as np
    from numba import njit

    import drt.lights.area as current
    from drt.kernels.vec3 import load
    from drt.lights.light_set import LightSet
    from drt.scene_file import load_scene

    versions = {"new": current}
    if args.old:
        versions["old"] = _area_module(os.path.abspath(args.old), "area_old")
    sc = load_scene(os.path.join(REPO, "blend_scenes", "cornell_box.npz"))
    ld = LightSet(sc.lights, sc.world_color, None).data
    rng = np.random.default_rng(1)
    p = rng.uniform(-0.95, 0.95, (args.n, 3))   # inside the box; the light is on the ceiling
    u = rng.random((args.n, 2))

    def sample_loop(fn):
        @njit(nogil=True)
        def loop(ld, p, u):
            s = 0.0
            for i in range(p.shape[0]):
                r = fn(ld, 0, load(p, i), u[i, 0], u[i, 1])
                s += r[3] + r[0][0]
            return s
        return loop

    def pdf_loop(fn):
        @njit(nogil=True)
        def loop(ld, p, u):
            s = 0.0
            for i in range(p.shape[0]):
                s += fn(ld, 0, load(p, i), (0.0, 0.0, 1.0), 1.0)
            return s
        return loop

    loops = {}
    for name, m in versions.items():
        loops[f"area_sample {name}"] = sample_loop(m.area_sample)
        loops[f"area_pdf {name}"] = pdf_loop(m.area_pdf)
    for f in loops.values():
        f(ld, p, u)  # compile
    best = dict.fromkeys(loops, float("inf"))
    for _ in range(7):
        for k, f in loops.items():
            c = time.process_time()
            f(ld, p, u)
            best[k] = min(best[k], time.process_time() - c)
    for k in sorted(loops):
        print(f"{k:16s} {best[k] / args.n * 1e9:7.1f} ns")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
