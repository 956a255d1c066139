"""Shared helpers for the light types: colours, matrices and the per-light protocol.

Every light type implements the same small protocol, vectorized over m shading points / rays:

- ``sample(p, n, u2) -> (wi, dist, radiance, pdf, valid)``: ``wi`` (m, 3) unit, world space, from
  ``p`` toward the light; ``dist`` (m,) to the sampled point (``inf`` for distant lights);
  ``radiance`` (m, 3) is the *radiance* arriving along ``-wi`` (for delta lights the irradiance-like
  term ``I/d²`` or the sun's ``S``); ``pdf`` (m,) solid angle, *without* the selection
  probability (1 for delta lights).
- ``intersect(o, d) -> t`` (m,): distance to the light's visible shape along unit rays, ``inf``
  on a miss (delta lights never hit).
- ``hit_radiance(o, d, t)`` and ``pdf(o, d, t)``: radiance arriving at ``o`` from the shape hit
  at ``o + t d`` and the solid-angle pdf with which ``sample(o, ·)`` would produce ``d``.
- ``power``: scalar flux estimate (luminance-weighted watts) used for light selection.
"""

from __future__ import annotations

import numpy as np

#: Rec.709 / sRGB luminance weights (Blender's default scene-linear space).
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])

#: Self-intersection guard for ray–shape tests (metres).
T_EPSILON = 1e-9


def luminance(rgb) -> np.ndarray:
    """Luminance of linear RGB (..., 3)."""
    return np.asarray(rgb, dtype=np.float64) @ LUMINANCE


def light_frame(matrix_world, origin_shift) -> tuple[np.ndarray, np.ndarray]:
    """Position (3,) and the 3×3 linear part (columns = local x, y, z in world space) of a
    Blender ``matrix_world`` (4×4 row-major), with ``origin_shift`` subtracted from the position."""
    m = np.asarray(matrix_world, dtype=np.float64).reshape(4, 4)
    return m[:3, 3] - np.asarray(origin_shift, dtype=np.float64), m[:3, :3]


def unit(v: np.ndarray) -> np.ndarray:
    """A single 3-vector normalized (raises on a zero vector: a degenerate light transform)."""
    length = float(np.linalg.norm(v))
    if not length > 0.0:
        raise ValueError("degenerate light transform (zero-length axis)")
    return np.asarray(v, dtype=np.float64) / length


def smoothstep01(x: np.ndarray) -> np.ndarray:
    """3x² − 2x³ of x clamped to [0, 1]."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def one_minus_cos_from_sin2(sin2: np.ndarray) -> np.ndarray:
    """1 − cos θ from sin²θ without cancellation (θ ≤ π/2)."""
    return sin2 / (1.0 + np.sqrt(np.maximum(1.0 - sin2, 0.0)))


def camera_visible(light: dict) -> bool:
    """The light's camera-ray visibility: ``visible_camera`` (scene format), or the add-on's
    ``visible_to_camera``; False by default, as for Blender 5.0 light objects."""
    return bool(light.get("visible_camera", light.get("visible_to_camera", False)))
