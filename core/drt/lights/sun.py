"""Sun (distant) lights.

``strength`` S (× color) is the irradiance in W/m² on a surface facing the sun. ``angle`` is the
*full* angular diameter: the sun is a uniform disk of directions of half-angle h = angle/2 with
radiance S / (π sin²h) (so that ∫ L cos dω = S at normal incidence); it is sampled uniformly in
that cone. ``angle = 0`` gives a delta direction whose ``radiance`` term is S itself (pdf 1).
The light shines along its local −Z, so the direction *toward* the sun is the local +Z axis.
"""

from __future__ import annotations

import numpy as np

from . import _warps
from .common import camera_visible, luminance, unit


class SunLight:
    """A Blender SUN light (position and scale are irrelevant)."""

    def __init__(self, light: dict, scene_radius: float = 1.0):
        m = np.asarray(light["matrix_world"], dtype=np.float64).reshape(4, 4)
        self.to_sun = unit(m[:3, 2])                               # world, unit, toward the sun
        self.color = np.asarray(light.get("color", (1.0, 1.0, 1.0)), dtype=np.float64)
        strength = float(light.get("strength", 1.0))
        self.irradiance = self.color * strength                    # W/m², RGB
        half = 0.5 * min(float(light.get("angle", 0.0)), np.pi)
        self.is_delta = half <= 0.0
        self.one_minus_cos = 2.0 * np.sin(0.5 * half) ** 2         # 1 − cos h without cancellation
        self.cos_half = 1.0 - self.one_minus_cos
        self.radiance = (self.irradiance / (np.pi * np.sin(half) ** 2)
                         if not self.is_delta else np.zeros(3))
        self.visible_to_camera = camera_visible(light)
        # Flux through the scene's cross-section (pbrt's DistantLight::Phi).
        self.power = float(strength * luminance(self.color)) * np.pi * scene_radius ** 2

    def sample(self, p, n, u2):
        m = len(p)
        axis = np.broadcast_to(self.to_sun, (m, 3))
        dist = np.full(m, np.inf)
        if self.is_delta:
            return (axis.copy(), dist, np.broadcast_to(self.irradiance, (m, 3)).copy(),
                    np.ones(m), np.ones(m, dtype=bool))
        local = _warps.square_to_uniform_cone(u2, np.full(m, self.one_minus_cos))
        wi = _warps.to_world(local, np.ascontiguousarray(axis))
        pdf = np.full(m, 1.0 / (2.0 * np.pi * self.one_minus_cos))
        return wi, dist, np.broadcast_to(self.radiance, (m, 3)).copy(), pdf, np.ones(m, dtype=bool)

    def in_cone(self, d) -> np.ndarray:
        """(m,) bool: unit directions d fall inside the sun's disk (never for a delta sun)."""
        if self.is_delta:
            return np.zeros(len(d), dtype=bool)
        return d @ self.to_sun >= self.cos_half

    def pdf_dir(self, d) -> np.ndarray:
        return np.where(self.in_cone(d), 1.0 / (2.0 * np.pi * max(self.one_minus_cos, 1e-300)), 0.0)
