"""Rendering on a Dask cluster of local worker processes vs the one-process render.

    python benchmarks/farm_scaling.py [--size 192] [--spp 64] [--workers 1 2 4]

Prints, for the Cornell box at SIZE² and SPP:
1. the one-process render on 1 thread and on every core (the baseline);
2. the cluster render on N worker processes of one thread each (a LocalCluster on this
   machine, warm: every worker has rendered once, so kernels are loaded), with speed-up and
   efficiency = T(1 thread) / (T(N) × min(N, cores));
3. the overhead per task: one worker, the same frame cut into more and more tasks; a line
   T = fixed + n_tasks × overhead fitted to the times, and the task duration (and paths) above
   which the overhead is under 5 % of the task.

Timings include sending the scene and each worker's BVH build (per frame, not per task).
Needs `distributed` (pip install -e ".[farm]"). Prints numbers; asserts nothing.
"""

import argparse
import os
import sys
import time
from dataclasses import replace

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(REPO, "core"))

from drt.farm import plan  # noqa: E402
from drt.farm.client import connect, render_frames  # noqa: E402
from drt.render import render  # noqa: E402
from drt.scene_file import load_scene  # noqa: E402


def cluster_time(address, scene, spp, task_seconds, repeat=1):
    """Best wall time of a cluster render (connect excluded) and its task count."""
    client = connect(address, timeout=60)
    best, tasks = float("inf"), 0
    try:
        for _ in range(repeat):
            t0 = time.perf_counter()
            st = render_frames(client, [None], lambda f: (scene, scene), {"spp": spp},
                               on_frame=lambda f, film: None, task_seconds=task_seconds)
            best = min(best, time.perf_counter() - t0)
            tasks = st.tasks_total
    finally:
        client.close()
    return best, tasks


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--size", type=int, default=192)
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--workers", type=int, nargs="+", default=[1, 2, 4])
    p.add_argument("--repeat", type=int, default=3)
    a = p.parse_args()
    from distributed import LocalCluster

    cores = os.cpu_count() or 1
    scene = load_scene(os.path.join(REPO, "blend_scenes", "cornell_box.npz"))
    scene.render = replace(scene.render, width=a.size, height=a.size)
    paths = a.size * a.size * a.spp
    render(scene, spp=1)  # warm the kernels
    t1 = min(_timed(lambda: render(scene, spp=a.spp, threads=1)) for _ in range(a.repeat))
    tn = min(_timed(lambda: render(scene, spp=a.spp)) for _ in range(a.repeat))
    print(f"Cornell box {a.size}x{a.size} at {a.spp} spp ({paths / 1e6:.2f} M camera paths), {cores} cores")
    print(f"one process, 1 thread:      {t1:7.2f} s  ({paths / t1 / 1e6:.2f} M paths/s)")
    print(f"one process, {cores} threads:     {tn:7.2f} s  speed-up {t1 / tn:.2f}")
    print()
    print("workers  tasks   time s  speed-up  efficiency   (1 thread per worker)")
    for n in a.workers:
        with LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                          dashboard_address=":0", silence_logs=50) as cl:
            cluster_time(cl.scheduler_address, scene, 1, plan.TASK_SECONDS)  # warm the workers
            t, tasks = cluster_time(cl.scheduler_address, scene, a.spp, plan.TASK_SECONDS, a.repeat)
        print(f"{n:7d} {tasks:6d} {t:8.2f} {t1 / t:9.2f} {t1 / (t * min(n, cores)):11.2f}")
    print()
    print("overhead per task (1 worker, 1 thread): the same frame cut into more tasks")
    rows = []
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=":0", silence_logs=50) as cl:
        cluster_time(cl.scheduler_address, scene, 1, plan.TASK_SECONDS)
        plan.MAX_TILE_TASK_FACTOR = 1.0  # cut sample ranges as soon as tiles run out: more tasks
        for ts in (16.0, 4.0, 1.0, 0.25, 0.066, 0.02):
            t, tasks = cluster_time(cl.scheduler_address, scene, a.spp, ts, a.repeat)
            rows.append((tasks, t))
            print(f"  {tasks:5d} tasks of {paths / tasks / 1e3:8.1f} k paths: {t:7.2f} s "
                  f"({(t - t1) / t1 * 100:+6.1f} % vs one process on 1 thread)")
    n = np.array([r[0] for r in rows], float)
    t = np.array([r[1] for r in rows])
    per_task, fixed = np.polyfit(n, t, 1)
    path_s = t1 / paths
    min_task = per_task / 0.05
    print(f"fit: time = {fixed:.2f} s + tasks x {per_task * 1e3:.1f} ms "
          f"(fixed part vs one process on 1 thread: {fixed - t1:+.2f} s: scene transfer and BVH build)")
    print(f"overhead < 5 % for tasks of >= {min_task:.2f} s, i.e. >= {min_task / path_s / 1e3:.0f} k camera paths "
          f"at this scene's {1 / path_s / 1e6:.2f} M paths/s; DRT's default target: {plan.TASK_SECONDS:g} s "
          f"({plan.TASK_SECONDS * plan.PATHS_PER_SECOND / 1e3:.0f} k paths)")


def _timed(fn):
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


if __name__ == "__main__":
    main()
