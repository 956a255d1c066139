"""The scalar warps the lights use: the shared ones from :mod:`drt.sampling.warps`, plus a uniform
cone parameterised by 1 − cos θmax (so that tiny cones — the sun, far sphere lights — keep their
precision) and two small vector helpers. One sample at a time; directions are unit 3-tuples.
"""

from __future__ import annotations

import math

from .common import scalar_kernel
from ..kernels.vec3 import build_frame
from ..kernels.vec3 import to_world as _to_world
from ..sampling.trig import sincos
from ..sampling.warps import (cosine_hemisphere, disk_concentric,  # noqa: F401 (re-exported)
                              uniform_sphere, uniform_triangle)

_TWO_PI = 2.0 * math.pi


@scalar_kernel
def to_world(local, axis):
    """Rotate a local direction (z = `axis`, unit) into world space."""
    t, b = build_frame(axis)
    return _to_world(local, t, b, axis)


@scalar_kernel
def uniform_cone(u0, u1, one_minus_cos_max):
    """(u0, u1) → local direction uniform in the cone θ ≤ θmax about +z: 1 − cos θ = u0·(1 −
    cos θmax), φ = 2π u1. Takes 1 − cos θmax so that tiny cones (the sun, far spheres) keep their
    precision. Solid-angle pdf = 1 / (2π (1 − cos θmax))."""
    s = u0 * one_minus_cos_max                       # 1 − cos θ
    cos_t = 1.0 - s
    sin_t = math.sqrt(max(s * (2.0 - s), 0.0))
    sin_phi, cos_phi = sincos(_TWO_PI * u1)
    return (sin_t * cos_phi, sin_t * sin_phi, cos_t)


@scalar_kernel
def normalize(v):
    """(unit vector, length) of v; a zero vector stays zero (divides, as the numpy code did)."""
    length = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    safe = length if length > 0.0 else 1.0
    return (v[0] / safe, v[1] / safe, v[2] / safe), length


@scalar_kernel
def norm(v):
    return math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
