"""Render speed of the core: time, samples/s, Mrays/s and the share of time inside Embree.

    python benchmarks/render_speed.py [SCENE.npz ...] [--resolution 512x512] [--spp 16] [--threads 2]

Without scenes it renders every ``blend_scenes/*.npz`` (and the built-in Cornell box when none
exist). Prints one line per scene; never asserts anything. "Embree share" is the summed time
worker threads spent inside Embree calls divided by (wall time × threads): the part of the
machine Embree had. CPU utilisation is process CPU time / (wall time × threads).
"""

from __future__ import annotations

import argparse
import glob
import os
import sys
import time
from dataclasses import replace

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests"))


def load_scenes(paths):
    from drt.scene import scene_from_dict
    from drt.scene_file import load_scene

    if not paths:
        paths = sorted(glob.glob(os.path.join(HERE, "..", "blend_scenes", "*.npz")))
    if not paths:
        from scene_builders import cornell_box

        yield "cornell_box (built-in)", scene_from_dict(*cornell_box())
        return
    for p in paths:
        yield os.path.basename(p), load_scene(p)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scenes", nargs="*")
    ap.add_argument("--resolution", default="512x512")
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--threads", type=int, default=os.cpu_count())
    args = ap.parse_args(argv)
    from drt.render import prepare, render

    w, h = (int(v) for v in args.resolution.split("x"))
    print(f"{'scene':28s} {'tris':>9s} {'setup s':>8s} {'render s':>9s} {'ksamples/s':>11s} {'Mrays/s':>8s} {'Embree %':>9s} {'CPU %':>6s}")
    for name, scene in load_scenes(args.scenes):
        scene.render = replace(scene.render, width=w, height=h)
        t0 = time.perf_counter()
        ctx = prepare(scene)
        setup = time.perf_counter() - t0
        cpu0 = time.process_time()
        film = render(scene, spp=args.spp, threads=args.threads, context=ctx)
        cpu = time.process_time() - cpu0
        st = film.stats
        wall = st.seconds
        print(
            f"{name:28s} {scene.triangle_count:9d} {setup:8.2f} {wall:9.2f} {st.camera_paths / wall / 1e3:11.1f} "
            f"{st.rays / wall / 1e6:8.2f} {100 * st.embree_seconds / (wall * st.threads):9.1f} {100 * cpu / (wall * st.threads):6.0f}"
        )


if __name__ == "__main__":
    main()
