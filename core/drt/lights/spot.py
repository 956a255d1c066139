"""Spot lights: a point light (delta, sphere or soft-falloff disk, see :mod:`.point`) whose
emission is multiplied by Cycles's smoothstep cone mask.

The intensity is the *point light's* I = P/(4π) W/sr — the power is not concentrated into the
cone. For a direction w leaving the light at angle θ from the spot axis (the light's local −Z):

    mask = smoothstep(0, 1, (cos θ − cos(size/2)) / ((1 − cos(size/2)) · blend))

with ``spot_size`` the *full* cone angle (radians) and ``spot_blend`` ∈ [0, 1] (blend 0 = hard
edge). As in Cycles the mask is evaluated per sample along the sampled direction, and is not
applied to points inside the light's radius. Non-uniform object scale (elliptic cones) is not
modelled: only the direction of the local −Z axis is used.
"""

from __future__ import annotations

import numpy as np

from .common import SPOT, unit
from .point import PointLight


class SpotLight(PointLight):
    """A Blender SPOT light (its kernels are the point light's: `drt.lights.point`)."""

    kind = SPOT

    def __init__(self, light: dict, origin_shift=(0.0, 0.0, 0.0)):
        self.spot_size = float(light.get("spot_size", np.pi / 4))
        self.spot_blend = float(light.get("spot_blend", 0.15))
        self.cos_half = float(np.cos(0.5 * min(self.spot_size, np.pi)))
        super().__init__(light, origin_shift)
        self.direction = -unit(self.basis[:, 2])        # spot axis, world space, leaving the light

    def _power_fraction(self) -> float:
        return 0.5 * (1.0 - self.cos_half)

    def _store(self, a: dict, i: int) -> None:
        super()._store(a, i)
        a["spot_dir"][i] = self.direction
        a["cos_half"][i] = self.cos_half
        a["spot_width"][i] = (1.0 - self.cos_half) * self.spot_blend
