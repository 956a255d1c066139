"""Cold compile and warm start of DRT's kernels, with a profile of where the compile goes.

    python benchmarks/compile_cost.py [SCENE.npz] [--top 25] [--profile] [--timeline]

Renders SCENE (default: the shipped Cornell box, 1 spp) in a child process whose kernel cache
is an empty temporary folder (``DRT_CACHE_DIR``), so everything its render needs compiles (as a
user's first render does: helper processes compile on every core, `drt.compile_plan`), then
again in a second child that loads that cache, and prints the wall and CPU time of both
processes (cold compile, warm start).

With ``--profile`` a third child compiles into another empty cache on one core
(``DRT_NO_PRECOMPILE``: the helpers' compile events happen in other processes) and records
numba's compile events (``numba.core.event``: one start/end pair per function numba compiles,
nested as the calls are discovered, and the LLVM lock); the script then also prints

- the CPU time inside numba's compiler, of which LLVM, and the number of functions compiled,
- the functions with the most *exclusive* compile time (their own typing, lowering and LLVM
  work, without the callees compiled while they were typed) and their *inclusive* time.

With ``--timeline`` it also runs the helpers a first render starts (one per core,
`drt.compile_plan.compile_part` for the scene's variant and features) into a third empty cache,
each logging its plan entries, and prints when each helper finished, its summed work, and when
the critical kernel (`shade`) started and ended: the first render's compile is bounded by its
callees shared out, plus `shade` itself (docs/kernels.md).

Asserts nothing; docs/kernels.md ("Cost and cache") records the figures.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)

#: the child: runs the CLI; given a file to write them to, records numba's compile events
#: (drt.kernels first: it sets up numba before numba's first import, as the CLI does)
_CHILD = r"""
import json, os, sys, time
import drt.kernels
from numba.core import event
events = []

class Recorder(event.Listener):
    def _add(self, tag, ev):
        data = ev.data if isinstance(ev.data, dict) else {}
        d = data.get("dispatcher")
        name = getattr(getattr(d, "py_func", None), "__qualname__", "") if d is not None else ""
        module = getattr(getattr(d, "py_func", None), "__module__", "") if d is not None else ""
        events.append((time.process_time(), tag, ev.kind, module + "." + name if name else ""))
    def on_start(self, ev):
        self._add("S", ev)
    def on_end(self, ev):
        self._add("E", ev)

if sys.argv[1] != os.devnull:
    rec = Recorder()
    event.register("numba:compile", rec)
    event.register("numba:llvm_lock", rec)
from drt.cli import main
code = main(sys.argv[2:])
if sys.argv[1] != os.devnull:
    with open(sys.argv[1], "w") as f:
        json.dump(events, f)
sys.exit(code)
"""


#: a helper of the timeline: compile_part with a logger, the start of the clock from its parent
_HELPER = r"""
import json, sys, time
import drt.kernels
from drt import compile_plan as CP
variant, part, parts, features, t0, out = json.loads(sys.argv[1])
log = []
def on_entry(k, entry, start, end):
    log.append((k, entry[0] + "." + entry[1], bool(entry[3]), start, end))
CP.compile_part(variant, part, parts, None, tuple(features), on_entry)
with open(out, "w") as f:
    json.dump({"log": log, "offset": time.time() - time.perf_counter() - t0}, f)
"""


def _cache_env(cache):
    """This environment with the kernel cache at ``cache`` (and no inherited numba cache)."""
    env = dict(os.environ, DRT_CACHE_DIR=cache)
    env.pop("NUMBA_CACHE_DIR", None)
    env.pop("DRT_SET_NUMBA_CACHE_DIR", None)
    return env


def timeline(scene_path, cache, tmp):
    """Run the helpers of a first render of the scene into the empty ``cache``, each logging its
    entries; [(helper, [(k, name, linked, start s, end s), ...])], times from their start."""
    from drt import compile_plan as CP
    from drt.kernels import scene_kernel_variant
    from drt.loaders import load_scene

    scene = load_scene(scene_path)
    variant, features = scene_kernel_variant(scene), CP.scene_features(scene)
    parts = max(CP.helper_count(), 1)
    env = _cache_env(cache)
    t0 = time.time()
    procs, outs = [], []
    for part in range(parts):
        outs.append(os.path.join(tmp, f"helper{part}.json"))
        arg = json.dumps([variant, part, parts, list(features), t0, outs[-1]])
        procs.append(subprocess.Popen([sys.executable, "-c", _HELPER, arg], env=env))
    for p in procs:
        if p.wait() != 0:
            raise SystemExit("a timeline helper failed")
    result = []
    for part, out in enumerate(outs):
        with open(out) as f:
            data = json.load(f)
        off = data["offset"]
        result.append((part, [(k, n, linked, a + off, b + off) for k, n, linked, a, b in data["log"]]))
    return variant, features, result


def _child(args, cache, events=None, serial=False):
    """Run the CLI in a child process with the kernel cache ``cache`` (``serial``: compiling on
    one core, without helpers); (wall s, CPU s)."""
    env = _cache_env(cache)
    if serial:
        env["DRT_NO_PRECOMPILE"] = "1"
    cmd = [sys.executable, "-c", _CHILD, events or os.devnull, *args]
    t0 = time.perf_counter()
    r0 = os.times()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
    r1 = os.times()
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"render failed:\n{proc.stderr[-2000:]}")
    return wall, (r1.children_user - r0.children_user) + (r1.children_system - r0.children_system)


def profile(events):
    """(compile CPU s, LLVM CPU s, functions compiled, {name: [exclusive, inclusive, count]})."""
    stack, table, llvm, llvm_t0, n = [], {}, 0.0, None, 0
    for t, tag, kind, name in events:
        if kind == "numba:llvm_lock":
            if tag == "S":
                llvm_t0 = t
            elif llvm_t0 is not None:
                llvm += t - llvm_t0
            continue
        if tag == "S":
            stack.append([name, t, 0.0])
            continue
        name, t0, children = stack.pop()
        took = t - t0
        row = table.setdefault(name, [0.0, 0.0, 0])
        row[0] += took - children
        row[1] += took
        row[2] += 1
        n += 1
        if stack:
            stack[-1][2] += took
    return sum(r[0] for r in table.values()), llvm, n, table


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene", nargs="?", default=os.path.join(REPO, "blend_scenes", "cornell_box.npz"))
    ap.add_argument("--top", type=int, default=25)
    ap.add_argument("--spp", type=int, default=1)
    ap.add_argument("--profile", action="store_true",
                    help="also compile on one core in a third process and print where the compile goes")
    ap.add_argument("--timeline", action="store_true",
                    help="also run a first render's helpers, logging their entries, and print their timeline")
    o = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="drt_compile_") as tmp:
        cache = os.path.join(tmp, "cache")
        out = os.path.join(tmp, "out.exr")
        events_path = os.path.join(tmp, "events.json")
        args = ["render", o.scene, "-o", out, "--spp", str(o.spp), "--threads", "1"]
        cold_wall, cold_cpu = _child(args, cache)
        warm_wall, warm_cpu = _child(args, cache)
        if o.profile:
            serial_wall, serial_cpu = _child(args, os.path.join(tmp, "serial"), events_path, serial=True)
            with open(events_path) as f:
                events = json.load(f)
        if o.timeline:
            variant, features, helpers = timeline(o.scene, os.path.join(tmp, "timeline"), tmp)
            from drt.compile_plan import CRITICAL_KERNEL
            critical = ".".join(CRITICAL_KERNEL)
    print(f"scene {os.path.basename(o.scene)}, {o.spp} spp, one thread, empty kernel cache")
    print(f"  cold process : {cold_wall:7.1f} s wall, {cold_cpu:7.1f} s CPU (helpers on every core)")
    print(f"  warm process : {warm_wall:7.1f} s wall, {warm_cpu:7.1f} s CPU (same cache, loaded)")
    if o.timeline:
        print(f"  helpers of variant {variant or 'plain'!r}, features {list(features)} (s from their start):")
        for part, log in helpers:
            work = sum(b - a for *_, a, b in log)
            end = max((b for *_, b in log), default=0.0)
            crit = [(a, b) for _, n, linked, a, b in log if not linked and n == critical]
            line = f"    helper {part}: {len(log):4d} entries, {work:5.1f} s of work, done at {end:5.1f} s"
            if crit:
                line += f"; shade from {crit[0][0]:5.1f} to {crit[0][1]:5.1f} s"
            print(line)
    if not o.profile:
        print("  (--profile: where the compile goes, from a serial compile in a third process)")
        return 0
    total, llvm, n, table = profile(events)
    print(f"  serial process: {serial_wall:6.1f} s wall, {serial_cpu:7.1f} s CPU (one core, numba's events recorded)")
    print(f"  numba compiler: {total:.1f} s CPU, of which LLVM {llvm:.1f} s; {n} functions compiled")
    print(f"  top {o.top} by exclusive compile time (s CPU: exclusive, inclusive, compiles):")
    for name, (excl, incl, count) in sorted(table.items(), key=lambda kv: -kv[1][0])[:o.top]:
        print(f"    {excl:7.2f} {incl:7.2f}  x{count:<3d} {name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
