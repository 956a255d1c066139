"""Sun (distant) lights.

``strength`` S (× color) is the irradiance in W/m² on a surface facing the sun. ``angle`` is the
*full* angular diameter: the sun is a uniform disk of directions of half-angle h = angle/2 with
radiance S / (π sin²h) (so that ∫ L cos dω = S at normal incidence); it is sampled uniformly in
that cone. ``angle = 0`` gives a delta direction whose ``radiance`` term is S itself (pdf 1).
The light shines along its local −Z, so the direction *toward* the sun is the local +Z axis.
"""

from __future__ import annotations

import math

import numpy as np

from . import _warps
from .common import SUN, camera_visible, luminance, scalar_kernel, unit
from ..kernels.vec3 import dot
from .common import I_IS_DELTA, L_COS_HALF, L_INTENSITY, L_ONE_MINUS_COS, L_RADIANCE, L_TO_SUN  # noqa: F401 (table columns)
from ..kernels.vec3 import load_col3

_INF = math.inf
_TWO_PI = 2.0 * np.pi


class SunLight:
    """A Blender SUN light (position and scale are irrelevant)."""

    kind = SUN

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

    def _store(self, a: dict, i: int) -> None:
        """Write this light's parameters into row i of the `LightData` arrays."""
        a["kind"][i] = SUN
        a["is_delta"][i] = self.is_delta
        a["visible_camera"][i] = self.visible_to_camera
        a["to_sun"][i] = self.to_sun
        a["one_minus_cos"][i] = self.one_minus_cos
        a["cos_half"][i] = self.cos_half
        a["radiance"][i] = self.radiance
        a["intensity"][i] = self.irradiance

    # --- thin wrappers over the kernels ---------------------------------------------------
    def sample(self, p, n, u2):
        from .light_set import header_light_sample
        return header_light_sample(self, p, n, u2)

    def in_cone(self, d) -> np.ndarray:
        """(m,) bool: unit directions d fall inside the sun's disk (never for a delta sun)."""
        from .light_set import header_sun_query
        return header_sun_query(self, d)[0]

    def pdf_dir(self, d) -> np.ndarray:
        from .light_set import header_sun_query
        return header_sun_query(self, d)[1]


# ----------------------------------------------------------------------------------- kernels
@scalar_kernel
def sun_sample(ld, i, u0, u1):
    """Sun i: (wi, dist = inf, radiance, pdf, valid); a delta sun gives its irradiance, pdf 1."""
    axis = load_col3(ld.lf, i, L_TO_SUN)
    if (ld.li[i, I_IS_DELTA] != 0):
        return axis, _INF, load_col3(ld.lf, i, L_INTENSITY), 1.0, True
    omc = ld.lf[i, L_ONE_MINUS_COS]
    wi = _warps.to_world(_warps.uniform_cone(u0, u1, omc), axis)
    return wi, _INF, load_col3(ld.lf, i, L_RADIANCE), 1.0 / (_TWO_PI * omc), True


@scalar_kernel
def sun_contains(ld, i, d):
    """The unit direction d falls inside sun i's disk (never for a delta sun)."""
    if (ld.li[i, I_IS_DELTA] != 0):
        return False
    return dot(d, load_col3(ld.lf, i, L_TO_SUN)) >= ld.lf[i, L_COS_HALF]


@scalar_kernel
def sun_pdf_dir(ld, i, d):
    """Solid-angle pdf of `sun_sample` producing d."""
    if sun_contains(ld, i, d):
        return 1.0 / (_TWO_PI * max(ld.lf[i, L_ONE_MINUS_COS], 1e-300))
    return 0.0
