"""Rendered-viewport latency, memory and stop time, driving the add-on headlessly through bpy.

No GPU is needed: the add-on's ``ViewportSync`` (what ``view_update`` / ``view_draw`` call) is
driven directly. Edits are made with bpy; a ``depsgraph_update_post`` handler hands Blender's
``depsgraph.updates`` to the sync, as ``view_update`` receives them. The view is the scene
camera at 640×360 (its projection from ``camera.calc_matrix_camera``, as a camera view shows).

Prints, per shipped scene:
  first      time from session start (full export, BVH build) to the first (coarse) image
  edit       time from the bpy edit to the first image of the new state, median / max over
             ``--edits`` object moves (includes depsgraph evaluation and the export of the
             edit), and where the session's part of it went (wait for the batches in flight,
             BVH/tables/camera build, the coarse render)
  material   the same for a material colour edit
  view       the same for a view (camera matrix) change
and, once: moving the 1M-triangle sphere of large_mesh (``python blend_scenes/make_all.py
--only large_mesh`` makes it), memory and threads over ``--memory-edits`` edits, and the time
``stop()`` (engine free: Solid mode) takes with a render in flight.

    python benchmarks/viewport.py [--scenes cornell_box dof] [--edits 20] [--memory-edits 1000]
"""

from __future__ import annotations

import argparse
import gc
import os
import statistics
import sys
import threading
import time

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)

import bpy  # noqa: E402

import addon  # noqa: E402
from addon import viewport  # noqa: E402

SCENES = ("cornell_box", "all_lights", "dof", "glossy_glass", "motion_blur")
W, H = 640, 360


def rss_mb() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def open_scene(name: str):
    if not hasattr(bpy.types.Scene, "drt"):
        addon.register()
    bpy.ops.wm.open_mainfile(filepath=os.path.join(REPO, "blend_scenes", f"{name}.blend"))
    return bpy.context.scene


def camera_view(scene, depsgraph, cam_obj=None):
    """The core camera of a camera view that shows exactly the camera frame at W×H."""
    interactive = viewport.compat.core_module("interactive")
    cam = cam_obj or scene.camera
    proj = np.array(cam.calc_matrix_camera(depsgraph, x=W, y=H), dtype=np.float64)
    d = viewport.camera_dict(cam, cam.matrix_world.copy())
    return interactive.camera_from_projection(np.array(d["matrix_world"]), proj, lens=d["lens"],
                                              clip_start=d["clip_start"], clip_end=d["clip_end"],
                                              dof=d["dof"])


class Driver:
    """A viewport session on the current scene, fed by the depsgraph handler."""

    def __init__(self, threads=None, spp=1 << 16):
        self.vp = viewport.ViewportSync(threads=threads)
        self.spp = spp
        self._handler = lambda scene, depsgraph: self.vp.sync(depsgraph)
        bpy.app.handlers.depsgraph_update_post.append(self._handler)
        t0 = time.perf_counter()
        dg = bpy.context.evaluated_depsgraph_get()
        self.vp.sync(dg)
        self.vp.set_view(camera_view(bpy.context.scene, dg), W, H, spp)
        self.first = self.wait_new(t0, 600)

    def wait_new(self, t0, timeout=30.0):
        """Seconds from t0 to the first frame of the session's current generation."""
        s = self.vp.session
        f = s.wait(lambda f: True, timeout)
        if f is None:
            raise RuntimeError(f"no frame: {s.error}")
        return s._requested_at + f.seconds - t0

    def edit(self, fn, settle: float = 0.15):
        """Run a bpy edit; return (seconds to its first frame, session timings)."""
        time.sleep(settle)  # let the render of the previous state get going (a realistic load)
        gen = self.vp.session.generation
        t0 = time.perf_counter()
        fn()
        bpy.context.evaluated_depsgraph_get()  # evaluates; the handler syncs the session
        if self.vp.session.generation == gen:
            raise RuntimeError("the edit did not restart the session")
        f = self.vp.session.wait(lambda f: True, 30)
        if f is None:
            raise RuntimeError(f"no frame: {self.vp.session.error}")
        done = self.vp.session._requested_at + f.seconds
        return done - t0, dict(self.vp.session.timings)

    def view(self, matrix_fn, settle: float = 0.15):
        time.sleep(settle)
        t0 = time.perf_counter()
        dg = bpy.context.evaluated_depsgraph_get()
        scene = bpy.context.scene
        cam = camera_view(scene, dg)
        cam.matrix = matrix_fn(cam.matrix)
        self.vp.set_view(cam, W, H, self.spp)
        f = self.vp.session.wait(lambda f: True, 30)
        return self.vp.session._requested_at + f.seconds - t0, dict(self.vp.session.timings)

    def close(self):
        bpy.app.handlers.depsgraph_update_post.remove(self._handler)
        t0 = time.perf_counter()
        ok = self.vp.stop(timeout=5.0)
        return ok, time.perf_counter() - t0


def fmt(samples) -> str:
    xs = [s for s, _ in samples]
    return f"median {statistics.median(xs) * 1e3:6.1f} ms  max {max(xs) * 1e3:6.1f} ms"


def breakdown(samples) -> str:
    keys = ("wait", "edits", "build", "render")
    med = {k: statistics.median([t.get(k, 0.0) for _, t in samples]) * 1e3 for k in keys}
    return "  (session: " + ", ".join(f"{k} {v:.1f}" for k, v in med.items()) + " ms)"


def movable(scene):
    return [o for o in scene.objects if o.type == "MESH" and o.visible_get()]


def bench_scene(name: str, n_edits: int) -> None:
    scene = open_scene(name)
    d = Driver()
    print(f"{name:13s} first image {d.first:6.2f} s ({d.vp.session.live.triangle_count} triangles)")
    obj = movable(scene)[-1]
    moves = []
    for i in range(n_edits):
        def move(i=i):
            obj.location.x += 0.01 if i % 2 == 0 else -0.01
        moves.append(d.edit(move))
    print(f"  move '{obj.name}':     {fmt(moves)}{breakdown(moves)}")
    mat = next((m for m in bpy.data.materials if m.users and m.node_tree), None)
    if mat is not None:
        node = next((n for n in mat.node_tree.nodes if "Color" in n.inputs or "Base Color" in n.inputs), None)
        sock = node.inputs.get("Base Color") or node.inputs.get("Color")
        edits = []
        for i in range(max(3, n_edits // 4)):
            def recolor(i=i):
                sock.default_value = (0.2 + 0.1 * (i % 5), 0.5, 0.5, 1.0)
            edits.append(d.edit(recolor))
        print(f"  material '{mat.name}': {fmt(edits)}{breakdown(edits)}")
    views = []
    for i in range(max(3, n_edits // 4)):
        def turn(m, i=i):
            m = m.copy()
            m[0, 3] += 0.01 * (i + 1)
            return m
        views.append(d.view(turn))
    print(f"  view change:        {fmt(views)}{breakdown(views)}")
    print(f"  exports {d.vp.exports}  builds {d.vp.session.live.counters}")
    ok, secs = d.close()
    print(f"  stop {secs * 1e3:.1f} ms (thread ended: {ok})")


def bench_large(n_edits: int) -> None:
    path = os.path.join(REPO, "blend_scenes", "large_mesh.blend")
    if not os.path.exists(path):
        print("large_mesh: not generated (python blend_scenes/make_all.py --only large_mesh)")
        return
    open_scene("large_mesh")
    bpy.ops.mesh.primitive_cube_add(size=0.3, location=(1.3, -1.0, 0.0))  # a small object too
    small = bpy.context.active_object
    big = bpy.data.objects["BigSphere"]
    d = Driver()
    live = d.vp.session.live
    print(f"large_mesh    first image {d.first:6.2f} s ({live.triangle_count} triangles, "
          f"{live.instance_count} own-BVH objects)")
    for obj in (big, small):
        moves = []
        for i in range(n_edits):
            def move(i=i, obj=obj):
                obj.location.z += 0.01 if i % 2 == 0 else -0.01
            moves.append(d.edit(move, settle=0.3))
        print(f"  move '{obj.name}': {fmt(moves)}{breakdown(moves)}")
    print(f"  exports {d.vp.exports}  builds {live.counters}")
    ok, secs = d.close()
    print(f"  stop {secs * 1e3:.1f} ms (thread ended: {ok})")


def bench_memory(n: int) -> None:
    scene = open_scene("cornell_box")
    d = Driver()
    obj = movable(scene)[-1]
    mat = next(m for m in bpy.data.materials if m.users and m.node_tree)
    node = next(n for n in mat.node_tree.nodes if "Color" in n.inputs or "Base Color" in n.inputs)
    sock = node.inputs.get("Base Color") or node.inputs.get("Color")

    def one(i):
        if i % 10 == 9:
            sock.default_value = (0.2 + 0.05 * (i % 7), 0.5, 0.5, 1.0)
        else:
            obj.location.x += 0.001 if i % 2 == 0 else -0.001

    warm = min(100, n // 10)
    for i in range(warm):
        d.edit(lambda i=i: one(i), settle=0.0)
    gc.collect()
    rss0, threads0, objs0 = rss_mb(), threading.active_count(), len(gc.get_objects())
    t0 = time.perf_counter()
    series = []
    for i in range(warm, n):
        d.edit(lambda i=i: one(i), settle=0.0)
        if (i + 1) % 100 == 0:
            series.append(f"{rss_mb():.1f}")
    gc.collect()
    rss1, threads1, objs1 = rss_mb(), threading.active_count(), len(gc.get_objects())
    print(f"memory over {n - warm} edits (after {warm} warm-up; {time.perf_counter() - t0:.0f} s): "
          f"RSS {rss0:.1f} → {rss1:.1f} MB (every 100 edits: {' '.join(series)}), "
          f"threads {threads0} → {threads1} (render threads come and go), "
          f"Python objects {objs0} → {objs1}")
    d.close()


def bench_stop(repeats: int = 5) -> None:
    open_scene("glossy_glass")
    times = []
    for _ in range(repeats):
        d = Driver()
        time.sleep(1.0)  # full-resolution samples in flight
        before = threading.active_count()
        ok, secs = d.close()
        times.append(secs)
        left = [t.name for t in threading.enumerate() if t is not threading.main_thread()]
        assert ok and not left, left
    print(f"stop with a render in flight ({before} threads before): median "
          f"{statistics.median(times) * 1e3:.1f} ms, max {max(times) * 1e3:.1f} ms, "
          f"threads left: 0")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scenes", nargs="*", default=list(SCENES))
    p.add_argument("--edits", type=int, default=20)
    p.add_argument("--memory-edits", type=int, default=1000)
    p.add_argument("--no-large", action="store_true")
    a = p.parse_args(argv)
    print(f"viewport {W}x{H}, {os.cpu_count()} CPUs, load {os.getloadavg()[0]:.1f}")
    for name in a.scenes:
        bench_scene(name, a.edits)
    if not a.no_large:
        bench_large(a.edits)
    if a.memory_edits:
        bench_memory(a.memory_edits)
    bench_stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
