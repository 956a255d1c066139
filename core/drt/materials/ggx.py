"""GGX microfacet reflection: Cycles's Glossy BSDF (distribution "GGX", single scattering).

    f(wo, wi) = color · D(h) · G2(wo, wi) / (4 |cos θo| |cos θi|),   h = normalize(wo + wi)

with the isotropic GGX (Trowbridge-Reitz) D, alpha = roughness² (Blender's mapping, done by the
material table), the height-correlated Smith G2 = 1 / (1 + Λ(wo) + Λ(wi)), and **no Fresnel**:
the colour multiplies directly, as in Cycles (``bsdf_microfacet_ggx_setup``, fresnel NONE).
Single-scatter GGX loses energy at high roughness; that is what Cycles's "GGX" does too
(its "Multiscatter GGX" is not modelled here).

Sampling uses the distribution of visible normals (Heitz 2018, "Sampling the GGX Distribution of
Visible Normals", JCGT 7(4)), so pdf(wi) = G1(wo) D(h) / (4 |cos θo|) and the sample weight of a
white lobe is G2 / G1(wo).

Frames: every direction is a unit vector in the local shading frame (z = shading normal on the
geometric front side); ``wo`` points toward where the path came from, ``wi`` toward the next
vertex. The lobe is two-sided: it reflects on whichever side ``wo`` is (everything is mirrored
through the tangent plane when ``wo.z < 0``); ``wi`` on the other side from ``wo`` gives 0.

Delta limit: when alpha² ≤ ``ALPHA_SQ_SINGULAR`` (2e-10, Cycles's ``BSDF_ROUGHNESS_SQ_THRESH``,
i.e. roughness ≤ 0.00376) the lobe is a perfect mirror: it cannot be evaluated, only sampled.
"""

from __future__ import annotations

import numpy as np

from ..sampling.warps import square_to_disk_concentric
from ..vecmath import row_norm

#: alpha² at or below which a microfacet lobe is a delta (mirror / smooth dielectric). Cycles 5.0:
#: ``BSDF_ROUGHNESS_SQ_THRESH = 2e-10`` compared with alpha_x·alpha_y.
ALPHA_SQ_SINGULAR = 2e-10


def is_singular(alpha: np.ndarray) -> np.ndarray:
    """alpha: array of GGX alphas; True where the lobe is treated as a delta."""
    return np.asarray(alpha) ** 2 <= ALPHA_SQ_SINGULAR


def ggx_d(cos_h: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Isotropic GGX normal distribution D(h), per unit solid angle of h, normalised so that
    ∫ D(h) cos θh dω_h = 1 over the upper hemisphere. cos_h: (n,) cosine of h with the normal
    (h on the normal's side); alpha: (n,)."""
    a2 = alpha * alpha
    c2 = cos_h * cos_h
    d = (1.0 - c2) + a2 * c2
    return np.where(cos_h > 0.0, a2 / (np.pi * d * d), 0.0)


def ggx_lambda(cos_v: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Smith Λ for GGX (Heitz 2014 eq. 72) of a direction with cosine cos_v to the normal (sign is
    ignored: Λ depends on tan² θ only). Returns (n,)."""
    c2 = np.maximum(cos_v * cos_v, 1e-300)
    tan2 = np.maximum(1.0 / c2 - 1.0, 0.0)
    return 0.5 * (np.sqrt(1.0 + alpha * alpha * tan2) - 1.0)


def sample_vndf(wo: np.ndarray, alpha: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """Heitz 2018 visible-normal sampling. wo: (n, 3) local with wo.z > 0 (the *upper* frame);
    alpha: (n,); u2: (n, 2) in [0, 1)². Returns microfacet normals h (n, 3), h.z ≥ 0, distributed
    with density D_wo(h) = G1(wo) max(0, wo·h) D(h) / wo.z."""
    a = alpha[:, None]
    v = wo * np.concatenate([a, a, np.ones_like(a)], axis=1)
    v /= row_norm(v)[:, None]
    lensq = v[:, 0] ** 2 + v[:, 1] ** 2
    has_t = lensq > 1e-14
    inv = np.where(has_t, 1.0 / np.sqrt(np.where(has_t, lensq, 1.0)), 0.0)
    t1 = np.stack([np.where(has_t, -v[:, 1] * inv, 1.0),
                   np.where(has_t, v[:, 0] * inv, 0.0),
                   np.zeros_like(inv)], axis=1)
    t2 = np.cross(v, t1)
    d = square_to_disk_concentric(u2)
    s = 0.5 * (1.0 + v[:, 2])
    p1 = d[:, 0]
    p2 = (1.0 - s) * np.sqrt(np.maximum(0.0, 1.0 - p1 * p1)) + s * d[:, 1]
    p3 = np.sqrt(np.maximum(0.0, 1.0 - p1 * p1 - p2 * p2))
    nh = p1[:, None] * t1 + p2[:, None] * t2 + p3[:, None] * v
    h = np.stack([alpha * nh[:, 0], alpha * nh[:, 1], np.maximum(nh[:, 2], 0.0)], axis=1)
    return h / row_norm(h)[:, None]


def reflect(wo: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Mirror wo (n, 3) about the unit normal h (n, 3): 2 (wo·h) h − wo."""
    return 2.0 * np.sum(wo * h, axis=1, keepdims=True) * h - wo


def _to_upper(wo: np.ndarray, wi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mirror both directions through the tangent plane where wo.z < 0; returns (wo', wi', flip)."""
    flip = wo[:, 2] < 0.0
    sign = np.where(flip, -1.0, 1.0)
    wo_u = wo.copy()
    wi_u = wi.copy()
    wo_u[:, 2] *= sign
    wi_u[:, 2] *= sign
    return wo_u, wi_u, flip


def eval_glossy(wo: np.ndarray, wi: np.ndarray, alpha: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """White GGX reflection lobe. wo, wi: (n, 3) local; alpha: (n,) > singular threshold.
    Returns (f·|cos θi| (n,), pdf (n,) per unit solid angle of ``sample_glossy``)."""
    wo_u, wi_u, _ = _to_upper(wo, wi)
    cos_o = wo_u[:, 2]
    cos_i = wi_u[:, 2]
    ok = (cos_o > 0.0) & (cos_i > 0.0)
    h = wo_u + wi_u
    hn = row_norm(h)
    ok &= hn > 0.0
    h = h / np.where(ok, hn, 1.0)[:, None]
    d = ggx_d(h[:, 2], alpha)
    lam_o = ggx_lambda(cos_o, alpha)
    lam_i = ggx_lambda(cos_i, alpha)
    safe_cos_o = np.where(ok, cos_o, 1.0)
    common = d / (4.0 * safe_cos_o)
    value = np.where(ok, common / (1.0 + lam_o + lam_i), 0.0)
    pdf = np.where(ok, common / (1.0 + lam_o), 0.0)
    return value, pdf


def sample_microfacet_normal(wo_u: np.ndarray, alpha: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """Microfacet normals h (n, 3) for wo_u on the upper side: visible-normal samples, or the
    macro normal z where alpha is singular (a perfect mirror / smooth interface)."""
    sing = is_singular(alpha)
    h = np.empty_like(wo_u)
    h[sing] = (0.0, 0.0, 1.0)
    rough = ~sing
    if np.any(rough):
        h[rough] = sample_vndf(wo_u[rough], alpha[rough], u2[rough])
    return h


def sample_glossy(wo: np.ndarray, alpha: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """wo: (n, 3) local (either side), alpha: (n,), u2: (n, 2). Returns wi (n, 3) on wo's side
    by visible-normal sampling, or the perfect mirror direction where alpha is singular. A sample
    may land on the other side of the surface (wi.z·wo.z ≤ 0): the caller discards it (its
    probability is exactly the mass the pdf misses)."""
    flip = wo[:, 2] < 0.0
    wo_u = wo.copy()
    wo_u[:, 2] = np.abs(wo_u[:, 2])
    wi = reflect(wo_u, sample_microfacet_normal(wo_u, alpha, u2))
    wi[:, 2] = np.where(flip, -wi[:, 2], wi[:, 2])
    return wi
