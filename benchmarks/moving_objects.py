"""What moving objects cost a render, by their number: the tracer's scene of instances
(``drt.trace._Instances``) against the per-object path it replaced, and the same objects
standing still.

    python benchmarks/moving_objects.py [--counts 1,2,3,10,30,100,300] [--repeat 5]

A floor and a grid of N cubes (each 12 triangles), a sun and a grey world, 128 × 128 at 4 spp,
one thread. Each cube translates over the shutter and every other one also turns (a rigid
motion with rotation: Embree's quaternion instances). For each N it prints the best process
CPU time of --repeat renders of: the cubes standing still (no motion at all: one static
scene), the cubes moving through the scene of instances, and moving through the per-object
path (the same tracer with ``instanced`` set to None: each ray tested against every object's
swept box, then a query per object it meets). The three alternate in one process, so the
machine's drift shows in all of them alike. Nothing is asserted: it prints figures.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(HERE), "tests"))


def crowd(n: int, moving: bool):
    """The scene: N cubes on a 20 m floor, moving (translation; every other one turning too)
    or standing where they are at the shutter's start."""
    import numpy as np
    from scene_builders import add_material, add_mesh, base_header, box_mesh, look_at, quad, translation

    from drt.scene import scene_from_dict

    h = base_header(128, 128, 4, world=(0.3, 0.3, 0.3), shutter=[0.0, 1.0],
                    camera={"type": "PERSP", "matrix_world": look_at((0, -14, 8), (0, 0, 0)), "lens": 35.0})
    a = {}
    m = add_material(h, "grey", [{"type": "DIFFUSE", "color": [0.7, 0.7, 0.7]}])
    add_mesh(h, a, "floor", *quad((0, 0, 0), (10, 0, 0), (0, 10, 0)), material=m)
    side = int(math.ceil(math.sqrt(n)))
    for i in range(n):
        x = -8 + 16 * (i % side) / max(side - 1, 1)
        y = -8 + 16 * (i // side) / max(side - 1, 1)
        pos, tri = box_mesh(0.3, 0.6)
        motion = None
        if moving:
            close = np.array(translation(x + 0.3, y, 0.1))
            if i % 2:
                c, s = math.cos(0.6), math.sin(0.6)
                close[:2, :2] = [[c, -s], [s, c]]
            motion = {"matrix_open": translation(x, y, 0), "matrix_close": close.tolist()}
        add_mesh(h, a, f"cube{i}", pos, tri, material=m, matrix=translation(x, y, 0), motion=motion)
    h["lights"].append({"name": "sun", "type": "SUN", "matrix_world": look_at((3, -2, 5), (0, 0, 0)),
                        "color": [1, 1, 1], "strength": 3.0, "angle": 0.05})
    return scene_from_dict(h, a)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--counts", default="1,2,3,10,30,100,300")
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args(argv)
    from drt.render import prepare, render

    print(f"{'cubes':>5}  {'still':>8}  {'instances':>9}  {'per object':>10}  (s, best of {args.repeat}, 1 thread)")
    for n in (int(v) for v in args.counts.split(",")):
        still, moving = crowd(n, False), crowd(n, True)
        c_still, c_moving = prepare(still), prepare(moving)
        instances = c_moving.tracer.instanced
        runs = {"still": (still, c_still, None), "instances": (moving, c_moving, instances),
                "per object": (moving, c_moving, None)}
        for scene, ctx, inst in runs.values():  # load the kernels, touch the memory
            ctx.tracer.instanced = inst
            render(scene, spp=1, threads=1, context=ctx)
        best = {k: math.inf for k in runs}
        for _ in range(max(args.repeat, 1)):
            for name, (scene, ctx, inst) in runs.items():
                ctx.tracer.instanced = inst
                c0 = time.process_time()
                render(scene, spp=4, threads=1, context=ctx)
                best[name] = min(best[name], time.process_time() - c0)
        c_moving.tracer.instanced = instances
        shown = f"{best['instances']:9.3f}" if instances is not None else f"{'(none)':>9}"
        print(f"{n:5d}  {best['still']:8.3f}  {shown}  {best['per object']:10.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
