"""Directions ↔ image coordinates of environment maps, exactly as Cycles maps them
(``kernel/camera/projection.h``; Blender world space, +Z up; u, v in [0, 1] with v from the
bottom row of the image).

- **Equirectangular** (Cycles's default range (−2π, π, −π, π)):
  u = (atan2(y, x) − π)/(−2π) = ½ − atan2(y, x)/2π, v = 1 − acos(z)/π. So u = ½ looks along
  +X, u grows toward −Y (clockwise seen from above), v = 1 is straight up (+Z).
  Back: φ = π − 2πu, θ = π − πv, d = (sin θ cos φ, sin θ sin φ, cos θ).
- **Mirror ball**: the image of a mirror sphere seen from −Y (orthographic): the point
  (2u − 1, −√(1 − x² − z²), 2v − 1) of the unit sphere reflects the view ray (0, 1, 0) into d.

Scalar ``@kernel`` functions; a zero direction maps to (0, 0) as in Cycles.
"""

from __future__ import annotations

import math

from ..kernels import kernel

EQUIRECTANGULAR, MIRROR_BALL = 0, 1


@kernel
def direction_to_equirectangular(x, y, z):
    """(u, v) of direction (x, y, z) (need not be unit; zero → (0, 0))."""
    length = math.sqrt(x * x + y * y + z * z)
    if length == 0.0:
        return 0.0, 0.0
    u = (math.atan2(y, x) - math.pi) / (-2.0 * math.pi)
    v = (math.acos(min(max(z / length, -1.0), 1.0)) - math.pi) / (-math.pi)
    return u, v


@kernel
def equirectangular_to_direction(u, v):
    """Unit direction of equirectangular coordinates (u, v)."""
    phi = -2.0 * math.pi * u + math.pi
    theta = -math.pi * v + math.pi
    st = math.sin(theta)
    return (st * math.cos(phi), st * math.sin(phi), math.cos(theta))


@kernel
def direction_to_mirrorball(x, y, z):
    """(u, v) of unit direction (x, y, z) on a mirror-ball image (Cycles's
    ``direction_to_mirrorball``: the inverse of `mirrorball_to_direction`)."""
    y -= 1.0
    div = 2.0 * math.sqrt(max(-0.5 * y, 0.0))
    if div > 0.0:
        x /= div
        y /= div
        z /= div
    return 0.5 * (x + 1.0), 0.5 * (z + 1.0)


@kernel
def mirrorball_to_direction(u, v):
    """Direction reflected at the mirror-ball image point (u, v); (0, 0, 0) outside the ball."""
    x = 2.0 * u - 1.0
    z = 2.0 * v - 1.0
    if x * x + z * z > 1.0:
        return (0.0, 0.0, 0.0)
    y = -math.sqrt(max(1.0 - x * x - z * z, 0.0))
    # reflect I = (0, −1, 0): 2 (n·I) n − I
    d = 2.0 * (-y)
    return (d * x, d * y + 1.0, d * z)


@kernel
def direction_to_uv(projection, x, y, z):
    """Environment Texture lookup coordinates of a direction (Cycles's
    ``svm_node_tex_environment_projection``: the vector is normalised first)."""
    length = math.sqrt(x * x + y * y + z * z)
    if length > 0.0:
        x, y, z = x / length, y / length, z / length
    if projection == EQUIRECTANGULAR:
        return direction_to_equirectangular(x, y, z)
    return direction_to_mirrorball(x, y, z)
