"""What `shade` executes a path, counted: instructions, branches and cache misses, free of timing noise.

    python benchmarks/shade_instructions.py [SCENE.npz] [--bounce 0] [--resolution 128x128]
                                            [--repeat 5] [--cache DIR] [--top 15]

Timings on the shared 2-vCPU machine move by ±15–30 % from hour to hour, and `shade_batch.py`'s
best-of-N still moves by a few percent: too much to see a change worth 2 % of `shade`. A count
of executed instructions does not move. This script runs ``shade_batch.py`` (the same captured
batch at bounce ``--bounce``) under valgrind's callgrind twice, each copying the batch's input
``--repeat`` + 1 times, one calling `shade` on one copy and one on every copy. It counts, per
instruction of `shade`'s machine code (its module: `shade` and the callees compiled into it,
not libm's functions it calls), and prints the difference per path and call — the render that
captured the batch and the copies cancel:

- instructions and branches (exact: the same input runs the same instructions; whole-process
  counts are not, Python's allocator and collector vary from run to run),
- callgrind's *simulated* first-level instruction and data cache misses (a 32 KB, 8-way L1i
  and a 48 KB, 12-way L1d) and branch mispredictions (its simple predictor): indications,
- the 1 KB stretches of the machine code where the instructions are executed, and a listing,
  ``bench_out/shade_instructions/shade.annotated.s``, of the disassembly with each
  instruction's count per path beside it: where the instructions go, inlined callees included
  (they have no symbols: read the listing by its constants and calls).

A count is not a time: a division costs more than an addition, several instructions run in a
cycle, and moving instructions where they overlap other work changes nothing (docs/kernels.md,
"Where `shade`'s time is not"). Count first, then time with `shade_batch.py`.

valgrind 3.19 does not decode AVX-512, so the kernels are compiled for the portable x86-64-v3
target (``drt.kernels.prebuilt.PORTABLE_X86_64``) into their own cache (``--cache``, default
``bench_out/shade_instructions/cache``; the first run compiles it natively, ~1 min). Needs
``valgrind`` and ``objdump`` on the PATH. Asserts nothing.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
SHADE_BATCH = os.path.join(HERE, "shade_batch.py")
OUT = os.path.join(REPO, "bench_out", "shade_instructions")

#: what is printed: name → callgrind's events summed (with --cache-sim=yes --branch-sim=yes)
_REPORT = {"instructions": ("Ir",), "branches": ("Bc", "Bi"), "I1 misses": ("I1mr",),
           "D1 misses": ("D1mr", "D1mw"), "mispredicts": ("Bcm", "Bim")}


def _portable_env(cache: str) -> dict:
    """The environment of a child that compiles for (or loads) the portable x86-64-v3 kernels in
    ``cache``: the target ``drt.kernels.prebuilt`` ships, which valgrind can decode."""
    sys.path.insert(0, os.path.join(REPO, "core"))
    from drt.kernels.prebuilt import PORTABLE_X86_64

    env = dict(os.environ)
    env["DRT_CACHE_DIR"] = cache
    env["NUMBA_CPU_NAME"], env["NUMBA_CPU_FEATURES"] = PORTABLE_X86_64
    env["OPENBLAS_NUM_THREADS"] = "1"
    return env


def _callgrind_costs(path: str, lo: int, hi: int) -> tuple[list, dict]:
    """(event names, {offset from lo: [count per event]}) of the instructions at addresses in
    [lo, hi), from a callgrind file written with ``--dump-instr=yes``: self costs (the inclusive
    cost line after each ``calls=`` is skipped). Addresses in cost lines are absolute (0x…),
    relative to the previous one (+n, −n) or the same (*); omitted trailing costs are zero."""
    events: list = []
    costs: dict = {}
    addr = 0
    after_call = False
    with open(path, encoding="utf-8", errors="replace") as f:
        for line in f:
            if line.startswith("events:"):
                events = line.split()[1:]
                continue
            if line.startswith("calls="):
                after_call = True
                continue
            if not line or line[0] not in "0123456789+-*":
                continue
            parts = line.split()
            a = parts[0]
            if a.startswith("0x"):
                addr = int(a, 16)
            elif a[0] in "+-":
                step = int(a[1:], 16) if a[1:].startswith("0x") else int(a[1:])
                addr += step if a[0] == "+" else -step
            elif a != "*":
                addr = int(a)
            if after_call:
                after_call = False
                continue
            if lo <= addr < hi and len(parts) > 2:
                row = costs.setdefault(addr - lo, [0] * len(events))
                for e, v in enumerate(parts[2:2 + len(events)]):
                    row[e] += int(v)
    return events, costs


def _run(cmd, env) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene", nargs="?", default=os.path.join(REPO, "blend_scenes", "cornell_box.npz"))
    ap.add_argument("--bounce", type=int, default=0)
    ap.add_argument("--resolution", default="128x128")
    ap.add_argument("--repeat", type=int, default=5, help="extra calls of shade counted (difference)")
    ap.add_argument("--cache", default=os.path.join(OUT, "cache"))
    ap.add_argument("--top", type=int, default=15, help="stretches of machine code printed")
    args = ap.parse_args(argv)

    tools = {name: shutil.which(name) for name in ("valgrind", "objdump")}
    if None in tools.values():
        missing = " and ".join(name for name, path in tools.items() if path is None)
        print(f"shade_instructions: needs {missing} on the PATH (Debian: apt install valgrind binutils)",
              file=sys.stderr)
        return 2
    os.makedirs(args.cache, exist_ok=True)
    env = _portable_env(os.path.abspath(args.cache))
    batch = [SHADE_BATCH, args.scene, "--bounce", str(args.bounce), "--resolution", args.resolution]
    # compile (or load) natively first: a compile under valgrind would take hours
    warm = _run([sys.executable, *batch, "--repeat", "1"], env)
    if warm.returncode != 0:
        print(warm.stdout + warm.stderr, file=sys.stderr)
        return 1
    paths = int(re.search(r"(\d+) paths", warm.stdout).group(1))

    counted = []
    with tempfile.TemporaryDirectory() as tmp:
        for calls in (1, 1 + args.repeat):
            prefix = os.path.join(tmp, f"code.{calls}")
            out = os.path.join(tmp, f"callgrind.{calls}")
            # sys.executable, not a launcher script: valgrind does not follow exec by default
            run = _run([tools["valgrind"], "--tool=callgrind", "--dump-instr=yes", "--cache-sim=yes",
                        "--branch-sim=yes", "--I1=32768,8,64", "--D1=49152,12,64", "--LL=1048576,16,64",
                        f"--callgrind-out-file={out}", sys.executable, *batch,
                        "--repeat", str(1 + args.repeat), "--copy-only", str(1 + args.repeat - calls),
                        "--dump-code", prefix], env)
            if run.returncode != 0 or not os.path.exists(out):
                print(run.stdout + run.stderr[-4000:], file=sys.stderr)
                return 1
            with open(prefix + ".addr", encoding="ascii") as f:
                lo = int(f.read(), 16)
            code = prefix + ".bin"
            counted.append(_callgrind_costs(out, lo, lo + os.path.getsize(code)))
        listing = subprocess.run([tools["objdump"], "-D", "-b", "binary", "-m", "i386:x86-64",
                                  "--no-show-raw-insn", code], capture_output=True, text=True, check=True).stdout

    events, once = counted[0]
    _, many = counted[1]
    n = args.repeat * paths
    per_path = {k: [(v - w) / n for v, w in zip(row, once.get(k, [0] * len(events)))] for k, row in many.items()}
    column = {e: i for i, e in enumerate(events)}
    print(f"{os.path.basename(args.scene)} {args.resolution}, bounce {args.bounce}: {paths} paths, "
          f"{args.repeat} extra calls of shade (x86-64-v3 kernels, callgrind), per path in shade's "
          f"machine code:")
    for name, names in _REPORT.items():
        if all(e in column for e in names):
            total = sum(row[column[e]] for row in per_path.values() for e in names)
            print(f"  {name:13s} {total:9.1f}")
    ir = column["Ir"]
    total = sum(row[ir] for row in per_path.values())
    stretches: dict = {}
    for k, row in per_path.items():
        stretches[k // 1024] = stretches.get(k // 1024, 0.0) + row[ir]
    print("  hottest 1 KB stretches (offset from shade's entry: instructions a path, share):")
    for k, v in sorted(stretches.items(), key=lambda kv: -kv[1])[:args.top]:
        print(f"    {k * 1024:#8x} .. {(k + 1) * 1024:#8x}  {v:7.1f}  {100 * v / total:5.1f} %")
    os.makedirs(OUT, exist_ok=True)
    path = os.path.join(OUT, "shade.annotated.s")
    with open(path, "w", encoding="utf-8") as f:
        f.write(f"# {os.path.basename(args.scene)}, bounce {args.bounce}: instructions executed a path "
                f"(shade_instructions.py); offsets from shade's entry\n")
        for line in listing.splitlines():
            m = re.match(r"\s*([0-9a-f]+):", line)
            v = per_path.get(int(m.group(1), 16), [0.0] * len(events))[ir] if m else 0.0
            f.write((f"{v:8.2f} " if v >= 0.005 else " " * 9) + line + "\n")
    print(f"  annotated listing: {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
