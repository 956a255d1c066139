"""How fast a render stops when cancelled: the ``cancel`` callback (Esc in Blender) with worker
threads, and SIGINT (Ctrl-C) on the CLI.

    python benchmarks/cancel_latency.py [--repeats 3] [--threads 2] [--resolution 320x240]

Latency = time from the moment the cancel request is made (the callback's deadline passes /
the signal is sent) to the moment ``render()`` returns / the CLI process exits (the CLI's figure
includes writing the partial EXR). Prints min / median / max per mode and the thread count
after the render against the baseline; never asserts anything (tests/test_cancel.py asserts the
behaviour).
"""

from __future__ import annotations

import argparse
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests"))


class CancelAt:
    def __init__(self, delay):
        self.delay, self.t0, self.fired = delay, None, None

    def __call__(self):
        now = time.perf_counter()
        if self.t0 is None:
            self.t0 = now
        if now - self.t0 >= self.delay:
            if self.fired is None:
                # the request counts from the moment it was made (a user pressing Esc), not from
                # the poll that noticed it: the wait for the next poll is part of the latency
                self.fired = self.t0 + self.delay
            return True
        return False


def summary(xs):
    return f"min {min(xs):.3f}  median {statistics.median(xs):.3f}  max {max(xs):.3f} s"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--resolution", default="320x240")
    args = ap.parse_args(argv)
    w, h = (int(v) for v in args.resolution.split("x"))

    from drt.render import BATCH_PATHS, BATCH_PATHS_THREADED, render
    from drt.scene import scene_from_dict
    from drt.scene_file import save_scene
    from scene_builders import cornell_box

    header, arrays = cornell_box(w, h, 4096)
    scene = scene_from_dict(header, arrays)
    print(f"scene: Cornell box {w}x{h}, 4096 spp requested; batches of {BATCH_PATHS if args.threads == 1 else BATCH_PATHS_THREADED} paths; {args.threads} workers")
    baseline = threading.active_count()
    for parallel in ("threads",):
        lat, leftover = [], []
        for i in range(args.repeats):
            cancel = CancelAt(0.5 + 0.5 * i)
            film = render(scene, threads=args.threads, parallel=parallel, cancel=cancel)
            lat.append(time.perf_counter() - cancel.fired)
            time.sleep(0.05)
            leftover.append(threading.active_count() - baseline)
            assert film.stats.cancelled
        print(f"cancel callback, {parallel:9}: {summary(lat)}; extra threads after return: {max(leftover)}")

    lat = []
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "box.npz")
        save_scene(path, header, arrays)
        for i in range(args.repeats):
            out = os.path.join(tmp, f"o{i}.exr")
            p = subprocess.Popen([sys.executable, "-m", "drt", "render", path, "-o", out, "--threads", str(args.threads)],
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
            time.sleep(3.0 + i)
            t0 = time.perf_counter()
            os.killpg(p.pid, signal.SIGINT)  # like Ctrl-C in a terminal: the whole process group
            p.communicate(timeout=60)
            lat.append(time.perf_counter() - t0)
            ok = p.returncode == 130 and os.path.exists(out)
            if not ok:
                print(f"  run {i}: exit {p.returncode}, partial EXR written: {os.path.exists(out)}")
    print(f"CLI SIGINT (incl. EXR write): {summary(lat)}")


if __name__ == "__main__":
    main()
