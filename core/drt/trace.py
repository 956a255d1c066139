"""Ray queries against the scene through Embree (embreex), in batches.

embreex's ``run()`` always starts rays at tnear = 0 with ray time 0 and overwrites the ``dists``
array it is given (used as tfar). So:

* self-intersection is avoided by offsetting spawn points along the geometric normal
  (``offset_origin``), by an amount that scales with the point's magnitude;
* motion blur cannot use Embree's own time: a rigidly moving object gets an Embree scene in its
  local space and each ray is transformed into it by the object's transform *at that ray's time*
  (exact, no time slices); deforming meshes are intersected exactly at each ray's time by a
  vectorised ray/triangle test (fine for the modest meshes that deform in practice).

All positions are in the shifted world frame of ``geometry.SceneGeometry``.
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass

import numpy as np
from embreex import rtcore_scene as rtcs
from embreex.mesh_construction import TriangleMesh

from .geometry import SceneGeometry
from .kernels import kernel
from .kernels.vec3 import load, store
from .motion import apply_linear, apply_linear_transposed, invert_linear
from .vecmath import row_norm

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
        a = triangles[k, 0]
        b = triangles[k, 1]
        c = triangles[k, 2]
        w1, w2 = b1[i], b2[i]
        for axis in range(3):
            v0 = float(positions[a, axis])
            p[i, axis] = v0 + w1 * (float(positions[b, axis]) - v0) + w2 * (float(positions[c, axis]) - v0)
            ng[i, axis] = face_normals[k, axis]
        if ng[i, 0] == 0.0 and ng[i, 1] == 0.0 and ng[i, 2] == 0.0:
            for axis in range(3):
                ng[i, axis] = -d[i, axis]


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

    @property
    def hit(self) -> np.ndarray:
        return self.prim >= 0


def _unit_face_normals(positions, triangles, chunk=1 << 20) -> np.ndarray:
    """(T, 3) float32 unit geometric normals (e1 × e2, counter-clockwise front), computed in
    float64 a chunk at a time; zero rows for degenerate (zero-area) triangles. Float32 storage
    keeps a 4M-triangle scene at 48 MB; the direction is still good to ~1e-7."""
    out = np.zeros((len(triangles), 3), dtype=np.float32)
    for lo in range(0, len(triangles), chunk):
        v = positions[triangles[lo:lo + chunk]].astype(np.float64)
        n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        length = np.linalg.norm(n, axis=1)
        good = length > 0
        n[good] /= length[good, None]
        n[~good] = 0.0
        out[lo:lo + chunk] = n
    return out


class _RigidObject:
    def __init__(self, mm):
        self.mesh = mm
        self.scene = None
        if mm.positions_close is None:
            self.scene = rtcs.EmbreeScene()
            TriangleMesh(self.scene, mm.positions.astype(np.float32), mm.triangles.astype(np.int32))
        self.box_lo, self.box_hi = _swept_box(mm)

    def rays_to_local(self, o, d, tau, rows):
        """The object's transform at each ray's τ (linear parts, translations) and rays ``rows``
        of (o, d) in its local space (directions not renormalised: t stays a world distance)."""
        lin, trans = self.mesh.motion.at(tau[rows])
        inv = invert_linear(lin)
        return lin, trans, apply_linear(inv, o[rows] - trans), apply_linear(inv, d[rows])

    def candidates(self, o, d, tmax, rows=None) -> np.ndarray:
        """Indices (into o) of the rays whose segment (0, tmax) meets the swept box; ``rows``
        restricts the test to those indices. Rays that miss it cannot hit the object at any τ,
        so they skip the per-ray transform and the trace."""
        if rows is not None:
            o, d, tmax = o[rows], d[rows], tmax[rows]
        with np.errstate(divide="ignore"):
            near, far = _slab(self.box_lo, self.box_hi, o, 1.0 / d)
        hit = np.flatnonzero((near <= far) & (far >= 0) & (near <= tmax))
        return hit if rows is None else rows[hit]


def _slab(lo, hi, o, inv_d) -> tuple[np.ndarray, np.ndarray]:
    """Entry and exit distances of rays o + t·d (``inv_d`` = 1/d) through boxes [lo, hi]; all
    arguments broadcast, the last axis is xyz. A ray misses where near > far."""
    with np.errstate(invalid="ignore"):
        t0 = (lo - o) * inv_d
        t1 = (hi - o) * inv_d
    # fmin/fmax skip the NaN of 0·inf (a ray in a slab's boundary plane)
    return np.fmax.reduce(np.fmin(t0, t1), axis=-1), np.fmin.reduce(np.fmax(t0, t1), axis=-1)


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
    return lo - pad, hi + pad


class Tracer:
    """Closest-hit and occlusion queries for batches of rays.

    Rays: origins ``o`` (n, 3) and unit directions ``d`` (n, 3) float64 in the shifted world
    frame; ``tau`` (n,) shutter fractions (only used when something moves); ``tmax`` (n,).
    Thread-safe: the render loop calls it from several worker threads at once (Embree releases
    the GIL). ``embree_seconds`` accumulates time spent inside Embree calls.
    """

    def __init__(self, geom: SceneGeometry):
        self.geom = geom
        self.static = None
        if geom.static_count:
            self.static = rtcs.EmbreeScene()
            TriangleMesh(self.static, geom.static_positions, geom.static_triangles)
        self.moving = [_RigidObject(mm) for mm in geom.moving]
        self._static_ng = _unit_face_normals(geom.static_positions, geom.static_triangles) \
            if geom.static_count else None
        self.embree_seconds = 0.0
        self.rays_traced = 0

    # ------------------------------------------------------------------ embree wrappers
    def _run(self, scene, o, d, tfar, occluded=False):
        t0 = _time.perf_counter()
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

    # ------------------------------------------------------------------ queries
    def intersect(self, o, d, tau=None, tmax=None) -> Hits:
        n = len(o)
        t = np.full(n, np.inf) if tmax is None else np.asarray(tmax, dtype=np.float64).copy()
        t = np.minimum(t, 3.0e38)
        prim = np.full(n, -1, dtype=np.int64)
        b1 = np.zeros(n)
        b2 = np.zeros(n)
        ng = np.zeros((n, 3))
        linear = None
        translation = None
        if self.static is not None and n:
            r = self._run(self.static, o, d, t)
            hit = r["primID"] >= 0
            t[hit] = r["tfar"][hit]
            prim[hit] = r["primID"][hit]
            b1[hit], b2[hit] = r["u"][hit], r["v"][hit]
        if self.moving and n:
            tau = np.zeros(n) if tau is None else tau
            for obj in self.moving:
                rows = obj.candidates(o, d, t)
                if not len(rows):
                    continue
                lin, trans, o_l, d_l = obj.rays_to_local(o, d, tau, rows)
                t_rows = t[rows]
                if obj.scene is not None:
                    r = self._run(obj.scene, o_l, d_l, t_rows)
                    hit = (r["primID"] >= 0) & (r["tfar"] < t_rows)
                    tl, pl, u, v = r["tfar"], r["primID"], r["u"], r["v"]
                else:
                    tl, pl, u, v, _ = _intersect_deforming(obj.mesh, o_l, d_l, tau[rows], t_rows)
                    hit = pl >= 0
                if not np.any(hit):
                    continue
                if linear is None:
                    linear = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
                    translation = np.zeros((n, 3))
                r_hit = rows[hit]
                t[r_hit] = tl[hit]
                prim[r_hit] = pl[hit] + obj.mesh.prim_offset
                b1[r_hit], b2[r_hit] = u[hit], v[hit]
                linear[r_hit] = lin[hit]
                translation[r_hit] = trans[hit]
        t[prim < 0] = np.inf
        hits = Hits(t, prim, b1, b2, ng, linear)
        self._surface_geometry(hits, o, d, tau, translation if linear is not None else None)
        return hits

    def _surface_geometry(self, hits, o, d, tau, translation):
        """Fill ``hits.p`` and ``hits.ng`` (unit, front side) from the triangles themselves, in
        float64: more accurate than Embree's float32 values, and the winding is ours to define."""
        n = len(hits.t)
        hits.p = np.zeros((n, 3))
        g = self.geom
        if g.static_count:
            static_surface(g.static_positions, g.static_triangles, self._static_ng, g.static_count,
                           np.ascontiguousarray(d, dtype=np.float64), hits.prim, hits.b1, hits.b2,
                           hits.p, hits.ng)
        for obj in self.moving:
            mm = obj.mesh
            sel = (hits.prim >= mm.prim_offset) & (hits.prim < mm.prim_offset + len(mm.triangles))
            if not np.any(sel):
                continue
            tri = mm.triangles[hits.prim[sel] - mm.prim_offset]
            v = mm.positions[tri]
            if mm.positions_close is not None:
                w = tau[sel][:, None, None]
                v = (1 - w) * v + w * mm.positions_close[tri]
            e1, e2 = v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]
            lin = hits.moving_linear[sel]
            p_local = v[:, 0] + hits.b1[sel, None] * e1 + hits.b2[sel, None] * e2
            hits.p[sel] = apply_linear(lin, p_local) + translation[sel]
            # normals transform by the inverse transpose of the local→world map
            ng = apply_linear_transposed(invert_linear(lin), np.cross(e1, e2))
            length = row_norm(ng)
            good = length > 0
            ng[good] /= length[good, None]
            # a degenerate (zero-area) triangle has no normal: face the ray
            ng[~good] = -d[sel][~good]
            hits.ng[sel] = ng
        miss = hits.prim < 0
        if np.any(miss):  # on a miss, p is where the ray ends (o + tmax·d, or o)
            t = np.where(np.isfinite(hits.t[miss]), hits.t[miss], 0.0)
            hits.p[miss] = o[miss] + t[:, None] * d[miss]

    def occluded(self, o, d, tmax, tau=None) -> np.ndarray:
        """(n,) bool: is anything hit in (0, tmax)?"""
        n = len(o)
        blocked = np.zeros(n, dtype=bool)
        tmax = np.minimum(np.asarray(tmax, dtype=np.float64), 3.0e38)
        if self.static is not None and n:
            blocked = self._run(self.static, o, d, tmax, occluded=True) >= 0
        if self.moving and n:
            tau = np.zeros(n) if tau is None else tau
            for obj in self.moving:
                idx = np.nonzero(~blocked)[0]
                if not len(idx):
                    break
                idx = obj.candidates(o, d, tmax, idx)
                if not len(idx):
                    continue
                _, _, o_l, d_l = obj.rays_to_local(o, d, tau, idx)
                if obj.scene is not None:
                    blocked[idx] = self._run(obj.scene, o_l, d_l, tmax[idx], occluded=True) >= 0
                else:
                    _, pl, *_ = _intersect_deforming(obj.mesh, o_l, d_l, tau[idx], tmax[idx].copy())
                    blocked[idx] = pl >= 0
        return blocked


CLUSTER_SIZE = 16  # triangles per bounding box in the deforming-mesh culling level


class DeformingBounds:
    """A one-level bounding hierarchy for a deforming mesh: consecutive triangles (meshes are
    stored with spatial coherence) grouped in clusters whose boxes bound their motion over the
    whole shutter (the box of all vertices at open and close contains every in-between
    position, since vertices move linearly)."""

    def __init__(self, mm):
        tri = mm.triangles
        t = len(tri)
        self.count = t
        c = -(-t // CLUSTER_SIZE)
        pad = c * CLUSTER_SIZE - t
        self.members = np.concatenate([np.arange(t), np.full(pad, -1)]).reshape(c, CLUSTER_SIZE)
        both = np.concatenate([mm.positions[tri], mm.positions_close[tri]], axis=1)  # (T, 6, 3)
        lo = both.min(axis=1)
        hi = both.max(axis=1)
        lo = np.concatenate([lo, np.full((pad, 3), np.inf)]).reshape(c, CLUSTER_SIZE, 3).min(axis=1)
        hi = np.concatenate([hi, np.full((pad, 3), -np.inf)]).reshape(c, CLUSTER_SIZE, 3).max(axis=1)
        margin = 1e-7 * (1.0 + np.abs(np.concatenate([lo, hi])).max())
        self.lo, self.hi = lo - margin, hi + margin


def _intersect_deforming(mm, o, d, tau, tmax, chunk_elems=2_000_000):
    """Exact closest hit against a deforming mesh whose vertices move linearly from
    ``positions`` to ``positions_close``: each ray sees the mesh at its own τ. Rays are culled
    against cluster boxes (slab test), then Möller–Trumbore runs on the surviving
    (ray, triangle) pairs only. Returns (t, prim, b1, b2, ng_local)."""
    if getattr(mm, "_bounds", None) is None:
        mm._bounds = DeformingBounds(mm)
    bounds = mm._bounds
    n = len(o)
    t_best = np.asarray(tmax, dtype=np.float64).copy()
    prim = np.full(n, -1, dtype=np.int64)
    b1 = np.zeros(n)
    b2 = np.zeros(n)
    ng = np.zeros((n, 3))
    n_clusters = len(bounds.lo)
    step = max(1, chunk_elems // max(n_clusters, 1))
    with np.errstate(divide="ignore"):
        inv_d = 1.0 / d
    # first the box around every cluster: most rays of a frame miss a small deforming mesh,
    # and the per-cluster test below costs n_rays × n_clusters
    g_near, g_far = _slab(bounds.lo.min(axis=0), bounds.hi.max(axis=0), o, inv_d)
    candidates = np.flatnonzero((g_near <= g_far) & (g_far > 0) & (g_near < t_best))
    for s in range(0, len(candidates), step):
        rows = candidates[s:s + step]
        # slab test of every ray of the chunk against every cluster box
        near, far = _slab(bounds.lo[None], bounds.hi[None], o[rows, None], inv_d[rows, None])
        ri, ci = np.nonzero((near <= far) & (far > 0) & (near < t_best[rows, None]))
        if not len(ri):
            continue
        ray = np.repeat(rows[ri], CLUSTER_SIZE)
        tri_id = bounds.members[ci].reshape(-1)
        keep = tri_id >= 0
        ray, tri_id = ray[keep], tri_id[keep]
        corners = mm.triangles[tri_id]
        w = tau[ray][:, None, None]
        v = (1 - w) * mm.positions[corners] + w * mm.positions_close[corners]  # (p, 3, 3)
        e1 = v[:, 1] - v[:, 0]
        e2 = v[:, 2] - v[:, 0]
        dd = d[ray]
        pvec = np.cross(dd, e2)
        det = np.einsum("pk,pk->p", e1, pvec)
        ok = np.abs(det) > 1e-20
        inv_det = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        tvec = o[ray] - v[:, 0]
        u = np.einsum("pk,pk->p", tvec, pvec) * inv_det
        qvec = np.cross(tvec, e1)
        vv = np.einsum("pk,pk->p", dd, qvec) * inv_det
        tt = np.einsum("pk,pk->p", e2, qvec) * inv_det
        valid = ok & (u >= 0) & (vv >= 0) & (u + vv <= 1) & (tt > 0) & (tt < t_best[ray])
        if not np.any(valid):
            continue
        ray, tri_id, tt, u, vv = ray[valid], tri_id[valid], tt[valid], u[valid], vv[valid]
        e1, e2 = e1[valid], e2[valid]
        # closest candidate per ray: sort by (ray, t) and take each ray's first
        order = np.lexsort((tt, ray))
        first = order[np.r_[True, ray[order][1:] != ray[order][:-1]]]
        r = ray[first]
        t_best[r] = tt[first]
        prim[r] = tri_id[first]
        b1[r] = u[first]
        b2[r] = vv[first]
        ng[r] = np.cross(e1[first], e2[first])
    return t_best, prim, b1, b2, ng
