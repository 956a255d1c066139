"""Emissive mesh triangles (Emission shader): sampled uniformly by area within a triangle chosen
with probability ∝ area × luminance(radiance).

Emission is **two-sided**, as measured in Cycles 5.0: a quad with an Emission shader shows the
same radiance from its back, and lights a receiver facing its back exactly as one facing its
front (0.7348 both ways for the 1×1, strength 10, 2 m case).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import _warps
from .common import luminance
from ..vecmath import row_norm


@dataclass
class EmissiveTriangles:
    """vertices (K, 3, 3) in the *tracer's* space (already re-centred by the integrator: no
    origin shift is applied to them); radiance (K, 3) W/(m² sr); tri_ids (K,) global triangle
    ids as Embree reports them."""
    vertices: np.ndarray
    radiance: np.ndarray
    tri_ids: np.ndarray


class EmissiveGroup:
    """All emissive triangles as one entry of the light-selection distribution."""

    def __init__(self, emissive: EmissiveTriangles):
        v = np.asarray(emissive.vertices, dtype=np.float64).reshape(-1, 3, 3)
        radiance = np.asarray(emissive.radiance, dtype=np.float64).reshape(-1, 3)
        ids = np.asarray(emissive.tri_ids, dtype=np.int64).reshape(-1)
        e1, e2 = v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]
        cross = np.cross(e1, e2)
        area = 0.5 * np.linalg.norm(cross, axis=1)
        weight = area * np.maximum(luminance(radiance), 0.0)
        keep = weight > 0.0
        self.v0, self.e1, self.e2 = v[keep, 0], e1[keep], e2[keep]
        self.ng = cross[keep] / (2.0 * area[keep])[:, None]
        self.area = area[keep]
        self.radiance = radiance[keep]
        weight = weight[keep]
        self.power = float(2.0 * np.pi * weight.sum())           # two-sided Lambertian flux
        self.pmf = weight / weight.sum() if len(weight) else weight
        self.cdf = np.cumsum(self.pmf)
        if len(self.cdf):
            self.cdf[-1] = 1.0
        self.ids = ids[keep]
        order = np.argsort(self.ids, kind="stable")
        self.sorted_ids = self.ids[order]
        self.sorted_local = order
        self.is_delta = False
        self.visible_to_camera = True

    def __len__(self):
        return len(self.area)

    def sample(self, p, n, u2, u_tri):
        """As the light protocol, plus the triangle choice from u_tri (m,) in [0, 1).
        Also returns the chosen triangles' global ids."""
        k = np.minimum(np.searchsorted(self.cdf, u_tri, side="right"), len(self.cdf) - 1)
        b1, b2 = _warps.square_to_triangle(u2)
        q = self.v0[k] + b1[:, None] * self.e1[k] + b2[:, None] * self.e2[k]
        wi, dist = _warps.normalize(q - p)
        cos_l = np.abs((wi * self.ng[k]).sum(axis=1))
        with np.errstate(divide="ignore", invalid="ignore"):
            pdf = self.pmf[k] * dist * dist / (self.area[k] * cos_l)
        valid = (cos_l > 0.0) & np.isfinite(pdf) & (dist > 0.0)
        return wi, dist, self.radiance[k].copy(), pdf, valid, self.ids[k]

    def local_index(self, tri) -> np.ndarray:
        """Local indices (m,) of global triangle ids, −1 for non-emissive triangles."""
        tri = np.asarray(tri, dtype=np.int64)
        if not len(self.sorted_ids):
            return np.full(tri.shape, -1)
        pos = np.minimum(np.searchsorted(self.sorted_ids, tri), len(self.sorted_ids) - 1)
        return np.where(self.sorted_ids[pos] == tri, self.sorted_local[pos], -1)

    def pdf(self, tri, o, p_hit, ng_hit) -> np.ndarray:
        """Solid-angle pdf (without the group's selection probability) of sampling p_hit on
        triangle `tri` from o; 0 for triangles that are not emissive."""
        k = self.local_index(tri)
        ok = k >= 0
        kk = np.where(ok, k, 0)
        w = p_hit - o
        d2 = (w * w).sum(axis=1)
        ng = ng_hit / np.maximum(row_norm(ng_hit), 1e-300)[:, None]
        cos_l = np.abs((w * ng).sum(axis=1)) / np.sqrt(np.maximum(d2, 1e-300))
        with np.errstate(divide="ignore", invalid="ignore"):
            pdf = self.pmf[kk] * d2 / (self.area[kk] * cos_l) if len(self.area) else np.zeros(len(o))
        return np.where(ok & np.isfinite(pdf), pdf, 0.0)
