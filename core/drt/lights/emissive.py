"""Emissive mesh triangles (Emission shader): sampled uniformly by area within a triangle chosen
with probability ∝ area × luminance(radiance).

Emission is **two-sided**, as measured in Cycles 5.0: a quad with an Emission shader shows the
same radiance from its back, and lights a receiver facing its back exactly as one facing its
front (0.7348 both ways for the 1×1, strength 10, 2 m case).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import _warps
from .common import luminance, scalar_kernel
from ..kernels.vec3 import dot, sub
from .common import T_AREA, T_E1, T_E2, T_NG, T_RADIANCE, T_V0  # noqa: F401 (table columns)
from ..kernels.vec3 import load_col3


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
        # two-sided Lambertian flux; inf for emission near float64's limit (the samples such a
        # light makes are dropped as Inf by the film, tests/fuzz_corpus/emission_1e308.npz), so
        # the pmf is taken from weights scaled by their maximum, which stays finite
        with np.errstate(over="ignore"):
            self.power = float(2.0 * np.pi * weight.sum())
        relative = weight / weight.max() if len(weight) else weight
        self.pmf = relative / relative.sum() if len(weight) else weight
        self.cdf = np.cumsum(self.pmf)
        if len(self.cdf):
            self.cdf[-1] = 1.0
        self.ids = ids[keep]
        order = np.argsort(self.ids, kind="stable")
        self.sorted_ids = self.ids[order]
        self.sorted_local = order
        self.is_delta = False
        self.visible_to_camera = True
        self._data = None

    def __len__(self):
        return len(self.area)

    def data(self):
        """A `LightData` with this group as its only strategy (for the wrappers below)."""
        if self._data is None:
            from .common import build_light_data
            self._data = build_light_data([], self, None)
        return self._data

    def sample(self, p, n, u2, u_tri):
        """As the light protocol, plus the triangle choice from u_tri (m,) in [0, 1).
        Also returns the chosen triangles' global ids."""
        from .light_set import strategy_sample_rows
        return strategy_sample_rows(self.data(), 0, p, n, u2, u_tri)

    def local_index(self, tri) -> np.ndarray:
        """Local indices (m,) of global triangle ids, −1 for non-emissive triangles."""
        from .light_set import emissive_local_rows
        return emissive_local_rows(self.data(), tri)

    def pdf(self, tri, o, p_hit, ng_hit) -> np.ndarray:
        """Solid-angle pdf (without the group's selection probability) of sampling p_hit on
        triangle `tri` from o; 0 for triangles that are not emissive."""
        from .light_set import emissive_dir_pdf_rows
        return emissive_dir_pdf_rows(self.data(), tri, o, p_hit, ng_hit)


# ----------------------------------------------------------------------------------- kernels
@scalar_kernel
def upper_bound(a, x):
    """np.searchsorted(a, x, side="right") for a sorted float64 array."""
    lo, hi = 0, len(a)
    while lo < hi:
        mid = (lo + hi) >> 1
        if x < a[mid]:
            hi = mid
        else:
            lo = mid + 1
    return lo


@scalar_kernel
def emissive_local_index(ld, tri):
    """Local index of global triangle id `tri`, −1 for a non-emissive triangle."""
    n = ld.n_tris
    if n == 0:
        return -1
    lo, hi = 0, n
    while lo < hi:                                   # np.searchsorted(sorted_ids, tri) (left)
        mid = (lo + hi) >> 1
        if ld.tri_sorted_ids[mid] < tri:
            lo = mid + 1
        else:
            hi = mid
    pos = min(lo, n - 1)
    if ld.tri_sorted_ids[pos] == tri:
        return ld.tri_sorted_local[pos]
    return -1


@scalar_kernel
def emissive_sample(ld, p, u0, u1, u_tri):
    """A triangle ∝ area × luminance from u_tri, then a uniform point on it: (wi, dist,
    radiance, pdf, valid, global triangle id) (pdf without the group's selection)."""
    k = min(upper_bound(ld.tri_cdf, u_tri), ld.n_tris - 1)
    b1, b2 = _warps.uniform_triangle(u0, u1)
    q = (ld.tf[k, T_V0 + 0] + b1 * ld.tf[k, T_E1 + 0] + b2 * ld.tf[k, T_E2 + 0],
         ld.tf[k, T_V0 + 1] + b1 * ld.tf[k, T_E1 + 1] + b2 * ld.tf[k, T_E2 + 1],
         ld.tf[k, T_V0 + 2] + b1 * ld.tf[k, T_E1 + 2] + b2 * ld.tf[k, T_E2 + 2])
    wi, dist = _warps.normalize(sub(q, p))
    cos_l = abs(dot(wi, load_col3(ld.tf, k, T_NG)))
    pdf = ld.tri_pmf[k] * dist * dist / (ld.tf[k, T_AREA] * cos_l)
    valid = cos_l > 0.0 and math.isfinite(pdf) and dist > 0.0
    return wi, dist, load_col3(ld.tf, k, T_RADIANCE), pdf, valid, ld.tri_ids[k]


@scalar_kernel
def emissive_dir_pdf(ld, tri, o, p_hit, ng_hit):
    """Solid-angle pdf (without selection) of sampling p_hit on triangle `tri` (global id) from
    o; 0 for triangles that are not emissive."""
    k = emissive_local_index(ld, tri)
    if k < 0:
        return 0.0
    w = sub(p_hit, o)
    d2 = dot(w, w)
    ng_len = max(_warps.norm(ng_hit), 1e-300)
    ng = (ng_hit[0] / ng_len, ng_hit[1] / ng_len, ng_hit[2] / ng_len)
    cos_l = abs(dot(w, ng)) / math.sqrt(max(d2, 1e-300))
    pdf = ld.tri_pmf[k] * d2 / (ld.tf[k, T_AREA] * cos_l)
    return pdf if math.isfinite(pdf) else 0.0
