"""Lambertian (Cycles's Diffuse BSDF at roughness 0): f = color / π.

Frame-free: every direction is a unit vector in the *local shading frame* (z = shading normal on
the geometric front side, see docs/architecture.md). ``wo`` points away from the surface toward
where the path came from, ``wi`` away from the surface toward the next vertex.

The lobe is two-sided: it reflects on whichever side ``wo`` is (the computation is mirrored when
``wo.z < 0``); a ``wi`` on the other side from ``wo`` gets 0. The functions here are colourless
(the colour multiplies outside, in the material table).
"""

from __future__ import annotations

import numpy as np

from ..sampling.warps import square_to_cosine_hemisphere

INV_PI = 1.0 / np.pi


def eval_diffuse(wo: np.ndarray, wi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """wo, wi: (n, 3) local. Returns (f·|cos θi| (n,) for a white lobe, pdf (n,) per unit solid
    angle of ``sample_diffuse``). Both are 0 when wi is not on wo's side of the surface."""
    same_side = wo[:, 2] * wi[:, 2] > 0.0
    cos_i = np.where(same_side, np.abs(wi[:, 2]), 0.0)
    value = cos_i * INV_PI
    return value, value


def sample_diffuse(wo: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """wo: (n, 3) local, u2: (n, 2) in [0, 1)². Returns wi (n, 3) cosine-distributed on wo's side
    (pdf |cos θi| / π, weight f·|cos θi| / pdf = 1 for a white lobe)."""
    wi = square_to_cosine_hemisphere(u2)
    wi[:, 2] = np.where(wo[:, 2] < 0.0, -wi[:, 2], wi[:, 2])
    return wi
