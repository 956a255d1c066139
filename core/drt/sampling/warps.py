"""Warps from the unit square to disks, polygons, the hemisphere, sphere, cones and triangles.

Every warp ``square_to_X(u)`` takes ``u: (n, 2)`` float in [0, 1)² and is vectorized over n
(any leading shape ``(..., 2)`` works; results are float64).  Beside each warp:

* ``square_to_X_pdf(x)``: its density, with the measure stated (per unit *area* for points in the
  plane, per unit *solid angle* for directions); 0 outside the support.
* ``X_to_square(x)``: the inverse map, where one exists (round-trip tested).

The implementation is the scalar ``@kernel`` functions below (one sample at a time, called
from the compiled integrator, BSDFs, lights and camera: ``disk_concentric(u0, u1)``,
``polygon(u0, u1, n_corners, rotation)``, ``cosine_hemisphere_pdf(d)``, …); the numpy functions
are thin wrappers that apply them to the rows of their arrays.

Directions are unit vectors in a **local z-up frame**: z is the axis (shading normal, cone axis),
theta is measured from +z and phi = atan2(y, x) counter-clockwise from +x.  ``build_frame`` /
``to_local`` / ``to_world`` move vectors between that frame and world space.

The concentric (Shirley-Chiu) disk map is the basis of the cosine hemisphere, uniform hemisphere
and cone warps (as in Cycles's ``kernel/sample/mapping.h``): it keeps strata compact, which
matters for Sobol / stratified samples.
"""

from __future__ import annotations

import math

import numpy as np

from ..kernels import kernel, vec3
from .trig import sincos, sincos_quarter

__all__ = [
    "square_to_disk_concentric", "square_to_disk_concentric_pdf", "disk_concentric_to_square",
    "square_to_polygon", "square_to_polygon_pdf", "polygon_to_square", "polygon_area",
    "square_to_cosine_hemisphere", "square_to_cosine_hemisphere_pdf",
    "cosine_hemisphere_to_square",
    "square_to_uniform_hemisphere", "square_to_uniform_hemisphere_pdf",
    "uniform_hemisphere_to_square",
    "square_to_uniform_sphere", "square_to_uniform_sphere_pdf", "uniform_sphere_to_square",
    "square_to_uniform_cone", "square_to_uniform_cone_pdf", "uniform_cone_to_square",
    "square_to_triangle", "square_to_triangle_pdf", "triangle_to_square",
    "hemisphere_midpoint_grid",
    "build_frame", "to_local", "to_world",
    # scalar kernels
    "disk_concentric", "disk_concentric_pdf", "disk_concentric_inverse", "disk_to_cone",
    "cone_to_disk", "polygon", "polygon_pdf", "polygon_inverse", "polygon_area_n",
    "cosine_hemisphere", "cosine_hemisphere_pdf", "cosine_hemisphere_inverse",
    "uniform_hemisphere", "uniform_hemisphere_pdf", "uniform_hemisphere_inverse",
    "uniform_sphere", "uniform_sphere_pdf", "uniform_sphere_inverse",
    "uniform_cone", "uniform_cone_pdf", "uniform_cone_inverse",
    "uniform_triangle", "triangle_pdf", "triangle_inverse",
]

_PI = np.pi
_INV_PI = 1.0 / np.pi
_INV_2PI = 0.5 / np.pi
_INV_4PI = 0.25 / np.pi
_PI_4 = 0.25 * np.pi

# Largest float64 below 1: inverse maps clamp into [0, 1) so their output is a valid sample.
_ONE_MINUS_EPS = float(np.nextafter(1.0, 0.0))


# ---------------------------------------------------------------------------------------------
# scalar kernels: one sample at a time, called from the compiled integrator, BSDFs and lights.
# They are the implementation; the vectorized functions below apply them to arrays.
# ---------------------------------------------------------------------------------------------


# numpy's NaN-propagating minimum / maximum / clip and float modulo, so the kernels keep the
# numpy semantics exactly
@kernel
def _np_min(a, b):
    return a if (a <= b or a != a) else b


@kernel
def _np_max(a, b):
    return a if (a >= b or a != a) else b


@kernel
def _clip(x, lo, hi):
    return _np_min(_np_max(x, lo), hi)


@kernel
def _unit(x):
    """Clamp into [0, 1): inverse maps return valid samples."""
    return _np_min(_np_max(x, 0.0), _ONE_MINUS_EPS)


@kernel
def _np_mod(a, b):
    """``np.mod`` for floats: the remainder with the sign of b."""
    m = np.fmod(a, b)
    if m != 0.0:
        if (b < 0.0) != (m < 0.0):
            m += b
    else:
        m = math.copysign(0.0, b)
    return m


@kernel
def disk_concentric(u0, u1):
    """Shirley-Chiu concentric map of (u0, u1) ∈ [0,1)² onto the unit disk → (x, y)."""
    a = 2.0 * u0 - 1.0
    b = 2.0 * u1 - 1.0
    if a == 0.0 and b == 0.0:
        return 0.0, 0.0
    if abs(a) > abs(b):
        s, c = sincos_quarter(_PI_4 * (b / a))    # φ = π/4·b/a
        return a * c, a * s
    # φ = π/2 − π/4·a/b: cos φ and sin φ are the sine and cosine of π/4·a/b
    s, c = sincos_quarter(_PI_4 * (a / b))
    return b * s, b * c


@kernel
def disk_to_cone(x, y, one_minus_cos):
    """Area-preserving lift of a unit-disk point onto the cone cos θ ≥ 1 − one_minus_cos about
    +z (Cycles's ``sample_uniform_cone``): cos θ = 1 − r²·one_minus_cos."""
    r2 = x * x + y * y
    s = math.sqrt(_np_max(0.0, one_minus_cos * (2.0 - one_minus_cos * r2)))
    return (x * s, y * s, 1.0 - r2 * one_minus_cos)


@kernel
def cosine_hemisphere(u0, u1):
    """Cosine-weighted direction, z ≥ 0 (Malley); pdf = z/π."""
    x, y = disk_concentric(u0, u1)
    return (x, y, math.sqrt(_np_max(0.0, 1.0 - x * x - y * y)))


@kernel
def uniform_hemisphere(u0, u1):
    """Uniform direction, z ≥ 0; pdf = 1/(2π)."""
    x, y = disk_concentric(u0, u1)
    return disk_to_cone(x, y, 1.0)


@kernel
def uniform_cone(u0, u1, one_minus_cos):
    """Uniform direction in the cone 1 − cos θ ≤ one_minus_cos about +z (concentric lift);
    pdf = 1/(2π·one_minus_cos)."""
    x, y = disk_concentric(u0, u1)
    return disk_to_cone(x, y, one_minus_cos)


@kernel
def uniform_sphere(u0, u1):
    """Uniform direction on the sphere (z = 1 − 2u0, φ = 2πu1); pdf = 1/(4π)."""
    z = 1.0 - 2.0 * u0
    r = math.sqrt(_np_max(0.0, 1.0 - z * z))
    s, c = sincos(2.0 * _PI * u1)
    return (r * c, r * s, z)


@kernel
def uniform_triangle(u0, u1):
    """Uniform barycentrics (b1, b2) (point = (1 − b1 − b2)·v0 + b1·v1 + b2·v2)."""
    s = math.sqrt(u0)
    return s * (1.0 - u1), s * u1


@kernel
def disk_concentric_pdf(x, y):
    """Density of ``disk_concentric`` per unit area: 1/π inside the unit disk, else 0."""
    return _INV_PI if x * x + y * y <= 1.0 else 0.0


@kernel
def disk_concentric_inverse(x, y):
    """Inverse of ``disk_concentric``: a point of the unit disk → (u0, u1) ∈ [0,1)²."""
    r = math.hypot(x, y)
    phi = math.atan2(y, x)
    if phi < -_PI_4:
        phi = phi + 2.0 * _PI  # phi in [-pi/4, 7pi/4)
    # four wedges of the square: right, top, left, bottom (NaN falls to the last, as numpy's)
    if phi < _PI_4:
        a = r
        b = phi * a / _PI_4
    elif phi < 3.0 * _PI_4:
        b = r
        a = -(phi - 0.5 * _PI) * b / _PI_4
    elif phi < 5.0 * _PI_4:
        a = -r
        b = (phi - _PI) * a / _PI_4
    else:
        b = -r
        a = -(phi - 1.5 * _PI) * b / _PI_4
    return _unit(0.5 * (a + 1.0)), _unit(0.5 * (b + 1.0))


@kernel
def polygon_area_n(n_corners):
    """Area of the regular n-gon inscribed in the unit circle: (N/2)·sin(2π/N) (N float)."""
    return 0.5 * n_corners * math.sin(2.0 * _PI / n_corners)


@kernel
def polygon(u0, u1, n_corners, rotation):
    """Uniform point (x, y) in the regular ``n_corners``-gon (float, ≥ 3) inscribed in the unit
    circle, rotated by ``rotation`` radians (Cycles's ``regular_polygon_sample``; see
    ``square_to_polygon``)."""
    uc = u0 * n_corners
    corner = _np_min(np.floor(uc), n_corners - 1.0)
    s = math.sqrt(_clip(uc - corner, 0.0, 1.0))
    v = u1 * s
    w = 1.0 - s
    half = _PI / n_corners
    px = (w + v) * math.cos(half)
    py = (w - v) * math.sin(half)
    ang = rotation + corner * 2.0 * half
    cr = math.cos(ang)
    sr = math.sin(ang)
    return cr * px - sr * py, sr * px + cr * py


@kernel
def _polygon_local(x, y, n_corners, rotation):
    """Wedge index k (float) and the point rotated back into wedge 0 (centred on +x)."""
    half = _PI / n_corners
    ang = math.atan2(y, x) - rotation
    k = _np_mod(np.floor(ang / (2.0 * half) + 0.5), n_corners)
    back = -(rotation + k * 2.0 * half)
    cb = math.cos(back)
    sb = math.sin(back)
    return k, cb * x - sb * y, sb * x + cb * y, half


@kernel
def polygon_pdf(x, y, n_corners, rotation):
    """Density of ``polygon`` per unit area: 1/area inside the polygon, else 0."""
    _, qx, _, half = _polygon_local(x, y, n_corners, rotation)
    if qx <= math.cos(half) * (1.0 + 1e-12):
        return 1.0 / polygon_area_n(n_corners)
    return 0.0


@kernel
def polygon_inverse(x, y, n_corners, rotation):
    """Inverse of ``polygon``: a point of the polygon → (u0, u1) ∈ [0,1)²."""
    k, qx, qy, half = _polygon_local(x, y, n_corners, rotation)
    ch = math.cos(half)
    sh = math.sin(half)
    w = 0.5 * (qx / ch + qy / sh)
    v = 0.5 * (qx / ch - qy / sh)
    # A point on the ray shared with the previous wedge (w = 0, which would need u.x = (k+1)/N)
    # is written as wedge k-1's point w' = v, v' = 0 instead, so u.x stays in [k/N, (k+1)/N)
    # (not the origin, which every wedge reaches at s = 1).
    if w <= 1e-12 and v > 1e-12:
        k = _np_mod(k - 1.0, n_corners)
        w = v
        v = 0.0
    s = 1.0 - w
    u1 = v / s if s > 0.0 else 0.0
    # keep floor(u.x·N) == k after rounding: s² < 1 by a margin far below float32 resolution
    u0 = (k + _clip(s * s, 0.0, 1.0 - 1e-12)) / n_corners
    return _unit(u0), _unit(u1)


@kernel
def cosine_hemisphere_pdf(d):
    """Solid-angle density of ``cosine_hemisphere``: max(cos θ, 0)/π (d local, z = normal)."""
    return _np_max(d[2], 0.0) * _INV_PI


@kernel
def cosine_hemisphere_inverse(d):
    """Inverse of ``cosine_hemisphere``: a direction (z ≥ 0) → (u0, u1)."""
    return disk_concentric_inverse(d[0], d[1])


@kernel
def cone_to_disk(d, one_minus_cos):
    """Inverse of ``disk_to_cone``: a direction in the cone → the unit-disk point (x, y)."""
    r2 = _clip((1.0 - d[2]) / one_minus_cos, 0.0, 1.0)
    sxy = math.hypot(d[0], d[1])
    k = math.sqrt(r2) / sxy if sxy > 0.0 else 0.0
    return d[0] * k, d[1] * k


@kernel
def uniform_hemisphere_pdf(d):
    """Solid-angle density of ``uniform_hemisphere``: 1/(2π) for z ≥ 0, else 0."""
    return _INV_2PI if d[2] >= 0.0 else 0.0


@kernel
def uniform_hemisphere_inverse(d):
    """Inverse of ``uniform_hemisphere``: a direction (z ≥ 0) → (u0, u1)."""
    x, y = cone_to_disk(d, 1.0)
    return disk_concentric_inverse(x, y)


@kernel
def uniform_sphere_pdf(d):
    """Solid-angle density of ``uniform_sphere``: 1/(4π)."""
    return _INV_4PI


@kernel
def uniform_sphere_inverse(d):
    """Inverse of ``uniform_sphere``: a unit vector → (u0, u1) ∈ [0,1)²."""
    u0 = 0.5 * (1.0 - d[2])
    u1 = _np_mod(math.atan2(d[1], d[0]), 2.0 * _PI) * _INV_2PI
    return _unit(u0), _unit(u1)


@kernel
def uniform_cone_pdf(d, cos_theta_max):
    """Solid-angle density of ``uniform_cone``: 1/(2π(1 − cos θmax)) for d.z ≥ cos θmax, else 0
    (inf for a degenerate cone).  Takes cos θmax (the sampler takes 1 − cos θmax)."""
    val = _INV_2PI / (1.0 - cos_theta_max)
    return val if d[2] >= cos_theta_max else 0.0


@kernel
def uniform_cone_inverse(d, one_minus_cos):
    """Inverse of ``uniform_cone``: a direction in the cone → (u0, u1)."""
    x, y = cone_to_disk(d, one_minus_cos)
    return disk_concentric_inverse(x, y)


@kernel
def triangle_pdf(b1, b2):
    """Density of ``uniform_triangle`` per unit barycentric area: 2 inside, else 0."""
    return 2.0 if (b1 >= 0.0 and b2 >= 0.0 and b1 + b2 <= 1.0) else 0.0


@kernel
def triangle_inverse(b1, b2):
    """Inverse of ``uniform_triangle``: barycentrics → (u0, u1) ∈ [0,1)²."""
    s = b1 + b2
    u1 = b2 / s if s > 0.0 else 0.0
    return _unit(s * s), _unit(u1)


# ---------------------------------------------------------------------------------------------
# row loops (compiled) and the numpy-facing helpers of the wrappers
# ---------------------------------------------------------------------------------------------


@kernel
def _disk_rows(u, out):
    for k in range(u.shape[0]):
        out[k, 0], out[k, 1] = disk_concentric(u[k, 0], u[k, 1])


@kernel
def _disk_pdf_rows(p, out):
    for k in range(p.shape[0]):
        out[k] = disk_concentric_pdf(p[k, 0], p[k, 1])


@kernel
def _disk_inverse_rows(p, out):
    for k in range(p.shape[0]):
        out[k, 0], out[k, 1] = disk_concentric_inverse(p[k, 0], p[k, 1])


@kernel
def _polygon_rows(u, n_corners, rotation, out):
    for k in range(u.shape[0]):
        out[k, 0], out[k, 1] = polygon(u[k, 0], u[k, 1], n_corners, rotation)


@kernel
def _polygon_pdf_rows(p, n_corners, rotation, out):
    for k in range(p.shape[0]):
        out[k] = polygon_pdf(p[k, 0], p[k, 1], n_corners, rotation)


@kernel
def _polygon_inverse_rows(p, n_corners, rotation, out):
    for k in range(p.shape[0]):
        out[k, 0], out[k, 1] = polygon_inverse(p[k, 0], p[k, 1], n_corners, rotation)


@kernel
def _cosine_rows(u, out):
    for k in range(u.shape[0]):
        vec3.store(out, k, cosine_hemisphere(u[k, 0], u[k, 1]))


@kernel
def _cosine_pdf_rows(d, out):
    for k in range(d.shape[0]):
        out[k] = cosine_hemisphere_pdf(vec3.load(d, k))


@kernel
def _hemisphere_rows(u, out):
    for k in range(u.shape[0]):
        vec3.store(out, k, uniform_hemisphere(u[k, 0], u[k, 1]))


@kernel
def _hemisphere_pdf_rows(d, out):
    for k in range(d.shape[0]):
        out[k] = uniform_hemisphere_pdf(vec3.load(d, k))


@kernel
def _hemisphere_inverse_rows(d, out):
    for k in range(d.shape[0]):
        out[k, 0], out[k, 1] = uniform_hemisphere_inverse(vec3.load(d, k))


@kernel
def _sphere_rows(u, out):
    for k in range(u.shape[0]):
        vec3.store(out, k, uniform_sphere(u[k, 0], u[k, 1]))


@kernel
def _sphere_pdf_rows(d, out):
    for k in range(d.shape[0]):
        out[k] = uniform_sphere_pdf(vec3.load(d, k))


@kernel
def _sphere_inverse_rows(d, out):
    for k in range(d.shape[0]):
        out[k, 0], out[k, 1] = uniform_sphere_inverse(vec3.load(d, k))


@kernel
def _cone_rows(u, one_minus_cos, out):
    for k in range(u.shape[0]):
        vec3.store(out, k, uniform_cone(u[k, 0], u[k, 1], one_minus_cos[k]))


@kernel
def _cone_pdf_rows(d, cos_theta_max, out):
    for k in range(d.shape[0]):
        out[k] = uniform_cone_pdf(vec3.load(d, k), cos_theta_max[k])


@kernel
def _cone_inverse_rows(d, one_minus_cos, out):
    for k in range(d.shape[0]):
        out[k, 0], out[k, 1] = uniform_cone_inverse(vec3.load(d, k), one_minus_cos[k])


@kernel
def _triangle_rows(u, b1, b2):
    for k in range(u.shape[0]):
        b1[k], b2[k] = uniform_triangle(u[k, 0], u[k, 1])


@kernel
def _triangle_pdf_rows(b1, b2, out):
    for k in range(b1.shape[0]):
        out[k] = triangle_pdf(b1[k], b2[k])


@kernel
def _triangle_inverse_rows(b1, b2, out):
    for k in range(b1.shape[0]):
        out[k, 0], out[k, 1] = triangle_inverse(b1[k], b2[k])


@kernel
def _frame_rows(n, t_out, b_out):
    for k in range(n.shape[0]):
        t, b = vec3.build_frame(vec3.load(n, k))
        vec3.store(t_out, k, t)
        vec3.store(b_out, k, b)


@kernel
def _to_local_rows(v, t, b, n, out):
    for k in range(v.shape[0]):
        vec3.store(out, k, vec3.to_local(vec3.load(v, k), vec3.load(t, k), vec3.load(b, k),
                                         vec3.load(n, k)))


@kernel
def _to_world_rows(v, t, b, n, out):
    for k in range(v.shape[0]):
        vec3.store(out, k, vec3.to_world(vec3.load(v, k), vec3.load(t, k), vec3.load(b, k),
                                         vec3.load(n, k)))


def _c64(a: np.ndarray) -> np.ndarray:
    """float64, C-contiguous and writeable: one compiled signature serves every call."""
    a = np.ascontiguousarray(a, dtype=np.float64)
    return a if a.flags.writeable else a.copy()


def _rows(x, k: int) -> tuple[np.ndarray, tuple]:
    """(..., k) array -> ((m, k) float64 rows, leading shape)."""
    a = np.asarray(x, dtype=np.float64)[..., :k]
    return _c64(a.reshape(-1, k)), a.shape[:-1]


def _broadcast_rows(*items) -> tuple[list[np.ndarray], tuple]:
    """Items (array, k): k = 0 for per-row scalars, else rows of k components; broadcast over
    the leading shape -> ([(m,) or (m, k) float64], leading shape)."""
    arrs = []
    for x, k in items:
        a = np.asarray(x, dtype=np.float64)
        arrs.append((a[..., :k] if k else a, k))
    lead = np.broadcast_shapes(*(a.shape[:-1] if k else a.shape for a, k in arrs))
    out = []
    for a, k in arrs:
        shape = lead + (k,) if k else lead
        if a.shape != shape:
            a = np.broadcast_to(a, shape)
        out.append(_c64(a.reshape((-1, k) if k else (-1,))))
    return out, lead


# ---------------------------------------------------------------------------------------------
# disk
# ---------------------------------------------------------------------------------------------


def square_to_disk_concentric(u) -> np.ndarray:
    """Shirley-Chiu concentric map of [0,1)² onto the unit disk (uniform in area).

    u: (n, 2) float.  Returns (n, 2) float64 points (x, y) with x² + y² ≤ 1.
    Concentric squares map to concentric circles; the square's centre maps to the origin.
    """
    u, lead = _rows(u, 2)
    out = np.empty_like(u)
    _disk_rows(u, out)
    return out.reshape(lead + (2,))


def square_to_disk_concentric_pdf(p) -> np.ndarray:
    """Density of ``square_to_disk_concentric`` per unit area: 1/pi inside the unit disk, else 0.

    p: (n, 2).  Returns (n,) float64.
    """
    p, lead = _rows(p, 2)
    out = np.empty(p.shape[0])
    _disk_pdf_rows(p, out)
    return out.reshape(lead)


def disk_concentric_to_square(p) -> np.ndarray:
    """Inverse of ``square_to_disk_concentric``: (n, 2) points in the unit disk -> (n, 2)."""
    p, lead = _rows(p, 2)
    out = np.empty_like(p)
    _disk_inverse_rows(p, out)
    return out.reshape(lead + (2,))


# ---------------------------------------------------------------------------------------------
# regular polygon (aperture blades)
# ---------------------------------------------------------------------------------------------


def polygon_area(blades: int) -> float:
    """Area of the regular ``blades``-gon inscribed in the unit circle: (N/2)·sin(2π/N)."""
    return polygon_area_n(float(blades))


def _check_blades(blades) -> float:
    if blades < 3:
        raise ValueError(f"a polygonal aperture needs blades >= 3 (got {blades}); "
                         "use square_to_disk_concentric for a round one")
    return float(blades)


def square_to_polygon(u, blades: int, rotation: float = 0.0) -> np.ndarray:
    """Uniform point in the regular ``blades``-gon inscribed in the unit circle (bokeh shape).

    u: (n, 2) float in [0,1)²; blades: number of corners (>= 3); rotation: radians,
    counter-clockwise.  Returns (n, 2) float64.

    Follows Cycles's ``regular_polygon_sample`` (``kernel/sample/mapping.h``, called from
    ``camera_sample_aperture`` in ``kernel/camera/camera.h`` with ``cam->bladesrotation``):
    u.x picks the wedge ``k = floor(u.x·N)`` and is reused; the wedge is the triangle
    (origin, corner at angle +π/N, corner at −π/N) rotated by ``rotation + 2πk/N``.  So with
    rotation 0 the corners sit at angles (2k+1)·π/N and an *edge* (not a corner) faces +x.
    The camera divides x by the aperture ratio afterwards (not done here).
    """
    n_corners = _check_blades(blades)
    u, lead = _rows(u, 2)
    out = np.empty_like(u)
    _polygon_rows(u, n_corners, float(rotation), out)
    return out.reshape(lead + (2,))


def square_to_polygon_pdf(p, blades: int, rotation: float = 0.0) -> np.ndarray:
    """Density of ``square_to_polygon`` per unit area: 1/area inside the polygon, else 0.

    p: (n, 2).  Returns (n,) float64.
    """
    n_corners = _check_blades(blades)
    p, lead = _rows(p, 2)
    out = np.empty(p.shape[0])
    _polygon_pdf_rows(p, n_corners, float(rotation), out)
    return out.reshape(lead)


def polygon_to_square(p, blades: int, rotation: float = 0.0) -> np.ndarray:
    """Inverse of ``square_to_polygon``: (n, 2) points in the polygon -> (n, 2) in [0,1)²."""
    n_corners = _check_blades(blades)
    p, lead = _rows(p, 2)
    out = np.empty_like(p)
    _polygon_inverse_rows(p, n_corners, float(rotation), out)
    return out.reshape(lead + (2,))


# ---------------------------------------------------------------------------------------------
# hemisphere, sphere, cone (directions in the local z-up frame)
# ---------------------------------------------------------------------------------------------


def square_to_cosine_hemisphere(u) -> np.ndarray:
    """Cosine-weighted direction on the upper hemisphere (Malley: concentric disk lifted to z).

    u: (n, 2).  Returns (n, 3) float64 unit vectors, z ≥ 0 (local frame, z = normal).
    """
    u, lead = _rows(u, 2)
    out = np.empty((u.shape[0], 3))
    _cosine_rows(u, out)
    return out.reshape(lead + (3,))


def square_to_cosine_hemisphere_pdf(d) -> np.ndarray:
    """Solid-angle density of ``square_to_cosine_hemisphere``: max(cos θ, 0)/π.

    d: (n, 3) unit vectors (local).  Returns (n,) float64.
    """
    d, lead = _rows(d, 3)
    out = np.empty(d.shape[0])
    _cosine_pdf_rows(d, out)
    return out.reshape(lead)


def cosine_hemisphere_to_square(d) -> np.ndarray:
    """Inverse of ``square_to_cosine_hemisphere``: (n, 3) directions (z ≥ 0) -> (n, 2)."""
    return disk_concentric_to_square(np.asarray(d, dtype=np.float64)[..., :2])


def square_to_uniform_hemisphere(u) -> np.ndarray:
    """Uniform direction on the upper hemisphere (z ≥ 0), via the concentric disk.

    u: (n, 2).  Returns (n, 3) float64 unit vectors (local frame).
    """
    u, lead = _rows(u, 2)
    out = np.empty((u.shape[0], 3))
    _hemisphere_rows(u, out)
    return out.reshape(lead + (3,))


def square_to_uniform_hemisphere_pdf(d) -> np.ndarray:
    """Solid-angle density of the uniform hemisphere: 1/(2π) for z ≥ 0, else 0.  d: (n, 3)."""
    d, lead = _rows(d, 3)
    out = np.empty(d.shape[0])
    _hemisphere_pdf_rows(d, out)
    return out.reshape(lead)


def uniform_hemisphere_to_square(d) -> np.ndarray:
    """Inverse of ``square_to_uniform_hemisphere``: (n, 3) directions (z ≥ 0) -> (n, 2)."""
    d, lead = _rows(d, 3)
    out = np.empty((d.shape[0], 2))
    _hemisphere_inverse_rows(d, out)
    return out.reshape(lead + (2,))


def square_to_uniform_sphere(u) -> np.ndarray:
    """Uniform direction on the unit sphere (Archimedes: z = 1 − 2u₀, φ = 2πu₁; as Cycles).

    u: (n, 2).  Returns (n, 3) float64 unit vectors.
    """
    u, lead = _rows(u, 2)
    out = np.empty((u.shape[0], 3))
    _sphere_rows(u, out)
    return out.reshape(lead + (3,))


def square_to_uniform_sphere_pdf(d) -> np.ndarray:
    """Solid-angle density of the uniform sphere: 1/(4π).  d: (n, 3).  Returns (n,)."""
    d, lead = _rows(d, 3)
    out = np.empty(d.shape[0])
    _sphere_pdf_rows(d, out)
    return out.reshape(lead)


def uniform_sphere_to_square(d) -> np.ndarray:
    """Inverse of ``square_to_uniform_sphere``: (n, 3) unit vectors -> (n, 2) in [0,1)²."""
    d, lead = _rows(d, 3)
    out = np.empty((d.shape[0], 2))
    _sphere_inverse_rows(d, out)
    return out.reshape(lead + (2,))


def square_to_uniform_cone(u, cos_theta_max) -> np.ndarray:
    """Uniform direction in the cone θ ≤ θmax around +z (sphere lights, sun disk).

    u: (n, 2); cos_theta_max: scalar or (n,) float, in [-1, 1).  Returns (n, 3) float64 unit
    vectors with z ≥ cos_theta_max.  Uses the concentric disk lifted with
    cos θ = 1 − r²(1 − cos θmax) (Cycles's ``sample_uniform_cone``), which keeps precision for
    tiny cones.  cos_theta_max = 1 is a delta (returns +z).
    """
    (u, cmax), lead = _broadcast_rows((u, 2), (cos_theta_max, 0))
    out = np.empty((u.shape[0], 3))
    _cone_rows(u, 1.0 - cmax, out)
    return out.reshape(lead + (3,))


def square_to_uniform_cone_pdf(d, cos_theta_max) -> np.ndarray:
    """Solid-angle density of ``square_to_uniform_cone``: 1/(2π(1 − cos θmax)) inside, else 0.

    d: (n, 3) unit vectors; cos_theta_max scalar or (n,).  Returns (n,) float64 (inf for a
    degenerate cone, cos_theta_max = 1).
    """
    (d, cmax), lead = _broadcast_rows((d, 3), (cos_theta_max, 0))
    out = np.empty(d.shape[0])
    _cone_pdf_rows(d, cmax, out)
    return out.reshape(lead)


def uniform_cone_to_square(d, cos_theta_max) -> np.ndarray:
    """Inverse of ``square_to_uniform_cone``: (n, 3) directions inside the cone -> (n, 2)."""
    (d, cmax), lead = _broadcast_rows((d, 3), (cos_theta_max, 0))
    out = np.empty((d.shape[0], 2))
    _cone_inverse_rows(d, 1.0 - cmax, out)
    return out.reshape(lead + (2,))


# ---------------------------------------------------------------------------------------------
# triangle
# ---------------------------------------------------------------------------------------------


def square_to_triangle(u) -> tuple[np.ndarray, np.ndarray]:
    """Uniform barycentrics on a triangle.

    u: (n, 2).  Returns (b1, b2), each (n,) float64, with b1, b2 ≥ 0 and b1 + b2 ≤ 1; the point
    is (1 − b1 − b2)·v0 + b1·v1 + b2·v2 (Embree's convention).  Map: s = √u₀, b1 = s(1 − u₁),
    b2 = s·u₁.
    """
    u, lead = _rows(u, 2)
    b1 = np.empty(u.shape[0])
    b2 = np.empty(u.shape[0])
    _triangle_rows(u, b1, b2)
    return b1.reshape(lead), b2.reshape(lead)


def square_to_triangle_pdf(b1, b2) -> np.ndarray:
    """Density of ``square_to_triangle`` per unit *barycentric* area: 2 inside, else 0.

    For the density per unit world area divide by the triangle's area instead: pdf = 1/A.
    """
    (b1, b2), lead = _broadcast_rows((b1, 0), (b2, 0))
    out = np.empty(b1.shape[0])
    _triangle_pdf_rows(b1, b2, out)
    return out.reshape(lead)


def triangle_to_square(b1, b2) -> np.ndarray:
    """Inverse of ``square_to_triangle``: barycentrics (n,), (n,) -> (n, 2) in [0,1)²."""
    (b1, b2), lead = _broadcast_rows((b1, 0), (b2, 0))
    out = np.empty((b1.shape[0], 2))
    _triangle_inverse_rows(b1, b2, out)
    return out.reshape(lead + (2,))


# ---------------------------------------------------------------------------------------------
# the lecture's deterministic midpoint rule
# ---------------------------------------------------------------------------------------------


def hemisphere_midpoint_grid(M: int, N: int) -> tuple[np.ndarray, np.ndarray]:
    """Directions and weights of the uniform midpoint rule over the upper hemisphere.

    The lecture's rule: ∫_Ω g(ω) dω ≈ Σ_m Σ_n g(θ_n, φ_m) sin θ_n Δθ Δφ with
    θ_n = (n − ½)Δθ, Δθ = (π/2)/M (n = 1..M) and φ_m = (m − ½)Δφ, Δφ = 2π/N (m = 1..N).

    Returns (dirs, weights): dirs (M·N, 3) float64 unit vectors (local z-up; θ-major order:
    index = n·N + m), weights (M·N,) float64 = sin θ Δθ Δφ (solid angle per cell; they sum to
    ≈ 2π).  Estimate: ``np.sum(g(dirs) * weights)``.
    """
    d_theta = 0.5 * _PI / M
    d_phi = 2.0 * _PI / N
    theta = (np.arange(M) + 0.5) * d_theta
    phi = (np.arange(N) + 0.5) * d_phi
    th, ph = np.meshgrid(theta, phi, indexing="ij")
    st = np.sin(th)
    dirs = np.stack([st * np.cos(ph), st * np.sin(ph), np.cos(th)], axis=-1).reshape(-1, 3)
    weights = (st * d_theta * d_phi).reshape(-1)
    return dirs, weights


# ---------------------------------------------------------------------------------------------
# frames (the scalar kernels are drt.kernels.vec3's build_frame / to_local / to_world)
# ---------------------------------------------------------------------------------------------


def build_frame(n) -> tuple[np.ndarray, np.ndarray]:
    """Orthonormal tangents (t, b) for unit normals n, so that (t, b, n) is right-handed.

    n: (n, 3) unit vectors.  Returns t, b: (n, 3) float64 with t × b = n.  Branchless
    construction of Duff et al. 2017, "Building an Orthonormal Basis, Revisited" (continuous
    except across n.z = 0 sign flip; exact for n = ±z).
    """
    n, lead = _rows(n, 3)
    t = np.empty_like(n)
    b = np.empty_like(n)
    _frame_rows(n, t, b)
    return t.reshape(lead + (3,)), b.reshape(lead + (3,))


def to_local(v, t, b, n) -> np.ndarray:
    """World vectors v (n, 3) -> local coordinates (v·t, v·b, v·n), (n, 3) float64."""
    (v, t, b, n), lead = _broadcast_rows((v, 3), (t, 3), (b, 3), (n, 3))
    out = np.empty_like(v)
    _to_local_rows(v, t, b, n, out)
    return out.reshape(lead + (3,))


def to_world(v, t, b, n) -> np.ndarray:
    """Local vectors v (n, 3) -> world: v.x·t + v.y·b + v.z·n, (n, 3) float64."""
    (v, t, b, n), lead = _broadcast_rows((v, 3), (t, 3), (b, 3), (n, 3))
    out = np.empty_like(v)
    _to_world_rows(v, t, b, n, out)
    return out.reshape(lead + (3,))
