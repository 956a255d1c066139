"""Private square → direction warps used by the lights.

Kept here (private) so that `drt.lights` does not depend on the order in which the sampling
module is written; every map is vectorized over the first axis. All directions are unit vectors.
"""

from __future__ import annotations

import numpy as np


def build_frame(nz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Orthonormal tangents (t, b) for unit vectors nz (m, 3), so that (t, b, nz) is right-handed.

    Duff et al. 2017, "Building an orthonormal basis, revisited" (branchless).
    """
    x, y, z = nz[:, 0], nz[:, 1], nz[:, 2]
    sign = np.where(z >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + z)
    b = x * y * a
    t = np.stack([1.0 + sign * x * x * a, sign * b, -sign * x], axis=1)
    s = np.stack([b, sign + y * y * a, -y], axis=1)
    return t, s


def to_world(local: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Rotate local directions (m, 3), z = `axis` (m, 3) unit, into world space."""
    t, b = build_frame(axis)
    return local[:, :1] * t + local[:, 1:2] * b + local[:, 2:3] * axis


def square_to_uniform_cone(u: np.ndarray, one_minus_cos_max: np.ndarray) -> np.ndarray:
    """u (m, 2) → local directions (m, 3) uniform in the cone θ ≤ θmax about +z.

    Takes 1 − cos θmax (m,) rather than cos θmax so that tiny cones (the sun, far spheres) keep
    their precision. Solid-angle pdf = 1 / (2π (1 − cos θmax)).
    """
    s = u[:, 0] * one_minus_cos_max                       # 1 − cos θ
    cos_t = 1.0 - s
    sin_t = np.sqrt(np.maximum(s * (2.0 - s), 0.0))
    phi = 2.0 * np.pi * u[:, 1]
    return np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t], axis=1)


def square_to_uniform_sphere(u: np.ndarray) -> np.ndarray:
    """u (m, 2) → uniform directions on the unit sphere (pdf 1/(4π))."""
    z = 1.0 - 2.0 * u[:, 0]
    r = np.sqrt(np.maximum(1.0 - z * z, 0.0))
    phi = 2.0 * np.pi * u[:, 1]
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def square_to_disk_concentric(u: np.ndarray) -> np.ndarray:
    """u (m, 2) → points (m, 2) uniform on the unit disk (Shirley–Chiu concentric map)."""
    a = 2.0 * u[:, 0] - 1.0
    b = 2.0 * u[:, 1] - 1.0
    first = np.abs(a) > np.abs(b)
    r = np.where(first, a, b)
    with np.errstate(divide="ignore", invalid="ignore"):
        phi = np.where(first, (np.pi / 4) * (b / a), np.pi / 2 - (np.pi / 4) * (a / b))
    phi = np.where((a == 0) & (b == 0), 0.0, phi)
    return np.stack([r * np.cos(phi), r * np.sin(phi)], axis=1)


def square_to_cosine_hemisphere(u: np.ndarray) -> np.ndarray:
    """u (m, 2) → local directions with pdf cos θ / π about +z (Malley's method)."""
    d = square_to_disk_concentric(u)
    z = np.sqrt(np.maximum(1.0 - (d * d).sum(axis=1), 0.0))
    return np.concatenate([d, z[:, None]], axis=1)


def square_to_triangle(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """u (m, 2) → barycentrics (b1, b2) uniform over a triangle (sqrt parameterisation)."""
    su = np.sqrt(u[:, 0])
    return 1.0 - su, u[:, 1] * su


def normalize(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors and lengths of v (m, 3); zero vectors stay zero."""
    length = np.linalg.norm(v, axis=1)
    safe = np.where(length > 0.0, length, 1.0)
    return v / safe[:, None], length
