"""What one BSDF sample and one BSDF evaluation cost, per material group, in nanoseconds.

    python benchmarks/bsdf_cost.py [SCENE.npz] [--rows 400000] [--repeat 5]

Builds the scene's material table plus a plain Principled (a specular layer over a diffuse,
multiscatter GGX), draws ``--rows`` random (material, wo) rows over the upper hemisphere and
times ``MaterialTable.sample`` (lobe choice, direction, the whole material's f and pdf) and
``MaterialTable.eval`` at the sampled directions, one thread, best of ``--repeat``. Groups: the
scene's layered materials (``has_layers`` > 0), its other materials, the plain Principled. Run
it for the old and the new code alternately (``PYTHONPATH=<old checkout>/core``): whole
renders on this machine vary by ±10–15 %, these figures by a few percent. Asserts nothing.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))

PLAIN_PRINCIPLED = {"name": "plain principled", "lobes": [
    {"type": "DIELECTRIC_SPECULAR", "color": [1, 1, 1], "roughness": 0.4, "ior": 1.5, "multiscatter": True},
    {"type": "DIFFUSE", "color": [0.8, 0.3, 0.2], "layer": 0}]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene", nargs="?", default=os.path.join(HERE, "..", "blend_scenes", "coat_sheen.npz"))
    ap.add_argument("--rows", type=int, default=400_000)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args(argv)

    from drt.materials.table import MaterialTable
    from drt.scene_file import load_scene

    materials = list(load_scene(args.scene).materials)
    table = MaterialTable.from_scene(materials + [PLAIN_PRINCIPLED])
    d = table.data
    usable = [i for i in range(len(materials)) if d.lobe_count[i] > 0 and not d.delta_only[i]]
    groups = {"layered": [i for i in usable if d.has_layers[i] > 0],
              "other": [i for i in usable if d.has_layers[i] == 0],
              "plain principled": [len(materials)]}
    n = args.rows
    rng = np.random.default_rng(1)
    print(f"{os.path.basename(args.scene)}: {n} rows, best of {args.repeat}, one thread")
    for name, mats in groups.items():
        if not mats:
            continue
        mat = rng.choice(mats, n)
        mu = rng.random(n)
        phi = 2.0 * np.pi * rng.random(n)
        s = np.sqrt(1.0 - mu * mu)
        wo = np.stack([s * np.cos(phi), s * np.sin(phi), mu], 1)
        table.sample(mat[:10], wo[:10], rng.random(10), rng.random((10, 2)))  # compile / load
        best_s = best_e = float("inf")
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            smp = table.sample(mat, wo, rng.random(n), rng.random((n, 2)))
            t1 = time.perf_counter()
            table.eval(mat, wo, smp.wi)
            t2 = time.perf_counter()
            best_s, best_e = min(best_s, t1 - t0), min(best_e, t2 - t1)
        print(f"  {name:18s} ({len(mats)} materials): sample {best_s / n * 1e9:6.0f} ns, "
              f"eval {best_e / n * 1e9:6.0f} ns")
    return 0


if __name__ == "__main__":
    sys.exit(main())
