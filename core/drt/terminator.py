"""Cycles's shadow terminator geometry offset: shadow rays of smooth-shaded triangles start on
(an approximation of) the smooth surface instead of the flat facet.

A low-poly mesh with interpolated normals is lit by its smooth normal, but its flat facets shadow
each other near the terminator: the facet's plane already faces away from the light where the
smooth normal still sees it, and neighbouring facets block shadow rays. Cycles (per object
``Object.shadow_terminator_geometry_offset``, Blender's default 0.1) lifts the shadow-ray origin
of a next-event estimate along the interpolated normal by the height ``h`` of a smooth surface
over the facet (``shadow_ray_smooth_surface_offset`` in Cycles's ``kernel/light/sample.h``,
after Hanika, "Hacking the Shadow Terminator", Ray Tracing Gems II): a parabolic fit through the
three vertex tangent planes, bounded by the local linear envelope of those planes. The lift is
blended in only for light directions near the terminator: ``offset_amount`` ramps from 0 (the
light at least ``cutoff`` above the geometric plane) to 1.

Data: ``Surfaces.terminator`` (T,) float32 the cutoff per global triangle (0: none; zero-size
when no object uses it), ``Surfaces.positions`` (V, 3) float32 the static triangles' world
(camera-shifted) vertices and ``Surfaces.triangles`` (T_static, 3) int32 their indices (the
tracer's own arrays, not a per-corner copy: a million triangles' corners were 37 MB and ~15 ms
of every render's start, most of it the first touch of the new memory). Smooth normals are
``Surfaces.normals`` (world, unit).
Everything is in world space: Cycles works in object space for objects whose transform it does
not apply (instances), which differs only under non-uniform scale. Moving objects get no offset.
"""
from __future__ import annotations

import math

import numpy as np

from .kernels import inline_kernel, kernel
from .kernels.row_chunks import over_rows
from .kernels.vec3 import add, dot, neg, normalize, scale, sub
from .trace import offset_point

NO_TERMINATOR = (np.zeros(0, np.float32), np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32))


def shading_multipliers(geom) -> np.ndarray:
    """(T,) float32 Cycles's shading-offset frequency multiplier 1 / (1 − s/2) per global
    triangle (``kernel/closure/bsdf.h``, ``shift_cos_in``), or (0,) when no object sets one."""
    s = getattr(geom, "terminator_shading", None)
    if s is None or not np.any(s > 0.0):
        return np.zeros(0, np.float32)
    return (1.0 / (1.0 - 0.5 * np.asarray(s, np.float64))).astype(np.float32)


@inline_kernel
def shading_factor(surf, prim, cos_in):
    """Cycles's shading offset (Appleseed's terminator softening): the BSDF value at a light
    direction cos_in = cos(angle to the closure normal) ≥ 0 is scaled by cos(kθ) / cos θ,
    k = the triangle's multiplier (> 1), so the lit side fades out before the terminator.
    1 when the scene has no shading offset or cos_in < 0 (transmission)."""
    if surf.shading_mult.shape[0] == 0 or cos_in < 0.0:
        return 1.0
    k = float(surf.shading_mult[prim])
    if k <= 1.0:
        return 1.0
    c = min(cos_in, 1.0)
    if c <= 0.0:
        return 0.0
    return max(math.cos(math.acos(c) * k), 0.0) / c


def terminator_arrays(geom) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(cutoff (T,) float32, positions (V, 3) float32, triangles (T_static, 3) int32) for
    ``Surfaces``, or zero-size arrays when no triangle needs an offset. Triangles whose three
    corner normals are equal (flat faces of a smooth mesh) get cutoff 0: their smooth surface
    is the facet, the offset would be 0. Moving triangles (after the static ones) get none."""
    cut = getattr(geom, "terminator", None)
    if cut is None or geom.normals is None:
        return NO_TERMINATOR
    out = np.empty(len(cut), np.float32)
    if not any(over_rows(_smooth_cutoffs, (np.asarray(cut, np.float32), geom.normals, geom.has_normals, out),
                         sliced=(0, 1, 2, 3))):
        return NO_TERMINATOR
    return (out, np.ascontiguousarray(geom.static_positions, np.float32),
            np.ascontiguousarray(geom.static_triangles, np.int32))


@kernel
def _smooth_cutoffs(cut, normals, has_normals, out):
    """out[t] = cut[t] for triangles with distinct smooth corner normals, else 0; True if any
    is nonzero. One pass: on a 1M-triangle mesh the numpy comparisons took ~0.1 s."""
    any_cut = False
    for t in range(cut.shape[0]):
        c = cut[t]
        if c != 0.0 and has_normals[t]:
            flat = True
            for k in range(3):
                if normals[t, 0, k] != normals[t, 1, k] or normals[t, 0, k] != normals[t, 2, k]:
                    flat = False
            if flat:
                c = 0.0
        else:
            c = 0.0
        out[t] = c
        any_cut = any_cut or c != 0.0
    return any_cut


@inline_kernel
def _corner(a, k):
    return (float(a[k, 0]), float(a[k, 1]), float(a[k, 2]))


@inline_kernel
def smooth_surface_offset(v0, v1, v2, nc, b0, b1, b2, ng):
    """Cycles's ``shadow_ray_smooth_surface_offset``: the lift (a vector along the interpolated,
    unnormalised normal) from the facet point with barycentrics (b0, b1, b2) to the smooth
    surface; v0, v1, v2 the facet's vertices, ``nc`` (3, 3) its corner normals, ``ng`` the
    geometric normal on the side the shadow ray leaves from."""
    n0, n1, n2 = normalize(_corner(nc, 0))[0], normalize(_corner(nc, 1))[0], normalize(_corner(nc, 2))[0]
    p = add(add(scale(v0, b0), scale(v1, b1)), scale(v2, b2))
    n = add(add(scale(n0, b0), scale(n1, b1)), scale(n2, b2))
    # parabolic approximation
    a = dot(sub(n2, n0), sub(v0, v2))
    b = dot(sub(n2, n1), sub(v1, v2))
    c = dot(sub(n1, n0), sub(v1, v0))
    h = a * b0 * (b0 - 1.0) + (a + b + c) * b0 * b1 + b * b1 * (b1 - 1.0)
    if dot(n, ng) > 0.0:  # local linear envelope of the three tangent planes
        h0 = max(max(dot(sub(v1, v0), n0), dot(sub(v2, v0), n0)), 0.0)
        h1 = max(max(dot(sub(v0, v1), n1), dot(sub(v2, v1), n1)), 0.0)
        h2 = max(max(dot(sub(v0, v2), n2), dot(sub(v1, v2), n2)), 0.0)
        h0 = max(dot(sub(v0, p), n0) + h0, 0.0)
        h1 = max(dot(sub(v1, p), n1) + h1, 0.0)
        h2 = max(dot(sub(v2, p), n2) + h2, 0.0)
        h = max(min(min(h0, h1), h2), h * 0.5)
    else:  # flipped normals
        h0 = max(max(dot(sub(v0, v1), n0), dot(sub(v0, v2), n0)), 0.0)
        h1 = max(max(dot(sub(v1, v0), n1), dot(sub(v1, v2), n1)), 0.0)
        h2 = max(max(dot(sub(v2, v0), n2), dot(sub(v2, v1), n2)), 0.0)
        h0 = max(dot(sub(p, v0), n0) + h0, 0.0)
        h1 = max(dot(sub(p, v1), n1) + h1, 0.0)
        h2 = max(dot(sub(p, v2), n2) + h2, 0.0)
        h = min(-min(min(h0, h1), h2), h * 0.5)
    return scale(n, h)


@inline_kernel
def shadow_origin(surf, hits, i, prim, p, ng, ns, wo, wi):
    """Origin of the NEE shadow ray from hit i (point p, unit geometric normal ng on the front
    side, smooth normal ns on the front side) toward wi, wo the direction back along the path:
    ``offset_point`` of p, lifted toward the smooth surface first when the triangle's object has
    a terminator offset (Cycles's ``shadow_ray_offset``). One array-size test otherwise.

    Returns (origin, lifted). ``lifted``: the origin was moved off the facet on wo's side, so
    a light below the facet's plane but above the smooth normal's horizon is reachable (Cycles
    lights such points when the shadow ray from the lifted origin escapes; without the lift
    the facet itself is in the way)."""
    if surf.terminator.shape[0] == 0 or surf.terminator[prim] <= 0.0:
        return offset_point(p, ng, wi), False
    if hits.moving.shape[0] and hits.moving[i]:
        return offset_point(p, ng, wi), False
    cutoff = float(surf.terminator[prim])
    # Cycles's sd->N and sd->Ng face the side the path arrived from
    side = 1.0 if dot(wo, ng) >= 0.0 else -1.0
    n_c = scale(ns, side)
    ng_c = scale(ng, side)
    nl = dot(n_c, wi)
    if nl < 0.0:  # transmission: the far side's normals
        nl = -nl
        ng_c = neg(ng_c)
    ngl = dot(ng_c, wi)
    if nl < cutoff:
        amount = min(max(2.0 - (ngl + nl) / cutoff, 0.0), 1.0)
    else:
        amount = min(max(1.0 - ngl / cutoff, 0.0), 1.0)
    if amount > 0.0:
        b1, b2 = hits.b1[i], hits.b2[i]
        pos, tri = surf.positions, surf.triangles
        lift = scale(smooth_surface_offset(_corner(pos, tri[prim, 0]), _corner(pos, tri[prim, 1]),
                                           _corner(pos, tri[prim, 2]), surf.normals[prim],
                                           1.0 - b1 - b2, b1, b2, ng_c), amount)
        if dot(lift, ng_c) > 0.0:
            return offset_point(add(p, lift), ng, wi), True
    return offset_point(p, ng, wi), False
