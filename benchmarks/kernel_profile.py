"""Where a render's CPU time goes, down to the compiled kernels: a `perf` profile with symbols.

    python benchmarks/kernel_profile.py [SCENE.npz] [--resolution 256x256] [--spp 16]
                                        [--repeat 3] [--top 25] [--kernel shade]

`perf` cannot name numba's machine code: it lives in anonymous memory. This script compiles the
kernels a render needs into an empty temporary cache (a cold compile, ~1–3 min), keeps the
object code numba generates for each of them, and writes a perf map (``/tmp/perf-PID.map``)
that names every function in the object code of the kernels the render calls from Python —
their private copies of the kernels they call included (``drt.kernels``: linked kernels are
internal to their caller's module, so most of them are inlined and count as their caller).
Then, in the same process, it records the warm renders (one thread) with ``perf record -p`` and
prints

- the share of the samples per shared object and per symbol (kernels as ``entry::function``),
- inside one kernel (``--kernel``, default ``shade``), the hottest 1 KB stretches of its machine
  code by offset and its hottest instructions (``--instructions``), to read next to
  ``objdump -d`` of the object file it saves (``bench_out/kernel_profile/<kernel>.o``).

Needs Linux ``perf`` (and permission to profile one's own processes). Asserts nothing.
"""

from __future__ import annotations

import argparse
import collections
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)


def _capture_object_code() -> dict:
    """Library name -> (object code, library) of every module numba compiles from now on."""
    from numba.core import codegen

    captured = {}
    original = codegen.CPUCodeLibrary._object_compiled_hook.__func__

    def hook(cls, ll_module, buf):
        library = getattr(ll_module, "_CPUCodeLibrary__library", None)
        if library is not None:
            captured[library.name] = (bytes(buf), library)
        return original(cls, ll_module, buf)

    codegen.CPUCodeLibrary._object_compiled_hook = classmethod(hook)
    return captured


def _short(symbol: str) -> str:
    """drt.path_stages.shade for numba's mangled _ZN3drt11path_stages5shadeB...."""
    m = re.match(r"_ZN(.*?)B\d", symbol)
    if not m:
        return symbol
    parts, rest = [], m.group(1)
    while rest:
        n = re.match(r"(\d+)(.*)", rest)
        if not n:
            break
        k = int(n.group(1))
        parts.append(n.group(2)[:k])
        rest = n.group(2)[k:]
    return ".".join(parts) or symbol


def _perf_map(captured: dict, out_dir: str) -> tuple[list[str], dict]:
    """Perf-map lines for the object code of every drt kernel with a compiled overload, and
    {kernel name: (load address, object file)}."""
    lines, bases = [], {}
    for module_name, module in sorted(sys.modules.items()):
        if not (module_name == "drt" or module_name.startswith("drt.")) or module is None:
            continue
        for attr in vars(module).values():
            overloads = getattr(attr, "overloads", None)
            py_func = getattr(attr, "py_func", None)
            if not overloads or py_func is None or py_func.__module__ != module_name:
                continue
            for cres in overloads.values():
                lib = cres.library
                if lib.name not in captured or py_func.__qualname__ in bases:
                    continue
                obj, _ = captured[lib.name]
                path = os.path.join(out_dir, f"{py_func.__qualname__}.o")
                with open(path, "wb") as f:
                    f.write(obj)
                nm = subprocess.run(["nm", "-S", "-n", "--defined-only", path], capture_output=True, text=True)
                syms = []
                for ln in nm.stdout.splitlines():
                    parts = ln.split()
                    if len(parts) == 4 and parts[2] in "tTwW":
                        syms.append((int(parts[0], 16), int(parts[1], 16), parts[3]))
                own = [s for s in syms if s[2] == cres.fndesc.llvm_func_name]
                if not own:
                    continue
                base = lib.get_pointer_to_function(cres.fndesc.llvm_func_name) - own[0][0]
                bases[py_func.__qualname__] = (base, path, own[0][1])
                for off, size, sym in syms:
                    lines.append(f"{base + off:x} {size:x} {py_func.__qualname__}::{_short(sym)}")
    return lines, bases


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene", nargs="?", default=os.path.join(REPO, "blend_scenes", "cornell_box.npz"))
    ap.add_argument("--resolution", default="256x256")
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--top", type=int, default=25)
    ap.add_argument("--instructions", type=int, default=20,
                    help="how many of the kernel's hottest instructions to list")
    ap.add_argument("--kernel", default="shade")
    ap.add_argument("--out", default=os.path.join("bench_out", "kernel_profile"))
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if shutil.which("perf") is None:
        print("kernel_profile: needs Linux `perf` on PATH", file=sys.stderr)
        return 2
    if not args.child:
        # a cold compile into an empty cache, so that numba generates (and we see) the object code
        with tempfile.TemporaryDirectory(prefix="drt-profile-") as cache:
            # and in this process: kernels the precompile helpers compiled would be loaded from
            # the cache as object code the capture never sees, and stay unnamed
            env = dict(os.environ, DRT_CACHE_DIR=cache, DRT_NO_PRECOMPILE="1")
            env.pop("NUMBA_CACHE_DIR", None)
            return subprocess.call([sys.executable, os.path.abspath(__file__), *(argv or sys.argv[1:]), "--child"],
                                   env=env)

    os.makedirs(args.out, exist_ok=True)
    captured = _capture_object_code()
    from dataclasses import replace

    from drt.render import prepare, render
    from drt.scene_file import load_scene

    w, h = (int(v) for v in args.resolution.split("x"))
    scene = load_scene(args.scene)
    scene = replace(scene, render=replace(scene.render, width=w, height=h))
    ctx = prepare(scene)
    t0 = time.perf_counter()
    render(scene, spp=1, threads=1, context=ctx)
    print(f"cold compile + 1 spp: {time.perf_counter() - t0:.1f} s", flush=True)
    lines, bases = _perf_map(captured, args.out)
    map_path = f"/tmp/perf-{os.getpid()}.map"
    with open(map_path, "w") as f:
        f.write("\n".join(lines) + "\n")
    data = os.path.join(args.out, "perf.data")
    perf = subprocess.Popen(["perf", "record", "-q", "-o", data, "-p", str(os.getpid())],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    time.sleep(1.0)  # perf attaches
    c0 = time.process_time()
    for _ in range(args.repeat):
        render(scene, spp=args.spp, threads=1, context=ctx)
    cpu = time.process_time() - c0
    perf.send_signal(signal.SIGINT)
    perf.wait()
    print(f"recorded {args.repeat} renders of {os.path.basename(args.scene)} {w}x{h} at {args.spp} spp, one thread: "
          f"{cpu:.2f} s CPU; {len(lines)} kernel symbols mapped", flush=True)
    try:
        for sort in ("dso", "dso,sym"):
            rep = subprocess.run(["perf", "report", "-i", data, "--sort", sort, "--stdio"], capture_output=True, text=True)
            rows = [ln for ln in rep.stdout.splitlines() if ln.strip() and not ln.startswith("#")]
            print(f"\nshare of samples by {sort}:")
            for ln in rows[:args.top]:
                print("  " + re.sub(r"\s+", " ", ln.strip())[:150])
        if args.kernel in bases:
            base, path, size = bases[args.kernel]
            script = subprocess.run(["perf", "script", "-i", data, "-F", "ip"], capture_output=True, text=True)
            ips = [int(x, 16) for x in script.stdout.split() if re.fullmatch(r"[0-9a-f]+", x)]
            offsets = [ip - base for ip in ips if 0 <= ip - base < size]
            stretches = collections.Counter(o // 1024 for o in offsets)
            print(f"\n{args.kernel}: {len(offsets)} samples in its own function ({size / 1024:.0f} KB of machine "
                  f"code, {path}); hottest 1 KB stretches by offset:")
            for k, v in stretches.most_common(12):
                print(f"  {k * 1024:#8x} .. {(k + 1) * 1024:#8x}  {100 * v / max(len(offsets), 1):5.1f} %")
            # per instruction (samples land on the instruction after a stall, often a load's
            # first use): the offsets to find in `objdump -d` of the saved object file
            hot = collections.Counter(offsets).most_common(args.instructions)
            if hot:
                print(f"hottest instructions of {args.kernel} (offset: share of its samples):")
                print("  " + ", ".join(f"{o:#x}: {100 * v / len(offsets):.1f} %" for o, v in hot))
    finally:
        os.remove(map_path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
