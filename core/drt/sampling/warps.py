"""Warps from the unit square to disks, polygons, the hemisphere, sphere, cones and triangles.

Every warp ``square_to_X(u)`` takes ``u: (n, 2)`` float in [0, 1)² and is vectorized over n
(any leading shape ``(..., 2)`` works; results are float64).  Beside each warp:

* ``square_to_X_pdf(x)``: its density, with the measure stated (per unit *area* for points in the
  plane, per unit *solid angle* for directions); 0 outside the support.
* ``X_to_square(x)``: the inverse map, where one exists (round-trip tested).

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

from ..kernels import kernel

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
]

_PI = np.pi
_INV_PI = 1.0 / np.pi
_INV_2PI = 0.5 / np.pi
_INV_4PI = 0.25 / np.pi
_PI_4 = 0.25 * np.pi

# Largest float64 below 1: inverse maps clamp into [0, 1) so their output is a valid sample.
_ONE_MINUS_EPS = np.nextafter(1.0, 0.0)


# ---------------------------------------------------------------------------------------------
# scalar kernels: one sample at a time, called from the compiled integrator, BSDFs and lights.
# They are the implementation; the vectorized functions below apply them to arrays.
# ---------------------------------------------------------------------------------------------


@kernel
def disk_concentric(u0, u1):
    """Shirley-Chiu concentric map of (u0, u1) ∈ [0,1)² onto the unit disk → (x, y)."""
    a = 2.0 * u0 - 1.0
    b = 2.0 * u1 - 1.0
    if a == 0.0 and b == 0.0:
        return 0.0, 0.0
    if abs(a) > abs(b):
        r = a
        phi = _PI_4 * (b / a)
    else:
        r = b
        phi = 0.5 * _PI - _PI_4 * (a / b)
    return r * math.cos(phi), r * math.sin(phi)


@kernel
def disk_to_cone(x, y, one_minus_cos):
    """Area-preserving lift of a unit-disk point onto the cone cos θ ≥ 1 − one_minus_cos about
    +z (Cycles's ``sample_uniform_cone``): cos θ = 1 − r²·one_minus_cos."""
    r2 = x * x + y * y
    s = math.sqrt(max(0.0, one_minus_cos * (2.0 - one_minus_cos * r2)))
    return (x * s, y * s, 1.0 - r2 * one_minus_cos)


@kernel
def cosine_hemisphere(u0, u1):
    """Cosine-weighted direction, z ≥ 0 (Malley); pdf = z/π."""
    x, y = disk_concentric(u0, u1)
    return (x, y, math.sqrt(max(0.0, 1.0 - x * x - y * y)))


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
    r = math.sqrt(max(0.0, 1.0 - z * z))
    phi = 2.0 * _PI * u1
    return (r * math.cos(phi), r * math.sin(phi), z)


@kernel
def uniform_triangle(u0, u1):
    """Uniform barycentrics (b1, b2) (point = (1 − b1 − b2)·v0 + b1·v1 + b2·v2)."""
    s = math.sqrt(u0)
    return s * (1.0 - u1), s * u1


def _f64(x) -> np.ndarray:
    return np.asarray(x, dtype=np.float64)


def _to_unit_square(u: np.ndarray) -> np.ndarray:
    return np.clip(u, 0.0, _ONE_MINUS_EPS)


# ---------------------------------------------------------------------------------------------
# disk
# ---------------------------------------------------------------------------------------------


def square_to_disk_concentric(u) -> np.ndarray:
    """Shirley-Chiu concentric map of [0,1)² onto the unit disk (uniform in area).

    u: (n, 2) float.  Returns (n, 2) float64 points (x, y) with x² + y² ≤ 1.
    Concentric squares map to concentric circles; the square's centre maps to the origin.
    """
    u = _f64(u)
    a = 2.0 * u[..., 0] - 1.0
    b = 2.0 * u[..., 1] - 1.0
    use_a = np.abs(a) > np.abs(b)
    r = np.where(use_a, a, b)
    with np.errstate(divide="ignore", invalid="ignore"):
        phi = np.where(use_a, _PI_4 * (b / a), 0.5 * _PI - _PI_4 * (a / b))
    phi = np.where((a == 0.0) & (b == 0.0), 0.0, phi)
    return np.stack([r * np.cos(phi), r * np.sin(phi)], axis=-1)


def square_to_disk_concentric_pdf(p) -> np.ndarray:
    """Density of ``square_to_disk_concentric`` per unit area: 1/pi inside the unit disk, else 0.

    p: (n, 2).  Returns (n,) float64.
    """
    p = _f64(p)
    r2 = p[..., 0] ** 2 + p[..., 1] ** 2
    return np.where(r2 <= 1.0, _INV_PI, 0.0)


def disk_concentric_to_square(p) -> np.ndarray:
    """Inverse of ``square_to_disk_concentric``: (n, 2) points in the unit disk -> (n, 2)."""
    p = _f64(p)
    x, y = p[..., 0], p[..., 1]
    r = np.hypot(x, y)
    phi = np.arctan2(y, x)
    phi = np.where(phi < -_PI_4, phi + 2.0 * _PI, phi)  # phi in [-pi/4, 7pi/4)
    # four wedges of the square: right, top, left, bottom
    right = phi < _PI_4
    top = ~right & (phi < 3.0 * _PI_4)
    left = ~right & ~top & (phi < 5.0 * _PI_4)
    a = np.where(right, r, np.where(left, -r, 0.0))
    b = np.where(top, r, np.where(right | left, 0.0, -r))
    b = np.where(right, phi * a / _PI_4, b)
    b = np.where(left, (phi - _PI) * a / _PI_4, b)
    a = np.where(top, -(phi - 0.5 * _PI) * b / _PI_4, a)
    bottom = ~right & ~top & ~left
    a = np.where(bottom, -(phi - 1.5 * _PI) * b / _PI_4, a)
    return _to_unit_square(np.stack([0.5 * (a + 1.0), 0.5 * (b + 1.0)], axis=-1))


# ---------------------------------------------------------------------------------------------
# regular polygon (aperture blades)
# ---------------------------------------------------------------------------------------------


def polygon_area(blades: int) -> float:
    """Area of the regular ``blades``-gon inscribed in the unit circle: (N/2)·sin(2π/N)."""
    return 0.5 * blades * np.sin(2.0 * _PI / blades)


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
    u = _f64(u)
    uc = u[..., 0] * n_corners
    corner = np.minimum(np.floor(uc), n_corners - 1.0)
    s = np.sqrt(np.clip(uc - corner, 0.0, 1.0))
    v = u[..., 1] * s
    w = 1.0 - s
    half = _PI / n_corners
    px = (w + v) * np.cos(half)
    py = (w - v) * np.sin(half)
    ang = rotation + corner * 2.0 * half
    cr, sr = np.cos(ang), np.sin(ang)
    return np.stack([cr * px - sr * py, sr * px + cr * py], axis=-1)


def _polygon_local(p, n_corners: float, rotation: float):
    """Wedge index k and the point rotated back into wedge 0 (centred on +x)."""
    p = _f64(p)
    half = _PI / n_corners
    ang = np.arctan2(p[..., 1], p[..., 0]) - rotation
    k = np.mod(np.floor(ang / (2.0 * half) + 0.5), n_corners)
    back = -(rotation + k * 2.0 * half)
    cb, sb = np.cos(back), np.sin(back)
    qx = cb * p[..., 0] - sb * p[..., 1]
    qy = sb * p[..., 0] + cb * p[..., 1]
    return k, qx, qy, half


def square_to_polygon_pdf(p, blades: int, rotation: float = 0.0) -> np.ndarray:
    """Density of ``square_to_polygon`` per unit area: 1/area inside the polygon, else 0.

    p: (n, 2).  Returns (n,) float64.
    """
    n_corners = _check_blades(blades)
    _, qx, _, half = _polygon_local(p, n_corners, rotation)
    inside = qx <= np.cos(half) * (1.0 + 1e-12)
    return np.where(inside, 1.0 / polygon_area(blades), 0.0)


def polygon_to_square(p, blades: int, rotation: float = 0.0) -> np.ndarray:
    """Inverse of ``square_to_polygon``: (n, 2) points in the polygon -> (n, 2) in [0,1)²."""
    n_corners = _check_blades(blades)
    k, qx, qy, half = _polygon_local(p, n_corners, rotation)
    w = 0.5 * (qx / np.cos(half) + qy / np.sin(half))
    v = 0.5 * (qx / np.cos(half) - qy / np.sin(half))
    # A point on the ray shared with the previous wedge (w = 0, which would need u.x = (k+1)/N)
    # is written as wedge k-1's point w' = v, v' = 0 instead, so u.x stays in [k/N, (k+1)/N).
    shared = (w <= 1e-12) & (v > 1e-12)  # (not the origin, which every wedge reaches at s = 1)
    k = np.where(shared, np.mod(k - 1.0, n_corners), k)
    w, v = np.where(shared, v, w), np.where(shared, 0.0, v)
    s = 1.0 - w
    with np.errstate(divide="ignore", invalid="ignore"):
        u1 = np.where(s > 0.0, v / s, 0.0)
    # keep floor(u.x·N) == k after rounding: s² < 1 by a margin far below float32 resolution
    u0 = (k + np.clip(s * s, 0.0, 1.0 - 1e-12)) / n_corners
    return _to_unit_square(np.stack([u0, u1], axis=-1))


# ---------------------------------------------------------------------------------------------
# hemisphere, sphere, cone (directions in the local z-up frame)
# ---------------------------------------------------------------------------------------------


def square_to_cosine_hemisphere(u) -> np.ndarray:
    """Cosine-weighted direction on the upper hemisphere (Malley: concentric disk lifted to z).

    u: (n, 2).  Returns (n, 3) float64 unit vectors, z ≥ 0 (local frame, z = normal).
    """
    d = square_to_disk_concentric(u)
    z = np.sqrt(np.maximum(0.0, 1.0 - d[..., 0] ** 2 - d[..., 1] ** 2))
    return np.concatenate([d, z[..., None]], axis=-1)


def square_to_cosine_hemisphere_pdf(d) -> np.ndarray:
    """Solid-angle density of ``square_to_cosine_hemisphere``: max(cos θ, 0)/π.

    d: (n, 3) unit vectors (local).  Returns (n,) float64.
    """
    return np.maximum(_f64(d)[..., 2], 0.0) * _INV_PI


def cosine_hemisphere_to_square(d) -> np.ndarray:
    """Inverse of ``square_to_cosine_hemisphere``: (n, 3) directions (z ≥ 0) -> (n, 2)."""
    return disk_concentric_to_square(_f64(d)[..., :2])


def _disk_to_cone(xy: np.ndarray, one_minus_cos) -> np.ndarray:
    """Area-preserving lift of the unit disk onto the cone cos θ ≥ 1 − one_minus_cos
    (Cycles's ``sample_uniform_cone``): cos θ = 1 − r²·(1 − cos θmax)."""
    r2 = xy[..., 0] ** 2 + xy[..., 1] ** 2
    cos_theta = 1.0 - r2 * one_minus_cos
    scale = np.sqrt(np.maximum(0.0, one_minus_cos * (2.0 - one_minus_cos * r2)))
    return np.concatenate([xy * scale[..., None], cos_theta[..., None]], axis=-1)


def _cone_to_disk(d: np.ndarray, one_minus_cos) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        r2 = np.clip((1.0 - d[..., 2]) / one_minus_cos, 0.0, 1.0)
        sxy = np.hypot(d[..., 0], d[..., 1])
        k = np.where(sxy > 0.0, np.sqrt(r2) / sxy, 0.0)
    return d[..., :2] * k[..., None]


def square_to_uniform_hemisphere(u) -> np.ndarray:
    """Uniform direction on the upper hemisphere (z ≥ 0), via the concentric disk.

    u: (n, 2).  Returns (n, 3) float64 unit vectors (local frame).
    """
    return _disk_to_cone(square_to_disk_concentric(u), 1.0)


def square_to_uniform_hemisphere_pdf(d) -> np.ndarray:
    """Solid-angle density of the uniform hemisphere: 1/(2π) for z ≥ 0, else 0.  d: (n, 3)."""
    return np.where(_f64(d)[..., 2] >= 0.0, _INV_2PI, 0.0)


def uniform_hemisphere_to_square(d) -> np.ndarray:
    """Inverse of ``square_to_uniform_hemisphere``: (n, 3) directions (z ≥ 0) -> (n, 2)."""
    return disk_concentric_to_square(_cone_to_disk(_f64(d), 1.0))


def square_to_uniform_sphere(u) -> np.ndarray:
    """Uniform direction on the unit sphere (Archimedes: z = 1 − 2u₀, φ = 2πu₁; as Cycles).

    u: (n, 2).  Returns (n, 3) float64 unit vectors.
    """
    u = _f64(u)
    z = 1.0 - 2.0 * u[..., 0]
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = 2.0 * _PI * u[..., 1]
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)


def square_to_uniform_sphere_pdf(d) -> np.ndarray:
    """Solid-angle density of the uniform sphere: 1/(4π).  d: (n, 3).  Returns (n,)."""
    return np.full(_f64(d).shape[:-1], _INV_4PI)


def uniform_sphere_to_square(d) -> np.ndarray:
    """Inverse of ``square_to_uniform_sphere``: (n, 3) unit vectors -> (n, 2) in [0,1)²."""
    d = _f64(d)
    u0 = 0.5 * (1.0 - d[..., 2])
    u1 = np.mod(np.arctan2(d[..., 1], d[..., 0]), 2.0 * _PI) * _INV_2PI
    return _to_unit_square(np.stack([u0, u1], axis=-1))


def square_to_uniform_cone(u, cos_theta_max) -> np.ndarray:
    """Uniform direction in the cone θ ≤ θmax around +z (sphere lights, sun disk).

    u: (n, 2); cos_theta_max: scalar or (n,) float, in [-1, 1).  Returns (n, 3) float64 unit
    vectors with z ≥ cos_theta_max.  Uses the concentric disk lifted with
    cos θ = 1 − r²(1 − cos θmax) (Cycles's ``sample_uniform_cone``), which keeps precision for
    tiny cones.  cos_theta_max = 1 is a delta (returns +z).
    """
    omc = 1.0 - _f64(cos_theta_max)
    return _disk_to_cone(square_to_disk_concentric(u), omc)


def square_to_uniform_cone_pdf(d, cos_theta_max) -> np.ndarray:
    """Solid-angle density of ``square_to_uniform_cone``: 1/(2π(1 − cos θmax)) inside, else 0.

    d: (n, 3) unit vectors; cos_theta_max scalar or (n,).  Returns (n,) float64 (inf for a
    degenerate cone, cos_theta_max = 1).
    """
    d = _f64(d)
    cmax = _f64(cos_theta_max)
    with np.errstate(divide="ignore"):
        val = _INV_2PI / (1.0 - cmax)
    return np.where(d[..., 2] >= cmax, val, 0.0)


def uniform_cone_to_square(d, cos_theta_max) -> np.ndarray:
    """Inverse of ``square_to_uniform_cone``: (n, 3) directions inside the cone -> (n, 2)."""
    return disk_concentric_to_square(_cone_to_disk(_f64(d), 1.0 - _f64(cos_theta_max)))


# ---------------------------------------------------------------------------------------------
# triangle
# ---------------------------------------------------------------------------------------------


def square_to_triangle(u) -> tuple[np.ndarray, np.ndarray]:
    """Uniform barycentrics on a triangle.

    u: (n, 2).  Returns (b1, b2), each (n,) float64, with b1, b2 ≥ 0 and b1 + b2 ≤ 1; the point
    is (1 − b1 − b2)·v0 + b1·v1 + b2·v2 (Embree's convention).  Map: s = √u₀, b1 = s(1 − u₁),
    b2 = s·u₁.
    """
    u = _f64(u)
    s = np.sqrt(u[..., 0])
    return s * (1.0 - u[..., 1]), s * u[..., 1]


def square_to_triangle_pdf(b1, b2) -> np.ndarray:
    """Density of ``square_to_triangle`` per unit *barycentric* area: 2 inside, else 0.

    For the density per unit world area divide by the triangle's area instead: pdf = 1/A.
    """
    b1, b2 = _f64(b1), _f64(b2)
    inside = (b1 >= 0.0) & (b2 >= 0.0) & (b1 + b2 <= 1.0)
    return np.where(inside, 2.0, 0.0)


def triangle_to_square(b1, b2) -> np.ndarray:
    """Inverse of ``square_to_triangle``: barycentrics (n,), (n,) -> (n, 2) in [0,1)²."""
    b1, b2 = _f64(b1), _f64(b2)
    s = b1 + b2
    with np.errstate(divide="ignore", invalid="ignore"):
        u1 = np.where(s > 0.0, b2 / s, 0.0)
    return _to_unit_square(np.stack([s * s, u1], axis=-1))


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
# frames
# ---------------------------------------------------------------------------------------------


def build_frame(n) -> tuple[np.ndarray, np.ndarray]:
    """Orthonormal tangents (t, b) for unit normals n, so that (t, b, n) is right-handed.

    n: (n, 3) unit vectors.  Returns t, b: (n, 3) float64 with t × b = n.  Branchless
    construction of Duff et al. 2017, "Building an Orthonormal Basis, Revisited" (continuous
    except across n.z = 0 sign flip; exact for n = ±z).
    """
    n = _f64(n)
    x, y, z = n[..., 0], n[..., 1], n[..., 2]
    sign = np.copysign(1.0, z)
    a = -1.0 / (sign + z)
    bxy = x * y * a
    t = np.stack([1.0 + sign * x * x * a, sign * bxy, -sign * x], axis=-1)
    b = np.stack([bxy, sign + y * y * a, -y], axis=-1)
    return t, b


def to_local(v, t, b, n) -> np.ndarray:
    """World vectors v (n, 3) -> local coordinates (v·t, v·b, v·n), (n, 3) float64."""
    v = _f64(v)
    out = np.empty(np.broadcast_shapes(v.shape, np.shape(t)))
    # one einsum pass per axis: no (n, 3) product temporaries (this runs several times a bounce)
    out[..., 0] = np.einsum("...j,...j->...", v, t)
    out[..., 1] = np.einsum("...j,...j->...", v, b)
    out[..., 2] = np.einsum("...j,...j->...", v, n)
    return out


def to_world(v, t, b, n) -> np.ndarray:
    """Local vectors v (n, 3) -> world: v.x·t + v.y·b + v.z·n, (n, 3) float64."""
    v = _f64(v)
    return v[..., 0:1] * _f64(t) + v[..., 1:2] * _f64(b) + v[..., 2:3] * _f64(n)
