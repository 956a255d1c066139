"""What `shade` executes a path, counted: instructions, branches and cache misses, free of timing noise.

    python benchmarks/shade_instructions.py [SCENE.npz] [--bounce 0] [--resolution 128x128]
                                            [--repeat 5] [--cache DIR]

Timings on the shared 2-vCPU machine move by ±15–30 % from hour to hour, and `shade_batch.py`'s
best-of-N still moves by a few percent: too much to see a change worth 2 % of `shade`. A count
of executed instructions does not move. This script runs ``shade_batch.py`` (the same captured
batch at bounce ``--bounce``) under valgrind's cachegrind twice, each copying the batch's
input ``--repeat`` + 1 times, one calling `shade` on one copy and one on every copy, and prints
the difference per path and call (the render that captured the batch and the copies cancel):

- instructions and branches (exact: the same input runs the same instructions),
- cachegrind's *simulated* first-level instruction and data cache misses (a 32 KB, 8-way L1i
  and a 48 KB, 12-way L1d) and branch mispredictions (its simple predictor): indications only.

A count is not a time: a division costs more than an addition, and the processor runs several
instructions a cycle. But on this machine `shade` runs at a high rate of instructions per
cycle (~2 400 instructions in ~130 ns a Cornell path), so fewer instructions are what makes it
faster (docs/kernels.md, "What shade executes").

valgrind 3.19 does not decode AVX-512, so the kernels are compiled for the portable x86-64-v3
target (``drt.kernels.prebuilt.PORTABLE_X86_64``) into their own cache (``--cache``, default
``bench_out/shade_instructions/cache``; the first run compiles it natively, ~1 min). Needs
``valgrind`` on the PATH. Asserts nothing.
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

#: cachegrind's summary lines: name → the label it prints
_COUNTS = {"instructions": "I   refs", "I1 misses": "I1  misses", "D1 misses": "D1  misses",
           "branches": "Branches", "mispredicts": "Mispredicts"}


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


def _counts(text: str) -> dict:
    """cachegrind's totals from its summary on stderr."""
    out = {}
    for name, label in _COUNTS.items():
        m = re.search(re.escape(label) + r":\s+([\d,]+)", text)
        if m:
            out[name] = int(m.group(1).replace(",", ""))
    return out


def _run(cmd, env) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene", nargs="?", default=os.path.join(REPO, "blend_scenes", "cornell_box.npz"))
    ap.add_argument("--bounce", type=int, default=0)
    ap.add_argument("--resolution", default="128x128")
    ap.add_argument("--repeat", type=int, default=5, help="extra calls of shade counted (difference)")
    ap.add_argument("--cache", default=os.path.join(REPO, "bench_out", "shade_instructions", "cache"))
    args = ap.parse_args(argv)

    valgrind = shutil.which("valgrind")
    if valgrind is None:
        print("shade_instructions: needs valgrind on the PATH (Debian: apt install valgrind)", file=sys.stderr)
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

    totals = []
    with tempfile.TemporaryDirectory() as tmp:
        for calls in (1, 1 + args.repeat):
            copies_only = 1 + args.repeat - calls
            # sys.executable, not a launcher script: valgrind does not follow exec by default
            run = _run([valgrind, "--tool=cachegrind", "--cache-sim=yes", "--branch-sim=yes",
                        "--I1=32768,8,64", "--D1=49152,12,64", "--LL=1048576,16,64",
                        f"--cachegrind-out-file={os.path.join(tmp, f'cg.{calls}')}",
                        sys.executable, *batch, "--repeat", str(1 + args.repeat),
                        "--copy-only", str(copies_only)], env)
            counts = _counts(run.stderr)
            if run.returncode != 0 or "instructions" not in counts:
                print(run.stdout + run.stderr[-4000:], file=sys.stderr)
                return 1
            totals.append(counts)
    n = args.repeat * paths
    print(f"{os.path.basename(args.scene)} {args.resolution}, bounce {args.bounce}: {paths} paths, "
          f"{args.repeat} extra calls of shade (x86-64-v3 kernels, cachegrind), per path:")
    for name in _COUNTS:
        if name in totals[0] and name in totals[1]:
            print(f"  {name:13s} {(totals[1][name] - totals[0][name]) / n:9.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
