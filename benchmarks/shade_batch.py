"""`shade` alone, on one captured batch: a steadier measure of per-hit work than whole renders.

    python benchmarks/shade_batch.py [SCENE.npz] [--bounce 0] [--resolution 256x256]
                                     [--repeat 25]

On the shared 2-vCPU machine whole renders of the same code vary by ±15–30 % from run to run,
which hides a change worth a few percent of `shade`. This script renders SCENE at 1 spp while
keeping a copy of everything `shade` is handed for one batch at bounce ``--bounce`` (the path
state, the hits, the outputs, the shadow-ray queue), then calls the compiled `shade` on fresh
copies of that same input ``--repeat`` times and prints the best time per path. Same input,
same code path, no Embree, no Python between the calls: run it for the old and the new code
alternately (``PYTHONPATH=<old checkout>/core``) and compare the best times.

The copies are made just before each call, so the batch's arrays start in the cache as they do
in a render, where Embree's answers were written just before `shade` reads them. Asserts
nothing.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import replace

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)


def _fresh(x):
    """A copy of every array in x (nested namedtuples of arrays kept as such)."""
    if isinstance(x, np.ndarray):
        return x.copy()
    if isinstance(x, tuple) and hasattr(x, "_fields"):
        return type(x)(*(_fresh(v) for v in x))
    return x


def _dump_code(shade, prefix: str) -> None:
    """shade's machine code in this process: the bytes from its entry to the end of the memory
    mapping that holds it (a little past the function: the listing's tail is other code), and
    the entry's address, which valgrind's per-instruction counts are relative to."""
    import ctypes

    cres = list(shade.overloads.values())[-1]  # (one signature: this scene's variant)
    addr = cres.library.get_pointer_to_function(cres.fndesc.llvm_func_name)
    end = addr + 4096
    with open("/proc/self/maps", encoding="ascii") as f:
        for line in f:
            lo, hi = (int(x, 16) for x in line.split()[0].split("-"))
            if lo <= addr < hi:
                end = hi
    with open(prefix + ".bin", "wb") as f:
        f.write(ctypes.string_at(addr, min(end - addr, 1 << 20)))
    with open(prefix + ".addr", "w", encoding="ascii") as f:
        f.write(f"{addr:#x}\n")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene", nargs="?", default=os.path.join(REPO, "blend_scenes", "cornell_box.npz"))
    ap.add_argument("--bounce", type=int, default=0, help="the bounce (shade's depth_i) to capture")
    ap.add_argument("--resolution", default="256x256")
    ap.add_argument("--repeat", type=int, default=25)
    ap.add_argument("--copy-only", type=int, default=0,
                    help="of the repeats, how many only copy the input without calling shade "
                         "(shade_instructions.py: equal copies in the runs it compares)")
    ap.add_argument("--dump-code", metavar="PREFIX", default=None,
                    help="write shade's machine code (PREFIX.bin, from its first byte to the end of "
                         "its memory mapping) and its address (PREFIX.addr) for shade_instructions.py")
    args = ap.parse_args(argv)

    import drt.integrator as integrator
    from drt.render import prepare, render
    from drt.scene_file import load_scene

    w, h = (int(v) for v in args.resolution.split("x"))
    scene = load_scene(args.scene)
    scene = replace(scene, render=replace(scene.render, width=w, height=h))
    ctx = prepare(scene)
    shade = integrator.stages.shade
    captured = []

    def keep(*a):  # shade's arguments: (..., depth_i at 8, live at 9, ...)
        if a[8] == args.bounce and not captured:
            captured.append(tuple(_fresh(x) for x in a))
        return shade(*a)

    integrator.stages.shade = keep
    try:
        render(scene, spp=1, threads=1, context=ctx)
    finally:
        integrator.stages.shade = shade
    if not captured:
        print(f"no batch reached bounce {args.bounce}", file=sys.stderr)
        return 1
    batch = captured[0]
    live = batch[9]
    best = float("inf")
    for k in range(args.repeat):
        inputs = tuple(_fresh(x) for x in batch)
        if k < args.copy_only:
            continue
        t0 = time.perf_counter()
        shade(*inputs)
        best = min(best, time.perf_counter() - t0)
    if args.dump_code:
        _dump_code(shade, args.dump_code)
    calls = max(args.repeat - args.copy_only, 0)
    print(f"{os.path.basename(args.scene)} {w}x{h}, bounce {args.bounce}: {live} paths, shade best of "
          f"{calls}: {best * 1e3:.2f} ms = {best / live * 1e9:.0f} ns a path")
    return 0


if __name__ == "__main__":
    sys.exit(main())
