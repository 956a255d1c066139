"""Area lights: one-sided Lambertian emitters (rectangle, square, disk, ellipse) with Cycles's spread.

Power P (× color) watts leaves the *front* side, which faces the light's local −Z. The radiance is
L = P / (π A), where A uses the object-scaled sizes: ``size`` along local X and ``size_y`` along
local Y (SQUARE and DISK use ``size`` for both), A = a·b for rectangles and π·a·b/4 for disks and
ellipses (the sizes are diameters). The back side emits nothing but still stops light rays
(`intersect` hits it from both sides, radiance 0).

``spread`` s < π narrows the emission: L(θ) = L · max(tan h − tan θ, 0) / (tan h − h), h = s/2,
θ the angle from the emission normal; Cycles normalizes it so that the power is preserved.

Sampling: rectangles with s = π by solid angle (Ureña, Fajardo, King 2013, "An area-preserving
parametrization for spherical rectangles"), falling back to area sampling when the subtended
solid angle is below 1e-7 sr (where the spherical-rectangle formulas lose precision); everything
else (disks, ellipses, spread < π) uniformly by area. `pdf` applies exactly the same rule.
"""

from __future__ import annotations

import numpy as np

from . import _warps
from .common import T_EPSILON, camera_visible, light_frame, luminance, unit

#: Below this solid angle (sr) rectangles are sampled by area instead of solid angle.
MIN_SOLID_ANGLE = 1e-7


class AreaLight:
    """A Blender AREA light."""

    def __init__(self, light: dict, origin_shift=(0.0, 0.0, 0.0)):
        self.center, basis = light_frame(light["matrix_world"], origin_shift)
        shape = str(light.get("shape", "SQUARE")).upper()
        size = float(light.get("size", 1.0))
        size_y = float(light.get("size_y", size))
        scale_x = float(np.linalg.norm(basis[:, 0]))
        scale_y = float(np.linalg.norm(basis[:, 1]))
        self.ex = unit(basis[:, 0])
        ey = basis[:, 1] - (basis[:, 1] @ self.ex) * self.ex      # orthogonalize (shear ignored)
        self.ey = unit(ey)
        self.ez = np.cross(self.ex, self.ey)
        self.normal = -unit(basis[:, 2])                           # emission direction
        self.is_ellipse = shape in ("DISK", "ELLIPSE")
        self.len_x = size * scale_x
        self.len_y = (size if shape in ("SQUARE", "DISK") else size_y) * scale_y
        self.area = (np.pi * 0.25 if self.is_ellipse else 1.0) * self.len_x * self.len_y
        self.color = np.asarray(light.get("color", (1.0, 1.0, 1.0)), dtype=np.float64)
        power = float(light.get("power", 0.0))
        self.radiance = self.color * power / (np.pi * self.area)   # W/(m² sr) on the normal
        spread = float(light.get("spread", np.pi))
        self.plain = spread >= np.pi - 1e-6
        self.half_spread = 0.5 * spread
        if not self.plain and self.half_spread > 1e-6:
            self.tan_half = float(np.tan(self.half_spread))
            self.spread_norm = 1.0 / (self.tan_half - self.half_spread)
        self.solid_angle_sampling = self.plain and not self.is_ellipse
        self.is_delta = False
        self.visible_to_camera = camera_visible(light)
        self.power = float(power * luminance(self.color))

    # --- emission profile ----------------------------------------------------------------
    def _emission(self, cos_e: np.ndarray) -> np.ndarray:
        """Radiance factor (m,) for directions leaving the light at cos θ = cos_e."""
        front = cos_e > 0.0
        if self.plain:
            return front.astype(np.float64)
        if self.half_spread <= 1e-6:
            return np.zeros_like(cos_e)          # spread 0 (a collimated beam) is not supported
        c = np.where(front, cos_e, 1.0)
        tan_e = np.sqrt(np.maximum(1.0 - c * c, 0.0)) / c
        return np.where(front, np.maximum(self.tan_half - tan_e, 0.0) * self.spread_norm, 0.0)

    # --- spherical rectangle (Ureña et al. 2013) -----------------------------------------
    def _spherical_rect(self, o):
        corner = self.center - 0.5 * self.len_x * self.ex - 0.5 * self.len_y * self.ey
        dv = corner - o
        x0, y0, z0 = dv @ self.ex, dv @ self.ey, dv @ self.ez
        zsign = np.where(z0 > 0.0, -1.0, 1.0)     # local z points away from the rectangle
        z0 = -np.abs(z0)
        x1, y1 = x0 + self.len_x, y0 + self.len_y

        def cross_n(ax, ay, bx, by):
            # normalized cross((ax, ay, z0), (bx, by, z0))
            cx = ay * z0 - z0 * by
            cy = z0 * bx - ax * z0
            cz = ax * by - ay * bx
            inv = 1.0 / np.maximum(np.sqrt(cx * cx + cy * cy + cz * cz), 1e-300)
            return cx * inv, cy * inv, cz * inv

        n0 = cross_n(x0, y0, x1, y0)
        n1 = cross_n(x1, y0, x1, y1)
        n2 = cross_n(x1, y1, x0, y1)
        n3 = cross_n(x0, y1, x0, y0)

        def angle(a, b):
            return np.arccos(np.clip(-(a[0] * b[0] + a[1] * b[1] + a[2] * b[2]), -1.0, 1.0))

        g0, g1, g2, g3 = angle(n0, n1), angle(n1, n2), angle(n2, n3), angle(n3, n0)
        k = 2.0 * np.pi - g2 - g3
        solid_angle = g0 + g1 - k
        return dict(x0=x0, y0=y0, z0=z0, x1=x1, y1=y1, zsign=zsign, b0=n0[2], b1=n2[2], k=k,
                    S=solid_angle)

    def _use_solid_angle(self, sr) -> np.ndarray:
        return (sr["S"] > MIN_SOLID_ANGLE) & (sr["z0"] < 0.0)

    def _sample_spherical_rect(self, o, u, sr):
        with np.errstate(divide="ignore", invalid="ignore"):
            au = u[:, 0] * sr["S"] + sr["k"]
            fu = (np.cos(au) * sr["b0"] - sr["b1"]) / np.sin(au)
            cu = np.clip(np.sign(fu) / np.sqrt(fu * fu + sr["b0"] ** 2), -1.0, 1.0)
            cu = np.nan_to_num(cu)
            z0 = sr["z0"]
            xu = -(cu * z0) / np.sqrt(np.maximum(1.0 - cu * cu, 1e-300))
            xu = np.clip(xu, sr["x0"], sr["x1"])
            dd = np.sqrt(xu * xu + z0 * z0)
            h0 = sr["y0"] / np.sqrt(dd * dd + sr["y0"] ** 2)
            h1 = sr["y1"] / np.sqrt(dd * dd + sr["y1"] ** 2)
            hv = h0 + u[:, 1] * (h1 - h0)
            hv2 = hv * hv
            yv = np.where(hv2 < 1.0 - 1e-12, hv * dd / np.sqrt(np.maximum(1.0 - hv2, 1e-300)), sr["y1"])
        return (o + xu[:, None] * self.ex + yv[:, None] * self.ey
                + (z0 * sr["zsign"])[:, None] * self.ez)

    # --- protocol --------------------------------------------------------------------------
    def _area_point(self, u):
        if self.is_ellipse:
            xy = _warps.square_to_disk_concentric(u) * np.array([0.5 * self.len_x, 0.5 * self.len_y])
        else:
            xy = (u - 0.5) * np.array([self.len_x, self.len_y])
        return self.center + xy[:, :1] * self.ex + xy[:, 1:] * self.ey

    def sample(self, p, n, u2):
        sr = None
        if self.solid_angle_sampling:
            sr = self._spherical_rect(p)
            use = self._use_solid_angle(sr)
            q = self._sample_spherical_rect(p, u2, sr)
            if not use.all():  # tiny or edge-on: uniform over the area there
                q[~use] = self._area_point(u2[~use])
        else:
            q = self._area_point(u2)
        wi, dist = _warps.normalize(q - p)
        pdf = self._pdf_given(p, wi, dist, sr)
        cos_e = -(wi @ self.normal)
        radiance = self.radiance[None, :] * self._emission(cos_e)[:, None]
        valid = (cos_e > 0.0) & (radiance.max(axis=1) > 0.0) & np.isfinite(pdf) & (pdf > 0.0)
        return wi, dist, radiance, pdf, valid

    def _pdf_given(self, o, d, t, sr):
        cos_l = np.abs(d @ self.normal)
        with np.errstate(divide="ignore", invalid="ignore"):
            area_pdf = t * t / (self.area * cos_l)
            if sr is None:
                return area_pdf
            return np.where(self._use_solid_angle(sr), 1.0 / sr["S"], area_pdf)

    def intersect(self, o, d):
        denom = d @ self.normal
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((self.center - o) @ self.normal) / denom
        t = np.where(np.isfinite(t) & (t > T_EPSILON), t, np.inf)
        x = o + np.where(np.isfinite(t), t, 0.0)[:, None] * d - self.center
        lx = 2.0 * (x @ self.ex) / self.len_x
        ly = 2.0 * (x @ self.ey) / self.len_y
        inside = (lx * lx + ly * ly <= 1.0) if self.is_ellipse else (np.abs(lx) <= 1.0) & (np.abs(ly) <= 1.0)
        # like Cycles, an area light does not exist seen from behind: rays pass through it
        return np.where(inside & (denom < 0), t, np.inf)

    def hit_radiance(self, o, d, t):
        return self.radiance[None, :] * self._emission(-(d @ self.normal))[:, None]

    def pdf(self, o, d, t):
        return self._pdf_given(o, d, t, self._spherical_rect(o) if self.solid_angle_sampling else None)
