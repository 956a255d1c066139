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

Object scale does not change the radius (as in Cycles). The kernels below serve point and spot
lights (``LightData.kind`` POINT or SPOT; a spot adds its cone mask and one-sided shape).
"""

from __future__ import annotations

import math

import numpy as np

from . import _warps
from .common import (POINT, SPOT, T_EPSILON, camera_visible, clip01, light_frame, luminance,
                     one_minus_cos_from_sin2, scalar_kernel)
from ..kernels.vec3 import build_frame, cross, dot, neg, sub
from .common import I_IS_DELTA, I_IS_SPHERE, I_KIND, L_COS_HALF, L_INTENSITY, L_POS, L_RADIANCE, L_RADIUS, L_SPOT_DIR, L_SPOT_WIDTH  # noqa: F401 (table columns)
from ..kernels.vec3 import load_col3

_INF = math.inf
_INV_4PI = 1.0 / (4.0 * np.pi)
_TWO_PI = 2.0 * np.pi


class PointLight:
    """A Blender POINT light. Subclassed by :class:`drt.lights.spot.SpotLight`."""

    kind = POINT

    def __init__(self, light: dict, origin_shift=(0.0, 0.0, 0.0)):
        self.position, self.basis = light_frame(light["matrix_world"], origin_shift)
        power = float(light.get("power", 0.0))
        self.color = np.asarray(light.get("color", (1.0, 1.0, 1.0)), dtype=np.float64)
        self.radius = float(light.get("radius", 0.0))
        self.soft_falloff = bool(light.get("soft_falloff", True))
        self.intensity = self.color * power / (4.0 * np.pi)          # W/sr, RGB
        self.is_delta = self.radius <= 0.0
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # radius² underflows: inf
            self.radiance = (self.color * power / (4.0 * np.pi ** 2 * self.radius ** 2)
                             if not self.is_delta else np.zeros(3))   # W/(m² sr), RGB
        self.is_sphere = not self.is_delta and not self.soft_falloff
        self.visible_to_camera = camera_visible(light)
        self.power = float(power * luminance(self.color)) * self._power_fraction()

    def _power_fraction(self) -> float:
        """Fraction of the 4π steradians that actually emit (1 for a point light)."""
        return 1.0

    def _store(self, a: dict, i: int) -> None:
        """Write this light's parameters into row i of the `LightData` arrays."""
        a["kind"][i] = self.kind
        a["is_delta"][i] = self.is_delta
        a["visible_camera"][i] = self.visible_to_camera
        a["pos"][i] = self.position
        a["radiance"][i] = self.radiance
        a["intensity"][i] = self.intensity
        a["radius"][i] = self.radius
        a["is_sphere"][i] = self.is_sphere

    # --- the per-light protocol (thin wrappers over the kernels, see common.py) -------------
    def sample(self, p, n, u2):
        from .light_set import header_light_sample
        return header_light_sample(self, p, n, u2)

    def intersect(self, o, d):
        from .light_set import header_light_intersect
        return header_light_intersect(self, o, d)

    def hit_radiance(self, o, d, t):
        from .light_set import header_light_hit_radiance
        return header_light_hit_radiance(self, o, d, t)

    def pdf(self, o, d, t):
        from .light_set import header_light_pdf
        return header_light_pdf(self, o, d, t)


# ----------------------------------------------------------------------------------- kernels
@scalar_kernel
def spot_mask(ld, i, w_out):
    """Angular factor for the direction w_out leaving light i (1 for a point light): Cycles's
    smoothstep((cos θ − cos(size/2)) / ((1 − cos(size/2))·blend)) for a spot."""
    if ld.li[i, I_KIND] != SPOT:
        return 1.0
    cos_t = dot(w_out, load_col3(ld.lf, i, L_SPOT_DIR))
    cos_half = ld.lf[i, L_COS_HALF]
    width = ld.lf[i, L_SPOT_WIDTH]
    if width <= 0.0:
        return 1.0 if cos_t > cos_half else 0.0
    x = clip01((cos_t - cos_half) / width)
    return x * x * (3.0 - 2.0 * x)


@scalar_kernel
def _sphere_omc(r, d):
    """1 − cos of the half-angle the sphere of radius r subtends at distance d (> r)."""
    x = r / d
    return one_minus_cos_from_sin2(min(x * x, 1.0))


@scalar_kernel
def _sample_sphere(r, axis, d, u0, u1):
    outside = d > r
    if outside:
        omc = _sphere_omc(r, d)
        local = _warps.uniform_cone(u0, u1, omc)
    else:
        omc = 1.0
        local = _warps.uniform_sphere(u0, u1)
    safe_axis = axis if d > 0.0 else (0.0, 0.0, 1.0)
    wi = _warps.to_world(local, safe_axis)
    cos_t = local[2]
    root = math.sqrt(max(r * r - d * d * (1.0 - cos_t * cos_t), 0.0))   # law of cosines
    if outside:
        return wi, d * cos_t - root, 1.0 / (_TWO_PI * omc)
    return wi, d * cos_t + root, _INV_4PI


@scalar_kernel
def _sample_disk(pos, r, p, axis, u0, u1):
    light_n = neg(axis)                                   # disk normal, toward the shaded point
    if not (math.isfinite(light_n[0]) and math.isfinite(light_n[1]) and math.isfinite(light_n[2])
            and abs(light_n[0]) + abs(light_n[1]) + abs(light_n[2]) > 0.0):
        light_n = (0.0, 0.0, 1.0)
    t, b = build_frame(light_n)
    x, y = _warps.disk_concentric(u0, u1)
    x *= r
    y *= r
    q = (pos[0] + x * t[0] + y * b[0], pos[1] + x * t[1] + y * b[1], pos[2] + x * t[2] + y * b[2])
    wi, dist = _warps.normalize(sub(q, p))
    cos_l = abs(dot(light_n, wi))
    pdf = dist * dist / (np.pi * r ** 2 * cos_l)
    return wi, dist, pdf


@scalar_kernel
def point_sample(ld, i, p, u0, u1):
    """Light i (POINT or SPOT) from p: (wi, dist, radiance, pdf, valid) (pdf without selection)."""
    pos = load_col3(ld.lf, i, L_POS)
    axis, d = _warps.normalize(sub(pos, p))
    r = ld.lf[i, L_RADIUS]
    if (ld.li[i, I_IS_DELTA] != 0):
        wi, dist = axis, d
        dd = d * d
        radiance = (ld.lf[i, L_INTENSITY + 0] / dd, ld.lf[i, L_INTENSITY + 1] / dd, ld.lf[i, L_INTENSITY + 2] / dd)
        pdf = 1.0
    else:
        if (ld.li[i, I_IS_SPHERE] != 0):
            wi, dist, pdf = _sample_sphere(r, axis, d, u0, u1)
        else:
            wi, dist, pdf = _sample_disk(pos, r, p, axis, u0, u1)
        radiance = load_col3(ld.lf, i, L_RADIANCE)
    mask = 1.0 if d <= r else spot_mask(ld, i, neg(wi))
    radiance = (radiance[0] * mask, radiance[1] * mask, radiance[2] * mask)
    valid = mask > 0.0 and pdf > 0.0 and math.isfinite(pdf) and dist > 0.0
    return wi, dist, radiance, pdf, valid


@scalar_kernel
def point_intersect(ld, i, o, d):
    """Distance to light i's shape (sphere, or disk facing o) along the unit ray, inf on a miss.
    A spot's shape is hit only by rays heading toward its centre (as in Cycles)."""
    if (ld.li[i, I_IS_DELTA] != 0):
        return _INF
    pos = load_col3(ld.lf, i, L_POS)
    oc = sub(o, pos)
    ok = True
    if ld.li[i, I_KIND] == SPOT:
        ok = dot(oc, d) < 0.0
    r = ld.lf[i, L_RADIUS]
    if (ld.li[i, I_IS_SPHERE] != 0):
        b = dot(d, oc)
        c = dot(oc, oc) - r ** 2
        disc = b * b - c
        root = math.sqrt(max(disc, 0.0))
        t0, t1 = -b - root, -b + root
        tt = t0 if t0 > T_EPSILON else (t1 if t1 > T_EPSILON else _INF)
        return tt if ok and disc >= 0.0 else _INF
    # the disk through pos facing o (normal oc/|oc|): a ray heading toward it (b = d·oc < 0)
    # meets its plane at t = −|oc|²/b, at a squared distance |oc|²·|oc × d|²/b² from pos. Every
    # shading point tests every shape this way, so the test takes no root and divides only
    # for a hit (|oc × d|², not |oc|² − b², keeps a ray aimed at a far light accurate)
    b = dot(d, oc)
    if not b < 0.0:
        return _INF
    cx = cross(oc, d)
    c2 = dot(oc, oc)
    if not c2 * dot(cx, cx) <= (r * r) * (b * b):
        return _INF
    tt = -c2 / b
    return tt if ok and tt > T_EPSILON else _INF


@scalar_kernel
def point_hit_radiance(ld, i, o, d):
    """Radiance arriving at o along −d from light i's shape."""
    dist_c = _warps.norm(sub(o, load_col3(ld.lf, i, L_POS)))
    mask = 1.0 if dist_c <= ld.lf[i, L_RADIUS] else spot_mask(ld, i, neg(d))
    return (ld.lf[i, L_RADIANCE + 0] * mask, ld.lf[i, L_RADIANCE + 1] * mask, ld.lf[i, L_RADIANCE + 2] * mask)


@scalar_kernel
def point_pdf(ld, i, o, d, t):
    """Solid-angle pdf of `point_sample` from o producing d (its shape hit at distance t)."""
    if (ld.li[i, I_IS_DELTA] != 0):
        return 0.0
    oc = sub(o, load_col3(ld.lf, i, L_POS))
    r = ld.lf[i, L_RADIUS]
    if (ld.li[i, I_IS_SPHERE] != 0):
        dist_c = _warps.norm(oc)
        if dist_c > r:
            return 1.0 / (_TWO_PI * _sphere_omc(r, dist_c))
        return _INV_4PI
    light_n, _ = _warps.normalize(oc)
    cos_l = abs(dot(light_n, d))
    return t * t / (np.pi * r * r * cos_l)
