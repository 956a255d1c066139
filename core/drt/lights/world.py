"""The world background: a constant radiance (color × strength) from every direction.

Sampled cosine-weighted about the normal ``n`` the integrator passes (pdf cos θ/π, zero below
the surface), or uniformly over the sphere when ``n`` is None (pdf 1/(4π)). The integrator must
pass a normal on the side it wants light from (e.g. flipped toward ``wo``), or None for
transmissive surfaces; `world_pdf` uses the same rule.
"""

from __future__ import annotations

import numpy as np

from . import _warps
from .common import luminance


class WorldLight:
    def __init__(self, color, scene_radius: float = 1.0):
        self.radiance = np.asarray(color, dtype=np.float64).reshape(3)
        self.is_delta = False
        self.visible_to_camera = True
        # Flux onto the scene's bounding sphere (pbrt's UniformInfiniteLight::Phi): 4π·πR²·L.
        self.power = float(luminance(self.radiance)) * 4.0 * np.pi ** 2 * scene_radius ** 2

    def sample(self, p, n, u2):
        m = len(p)
        if n is None:
            wi = _warps.square_to_uniform_sphere(u2)
        else:
            wi = _warps.to_world(_warps.square_to_cosine_hemisphere(u2), n)
        pdf = self.pdf(n, wi)
        radiance = np.broadcast_to(self.radiance, (m, 3)).copy()
        return wi, np.full(m, np.inf), radiance, pdf, pdf > 0.0

    def pdf(self, n, d):
        if n is None:
            return np.full(len(d), 1.0 / (4.0 * np.pi))
        return np.maximum((n * d).sum(axis=1), 0.0) / np.pi
