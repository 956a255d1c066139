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

It is a guess, so the selection keeps a defensive share (`DEFENSIVE_SHARE`) spread evenly over
the lights whose E_j > 0: each keeps a probability ≥ that share / their number, and the
estimator stays unbiased whatever B_j says (only its variance depends on B_j). Even, not ∝ E_j:
neither factor knows occlusion, and where the strongest light is hidden (a key light behind the
subject, lighting only its rim) the weak unoccluded ones must still be found often — a sun
beside a 400 W area light got 3.5–5.5 % of the samples at such points and came back ×20–30
(sss_head's fireflies; Cycles's light tree gives it 33–70 % there, docs/lights.md).

At a point that only reflects (kt = 0), with every lobe shaded about ``n``, a light whose
whole bounding cone lies below the horizon adds exactly nothing, so it gets no share at all
(``reflect_only``; Cycles's light tree gives such lights no importance either). Where a lobe is
shaded about another normal (a smooth mesh's silhouette, a valid-reflection or coat normal)
the hint carries kt = ``KT_FLOOR`` and every light keeps its even share.

Directions are world space; ``n`` is the shading normal on wo's side, ``wo`` points from the
surface toward the viewer (docs/architecture.md).

The kernels take the hint of one point as a tuple ``(n, wo, kd, kg, alpha, kt)``; an all-zero
hint (nothing known: camera rays) selects exactly as no hint. The per-point pmf is never stored:
`selection_prob` makes one pass over the strategies (a running maximum and sum of the weights),
`select_strategy` a second one that walks the cdf.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .common import scalar_kernel
from ..kernels.vec3 import dot, sub
from .common import S_CENTRE, S_FACING, S_IS_SUN, S_IS_WORLD, S_LOCAL, S_ONE_SIDED, S_RADIUS2, S_SCALE, S_SUN_DIR, S_SUN_SIN2  # noqa: F401 (table columns)
from ..kernels.vec3 import load_col3

#: a hint's kt when the point has no transmission but a lobe shaded about a normal other than the
#: hint's (a silhouette, a valid-reflection or coat normal): far below any real weight, so it
#: moves no choice, but nonzero, so that lights below n's horizon keep their defensive share
KT_FLOOR = 1e-9

#: share of the BSDF-aware selection spread evenly over the lights reaching the point (robustness
#: to a bad guess and to occlusion, which no estimate sees)
DEFENSIVE_SHARE = 0.25
_COS_FLOOR = 1e-2  # keeps D/(4 cos θo) finite at grazing view

_GUIDED_SHARE = 1.0 - DEFENSIVE_SHARE
_FMAX = float(np.finfo(np.float64).max)
_ONE_MINUS_EPS = float(np.nextafter(1.0, 0.0))
_INV_PI = 1.0 / np.pi


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

    def arrays(self, m: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(n (m, 3), wo (m, 3), [kd, kg, alpha, kt] (m, 4)) as C-contiguous float64 arrays."""
        return hint_arrays(self, m)


def hint_arrays(hint: ShadingHint | None, m: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The row arrays the wrapper kernels take for a hint (all zeros for None: nothing known)."""
    if hint is None:
        return np.zeros((m, 3)), np.zeros((m, 3)), np.zeros((m, 4))
    n = np.array(np.broadcast_to(np.asarray(hint.n, dtype=np.float64), (m, 3)), order="C")
    wo = np.array(np.broadcast_to(np.asarray(hint.wo, dtype=np.float64), (m, 3)), order="C")
    summary = np.empty((m, 4))
    for j, a in enumerate((hint.kd, hint.kg, hint.alpha, hint.kt)):
        summary[:, j] = np.broadcast_to(np.asarray(a, dtype=np.float64), (m,))
    return n, wo, summary


@scalar_kernel
def row_hint(hn, hwo, hs, r):
    """Row r of the wrapper arrays as a hint tuple (n, wo, kd, kg, alpha, kt)."""
    return ((hn[r, 0], hn[r, 1], hn[r, 2]), (hwo[r, 0], hwo[r, 1], hwo[r, 2]),
            hs[r, 0], hs[r, 1], hs[r, 2], hs[r, 3])


# ----------------------------------------------------------------------------------- kernels
@scalar_kernel
def bsdf_factor(to_light, radius2, hint):
    """Guess of the BSDF·cos averaged over a light's cone (1/sr, see the module docstring).

    to_light: light centre − point (a sun: its unit direction); radius2: squared bounding radius
    (a sun: sin² of its half-angle), so that sin θ_L = √(radius2 / d²) ≤ 1."""
    n, wo, kd, kg, alpha, kt = hint
    d2 = dot(to_light, to_light)
    d = math.sqrt(d2)
    s = d if d > 0.0 else 1.0
    wi = (to_light[0] / s, to_light[1] / s, to_light[2] / s)
    ratio = min(radius2 / max(d2, 1e-300), 1.0)  # sin²θ_L
    sin_l = math.sqrt(ratio)
    cos_c = dot(wi, n)
    if cos_c < -1.0:
        cos_c = -1.0
    if cos_c > 1.0:
        cos_c = 1.0
    # largest cosine over the light's cone: cos(max(θ − θ_L, 0)); θ > θ_L ⇔ cos θ < cos θ_L,
    # then cos(θ − θ_L) = cos θ cos θ_L + sin θ sin θ_L (two square roots instead of acos, asin
    # and cos: this runs once per strategy per light sample)
    cos_l = math.sqrt(1.0 - ratio)
    if cos_c < cos_l:
        cos_bound = cos_c * cos_l + math.sqrt(max(1.0 - cos_c * cos_c, 0.0)) * sin_l
    else:
        cos_bound = 1.0
    value = (kd / np.pi) * max(cos_bound, 0.0)
    if kg > 0.0 and cos_bound > 0.0:
        h = (wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2])
        h_len = math.sqrt(dot(h, h))
        cos_h = dot(h, n) / (h_len if h_len > 1e-12 else 1.0)
        a2 = alpha ** 2 + 0.25 * sin_l ** 2
        c = max(cos_h, 0.0)
        denom = c * c * (a2 - 1.0) + 1.0
        big_d = a2 / (np.pi * denom * denom)
        cos_o = max(dot(n, wo), _COS_FLOOR)
        value = value + kg / (4.0 * cos_o) * big_d
    return value + kt / np.pi


@scalar_kernel
def reflect_only(hint, guided):
    """The hint's lobes only reflect, about its normal n (kt = 0; a point where some lobe is
    shaded about another normal has kt ≥ KT_FLOOR, ``drt.path_stages.material_hint``), so a
    light whose whole bounding cone lies below n's horizon contributes exactly nothing at the
    point: not even the defensive share goes to it."""
    return guided and hint[5] == 0.0


@scalar_kernel
def reaches(w, g, strict):
    """Does a strategy with weights (E_j, E_j·B_j) take part in the defensive share?"""
    return w > 0.0 and (g > 0.0 or not strict)


@scalar_kernel
def hint_known(hint):
    """The hint says something about the material (kd + kg + kt > 0): BSDF-aware selection."""
    return hint[2] + hint[3] + hint[5] > 0.0


@scalar_kernel
def distance_weight(ld, j, p):
    """(irradiance estimate E_j of strategy j at p, p − its centre)."""
    rel = sub(p, load_col3(ld.sf, j, S_CENTRE))
    if (ld.sf[j, S_LOCAL] != 0.0):
        d2 = dot(rel, rel)
        w = ld.sf[j, S_SCALE] / max(d2, max(ld.sf[j, S_RADIUS2], 1e-12))
    else:
        w = ld.sf[j, S_SCALE]
    if (ld.sf[j, S_ONE_SIDED] != 0.0) and dot(rel, load_col3(ld.sf, j, S_FACING)) <= 0.0:
        w = 0.0       # behind a one-sided light
    return w, rel


@scalar_kernel
def strategy_bsdf_factor(ld, j, rel, hint):
    """`bsdf_factor` of strategy j (rel = p − its centre); the world gets the hemisphere
    average of f·cos: albedo / 4π (its E estimate is 4πL)."""
    if (ld.sf[j, S_IS_WORLD] != 0.0):
        return (hint[2] + hint[3] + hint[5]) / (4.0 * np.pi)
    if (ld.sf[j, S_IS_SUN] != 0.0):
        return bsdf_factor(load_col3(ld.sf, j, S_SUN_DIR), ld.sf[j, S_SUN_SIN2], hint)
    if (ld.sf[j, S_LOCAL] != 0.0):
        return bsdf_factor((-rel[0], -rel[1], -rel[2]), ld.sf[j, S_RADIUS2], hint)
    return 0.0


@scalar_kernel
def _accumulate(peak, total, bad, x):
    """Running (max, Σ x/max, NaN seen) of weights, so that x_j / max / Σ is the normalised
    row without storing it. Infinite weights count as the largest finite one."""
    if x != x:
        return peak, total, True
    x = min(x, _FMAX)
    if x > peak:
        total = total * (peak / x) + 1.0
        peak = x
    elif peak > 0.0:
        total += x / peak
    return peak, total, bad


@scalar_kernel
def selection_totals(ld, p, hint, guided):
    """One pass over the strategies: (peak, total, ok) of the distance weights and of the
    guided ones (E_j · B_j, when `guided`)."""
    pw = tw = pg = tg = 0.0
    bw = bg = False
    reaching = 0
    strict = reflect_only(hint, guided)
    for j in range(ld.n_strategies):
        w, rel = distance_weight(ld, j, p)
        pw, tw, bw = _accumulate(pw, tw, bw, w)
        g = w * strategy_bsdf_factor(ld, j, rel, hint) if guided else 0.0
        if reaches(w, g, strict):
            reaching += 1
        if guided:
            pg, tg, bg = _accumulate(pg, tg, bg, g)
    return pw, tw, pw > 0.0 and not bw, pg, tg, pg > 0.0 and not bg, reaching


@scalar_kernel
def strategy_prob(ld, j, p, hint, guided, totals):
    """Probability of strategy j at p given `selection_totals` (per-point selection)."""
    w, rel = distance_weight(ld, j, p)
    g = w * strategy_bsdf_factor(ld, j, rel, hint) if guided and totals[5] else 0.0
    return _prob_given(ld, j, w, g, guided, totals, reflect_only(hint, guided))


@scalar_kernel
def selection_prob(ld, p, hint, strategy):
    """Probability that `light_sample` at p with this hint chooses `strategy`."""
    if not ld.per_point:
        return ld.pmf[strategy]
    guided = hint_known(hint)
    totals = selection_totals(ld, p, hint, guided)
    return strategy_prob(ld, strategy, p, hint, guided, totals)


@scalar_kernel
def _finish_select(u, idx, prob, top, last, last_prob, last_top):
    """(index, probability, rescaled u) of a walk along a cdf that stopped at idx (cdf value
    `top`); a zero-probability pick (round-off at the top of the cdf) becomes the last non-zero
    entry seen (`last`, or −1)."""
    if prob == 0.0 and last >= 0:
        idx, prob, top = last, last_prob, last_top
    lo = top - prob
    u_rem = (u - lo) / (prob if prob > 0.0 else 1.0)
    if u_rem < 0.0:
        u_rem = 0.0
    if u_rem > _ONE_MINUS_EPS:
        u_rem = _ONE_MINUS_EPS
    return idx, prob, u_rem


@scalar_kernel
def select_in(pmf, cdf, u, use_cdf):
    """Choose an index of the 1-D `pmf` for u in [0, 1): (index, probability, u rescaled to
    [0, 1) within the chosen interval, reusable for a second discrete choice). The cdf is `cdf`
    (use_cdf) or the running sum of pmf, its last entry taken as 1. Never lands on a
    zero-probability entry through round-off at the top of the cdf."""
    k = len(pmf)
    c = 0.0
    last, last_prob, last_top = -1, 0.0, 0.0
    for j in range(k):
        pj = pmf[j]
        c += pj
        cj = 1.0 if j == k - 1 else (cdf[j] if use_cdf else c)
        if u < cj or j == k - 1:
            return _finish_select(u, j, pj, cj, last, last_prob, last_top)
        if pj > 0.0:
            last, last_prob, last_top = j, pj, cj
    return -1, 0.0, 0.0


#: strategies up to which `select_strategy` keeps each one's weights between its two passes
CACHED_STRATEGIES = 16


@scalar_kernel
def _weights(ld, j, p, hint, guided):
    """(E_j, E_j · B_j) of strategy j at p as `selection_totals` and `strategy_prob` compute
    them ((0, 0) past the last strategy; B_j only when guided)."""
    if j >= ld.n_strategies:
        return 0.0, 0.0
    w, rel = distance_weight(ld, j, p)
    g = w * strategy_bsdf_factor(ld, j, rel, hint) if guided else 0.0
    return w, g


@scalar_kernel
def _prob_given(ld, j, w, g, guided, totals, strict):
    """`strategy_prob` from strategy j's weights (w, g) already computed."""
    pw, tw, ok_w, pg, tg, ok_g, reaching = totals
    if ok_w:
        dist_pmf = (min(w, _FMAX) / pw) / tw
    else:
        dist_pmf = ld.pmf[j]      # nothing reaches p: the power distribution
    if not guided:
        return dist_pmf
    guided_pmf = (min(g, _FMAX) / pg) / tg if ok_g else dist_pmf
    if ok_w and reaching > 0:
        even = (1.0 / reaching) if reaches(w, g, strict) else 0.0
    else:
        even = dist_pmf
    return _GUIDED_SHARE * guided_pmf + DEFENSIVE_SHARE * even


@scalar_kernel
def _select_cached(ld, p, hint, u, guided):
    """`select_strategy` for at most CACHED_STRATEGIES strategies, each strategy's weights
    computed once (held in two tuples: kernels allocate no arrays) instead of once for the totals
    and again along the cdf walk — the same operations on the same values, so the same choice
    bit for bit; the weights' acos/asin/cos are most of a many-light light sample."""
    w0, g0 = _weights(ld, 0, p, hint, guided)
    w1, g1 = _weights(ld, 1, p, hint, guided)
    w2, g2 = _weights(ld, 2, p, hint, guided)
    w3, g3 = _weights(ld, 3, p, hint, guided)
    w4, g4 = _weights(ld, 4, p, hint, guided)
    w5, g5 = _weights(ld, 5, p, hint, guided)
    w6, g6 = _weights(ld, 6, p, hint, guided)
    w7, g7 = _weights(ld, 7, p, hint, guided)
    w8, g8 = _weights(ld, 8, p, hint, guided)
    w9, g9 = _weights(ld, 9, p, hint, guided)
    w10, g10 = _weights(ld, 10, p, hint, guided)
    w11, g11 = _weights(ld, 11, p, hint, guided)
    w12, g12 = _weights(ld, 12, p, hint, guided)
    w13, g13 = _weights(ld, 13, p, hint, guided)
    w14, g14 = _weights(ld, 14, p, hint, guided)
    w15, g15 = _weights(ld, 15, p, hint, guided)
    W = (w0, w1, w2, w3, w4, w5, w6, w7, w8, w9, w10, w11, w12, w13, w14, w15)
    G = (g0, g1, g2, g3, g4, g5, g6, g7, g8, g9, g10, g11, g12, g13, g14, g15)
    k = ld.n_strategies
    pw = tw = pg = tg = 0.0
    bw = bg = False
    reaching = 0
    strict = reflect_only(hint, guided)
    for j in range(k):
        pw, tw, bw = _accumulate(pw, tw, bw, W[j])
        if reaches(W[j], G[j], strict):
            reaching += 1
        if guided:
            pg, tg, bg = _accumulate(pg, tg, bg, G[j])
    totals = (pw, tw, pw > 0.0 and not bw, pg, tg, pg > 0.0 and not bg, reaching)
    c = 0.0
    last, last_prob, last_top = -1, 0.0, 0.0
    for j in range(k):
        pj = _prob_given(ld, j, W[j], G[j], guided, totals, strict)
        c += pj
        cj = 1.0 if j == k - 1 else c
        if u < cj or j == k - 1:
            return _finish_select(u, j, pj, cj, last, last_prob, last_top)
        if pj > 0.0:
            last, last_prob, last_top = j, pj, cj
    return -1, 0.0, 0.0


@scalar_kernel
def select_strategy(ld, p, hint, u):
    """Choose a strategy at p (with this hint) for u in [0, 1): (index, probability, u
    rescaled), as `select_in` on the point's pmf, computed in two passes without storing it."""
    if not ld.per_point:
        return select_in(ld.pmf, ld.cdf, u, True)
    k = ld.n_strategies
    guided = hint_known(hint)
    if k <= CACHED_STRATEGIES:
        return _select_cached(ld, p, hint, u, guided)
    totals = selection_totals(ld, p, hint, guided)
    c = 0.0
    last, last_prob, last_top = -1, 0.0, 0.0
    for j in range(k):
        pj = strategy_prob(ld, j, p, hint, guided, totals)
        c += pj
        cj = 1.0 if j == k - 1 else c
        if u < cj or j == k - 1:
            return _finish_select(u, j, pj, cj, last, last_prob, last_top)
        if pj > 0.0:
            last, last_prob, last_top = j, pj, cj
    return -1, 0.0, 0.0
