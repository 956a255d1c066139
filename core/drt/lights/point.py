"""Point lights (and the geometry that spot lights share): delta, sphere, or soft-falloff disk.

Cycles's radiometry (Blender's ``normalize=True``): a point light of power P watts has intensity
I = P/(4π) W/sr. With ``radius`` r > 0 it becomes a shape of radiance L = P/(4π²r²):

- ``soft_falloff=False``: a true sphere of radius r. Outside it we sample the cone it subtends
  uniformly; inside it (rare) we sample the whole sphere of directions uniformly (pdf 1/(4π)).
  (Cycles samples a cosine hemisphere about N inside; we use the sphere so that the MIS pdf does
  not depend on the shading normal.)
- ``soft_falloff=True`` (Blender's default): a disk of radius r centred on the light and facing
  the shaded point, sampled uniformly by area. On axis E = P/(4π)/(d² + r²): the disk subtends a
  cone of half-angle atan(r/d), so there is no singularity when a surface touches the light.

Object scale does not change the radius (as in Cycles).
"""

from __future__ import annotations

import numpy as np

from . import _warps
from .common import T_EPSILON, camera_visible, light_frame, luminance, one_minus_cos_from_sin2
from ..vecmath import row_norm


class PointLight:
    """A Blender POINT light. Subclassed by :class:`drt.lights.spot.SpotLight`."""

    def __init__(self, light: dict, origin_shift=(0.0, 0.0, 0.0)):
        self.position, self.basis = light_frame(light["matrix_world"], origin_shift)
        power = float(light.get("power", 0.0))
        self.color = np.asarray(light.get("color", (1.0, 1.0, 1.0)), dtype=np.float64)
        self.radius = float(light.get("radius", 0.0))
        self.soft_falloff = bool(light.get("soft_falloff", True))
        self.intensity = self.color * power / (4.0 * np.pi)          # W/sr, RGB
        self.is_delta = self.radius <= 0.0
        self.radiance = (self.color * power / (4.0 * np.pi ** 2 * self.radius ** 2)
                         if not self.is_delta else np.zeros(3))       # W/(m² sr), RGB
        self.is_sphere = not self.is_delta and not self.soft_falloff
        self.visible_to_camera = camera_visible(light)
        self.power = float(power * luminance(self.color)) * self._power_fraction()

    # --- overridden by spot lights -------------------------------------------------------
    def _power_fraction(self) -> float:
        """Fraction of the 4π steradians that actually emit (1 for a point light)."""
        return 1.0

    def _mask(self, w_out: np.ndarray) -> np.ndarray:
        """Angular factor for directions w_out (m, 3) leaving the light (1 for a point light)."""
        return np.ones(len(w_out))

    def _one_sided_ok(self, o: np.ndarray, d: np.ndarray) -> np.ndarray:
        return np.ones(len(o), dtype=bool)

    # --- sampling -------------------------------------------------------------------------
    def sample(self, p, n, u2):
        to_c = self.position - p
        axis, d = _warps.normalize(to_c)
        m = len(p)
        if self.is_delta:
            wi, dist = axis, d
            with np.errstate(divide="ignore"):
                radiance = self.intensity[None, :] / (d * d)[:, None]
            pdf = np.ones(m)
        elif self.is_sphere:
            wi, dist, pdf = self._sample_sphere(p, axis, d, u2)
            radiance = np.broadcast_to(self.radiance, (m, 3)).copy()
        else:
            wi, dist, pdf = self._sample_disk(p, axis, u2)
            radiance = np.broadcast_to(self.radiance, (m, 3)).copy()
        inside = d <= self.radius
        mask = np.where(inside, 1.0, self._mask(-wi))
        radiance = radiance * mask[:, None]
        valid = (mask > 0.0) & (pdf > 0.0) & np.isfinite(pdf) & (dist > 0.0)
        return wi, dist, radiance, pdf, valid

    def _sample_sphere(self, p, axis, d, u2):
        r = self.radius
        outside = d > r
        omc = one_minus_cos_from_sin2(np.minimum((r / np.where(outside, d, 1.0)) ** 2, 1.0))
        local = np.where(outside[:, None], _warps.square_to_uniform_cone(u2, omc),
                         _warps.square_to_uniform_sphere(u2))
        safe_axis = np.where(d[:, None] > 0.0, axis, np.array([0.0, 0.0, 1.0]))
        wi = _warps.to_world(local, safe_axis)
        cos_t = local[:, 2]
        root = np.sqrt(np.maximum(r * r - d * d * (1.0 - cos_t * cos_t), 0.0))
        dist = np.where(outside, d * cos_t - root, d * cos_t + root)   # law of cosines
        pdf = np.where(outside, 1.0 / (2.0 * np.pi * np.where(outside, omc, 1.0)),
                       1.0 / (4.0 * np.pi))
        return wi, dist, pdf

    def _sample_disk(self, p, axis, u2):
        light_n = -axis                                   # disk normal, toward the shaded point
        light_n = np.where(np.isfinite(light_n).all(axis=1)[:, None] & (np.abs(light_n).sum(1) > 0)[:, None],
                           light_n, np.array([0.0, 0.0, 1.0]))
        t, b = _warps.build_frame(light_n)
        xy = _warps.square_to_disk_concentric(u2) * self.radius
        q = self.position + xy[:, :1] * t + xy[:, 1:] * b
        wi, dist = _warps.normalize(q - p)
        cos_l = np.abs((light_n * wi).sum(axis=1))
        with np.errstate(divide="ignore", invalid="ignore"):
            pdf = dist * dist / (np.pi * self.radius ** 2 * cos_l)
        return wi, dist, pdf

    # --- intersection ---------------------------------------------------------------------
    def intersect(self, o, d):
        m = len(o)
        t = np.full(m, np.inf)
        if self.is_delta:
            return t
        oc = o - self.position
        ok = self._one_sided_ok(o, d)
        if self.is_sphere:
            b = (d * oc).sum(axis=1)
            c = (oc * oc).sum(axis=1) - self.radius ** 2
            disc = b * b - c
            root = np.sqrt(np.maximum(disc, 0.0))
            t0, t1 = -b - root, -b + root
            tt = np.where(t0 > T_EPSILON, t0, np.where(t1 > T_EPSILON, t1, np.inf))
            return np.where(ok & (disc >= 0.0), tt, np.inf)
        light_n, dist_c = _warps.normalize(oc)
        denom = (d * light_n).sum(axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            tt = np.where(denom < 0.0, -dist_c / denom, np.inf)
        x = o + np.where(np.isfinite(tt), tt, 0.0)[:, None] * d - self.position
        inside = (x * x).sum(axis=1) <= self.radius ** 2
        return np.where(ok & inside & (tt > T_EPSILON), tt, np.inf)

    def hit_radiance(self, o, d, t):
        dist_c = row_norm(o - self.position)
        mask = np.where(dist_c <= self.radius, 1.0, self._mask(-d))
        return self.radiance[None, :] * mask[:, None]

    def pdf(self, o, d, t):
        if self.is_delta:
            return np.zeros(len(o))
        oc = o - self.position
        dist_c = row_norm(oc)
        r = self.radius
        if self.is_sphere:
            outside = dist_c > r
            omc = one_minus_cos_from_sin2(np.minimum((r / np.where(outside, dist_c, 1.0)) ** 2, 1.0))
            return np.where(outside, 1.0 / (2.0 * np.pi * omc), 1.0 / (4.0 * np.pi))
        light_n, _ = _warps.normalize(oc)
        cos_l = np.abs((light_n * d).sum(axis=1))
        with np.errstate(divide="ignore", invalid="ignore"):
            return t * t / (np.pi * r * r * cos_l)
