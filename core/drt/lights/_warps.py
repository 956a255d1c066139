"""The warps the lights use: the shared ones from :mod:`drt.sampling.warps`, plus a uniform cone
parameterised by 1 − cos θmax (so that tiny cones — the sun, far sphere lights — keep their
precision) and two small vector helpers. Vectorized over the first axis; directions are unit.
"""

from __future__ import annotations

import numpy as np

from ..sampling.warps import (build_frame, square_to_cosine_hemisphere,  # noqa: F401 (re-exported)
                              square_to_disk_concentric, square_to_triangle,
                              square_to_uniform_sphere)
from ..vecmath import row_norm


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


def normalize(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors and lengths of v (m, 3); zero vectors stay zero."""
    length = row_norm(v)
    safe = np.where(length > 0.0, length, 1.0)
    return v / safe[:, None], length
