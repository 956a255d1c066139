"""Tracer cost in a scene with moving objects: process CPU time of ``Tracer.intersect`` (plus the
shading normals' map the integrator needs from it) and ``Tracer.occluded`` on 8 fixed batches of
16 384 random rays (half from the shipped motion_blur camera, half from inside the scene), one
thread, best of REPS. Works on older versions of the tracer too (which returned only
``moving_linear``: the map is then computed as the integrator did), for A/B runs.

    python benchmarks/motion_tracer.py blend_scenes/motion_blur.npz 5
"""
import sys, time, numpy as np
from drt.scene_file import load_scene
from drt.geometry import build_geometry
from drt.trace import Tracer
scene = load_scene(sys.argv[1])
geom = build_geometry(scene)
tr = Tracer(geom)
rng = np.random.default_rng(3)
n = 16384
lo, hi = np.array([-3.0, -2.0, 0.0]), np.array([3.0, 2.0, 2.0])
cam = np.array([0.0, -6.0, 2.5]) - geom.origin_shift if hasattr(geom, "origin_shift") else np.array([0.0, -6.0, 2.5])
batches = []
for k in range(8):
    tgt = rng.uniform(lo, hi, (n, 3)) - (geom.origin_shift if hasattr(geom, "origin_shift") else 0)
    o = np.where(rng.random((n, 1)) < 0.5, cam, rng.uniform(lo, hi, (n, 3)) - (geom.origin_shift if hasattr(geom, "origin_shift") else 0))
    d = tgt - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    batches.append((np.ascontiguousarray(o), np.ascontiguousarray(d), rng.random(n), np.full(n, np.inf), rng.uniform(0.5, 6, n)))

def hit_arrays(h):
    if getattr(h, "normal_xform", None) is not None:
        return h.normal_xform, h.moving
    if h.moving_linear is not None:
        from drt.motion import invert_linear
        return np.ascontiguousarray(np.swapaxes(invert_linear(h.moving_linear), 1, 2)), h.prim >= geom.static_count
    return None

def once():
    ti = to = 0.0
    hits = 0
    for o, d, tau, tmax, smax in batches:
        c0 = time.process_time()
        h = tr.intersect(o, d, tau, tmax)
        hit_arrays(h)
        c1 = time.process_time()
        tr.occluded(o, d, smax, tau)
        c2 = time.process_time()
        ti += c1 - c0; to += c2 - c1
        hits += int((h.prim >= geom.static_count).sum())
    return ti, to, hits
once()
res = [once() for _ in range(int(sys.argv[2]))]
print("intersect best %.4f s  occluded best %.4f s  (moving hits %d, rays %d)" % (min(r[0] for r in res), min(r[1] for r in res), res[0][2], 8 * n))
