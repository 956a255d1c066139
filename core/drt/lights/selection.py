"""BSDF-aware light selection: how much of each light a shading point's BSDF can use.

Distance-based selection (`LightSet.selection_pmf`) estimates the irradiance E_j each light
delivers at a point. On a glossy surface most of that irradiance is wasted: only lights near the
mirror direction matter, and picking the others spends light samples on near-zero
contributions (Veach's plates: a sharp plate lit by four lights picks the one it reflects a
quarter of the time). This module supplies a second factor B_j, a cheap guess of the BSDF × cos
averaged over light j's cone seen from the point, so that selection ∝ E_j · B_j.

B_j uses only the light's bounding sphere (centre, radius) and a summary of the material
(`MaterialTable.lobe_summary`):

    diffuse   kd/π · cos⁺(θ − θ_L)                    θ: angle of the centre from the normal,
                                                       θ_L: the sphere's angular radius
    glossy    kg · D_GGX(n·h; α'²) / (4·max(n·wo, ε))  h: half vector of wo and the centre
              α'² = α² + sin²θ_L / 4                   (the light's disk widens the lobe)
              (zero when the whole sphere is below the horizon)
    glass     kt / π                                   (reflects and refracts: every direction)

It is a guess, so the selection keeps a defensive share of the plain distance pmf
(`DEFENSIVE_SHARE`): every light whose E_j > 0 keeps a probability ≥ that share of its distance
pmf, and the estimator stays unbiased whatever B_j says (only its variance depends on B_j).

Directions are world space; ``n`` is the shading normal on wo's side, ``wo`` points from the
surface toward the viewer (docs/architecture.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..vecmath import row_norm

#: share of the distance-only pmf kept in the BSDF-aware selection (robustness to a bad guess)
DEFENSIVE_SHARE = 0.1
_COS_FLOOR = 1e-2  # keeps D/(4 cos θo) finite at grazing view


@dataclass
class ShadingHint:
    """What light selection may know about m shading points beyond their positions.

    n (m, 3): unit shading normal on wo's side (zero rows: unknown, e.g. camera rays);
    wo (m, 3): unit direction toward the viewer; kd, kg, alpha, kt (m,): the material's lobe
    summary (`drt.materials.MaterialTable.lobe_summary`)."""

    n: np.ndarray
    wo: np.ndarray
    kd: np.ndarray
    kg: np.ndarray
    alpha: np.ndarray
    kt: np.ndarray

    @classmethod
    def from_materials(cls, materials, mat, n, wo) -> "ShadingHint":
        kd, kg, alpha, kt = materials.lobe_summary(mat)
        return cls(np.asarray(n, dtype=np.float64), np.asarray(wo, dtype=np.float64), kd, kg, alpha, kt)

    def subset(self, rows) -> "ShadingHint":
        return ShadingHint(self.n[rows], self.wo[rows], self.kd[rows], self.kg[rows],
                           self.alpha[rows], self.kt[rows])


def bsdf_factor(to_light: np.ndarray, radius2: np.ndarray, hint: ShadingHint) -> np.ndarray:
    """(m, k) guess of the BSDF·cos averaged over each light's cone (1/sr, see module docstring).

    to_light (m, k, 3): light centre − point (a sun: its unit direction); radius2 (k,): squared
    bounding radius (a sun: sin² of its half-angle), so that sin θ_L = √(radius2 / d²) ≤ 1."""
    d2 = np.einsum("mkj,mkj->mk", to_light, to_light)
    d = np.sqrt(d2)
    wi = to_light / np.where(d > 0, d, 1.0)[..., None]
    sin_l = np.sqrt(np.minimum(radius2 / np.maximum(d2, 1e-300), 1.0))
    cos_c = np.clip(np.einsum("mkj,mj->mk", wi, hint.n), -1.0, 1.0)
    # largest cosine over the light's cone: cos(max(θ − θ_L, 0))
    theta = np.arccos(cos_c) - np.arcsin(sin_l)
    cos_bound = np.where(theta > 0, np.cos(theta), 1.0)
    above = cos_bound > 0

    value = (hint.kd / np.pi)[:, None] * np.maximum(cos_bound, 0.0)
    if np.any(hint.kg > 0):
        h = wi + hint.wo[:, None, :]
        h_len = row_norm(h)
        cos_h = np.einsum("mkj,mj->mk", h, hint.n) / np.where(h_len > 1e-12, h_len, 1.0)
        a2 = hint.alpha[:, None] ** 2 + 0.25 * sin_l ** 2
        denom = np.maximum(cos_h, 0.0) ** 2 * (a2 - 1.0) + 1.0
        D = a2 / (np.pi * denom * denom)
        cos_o = np.maximum(np.einsum("mj,mj->m", hint.n, hint.wo), _COS_FLOOR)
        value = value + np.where(above, (hint.kg / (4.0 * cos_o))[:, None] * D, 0.0)
    value = value + (hint.kt / np.pi)[:, None]
    return value


def normalise_rows(weights: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    """(m, k) rows of non-negative ``weights`` scaled to sum to 1; rows with no positive finite
    weight take ``fallback`` ((k,) or (m, k)). Infinite weights count as the row's largest
    finite scale, so an absurd flux cannot make inf / inf."""
    w = np.minimum(weights, np.finfo(np.float64).max)
    peak = w.max(axis=1, keepdims=True) if w.shape[1] else np.zeros((len(w), 1))
    ok = peak > 0
    w = w / np.where(ok, peak, 1.0)  # now in [0, 1]: the sum cannot overflow
    total = w.sum(axis=1, keepdims=True)
    return np.where(ok, w / np.where(ok, total, 1.0), fallback)


def mix_with_defensive(weights: np.ndarray, distance_pmf: np.ndarray) -> np.ndarray:
    """(m, k) BSDF-aware pmf: ``weights`` (E_j·B_j) normalised per row, mixed with the
    distance pmf by DEFENSIVE_SHARE; rows whose weights are all zero keep the distance pmf."""
    guided = normalise_rows(weights, distance_pmf)
    return (1.0 - DEFENSIVE_SHARE) * guided + DEFENSIVE_SHARE * distance_pmf
