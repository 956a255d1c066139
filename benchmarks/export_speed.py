"""Export speed of the add-on: a ~1M-triangle smooth UV sphere (blend_scenes/large_mesh.py).

    python benchmarks/export_speed.py [--repeat 3]

Builds the scene in memory with the bpy module, then times ``export_current()`` (depsgraph →
header + arrays, in memory, no file). Prints triangles, best and median seconds. Target: < 2 s.
"""

import argparse
import os
import statistics
import sys
import time

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)
sys.path.insert(0, os.path.join(REPO, "blend_scenes"))


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--repeat", type=int, default=3)
    opts = p.parse_args()
    import addon
    import large_mesh
    from addon.export.blend import export_current
    addon.register()
    large_mesh.build()
    times, res = [], None
    for _ in range(opts.repeat):
        t0 = time.perf_counter()
        res = export_current()
        times.append(time.perf_counter() - t0)
    tris = sum(len(v) for k, v in res.arrays.items() if k.endswith(".triangles"))
    print(f"export_speed: {tris} triangles, best {min(times):.3f} s, "
          f"median {statistics.median(times):.3f} s over {opts.repeat} runs "
          f"({tris / min(times) / 1e6:.2f} Mtri/s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
