"""Ray queries against the scene through Embree (embreex), in batches.

embreex's ``run()`` always starts rays at tnear = 0 with ray time 0 and overwrites the ``dists``
array it is given (used as tfar). So:

* self-intersection is avoided by offsetting spawn points along the geometric normal
  (``offset_origin``), by an amount that scales with the point's magnitude;
* a rigidly moving object gets an Embree scene in its local space and each ray is transformed
  into it by the object's transform *at that ray's time* (exact, no time slices). Where Embree's
  C handles are confirmed (``drt.embree_direct``), one kernel per object culls, transforms and
  traces each ray itself, and a deforming mesh is an Embree motion-blur scene (two time steps,
  vertices linear in between, as DRT's model) queried at each ray's time — embreex's batch
  ``run`` has no ray times. Otherwise rigid objects go through embreex's batches and deforming
  meshes through a compiled exact ray/triangle test behind one level of cluster boxes (the
  fallback: linear in the mesh size, fine only for modest meshes).
* with two or more moving objects (and the C handles), every object goes into one Embree scene
  of instances (``_Instances``): the static triangles as they are, each moving object's scene
  under its motion (Embree's quaternion instances: translation and scale linear, rotation by
  slerp, as DRT's), so each ray is one query at its own time whatever the number of objects —
  object by object, each ray met every object's swept box, and 100 moving cubes made a render
  six times as long as the same cubes standing still (docs/kernels.md). Embree evaluates the
  motion in float32; the hit's point, normal and transform are still DRT's own in float64, and
  the instances are checked against the per-object path on probe rays before they are used.

The moving-object work around Embree (swept-box culling, per-ray transforms, merging hits, the
deforming-mesh intersector, hit points and normals) is compiled (``@kernel``, docs/kernels.md);
each query takes its arrays from the caller's ``drt.scratch`` (fresh ones by default, a
thread's own in the render loop), so concurrent queries from several threads are safe.

All positions are in the shifted world frame of ``geometry.SceneGeometry``.
"""

from __future__ import annotations

import math
import time as _time
from collections import namedtuple
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from . import embree_direct
from .embree_direct import occluded1_at, ray_buffer, trace1_at, trace1_instance
from .embree_mesh import deforming_scene, instance_scene, new_device, triangle_scene
from .geometry import SceneGeometry
from .kernels import inline_kernel, kernel
from .kernels.row_chunks import over_rows
from .kernels.vec3 import cross, dot, load, store, sub
from .motion import MotionData, _motion_at_rows, apply_rows, motion_at
from .scratch import FRESH

# Spawn offset: relative part scales with |p| (float32 spacing is 6e-8·|p|, Embree's hit error
# a small multiple of it); the absolute part covers points near the origin.
OFFSET_RELATIVE = 2e-6
OFFSET_ABSOLUTE = 1e-5


@kernel
def offset_point(p, ng, toward):
    """One point p (3-tuple) moved off the surface with unit geometric normal ng to the side
    ``toward`` points to (see ``offset_origin``)."""
    eps = OFFSET_ABSOLUTE + OFFSET_RELATIVE * max(abs(p[0]), max(abs(p[1]), abs(p[2])))
    if ng[0] * toward[0] + ng[1] * toward[1] + ng[2] * toward[2] < 0.0:
        eps = -eps
    return (p[0] + ng[0] * eps, p[1] + ng[1] * eps, p[2] + ng[2] * eps)


@kernel
def _offset_rows(p, ng, toward, out):
    for i in range(p.shape[0]):
        store(out, i, offset_point(load(p, i), load(ng, i), load(toward, i)))


def offset_origin(p: np.ndarray, ng: np.ndarray, toward: np.ndarray) -> np.ndarray:
    """Move ``p`` off the surface with geometric normal ``ng`` to the side ``toward`` points to.

    p, ng, toward: (n, 3) float64 (ng unit). Returns (n, 3) float64.
    """
    def f64(a):
        return np.ascontiguousarray(a, dtype=np.float64).reshape(-1, 3)

    p = f64(p)
    out = np.empty_like(p)
    _offset_rows(p, f64(ng), f64(toward), out)
    return out


@kernel
def static_surface(positions, triangles, face_normals, static_count, d, prim, b1, b2, p, ng):
    """Hit points and unit geometric normals of hits on static triangles, in float64 from the
    triangles themselves (more accurate than Embree's float32 t; the front side is ours). A
    degenerate (zero-area) triangle has no normal: it faces the ray so shading stays finite."""
    for i in range(prim.shape[0]):
        k = prim[i]
        if k < 0 or k >= static_count:
            continue
        static_hit_row(positions, triangles, face_normals, k, b1[i], b2[i], (d[i, 0], d[i, 1], d[i, 2]), p, ng, i)


@inline_kernel
def static_hit_row(positions, triangles, face_normals, k, w1, w2, d, p, ng, i):
    """Row i of ``static_surface``: the point at barycentrics (w1, w2) of static triangle k
    into p[i] and its unit face normal into ng[i] (−d, the ray's 3-tuple direction reversed,
    for a degenerate triangle)."""
    a = triangles[k, 0]
    b = triangles[k, 1]
    c = triangles[k, 2]
    for axis in range(3):
        v0 = float(positions[a, axis])
        p[i, axis] = v0 + w1 * (float(positions[b, axis]) - v0) + w2 * (float(positions[c, axis]) - v0)
        ng[i, axis] = face_normals[k, axis]
    if ng[i, 0] == 0.0 and ng[i, 1] == 0.0 and ng[i, 2] == 0.0:
        for axis in range(3):
            ng[i, axis] = -d[axis]


_NO_TMAX = np.zeros(0)


@kernel
def _rays32(o, d, tmax, o32, d32, t32):
    """Rays as Embree takes them: float32 origins, directions and tfar (clamped to 3e38, the
    largest float32 Embree accepts as "unbounded"); tmax (n,) float64 or (0,): unbounded."""
    for i in range(o.shape[0]):
        for axis in range(3):
            o32[i, axis] = o[i, axis]
            d32[i, axis] = d[i, axis]
        t32[i] = min(tmax[i], 3.0e38) if tmax.shape[0] else 3.0e38


@kernel
def _copy_embree_hits(r_prim, r_tfar, r_u, r_v, i, miss_t, t, prim, b1, b2):
    """Ray i of Embree's answer into float64 arrays: a hit's t, prim and barycentrics, or on a
    miss t = ``miss_t``, prim −1, barycentrics 0. Returns whether it hit."""
    k = r_prim[i]
    if k >= 0:
        t[i] = r_tfar[i]
        prim[i] = k
        b1[i] = r_u[i]
        b2[i] = r_v[i]
        return True
    t[i] = miss_t
    prim[i] = -1
    b1[i] = 0.0
    b2[i] = 0.0
    return False


@kernel
def _static_hits(r_prim, r_tfar, r_u, r_v, o, d, t, prim, b1, b2, p):
    """Embree's static answer in float64 arrays: t (inf on a miss), prim (−1), barycentrics, and
    p = o for misses (hits get their point from the triangle in `static_surface`)."""
    for i in range(r_prim.shape[0]):
        if not _copy_embree_hits(r_prim, r_tfar, r_u, r_v, i, np.inf, t, prim, b1, b2):
            for axis in range(3):
                p[i, axis] = o[i, axis]


def _embree_rays(scratch, n: int):
    """Float32 origins, directions and tfar for one Embree query (`_rays32` fills them)."""
    return (scratch.take("o32", n, (3,), np.float32), scratch.take("d32", n, (3,), np.float32),
            scratch.take("t32", n, (), np.float32))


def _hit_columns(scratch, n: int):
    """A query's t, prim, b1, b2 arrays (filled by the hit kernels)."""
    return (scratch.take("t", n), scratch.take("prim", n, (), np.int64), scratch.take("b1", n),
            scratch.take("b2", n))


@dataclass
class Hits:
    """Closest hits. t: (n,) distance along the unit direction (inf: miss); prim: (n,) global
    triangle id (-1: miss); b1, b2: barycentrics of corners 1 and 2; ng: (n, 3) unit geometric
    normal in world space, facing the triangle's front (counter-clockwise) side; linear: per-ray
    local→world linear map for hits on moving objects (identity rows for static)."""

    t: np.ndarray
    prim: np.ndarray
    b1: np.ndarray
    b2: np.ndarray
    ng: np.ndarray
    moving_linear: np.ndarray | None = None
    p: np.ndarray | None = None  # (n, 3) hit points, float64, shifted world frame
    #: (n, 3, 3) the normal map (inverse transpose of ``moving_linear``) of hits on moving
    #: objects, and (n,) bool: which rays hit one; None when none did
    normal_xform: np.ndarray | None = None
    moving: np.ndarray | None = None

    @property
    def hit(self) -> np.ndarray:
        return self.prim >= 0


@kernel
def _face_normals_into(positions, triangles, out):
    for k in range(triangles.shape[0]):
        a, b, c = triangles[k, 0], triangles[k, 1], triangles[k, 2]
        ax, ay, az = float(positions[a, 0]), float(positions[a, 1]), float(positions[a, 2])
        e1 = (float(positions[b, 0]) - ax, float(positions[b, 1]) - ay, float(positions[b, 2]) - az)
        e2 = (float(positions[c, 0]) - ax, float(positions[c, 1]) - ay, float(positions[c, 2]) - az)
        n = (e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0])
        length = math.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2])
        for axis in range(3):
            out[k, axis] = n[axis] / length if length > 0.0 else 0.0


def _unit_face_normals(positions, triangles) -> np.ndarray:
    """(T, 3) float32 unit geometric normals (e1 × e2, counter-clockwise front), computed in
    float64; zero rows for degenerate (zero-area) triangles. Float32 storage keeps a
    4M-triangle scene at 48 MB; the direction is still good to ~1e-7."""
    out = np.empty((len(triangles), 3), dtype=np.float32)
    over_rows(_face_normals_into, (np.ascontiguousarray(positions), np.ascontiguousarray(triangles), out),
              sliced=(1, 2))
    return out


# ---------------------------------------------------------------------- moving objects: kernels

@kernel
def _fmin(a, b):
    """np.fmin: the smaller value, ignoring a NaN operand."""
    if a != a:
        return b
    if b != b:
        return a
    return a if a < b else b


@kernel
def _fmax(a, b):
    """np.fmax: the larger value, ignoring a NaN operand."""
    if a != a:
        return b
    if b != b:
        return a
    return a if a > b else b


@kernel
def _slab(lo, hi, o, inv_d):
    """Entry and exit distances (near, far) of the ray o + t·d (``inv_d`` = 1/d, 3-tuples)
    through the box [lo, hi]; the ray misses where near > far (or either is NaN). NaNs of 0·inf
    (a ray in a slab's boundary plane) are skipped, as np.fmin/np.fmax do."""
    a0 = (lo[0] - o[0]) * inv_d[0]
    b0 = (hi[0] - o[0]) * inv_d[0]
    a1 = (lo[1] - o[1]) * inv_d[1]
    b1 = (hi[1] - o[1]) * inv_d[1]
    a2 = (lo[2] - o[2]) * inv_d[2]
    b2 = (hi[2] - o[2]) * inv_d[2]
    near = _fmax(_fmax(_fmin(a0, b0), _fmin(a1, b1)), _fmin(a2, b2))
    far = _fmin(_fmin(_fmax(a0, b0), _fmax(a1, b1)), _fmax(a2, b2))
    return near, far


@kernel
def _reciprocal(d):
    return (1.0 / d[0], 1.0 / d[1], 1.0 / d[2])


@kernel
def _inverse_rows(r0, r1, r2):
    """Rows of the inverse of the matrix with rows r0, r1, r2 (cofactors / determinant, as
    ``motion.invert_linear``); a singular matrix (an object scaled to zero) gives zeros, so rays
    mapped through it have no direction and hit nothing."""
    c0 = cross(r1, r2)  # cofactor rows: the inverse's columns
    c1 = cross(r2, r0)
    c2 = cross(r0, r1)
    det = dot(r0, c0)
    scale = max(max(max(abs(r0[0]), abs(r0[1])), max(abs(r0[2]), abs(r1[0]))),
                max(max(abs(r1[1]), abs(r1[2])), max(max(abs(r2[0]), abs(r2[1])), abs(r2[2]))))
    inv_det = 0.0
    if abs(det) > 1e-12 * max(scale, 1e-300) ** 3:
        inv_det = 1.0 / det
    return ((c0[0] * inv_det, c1[0] * inv_det, c2[0] * inv_det),
            (c0[1] * inv_det, c1[1] * inv_det, c2[1] * inv_det),
            (c0[2] * inv_det, c1[2] * inv_det, c2[2] * inv_det))


@kernel
def _ray_to_local(md, tau, o, d):
    """The ray (o, d) in the local space of the object with motion ``md`` at shutter fraction
    tau (direction not renormalised: t stays a world distance)."""
    r0, r1, r2, trans = motion_at(md, tau)
    i0, i1, i2 = _inverse_rows(r0, r1, r2)
    return apply_rows(i0, i1, i2, sub(o, trans)), apply_rows(i0, i1, i2, d)


@kernel
def _store_motion(md, tau, i, linear, translation):
    """Row i of ``linear`` (n, 3, 3) and ``translation`` (n, 3): the object's local→world map
    at tau."""
    r0, r1, r2, trans = motion_at(md, tau)
    for j in range(3):
        linear[i, 0, j] = r0[j]
        linear[i, 1, j] = r1[j]
        linear[i, 2, j] = r2[j]
        translation[i, j] = trans[j]


@kernel
def _in_swept_box(box_lo, box_hi, o, d, tmax):
    """Does the segment (0, tmax) of the ray meet the object's swept box? Rays that miss it
    cannot hit the object at any τ."""
    near, far = _slab((box_lo[0], box_lo[1], box_lo[2]), (box_hi[0], box_hi[1], box_hi[2]),
                      o, _reciprocal(d))
    return near <= far and far >= 0.0 and near <= tmax


@inline_kernel
def _object_ray(md, box_lo, box_hi, o, d, tau, i, tmax):
    """Ray i (rows of o, d, tau) for one moving object: (meets, o_local, d_local) — whether its
    segment (0, tmax) meets the object's swept box and, if so, the ray in the object's space at
    the ray's τ (zeros otherwise)."""
    oi = load(o, i)
    di = load(d, i)
    if not _in_swept_box(box_lo, box_hi, oi, di, tmax):
        return False, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
    o_l, d_l = _ray_to_local(md, tau[i], oi, di)
    return True, o_l, d_l


@kernel
def _rigid_candidates(md, box_lo, box_hi, o, d, tau, tmax, skip, idx, o_local, d_local, tfar):
    """The rays (rows of o, d, tau, tmax; not those with ``skip[i]`` when skip is non-empty)
    whose segment meets the swept box: their indices into ``idx``, their local-space origins and
    directions at their own τ into ``o_local``, ``d_local`` and tmax into ``tfar`` (float32, for
    Embree). Returns the count."""
    count = 0
    check_skip = skip.shape[0] > 0
    for i in range(o.shape[0]):
        if check_skip and skip[i]:
            continue
        meets, o_l, d_l = _object_ray(md, box_lo, box_hi, o, d, tau, i, tmax[i])
        if not meets:
            continue
        idx[count] = i
        for j in range(3):
            o_local[count, j] = o_l[j]
            d_local[count, j] = d_l[j]
        tfar[count] = tmax[i]
        count += 1
    return count


@kernel
def _rigid_merge(md, prim_offset, tau, idx, count, r_t, r_prim, r_u, r_v, t, prim, b1, b2,
                 linear, translation):
    """Merge Embree's hits on a rigid object (row k belongs to ray idx[k]) into the closest
    hits where closer; records the object's local→world map at the ray's τ. Returns the number
    of rays whose hit changed."""
    merged = 0
    for k in range(count):
        i = idx[k]
        if r_prim[k] < 0 or not (r_t[k] < t[i]):
            continue
        t[i] = r_t[k]
        prim[i] = r_prim[k] + prim_offset
        b1[i] = r_u[k]
        b2[i] = r_v[k]
        _store_motion(md, tau[i], i, linear, translation)
        merged += 1
    return merged


@kernel
def _moving_hits(fn, scene, words, timed, dd, md, box_lo, box_hi, prim_offset, o, d, tau, t, prim,
                 b1, b2, linear, translation):
    """Closest hits against one moving object, each ray that meets its swept box taken into the
    object's space at its own τ, merged into (t, prim, b1, b2) where closer, with the object's
    local→world map. ``fn`` ≠ 0: traced here by Embree (``rtcIntersect1`` on ``scene``, through
    ``embree_direct``; ``timed``: a deforming mesh's motion-blur scene, seen at time τ) — for a
    rigid object the same float32 rays and answers as `_rigid_candidates`, embreex and
    `_rigid_merge`; ``fn`` = 0: the exact intersector of the deforming mesh ``dd``.
    Returns (rays merged, rays traced by Embree)."""
    bits, base, addr = ray_buffer(words)
    merged = 0
    traced = 0
    for i in range(o.shape[0]):
        meets, o_l, d_l = _object_ray(md, box_lo, box_hi, o, d, tau, i, t[i])
        if not meets:
            continue
        if fn != 0:
            tt, k, u, v = trace1_at(fn, scene, words, bits, base, addr, o_l, d_l, t[i], tau[i] if timed else 0.0)
            traced += 1
        else:
            tt, k, u, v = _deforming_hit(dd, o_l, d_l, tau[i], t[i], False)
        if k < 0 or not (tt < t[i]):
            continue
        t[i] = tt
        prim[i] = k + prim_offset
        b1[i] = u
        b2[i] = v
        _store_motion(md, tau[i], i, linear, translation)
        merged += 1
    return merged, traced


@kernel
def _moving_blocked(fn, scene, words, timed, dd, md, box_lo, box_hi, o, d, tau, tmax, blocked):
    """`_moving_hits` for occlusion: marks ``blocked`` the rays not yet blocked that hit the
    object in (0, tmax) (``fn`` ≠ 0: ``rtcOccluded1``). Returns the rays traced by Embree."""
    bits, base, addr = ray_buffer(words)
    traced = 0
    for i in range(o.shape[0]):
        if blocked[i]:
            continue
        meets, o_l, d_l = _object_ray(md, box_lo, box_hi, o, d, tau, i, tmax[i])
        if not meets:
            continue
        if fn != 0:
            traced += 1
            hit = occluded1_at(fn, scene, words, bits, base, addr, o_l, d_l, tmax[i], tau[i] if timed else 0.0)
        else:
            hit = _deforming_hit(dd, o_l, d_l, tau[i], tmax[i], True)[1] >= 0
        if hit:
            blocked[i] = True
    return traced


@kernel
def _merge_blocked(idx, count, result, blocked):
    """Occlusion answers from Embree (row k: ray idx[k]; >= 0 means blocked)."""
    for k in range(count):
        if result[k] >= 0:
            blocked[idx[k]] = True


@kernel
def _deformed_vertex(dd, vertex, tau):
    """A deforming mesh's vertex at shutter fraction tau (linear between open and close)."""
    w = tau
    c = 1.0 - w
    return (c * dd.positions[vertex, 0] + w * dd.positions_close[vertex, 0],
            c * dd.positions[vertex, 1] + w * dd.positions_close[vertex, 1],
            c * dd.positions[vertex, 2] + w * dd.positions_close[vertex, 2])


@kernel
def _triangle_hit(dd, k, o, d, tau, t_best):
    """Möller–Trumbore against triangle k of the deforming mesh at tau: (t, u, v), t = -1 unless
    the hit lies in (0, t_best)."""
    v0 = _deformed_vertex(dd, dd.triangles[k, 0], tau)
    v1 = _deformed_vertex(dd, dd.triangles[k, 1], tau)
    v2 = _deformed_vertex(dd, dd.triangles[k, 2], tau)
    e1 = sub(v1, v0)
    e2 = sub(v2, v0)
    pvec = cross(d, e2)
    det = dot(e1, pvec)
    if not (abs(det) > 1e-20):
        return -1.0, 0.0, 0.0
    inv_det = 1.0 / det
    tvec = sub(o, v0)
    u = dot(tvec, pvec) * inv_det
    qvec = cross(tvec, e1)
    v = dot(d, qvec) * inv_det
    tt = dot(e2, qvec) * inv_det
    if u >= 0.0 and v >= 0.0 and u + v <= 1.0 and tt > 0.0 and tt < t_best:
        return tt, u, v
    return -1.0, 0.0, 0.0


@kernel
def _deforming_hit(dd, o, d, tau, tmax, any_hit):
    """The closest hit in (0, tmax) of the ray (o, d) (local space, 3-tuples) against the
    deforming mesh at tau: (t, triangle, b1, b2), triangle -1 on a miss. The whole-mesh box,
    then each cluster's box (bounding its motion over the shutter) cull; ``any_hit`` returns at
    the first hit found (occlusion)."""
    inv_d = _reciprocal(d)
    t_best = tmax
    best = -1
    bu = 0.0
    bv = 0.0
    near, far = _slab((dd.all_lo[0], dd.all_lo[1], dd.all_lo[2]),
                      (dd.all_hi[0], dd.all_hi[1], dd.all_hi[2]), o, inv_d)
    if not (near <= far and far > 0.0 and near < t_best):
        return t_best, best, bu, bv
    n_tri = dd.triangles.shape[0]
    for c in range(dd.lo.shape[0]):
        near, far = _slab(load(dd.lo, c), load(dd.hi, c), o, inv_d)
        if not (near <= far and far > 0.0 and near < t_best):
            continue
        for k in range(c * CLUSTER_SIZE, min((c + 1) * CLUSTER_SIZE, n_tri)):
            tt, u, v = _triangle_hit(dd, k, o, d, tau, t_best)
            if tt > 0.0:
                t_best = tt
                best = k
                bu = u
                bv = v
                if any_hit:
                    return t_best, best, bu, bv
    return t_best, best, bu, bv


@kernel
def _deforming_rows(dd, o, d, tau, t, prim, b1, b2):
    """``_deforming_hit`` for every row (rays already in the mesh's space); t holds tmax."""
    for i in range(o.shape[0]):
        tt, k, u, v = _deforming_hit(dd, load(o, i), load(d, i), tau[i], t[i], False)
        if k >= 0:
            t[i] = tt
            prim[i] = k
            b1[i] = u
            b2[i] = v


@kernel
def _static_first(r_prim, r_tfar, r_u, r_v, tmax, t, prim, b1, b2):
    """Embree's static answer as the start of a moving scene's closest hits: a hit's t, prim
    and barycentrics; a miss keeps t = min(tmax, 3e38) (tmax (0,): unbounded), the bound the
    moving objects are then searched within, and prim −1."""
    for i in range(r_prim.shape[0]):
        _copy_embree_hits(r_prim, r_tfar, r_u, r_v, i, min(tmax[i], 3.0e38) if tmax.shape[0] else 3.0e38,
                          t, prim, b1, b2)


@kernel
def _unbounded_start(tmax, t, prim, b1, b2):
    """The start of the closest hits when no static scene exists: nothing hit, t = min(tmax,
    3e38)."""
    for i in range(t.shape[0]):
        t[i] = min(tmax[i], 3.0e38) if tmax.shape[0] else 3.0e38
        prim[i] = -1
        b1[i] = 0.0
        b2[i] = 0.0


@kernel
def _finish_moving_hits(prim, first_moving, o, d, t, p, ng, linear, moving):
    """After every object merged its hits: misses get t = inf and p = o (ng 0), rays that hit
    nothing moving get identity rows in ``linear``; ``moving[i]``: ray i hit a moving object
    (whose p, ng come from `_moving_surface`). Returns whether any ray did."""
    any_moving = False
    for i in range(prim.shape[0]):
        k = prim[i]
        if k >= first_moving:
            moving[i] = True
            any_moving = True
            continue
        moving[i] = False
        for r in range(3):
            for c in range(3):
                linear[i, r, c] = 1.0 if r == c else 0.0
        if k < 0:
            t[i] = np.inf
            for axis in range(3):
                p[i, axis] = o[i, axis] + 0.0 * d[i, axis]
                ng[i, axis] = 0.0
    return any_moving


@kernel
def _moving_surface(positions, positions_close, deforming, triangles, prim_offset, tau, d, prim,
                    b1, b2, linear, translation, p, ng, normal_xform):
    """Hit points and unit geometric normals (front = counter-clockwise side) of the hits on
    one moving object (`_moving_surface_row` for each ray that hit one of its triangles)."""
    n_tri = triangles.shape[0]
    for i in range(prim.shape[0]):
        k = prim[i] - prim_offset
        if k < 0 or k >= n_tri:
            continue
        _moving_surface_row(positions, positions_close, deforming, triangles, k, tau, d, b1, b2, linear,
                            translation, p, ng, normal_xform, i)


@inline_kernel
def _moving_surface_row(positions, positions_close, deforming, triangles, k, tau, d, b1, b2, linear,
                        translation, p, ng, normal_xform, i):
    """Ray i hit triangle k (a row of ``triangles``, indexing ``positions``) of a moving object:
    its hit point into p[i] and unit geometric normal into ng[i], in float64 from the local
    triangle (at the ray's τ if it deforms: vertices lerp to ``positions_close``) mapped by the
    hit's local→world transform (rows i of ``linear``, ``translation``). Normals go through the
    inverse transpose, which goes to ``normal_xform`` (n, 3, 3) for the shading normals (when it
    has rows). A degenerate (zero-area) triangle has no normal: it faces the ray."""
    a = triangles[k, 0]
    b = triangles[k, 1]
    c = triangles[k, 2]
    if deforming:
        w = tau[i]
        cw = 1.0 - w
        v0 = (cw * positions[a, 0] + w * positions_close[a, 0],
              cw * positions[a, 1] + w * positions_close[a, 1],
              cw * positions[a, 2] + w * positions_close[a, 2])
        v1 = (cw * positions[b, 0] + w * positions_close[b, 0],
              cw * positions[b, 1] + w * positions_close[b, 1],
              cw * positions[b, 2] + w * positions_close[b, 2])
        v2 = (cw * positions[c, 0] + w * positions_close[c, 0],
              cw * positions[c, 1] + w * positions_close[c, 1],
              cw * positions[c, 2] + w * positions_close[c, 2])
    else:
        v0 = load(positions, a)
        v1 = load(positions, b)
        v2 = load(positions, c)
    e1 = sub(v1, v0)
    e2 = sub(v2, v0)
    u = b1[i]
    v = b2[i]
    p_local = (v0[0] + u * e1[0] + v * e2[0], v0[1] + u * e1[1] + v * e2[1],
               v0[2] + u * e1[2] + v * e2[2])
    r0 = (linear[i, 0, 0], linear[i, 0, 1], linear[i, 0, 2])
    r1 = (linear[i, 1, 0], linear[i, 1, 1], linear[i, 1, 2])
    r2 = (linear[i, 2, 0], linear[i, 2, 1], linear[i, 2, 2])
    pw = apply_rows(r0, r1, r2, p_local)
    for j in range(3):
        p[i, j] = pw[j] + translation[i, j]
    i0, i1, i2 = _inverse_rows(r0, r1, r2)
    if normal_xform.shape[0] > 0:  # (the inverse's transpose: row r holds column r of the inverse)
        for r in range(3):
            normal_xform[i, r, 0] = i0[r]
            normal_xform[i, r, 1] = i1[r]
            normal_xform[i, r, 2] = i2[r]
    n_l = cross(e1, e2)
    nx = i0[0] * n_l[0] + i1[0] * n_l[1] + i2[0] * n_l[2]
    ny = i0[1] * n_l[0] + i1[1] * n_l[1] + i2[1] * n_l[2]
    nz = i0[2] * n_l[0] + i1[2] * n_l[1] + i2[2] * n_l[2]
    length = math.sqrt(nx * nx + ny * ny + nz * nz)
    if length > 0.0:
        ng[i, 0] = nx / length
        ng[i, 1] = ny / length
        ng[i, 2] = nz / length
    else:
        ng[i, 0] = -d[i, 0]
        ng[i, 1] = -d[i, 1]
        ng[i, 2] = -d[i, 2]


# ---------------------------------------------------------------------- moving objects: one scene

MotionStack = namedtuple("MotionStack", MotionData._fields)
MotionStack.__doc__ = """The rigid motions of several objects for the kernels: ``MotionData``'s
fields with one row per object (q0, q1 (K, 4); omega (K,); scale0, scale1, trans0, trans1
(K, 3); float64)."""


@inline_kernel
def _motion_row(ms, k):
    """Object k's ``MotionData`` from a ``MotionStack`` (views of its rows)."""
    return MotionData(ms.q0[k], ms.q1[k], ms.omega[k], ms.scale0[k], ms.scale1[k], ms.trans0[k], ms.trans1[k])


@kernel
def _instanced_hits(fn, scene, words, inst_offset, inst_object, ms, o, d, tau, tmax, t, prim, b1, b2,
                    obj, linear, translation, p, ng, moving):
    """Closest hits of every ray against a scene of instances (``_Instances``): one Embree query
    at the ray's τ finds the nearest of the static triangles and every moving object (each seen
    where it is at that τ). Writes t (inf on a miss), prim (global triangle id: ``inst_offset``
    of the instance hit + its triangle; −1), b1, b2, obj (the moving object's index, from
    ``inst_object``; −1 for static hits and misses), ``moving``, and for hits on a moving object
    its local→world map at τ into ``linear``, ``translation`` (identity rows otherwise); misses
    get p = o and ng = 0. ``tmax`` (n,) or (0,): unbounded. Returns whether any ray hit a
    moving object (`_instanced_surface` then gives their points and normals)."""
    bits, base, addr = ray_buffer(words)
    bounded = tmax.shape[0] > 0
    any_moving = False
    for i in range(o.shape[0]):
        tt, k, u, v, inst = trace1_instance(fn, scene, words, bits, base, addr, load(o, i), load(d, i),
                                            tmax[i] if bounded else math.inf, tau[i])
        m = inst_object[inst] if inst >= 0 else -1
        obj[i] = m
        moving[i] = m >= 0
        if m >= 0:
            any_moving = True
            _store_motion(_motion_row(ms, m), tau[i], i, linear, translation)
        else:
            for r in range(3):
                for c in range(3):
                    linear[i, r, c] = 1.0 if r == c else 0.0
        if inst < 0:
            t[i] = np.inf
            prim[i] = -1
            b1[i] = 0.0
            b2[i] = 0.0
            for axis in range(3):
                p[i, axis] = o[i, axis] + 0.0 * d[i, axis]
                ng[i, axis] = 0.0
            continue
        t[i] = tt
        prim[i] = inst_offset[inst] + k
        b1[i] = u
        b2[i] = v
    return any_moving


@kernel
def _instanced_surface(positions, positions_close, deforming, triangles, first_moving, obj, tau, d, prim,
                       b1, b2, linear, translation, p, ng, normal_xform):
    """`_moving_surface` for the hits of every moving object at once: ``positions``,
    ``positions_close`` and ``triangles`` are all moving objects' own, concatenated in object
    order (triangle prim − ``first_moving``; a rigid object's close positions are its open
    ones), ``deforming`` (K,) bool per object, ``obj`` each ray's object (−1: none)."""
    for i in range(prim.shape[0]):
        m = obj[i]
        if m < 0:
            continue
        _moving_surface_row(positions, positions_close, deforming[m], triangles, prim[i] - first_moving, tau, d,
                            b1, b2, linear, translation, p, ng, normal_xform, i)


@kernel
def _instanced_blocked(fn, scene, words, o, d, tau, tmax, blocked):
    """Occlusion against a scene of instances: ``blocked[i]`` is whether anything, static or
    moving at the ray's τ, lies in (0, tmax[i])."""
    bits, base, addr = ray_buffer(words)
    for i in range(o.shape[0]):
        blocked[i] = occluded1_at(fn, scene, words, bits, base, addr, load(o, i), load(d, i), tmax[i], tau[i])


# ---------------------------------------------------------------------- moving objects: data

CLUSTER_SIZE = 16  # triangles per bounding box in the deforming-mesh culling level

DeformingData = namedtuple("DeformingData", ["positions", "positions_close", "triangles", "lo",
                                             "hi", "all_lo", "all_hi"])
DeformingData.__doc__ = """A deforming mesh for the kernels, in its local space: positions and
positions_close (V, 3) float64 at shutter open / close (vertices move linearly in between),
triangles (T, 3) int64, and a one-level bounding hierarchy: cluster c holds the CLUSTER_SIZE
consecutive triangles from c·CLUSTER_SIZE (meshes are stored with spatial coherence), its box
lo[c], hi[c] ((C, 3) float64) bounds them over the whole shutter (the box of all vertices at
open and close contains every in-between position); all_lo, all_hi (3,) bound every cluster."""


def deforming_data(mm) -> DeformingData:
    """``DeformingData`` of a mesh with ``positions``, ``positions_close`` and ``triangles``."""
    pos = np.ascontiguousarray(mm.positions, dtype=np.float64)
    pos_close = np.ascontiguousarray(mm.positions_close, dtype=np.float64)
    tri = np.ascontiguousarray(mm.triangles, dtype=np.int64).reshape(-1, 3)
    t = len(tri)
    c = -(-t // CLUSTER_SIZE)
    pad = c * CLUSTER_SIZE - t
    both = np.concatenate([pos[tri], pos_close[tri]], axis=1)  # (T, 6, 3)
    lo = both.min(axis=1)
    hi = both.max(axis=1)
    lo = np.concatenate([lo, np.full((pad, 3), np.inf)]).reshape(c, CLUSTER_SIZE, 3).min(axis=1)
    hi = np.concatenate([hi, np.full((pad, 3), -np.inf)]).reshape(c, CLUSTER_SIZE, 3).max(axis=1)
    if c:
        margin = 1e-7 * (1.0 + np.abs(np.concatenate([lo, hi])).max())
        lo, hi = lo - margin, hi + margin
        all_lo, all_hi = lo.min(axis=0), hi.max(axis=0)
    else:  # no triangles: an empty box
        all_lo, all_hi = np.full(3, np.inf), np.full(3, -np.inf)
    f64 = lambda a: np.ascontiguousarray(a, dtype=np.float64).reshape(-1, 3)  # noqa: E731
    return DeformingData(positions=pos, positions_close=pos_close, triangles=tri, lo=f64(lo),
                         hi=f64(hi), all_lo=f64(all_lo).reshape(3), all_hi=f64(all_hi).reshape(3))


#: `_moving_hits` / `_moving_blocked` arguments of an object without a scene for the kernels:
#: (no rtcIntersect1, no rtcOccluded1, no scene, no owner, untimed), and the empty
#: DeformingData passed for rigid objects (one compiled variant serves both)
_EXACT = (0, 0, 0, None, False)
_NO_DEFORMING = deforming_data(SimpleNamespace(positions=np.zeros((0, 3)), positions_close=np.zeros((0, 3)),
                                               triangles=np.zeros((0, 3), dtype=np.int64)))


def _intersect_deforming(mm, o, d, tau, tmax):
    """Exact closest hits against a deforming mesh (``mm``: positions, positions_close,
    triangles, or its ``DeformingData`` already built) for rays already in its space, each ray
    seeing the mesh at its own τ. Returns (t, prim, b1, b2): t = tmax and prim = -1 where
    nothing is hit in (0, tmax)."""
    dd = mm if isinstance(mm, DeformingData) else deforming_data(mm)
    o = np.ascontiguousarray(o, dtype=np.float64).reshape(-1, 3)
    d = np.ascontiguousarray(d, dtype=np.float64).reshape(-1, 3)
    n = len(o)
    t = np.array(tmax, dtype=np.float64).reshape(n)
    prim = np.full(n, -1, dtype=np.int64)
    b1 = np.zeros(n)
    b2 = np.zeros(n)
    _deforming_rows(dd, o, d, np.ascontiguousarray(tau, dtype=np.float64).reshape(n), t, prim, b1, b2)
    return t, prim, b1, b2


class _MovingObject:
    """One moving object for the tracer: its swept box, its motion for the kernels, and either
    an Embree scene of its local triangles (rigid) or its ``DeformingData``."""

    def __init__(self, mm, fast_build: bool = False, device=None):
        self.mesh = mm
        self.prim_offset = int(mm.prim_offset)
        self.motion = mm.motion.data
        self.positions = np.ascontiguousarray(mm.positions, dtype=np.float64)
        self.triangles = np.ascontiguousarray(mm.triangles, dtype=np.int64)
        self.scene = None
        self.deforming = None
        if mm.positions_close is None:
            self.scene = triangle_scene(mm.positions, mm.triangles, fast_build, device)
            self.positions_close = self.positions
        else:
            self.deforming = deforming_data(mm)
            self.positions_close = self.deforming.positions_close
        # the culling box; setting it to ±inf disables culling (tests)
        self.box_lo, self.box_hi = _swept_box(mm)
        # (rtcIntersect1, rtcOccluded1, RTCScene handle, the scene object that owns it, timed)
        # when kernels may query this object's Embree scene themselves, else None
        self.direct = _direct_scene(self, device)


#: probe rays a moving object's Embree scene must answer as expected before kernels query it
DIRECT_PROBE_RAYS = 256


#: the R3 low-discrepancy sequence's steps (Roberts): 1/φ3, 1/φ3², 1/φ3³ with φ3³ = φ3 + 1
_R3 = np.array([1.0 / 1.2207440846057596 ** k for k in (1, 2, 3)])


def probe_pattern(n: int):
    """A fixed pattern for probe rays, no random generator (a render stays a function of its
    seed alone): (n, 3) points of the R3 sequence in [0, 1)³ and (n, 3) unit vectors on a
    Fibonacci sphere."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    phi = k * (np.pi * (3.0 - np.sqrt(5.0)))
    ring = np.sqrt(np.maximum(1.0 - z * z, 0.0))
    return np.modf(0.5 + k[:, None] * _R3)[0], np.column_stack([ring * np.cos(phi), ring * np.sin(phi), z])


def _probe_rays(positions: np.ndarray, n: int):
    """n rays (float32-representable) from a Fibonacci sphere around the points' box to points
    of an R3 sequence inside it, with tmax inf (most meet the mesh), and a time in [0, 1) each
    (``probe_pattern``)."""
    return _box_probe_rays(positions.min(axis=0), positions.max(axis=0), n)


def _box_probe_rays(lo: np.ndarray, hi: np.ndarray, n: int):
    """`_probe_rays` aimed into the box [lo, hi]: (o, d, tmax, tau)."""
    centre, radius = 0.5 * (lo + hi), 0.5 * math.sqrt(float(((hi - lo) ** 2).sum())) + 1e-3
    k = np.arange(n) + 0.5
    inside, sphere = probe_pattern(n)
    o = centre + 2.0 * radius * sphere
    target = lo + inside * (hi - lo)
    d = target - o
    d /= np.sqrt((d * d).sum(axis=1, keepdims=True))
    tau = np.modf(0.5 + k * 0.6180339887498949)[0]
    return (o.astype(np.float32).astype(np.float64), d.astype(np.float32).astype(np.float64),
            np.full(n, np.inf), tau)


def _direct_scene(obj, device=None):
    """``_MovingObject.direct`` for obj, after checking its Embree scene on probe rays: a rigid
    object's scene must answer exactly as embreex's ``run``; a deforming mesh's motion-blur scene
    as the exact intersector does at random times (same triangle, t within float32 error, on all
    but rays grazing an edge). None (the batch / exact path) when anything is not as expected."""
    try:
        return _checked_direct_scene(obj, device)
    except Exception:  # noqa: BLE001 - any surprise: the batch / exact path is always right
        return None


def _checked_direct_scene(obj, device=None):
    fn_hit, fn_occluded = embree_direct.intersect1_address(), embree_direct.occluded1_address()
    if not fn_hit or not fn_occluded or not len(obj.triangles):
        return None
    o, d, tmax, tau = _probe_rays(obj.positions, DIRECT_PROBE_RAYS)
    if obj.deforming is None:
        if not embree_direct.matches_embreex(obj.scene, o, d, tmax):
            return None
        return fn_hit, fn_occluded, embree_direct.scene_address(obj.scene), obj.scene, False
    scene = deforming_scene(obj.positions, obj.positions_close, obj.triangles, device)
    handle = embree_direct.scene_address(scene) if scene is not None else 0
    if not handle:
        return None
    n = len(o)
    t, prim = np.full(n, np.inf), np.full(n, -1, dtype=np.int64)
    u, v = np.zeros(n), np.zeros(n)
    embree_direct.trace_rows_at(fn_hit, handle, embree_direct.scratch(), o, d, tmax, tau, t, prim, u, v)
    t_ref, prim_ref, *_ = _intersect_deforming(obj.deforming, o, d, tau, tmax)
    same = prim == prim_ref
    both = same & (prim >= 0)
    close = np.all(np.abs(t[both] - t_ref[both]) <= 1e-4 * (1.0 + np.abs(t_ref[both])))
    if not close or same.mean() < 0.98 or both.sum() < min(16, (prim_ref >= 0).sum()):
        return None
    return fn_hit, fn_occluded, handle, scene, True


def _swept_box(mm) -> tuple[np.ndarray, np.ndarray]:
    """World box (tracer space) containing the object at every shutter fraction: local points
    lie within R of the local origin, the linear part stretches them by at most the larger end
    scale (scale is interpolated per axis, rotation is a rotation), and the translation runs
    along the segment between its ends. Padded by a relative 1e-6 for rounding."""
    pts = mm.positions if mm.positions_close is None else np.concatenate([mm.positions, mm.positions_close])
    radius = float(np.sqrt((np.asarray(pts, dtype=np.float64) ** 2).sum(axis=1).max())) if len(pts) else 0.0
    m = mm.motion
    stretch = float(max(np.abs(m.open.scale).max(), np.abs(m.close.scale).max()))
    rho = radius * stretch
    t0, t1 = m.open.translation, m.close.translation
    lo, hi = np.minimum(t0, t1) - rho, np.maximum(t0, t1) + rho
    pad = 1e-6 * (np.abs(lo) + np.abs(hi) + rho) + 1e-9
    f64 = lambda a: np.ascontiguousarray(a, dtype=np.float64).reshape(3).copy()  # noqa: E731
    return f64(lo - pad), f64(hi + pad)


class _Instances:
    """Every object of a scene with moving objects in one Embree scene of instances
    (``embree_mesh.instance_scene``): the static triangles as they are, and each moving object's
    own scene (rigid: its local triangles; deforming: its two-time-step scene) under its motion,
    so one query per ray at the ray's τ replaces a pass over every moving object (whose cost
    grew with their number). Instance k: ``inst_offset[k]`` its first global triangle id,
    ``inst_object[k]`` its index in ``Tracer.moving`` (−1: the static triangles). ``motions``
    (a ``MotionStack``) and the concatenated local triangles of the moving objects give the
    hits' transforms and surfaces, computed by DRT in float64 as on the per-object path."""

    def __init__(self, tracer, scene):
        self.scene = scene  # owns the Embree scene and, through it, the instanced ones
        self.handle = embree_direct.scene_address(scene)
        self.fn_hit = embree_direct.intersect1_address()
        self.fn_occluded = embree_direct.occluded1_address()
        moving = tracer.moving
        first = [0] if tracer.static is not None else []
        self.inst_offset = np.array(first + [obj.prim_offset for obj in moving], np.int64)
        self.inst_object = np.array([-1] * len(first) + list(range(len(moving))), np.int64)
        rows = lambda name: np.ascontiguousarray([getattr(obj.motion, name) for obj in moving],  # noqa: E731
                                                 dtype=np.float64)
        self.motions = MotionStack(*(rows(name) for name in MotionData._fields))
        self.first_moving = int(moving[0].prim_offset)
        # `_instanced_surface` finds a hit's triangle at prim − first_moving in the concatenation
        counts = np.array([len(obj.triangles) for obj in moving])
        if not np.array_equal([obj.prim_offset for obj in moving], self.first_moving + np.cumsum(counts) - counts):
            raise ValueError("moving objects' triangle ids are not consecutive")
        starts = np.cumsum([0] + [len(obj.positions) for obj in moving])
        self.positions = np.ascontiguousarray(np.concatenate([obj.positions for obj in moving]))
        self.positions_close = np.ascontiguousarray(np.concatenate([obj.positions_close for obj in moving]))
        self.triangles = np.ascontiguousarray(np.concatenate(
            [obj.triangles + start for obj, start in zip(moving, starts)]), dtype=np.int64)
        self.deforming = np.array([obj.deforming is not None for obj in moving], dtype=bool)


#: fewest moving objects for a scene of instances. With one, Embree's tree over the moving
#: instances is a single leaf, so every ray pays the instance's interpolated transform (a
#: floor and one moving cube, 128² at 4 spp, one thread: 184-192 ns a ray against 62-79 ns on
#: the per-object path, whose swept box culls first); from two on the tree culls: 60-70 against
#: 70-88 ns with 2-3 moving cubes, 66 against 152 with 10, 113 against 411 with 30
INSTANCED_MIN_OBJECTS = 2

#: probe rays a scene of instances must answer as the per-object path does, for each of up to
#: INSTANCE_PROBE_OBJECTS moving objects (spread over the list), before the tracer uses it
INSTANCE_PROBE_RAYS = 64
INSTANCE_PROBE_OBJECTS = 64


def _instances(tracer, device):
    """``Tracer.instanced``: the scene's ``_Instances``, or None (the per-object path) without
    moving objects, without Embree's checked handles, when an object's scene is not queried by
    the kernels themselves, or when anything is not as expected."""
    try:
        return _checked_instances(tracer, device)
    except Exception:  # noqa: BLE001 - any surprise: the per-object path is always right
        return None


def _checked_instances(tracer, device):
    moving = tracer.moving
    if device is None or len(moving) < INSTANCED_MIN_OBJECTS or any(obj.direct is None for obj in moving):
        return None
    if not embree_direct.occluded1_address():
        return None
    parts = [(tracer.static, None)] if tracer.static is not None else []
    for obj in moving:
        child = obj.scene if obj.deforming is None else obj.direct[3]
        parts.append((child, _instance_placement(obj.motion)))
    scene = instance_scene(device, parts)
    if scene is None:
        return None
    inst = _Instances(tracer, scene)
    return inst if _instances_agree(tracer, inst) else None


def _instance_placement(m):
    """How ``embree_mesh.instance_scene`` places an object with rigid motion ``m`` (a
    ``MotionData``): its (3, 4) local→world map when it stands still over the shutter (a viewport
    object kept apart from the static set, an animated object at rest: Embree's plain instance,
    no interpolation), else its motion's two quaternion decompositions."""
    if (np.array_equal(m.q0, m.q1) and np.array_equal(m.scale0, m.scale1)
            and np.array_equal(m.trans0, m.trans1)):
        linear, translation = np.empty((1, 3, 3)), np.empty((1, 3))
        _motion_at_rows(m, np.zeros(1), linear, translation)
        return np.concatenate([linear[0], translation[0][:, None]], axis=1)
    return (m.q0, m.scale0, m.trans0), (m.q1, m.scale1, m.trans1)


def _instances_agree(tracer, inst) -> bool:
    """Do the instances answer probe rays through moving objects as the per-object path does?
    Embree evaluates each instance's motion in float32 with approximate trigonometry; DRT's own
    transform is float64. Rays aimed into each probed object's swept box at spread τ must hit
    or miss alike and, all but rays grazing an edge, at the same distance to within float32
    error (the distance, not the triangle: on surfaces that coincide either is right), and
    agree on occlusion."""
    moving = tracer.moving
    pick = np.unique(np.linspace(0, len(moving) - 1, min(len(moving), INSTANCE_PROBE_OBJECTS)).astype(int))
    o, d, tau = [], [], []
    for k in pick:
        obj = moving[k]
        lo, hi = obj.box_lo, obj.box_hi
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            return False
        ok, dk, _, tk = _box_probe_rays(lo, hi, INSTANCE_PROBE_RAYS)
        o.append(ok)
        d.append(dk)
        tau.append(tk)
    o, d, tau = np.concatenate(o), np.concatenate(d), np.concatenate(tau)
    a = tracer._intersect_instanced(o, d, tau, _NO_TMAX, inst, FRESH)
    b = tracer._intersect_per_object(o, d, tau, None, FRESH)
    # the distance, not the triangle: where surfaces coincide (overlapping objects) either may
    # be the nearer in float32
    both = (a.prim >= 0) & (b.prim >= 0)
    if (a.hit == b.hit).mean() < 0.99 or both.sum() < min(16, int(b.hit.sum())):
        return False
    # float32 error grows with the coordinates: far from the camera (the frame's origin) allow
    # up to half the spawn offset (``offset_point``), which keeps spawned rays off the surface
    far = 0.5 * OFFSET_RELATIVE * np.abs(o[both]).max(axis=1)
    if (np.abs(a.t[both] - b.t[both]) <= 1e-4 * (1.0 + np.abs(b.t[both])) + far).mean() < 0.99:
        return False
    tmax = np.where(b.prim >= 0, b.t * 1.01, 1e30)
    blocked = np.empty(len(o), dtype=bool)
    _instanced_blocked(inst.fn_occluded, inst.handle, embree_direct.scratch(), o, d, tau, tmax, blocked)
    return bool((blocked == tracer._occluded_per_object(o, d, tmax, tau, FRESH)).mean() >= 0.99)


_NO_SKIP = np.zeros(0, dtype=bool)


def _column(a, n: int) -> np.ndarray:
    """a as a contiguous, writable (n,) float64 array (a scalar or a (1,) array broadcast): the
    kernels get one array type, so no extra compiled variants."""
    a = np.asarray(a, dtype=np.float64)
    if a.shape != (n,):
        return np.array(np.broadcast_to(a.reshape(-1) if a.ndim else a, (n,)), dtype=np.float64)
    return a if a.flags.c_contiguous and a.flags.writeable else a.copy()


#: below this many camera samples per triangle a mesh gets Embree's fast BVH build. Measured on
#: the 1M-triangle large_mesh, two runs each, two threads (render wall time incl. the build, fast
#: against default): 0.26 M samples 0.17-0.19 / 0.36 s, 1 M 0.60-0.65 / 0.68-0.96 s, 4 M
#: 1.51-1.62 / 1.54-1.62 s, 16 M 5.09-5.22 / 4.99-5.15 s. The two break even at about four
#: samples a triangle; past that the slower queries cost more than the quicker build saves
FAST_BUILD_SAMPLES_PER_TRIANGLE = 2


class Tracer:
    """Closest-hit and occlusion queries for batches of rays.

    Rays: origins ``o`` (n, 3) and unit directions ``d`` (n, 3) float64 in the shifted world
    frame; ``tau`` (n,) shutter fractions (only used when something moves); ``tmax`` (n,).
    Thread-safe: the render loop calls it from several worker threads at once (Embree and the
    kernels release the GIL; a query's arrays are fresh or from the calling thread's own
    ``drt.scratch.Scratch``). ``embree_seconds`` accumulates time spent inside Embree calls.

    expected_samples: camera samples the renders will trace (pixels × spp), or None (unknown).
    A mesh with more than ``1 / FAST_BUILD_SAMPLES_PER_TRIANGLE`` triangles per sample gets
    Embree's fast, lower-quality BVH (``embree_mesh.triangle_scene``): with so few rays per
    triangle the build, not the queries, is the cost.
    """

    #: every object in one Embree scene of instances (``_Instances``), or None: static-only
    #: scenes, and the per-object path (``_intersect_per_object``), e.g. a viewport's tracer
    instanced = None

    def __init__(self, geom: SceneGeometry, expected_samples: int | None = None):
        self.geom = geom
        self.static = None

        def fast(triangles: int) -> bool:
            return expected_samples is not None and expected_samples < FAST_BUILD_SAMPLES_PER_TRIANGLE * triangles

        # with moving objects every scene goes on one device, which a scene of instances needs
        device = new_device() if geom.moving and embree_direct.intersect1_address() else None
        if geom.static_count:
            self.static = triangle_scene(geom.static_positions, geom.static_triangles, fast(geom.static_count),
                                         device)
        self.moving = [_MovingObject(mm, fast(len(mm.triangles)), device) for mm in geom.moving]
        self._static_ng = _unit_face_normals(geom.static_positions, geom.static_triangles) \
            if geom.static_count else None
        self.embree_seconds = 0.0
        self.rays_traced = 0
        self.instanced = _instances(self, device)

    # ------------------------------------------------------------------ embree wrappers
    def _run(self, scene, o, d, tfar, occluded=False, scratch=False):
        """Embree on rays (o, d) with tfar; ``scratch``: o, d, tfar are already contiguous
        float32 arrays of this query that Embree may overwrite."""
        t0 = _time.perf_counter()
        if scratch:
            o32, d32, dists = o, d, tfar
        else:
            # values beyond float32 (an absurd camera) become inf: Embree reports such rays as
            # misses, which is what a renderer can say about them
            with np.errstate(over="ignore"):
                o32 = np.ascontiguousarray(o, dtype=np.float32)
                d32 = np.ascontiguousarray(d, dtype=np.float32)
                dists = np.ascontiguousarray(tfar, dtype=np.float32).copy()
        if occluded:
            out = scene.run(o32, d32, dists=dists, query="OCCLUDED")
        else:
            out = scene.run(o32, d32, dists=dists, output=1)
        self.embree_seconds += _time.perf_counter() - t0
        self.rays_traced += len(o32)
        return out

    @staticmethod
    def _local_rays(scratch, n):
        """Scratch for the candidate rays of a rigid object: indices, local origins and
        directions, tfar (float32 for Embree)."""
        return (scratch.take("local_idx", n, (), np.int64), scratch.take("local_o", n, (3,), np.float32),
                scratch.take("local_d", n, (3,), np.float32), scratch.take("local_t", n, (), np.float32))

    # ------------------------------------------------------------------ queries
    def intersect(self, o, d, tau=None, tmax=None, scratch=FRESH) -> Hits:
        """Closest hits of rays (o, d) at shutter times tau within tmax. ``scratch``: where the
        query's arrays come from (``drt.scratch``); a thread's ``Scratch`` makes the returned
        ``Hits`` views that its next query with that scratch overwrites."""
        n = len(o)
        if self.static is not None and n and not self.moving:
            return self._intersect_static(o, d, tmax, scratch)
        o = np.ascontiguousarray(o, dtype=np.float64).reshape(n, 3)
        d = np.ascontiguousarray(d, dtype=np.float64).reshape(n, 3)
        if self.instanced is not None and n:
            tau = np.zeros(n) if tau is None else _column(tau, n)
            return self._intersect_instanced(o, d, tau, _NO_TMAX if tmax is None else _column(tmax, n),
                                             self.instanced, scratch)
        return self._intersect_per_object(o, d, tau, tmax, scratch)

    def _intersect_instanced(self, o, d, tau, tmax, inst, scratch) -> Hits:
        """`intersect` through the scene of instances: one Embree query per ray, then the hit
        points and normals (o, d (n, 3), tau (n,) float64 contiguous; tmax (n,) or (0,))."""
        n = len(o)
        t, prim, b1, b2 = _hit_columns(scratch, n)
        p, ng = scratch.take("p", n, (3,)), scratch.take("ng", n, (3,))
        linear = scratch.take("linear", n, (3, 3))
        translation = scratch.take("translation", n, (3,))
        moving = scratch.take("moving", n, dtype=bool)
        obj = scratch.take("object", n, (), np.int64)
        t0 = _time.perf_counter()
        any_moving = _instanced_hits(inst.fn_hit, inst.handle, embree_direct.scratch(), inst.inst_offset,
                                     inst.inst_object, inst.motions, o, d, tau, tmax, t, prim, b1, b2, obj,
                                     linear, translation, p, ng, moving)
        self.embree_seconds += _time.perf_counter() - t0
        self.rays_traced += n
        g = self.geom
        if g.static_count:
            static_surface(g.static_positions, g.static_triangles, self._static_ng, g.static_count,
                           d, prim, b1, b2, p, ng)
        if not any_moving:
            return Hits(t, prim, b1, b2, ng, None, p)
        xform = scratch.take("xform", n, (3, 3))
        _instanced_surface(inst.positions, inst.positions_close, inst.deforming, inst.triangles, inst.first_moving,
                           obj, tau, d, prim, b1, b2, linear, translation, p, ng, xform)
        return Hits(t, prim, b1, b2, ng, linear, p, xform, moving)

    def _intersect_per_object(self, o, d, tau, tmax, scratch) -> Hits:
        """`intersect` object by object: the static scene's batch, then each moving object in
        turn (o, d (n, 3) float64 contiguous)."""
        n = len(o)
        tmax = _NO_TMAX if tmax is None else _column(tmax, n)
        t, prim, b1, b2 = _hit_columns(scratch, n)
        if self.static is not None and n:
            o32, d32, t32 = _embree_rays(scratch, n)
            _rays32(o, d, tmax, o32, d32, t32)
            r = self._run(self.static, o32, d32, t32, scratch=True)
            _static_first(r["primID"], r["tfar"], r["u"], r["v"], tmax, t, prim, b1, b2)
        else:
            _unbounded_start(tmax, t, prim, b1, b2)
        linear = translation = None
        merged = 0
        if self.moving and n:
            tau = np.zeros(n) if tau is None else _column(tau, n)
            linear = scratch.take("linear", n, (3, 3))
            translation = scratch.take("translation", n, (3,))
            local = None
            words = embree_direct.scratch()
            for obj in self.moving:
                if obj.direct is not None or obj.deforming is not None:
                    fn, _, handle, _, timed = obj.direct or _EXACT
                    m, traced = _moving_hits(fn, handle, words, timed, obj.deforming or _NO_DEFORMING,
                                             obj.motion, obj.box_lo, obj.box_hi, obj.prim_offset, o, d,
                                             tau, t, prim, b1, b2, linear, translation)
                    merged += m
                    self.rays_traced += traced
                    continue
                if local is None:
                    local = self._local_rays(scratch, n)
                idx, o_l, d_l, tfar = local
                count = _rigid_candidates(obj.motion, obj.box_lo, obj.box_hi, o, d, tau, t,
                                          _NO_SKIP, idx, o_l, d_l, tfar)
                if not count:
                    continue
                r = self._run(obj.scene, o_l[:count], d_l[:count], tfar[:count], scratch=True)
                merged += _rigid_merge(obj.motion, obj.prim_offset, tau, idx, count, r["tfar"],
                                       r["primID"], r["u"], r["v"], t, prim, b1, b2, linear,
                                       translation)
        # hit points and normals from the triangles themselves, in float64 (more accurate than
        # Embree's float32 t; the winding is ours to define); misses end at p = o
        p, ng = scratch.take("p", n, (3,)), scratch.take("ng", n, (3,))
        if linear is None:
            linear = scratch.take("linear", n, (3, 3))
        moving = scratch.take("moving", n, dtype=bool)
        g = self.geom
        any_moving = _finish_moving_hits(prim, g.static_count, o, d, t, p, ng, linear, moving) if n else False
        if g.static_count:
            static_surface(g.static_positions, g.static_triangles, self._static_ng, g.static_count,
                           d, prim, b1, b2, p, ng)
        if not (merged and any_moving):
            return Hits(t, prim, b1, b2, ng, None, p)
        xform = scratch.take("xform", n, (3, 3))
        for obj in self.moving:
            _moving_surface(obj.positions, obj.positions_close, obj.deforming is not None,
                            obj.triangles, obj.prim_offset, tau, d, prim, b1, b2, linear,
                            translation, p, ng, xform)
        return Hits(t, prim, b1, b2, ng, linear, p, xform, moving)

    def _intersect_static(self, o, d, tmax, scratch) -> Hits:
        """`intersect` for scenes where nothing moves: two kernels around one Embree call, no
        per-bounce numpy passes."""
        n = len(o)
        o = np.ascontiguousarray(o, dtype=np.float64)
        d = np.ascontiguousarray(d, dtype=np.float64)
        tmax = _NO_TMAX if tmax is None else np.ascontiguousarray(tmax, dtype=np.float64)
        o32, d32, t32 = _embree_rays(scratch, n)
        _rays32(o, d, tmax, o32, d32, t32)
        r = self._run(self.static, o32, d32, t32, scratch=True)
        t, prim, b1, b2 = _hit_columns(scratch, n)
        p, ng = scratch.take("p", n, (3,)), scratch.take("ng", n, (3,))
        _static_hits(r["primID"], r["tfar"], r["u"], r["v"], o, d, t, prim, b1, b2, p)
        g = self.geom
        static_surface(g.static_positions, g.static_triangles, self._static_ng, g.static_count,
                       d, prim, b1, b2, p, ng)
        return Hits(t, prim, b1, b2, ng, None, p)

    def occluded(self, o, d, tmax, tau=None, scratch=FRESH) -> np.ndarray:
        """(n,) bool: is anything hit in (0, tmax)? ``scratch`` as in `intersect`."""
        n = len(o)
        o = np.ascontiguousarray(o, dtype=np.float64).reshape(n, 3)
        d = np.ascontiguousarray(d, dtype=np.float64).reshape(n, 3)
        tmax = _column(tmax, n)
        inst = self.instanced
        if inst is not None and n:
            blocked = scratch.take("blocked", n, dtype=bool)
            t0 = _time.perf_counter()
            _instanced_blocked(inst.fn_occluded, inst.handle, embree_direct.scratch(), o, d,
                               np.zeros(n) if tau is None else _column(tau, n), tmax, blocked)
            self.embree_seconds += _time.perf_counter() - t0
            self.rays_traced += n
            return blocked
        return self._occluded_per_object(o, d, tmax, tau, scratch)

    def _occluded_per_object(self, o, d, tmax, tau, scratch) -> np.ndarray:
        """`occluded` object by object (o, d (n, 3) float64 contiguous, tmax (n,))."""
        n = len(o)
        blocked = scratch.take("blocked", n, dtype=bool)
        if self.static is not None and n:
            o32, d32, t32 = _embree_rays(scratch, n)
            _rays32(o, d, tmax, o32, d32, t32)
            np.greater_equal(self._run(self.static, o32, d32, t32, occluded=True, scratch=True), 0,
                             out=blocked)
        else:
            blocked[:] = False
        if self.moving and n:
            tau = np.zeros(n) if tau is None else _column(tau, n)
            tmax = np.minimum(tmax, 3.0e38)
            blocked = np.ascontiguousarray(blocked)
            local = None
            words = embree_direct.scratch()
            for obj in self.moving:
                if obj.direct is not None or obj.deforming is not None:
                    _, fn, handle, _, timed = obj.direct or _EXACT
                    self.rays_traced += _moving_blocked(fn, handle, words, timed, obj.deforming or _NO_DEFORMING,
                                                        obj.motion, obj.box_lo, obj.box_hi, o, d, tau, tmax,
                                                        blocked)
                    continue
                if local is None:
                    local = self._local_rays(scratch, n)
                idx, o_l, d_l, tfar = local
                count = _rigid_candidates(obj.motion, obj.box_lo, obj.box_hi, o, d, tau, tmax,
                                          blocked, idx, o_l, d_l, tfar)
                if count:
                    r = self._run(obj.scene, o_l[:count], d_l[:count], tfar[:count], occluded=True,
                                  scratch=True)
                    _merge_blocked(idx, count, r, blocked)
        return blocked
