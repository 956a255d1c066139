"""The world background: a constant radiance (color × strength) from every direction, or a
textured world (``drt.lights.world_map``: a program per direction, sampled from its importance
map; `world_sample` / `world_pdf_dir` switch to the map when ``ld.wm_cond`` is not empty).

Sampled cosine-weighted about the normal ``n`` the integrator passes (pdf cos θ/π, zero below
the surface), or uniformly over the sphere when ``n`` is None — in the kernels, a zero normal
(pdf 1/(4π)). The integrator must pass a normal on the side it wants light from (e.g. flipped
toward ``wo``), or None / zero for transmissive surfaces; `world_pdf` uses the same rule.
"""

from __future__ import annotations

import math

import numpy as np

from . import _warps
from .common import luminance, scalar_kernel
from .world_map import world_map_pdf, world_map_sample
from ..kernels import inline_kernel
from ..kernels.vec3 import dot

_INF = math.inf
_INV_4PI = 1.0 / (4.0 * np.pi)


class WorldLight:
    def __init__(self, color, scene_radius: float = 1.0, average_luminance: float | None = None):
        self.radiance = np.asarray(color, dtype=np.float64).reshape(3)
        self.is_delta = False
        self.visible_to_camera = True
        # Flux onto the scene's bounding sphere (pbrt's UniformInfiniteLight::Phi): 4π·πR²·L,
        # with L the average over directions for a textured world (its importance map's)
        lum = float(luminance(self.radiance)) if average_luminance is None else float(average_luminance)
        self.power = lum * 4.0 * np.pi ** 2 * scene_radius ** 2
        self._data = None

    def data(self):
        """A `LightData` with this world as its only strategy (for the wrappers below)."""
        if self._data is None:
            from .common import build_light_data
            self._data = build_light_data([], None, self.radiance)
        return self._data

    def sample(self, p, n, u2):
        from .light_set import strategy_sample_rows
        wi, dist, radiance, pdf, valid, _ = strategy_sample_rows(self.data(), 0, p, n, u2)
        return wi, dist, radiance, pdf, valid

    def pdf(self, n, d):
        from .light_set import world_dir_pdf_rows
        return world_dir_pdf_rows(self.data(), n, d)


# ----------------------------------------------------------------------------------- kernels
@scalar_kernel
def world_dir_pdf(n, d):
    """Solid-angle pdf of `world_sample` about n producing d (n zero: uniform sphere)."""
    if n[0] == 0.0 and n[1] == 0.0 and n[2] == 0.0:
        return _INV_4PI
    return max(dot(n, d), 0.0) / np.pi


@inline_kernel
def world_pdf_dir(ld, n, d):
    """Solid-angle pdf of `world_sample` producing d: the importance map's for a textured world
    (independent of n, as Cycles), else `world_dir_pdf`."""
    if ld.wm_cond.shape[0]:
        return world_map_pdf(ld, d)
    return world_dir_pdf(n, d)


@scalar_kernel
def world_sample(ld, p, n, u0, u1):
    """(wi, dist = inf, radiance, pdf, valid): from the importance map of a textured world
    (radiance: the world's constant fallback colour; the integrator evaluates the world
    program for the sampled direction), else cosine-weighted about n, uniform sphere for n = 0."""
    if ld.wm_cond.shape[0]:
        wi, pdf = world_map_sample(ld, u0, u1)
        radiance = (ld.world_color[0], ld.world_color[1], ld.world_color[2])
        return wi, _INF, radiance, pdf, pdf > 0.0
    if n[0] == 0.0 and n[1] == 0.0 and n[2] == 0.0:
        wi = _warps.uniform_sphere(u0, u1)
    else:
        wi = _warps.to_world(_warps.cosine_hemisphere(u0, u1), n)
    pdf = world_dir_pdf(n, wi)
    radiance = (ld.world_color[0], ld.world_color[1], ld.world_color[2])
    return wi, _INF, radiance, pdf, pdf > 0.0
