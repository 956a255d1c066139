"""Dielectric interface: Cycles's Glass BSDF (GGX), smooth or rough.

Frames: unit vectors in the local shading frame, z = shading normal on the geometric *front*
side. The light enters the glass when ``wo.z > 0`` (relative index eta = ior: the glass is on the
−z side) and exits when ``wo.z < 0`` (eta = 1 / ior). Internally everything is mirrored so that
wo is on the +z side ("upper frame") and eta is the index of the −z side relative to the +z side.

Model (Walter et al. 2007, "Microfacet Models for Refraction through Rough Surfaces", with GGX D,
alpha = roughness², height-correlated Smith G2 = 1 / (1 + Λ(wo) + Λ(wi))):

    reflection    f·|cos θi| = F(wo·h) D G2 / (4 |cos θo|),       h = normalize(wo + wi)
    transmission  f·|cos θi| = (1 − F(wo·h)) D G2 |wo·h| η² |wi·h| / (|cos θo| |wo + η wi|²)
                  with h ∝ ±(wo + η wi), h.z > 0

F is the exact unpolarised dielectric Fresnel (1 at total internal reflection). The colour tints
reflection and transmission alike (Cycles 5.0 sets ``reflection_tint = transmission_tint =
color`` for the Glass BSDF); the functions here are colourless.

Radiance scaling on refraction — decision: **no 1/η² factor**, like Cycles. The transmission
term above carries η² |wi·h| / |wo + η wi|², which is exactly Cycles's
``sqr(ior * inv_len_H) * |cos_HI cos_HO|`` in ``bsdf_microfacet_eval`` (kernel/closure/
bsdf_microfacet.h, shipped in the bpy 5.0.1 wheel) and its sampling branch
``|cos_HI cos_HO| / sqr(cos_HO + cos_HI / eta)``; the delta branch returns eval = (1 − F)·1e6
with pdf = (1 − F)·1e6, i.e. weight 1. This is the *adjoint* (importance) form of Walter's BTDF: the
physically correct radiance BTDF would be this divided by η² (pbrt-v4 divides by η² in
TransportMode::Radiance). For camera paths Cycles therefore does not compress radiance entering a
denser medium; a ray that enters and leaves a closed object gets η²·(1/η²) = 1 either way, so
furnace tests and ordinary glass objects are unaffected. Only a camera or light *inside* a
dielectric would differ from physics, and there DRT matches Blender.

Sampling (as Cycles): a microfacet normal h from the visible normals of wo (delta: h = z), then
reflection with probability F(wo·h), refraction otherwise; so the pdf is F·pdf_h·J_r or
(1 − F)·pdf_h·J_t, and the sample weight of a white lobe is G2/G1(wo) (1 in the delta case).

Delta limit: alpha² ≤ ``ALPHA_SQ_SINGULAR`` (roughness ≤ 0.00376), as for the glossy lobe. Like
Cycles, a refraction with |ior − 1| < 1e-4 is treated as a delta (the rough transmission lobe is
degenerate there): the material table marks such glass lobes delta.
"""

from __future__ import annotations

import numpy as np

from .ggx import ggx_d, ggx_lambda, reflect, sample_microfacet_normal

#: |ior − 1| below which a glass lobe is a pass-through delta (Cycles: 1e-4).
IOR_ONE_EPS = 1e-4


def fresnel_dielectric(cos_i: np.ndarray, eta: np.ndarray) -> np.ndarray:
    """Exact unpolarised Fresnel reflectance. cos_i: (n,) cosine between the incident direction
    and the (micro)normal on the incident side (sign ignored); eta: (n,) index of the far side
    relative to the incident side. Returns F (n,) in [0, 1]; 1 under total internal reflection.
    At normal incidence F = ((eta − 1) / (eta + 1))² exactly."""
    c = np.abs(cos_i)
    g2 = eta * eta - 1.0 + c * c
    tir = g2 <= 0.0
    g = np.sqrt(np.where(tir, 1.0, g2))
    a = (g - c) / (g + c)
    b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
    return np.where(tir, 1.0, 0.5 * a * a * (1.0 + b * b))


def refract(wo: np.ndarray, h: np.ndarray, eta: np.ndarray) -> np.ndarray:
    """Refract wo (n, 3, pointing away on h's side, wo·h > 0) through the interface with normal h
    into the medium of relative index eta. Returns wi (n, 3) unit, on the far side of h; rows under
    total internal reflection are NaN-free but meaningless (check F < 1 first)."""
    c = np.sum(wo * h, axis=1)
    inv_eta = 1.0 / eta
    cos_t = np.sqrt(np.maximum(0.0, 1.0 - inv_eta * inv_eta * (1.0 - c * c)))
    return -inv_eta[:, None] * wo + (inv_eta * c - cos_t)[:, None] * h


def _upper(wo: np.ndarray, wi: np.ndarray | None, ior: np.ndarray):
    """Mirror to the upper frame: returns (wo', wi', eta, flip)."""
    flip = wo[:, 2] < 0.0
    eta = np.where(flip, 1.0 / ior, ior)
    wo_u = wo.copy()
    wo_u[:, 2] = np.abs(wo_u[:, 2])
    wi_u = None
    if wi is not None:
        wi_u = wi.copy()
        wi_u[:, 2] = np.where(flip, -wi_u[:, 2], wi_u[:, 2])
    return wo_u, wi_u, eta, flip


def eval_glass(wo: np.ndarray, wi: np.ndarray, alpha: np.ndarray,
               ior: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """White rough dielectric. wo, wi: (n, 3) local; alpha: (n,) above the singular threshold;
    ior: (n,) > 0, not ≈ 1. Returns (f·|cos θi| (n,), pdf (n,) per unit solid angle of
    ``sample_glass``), covering both reflection (wi on wo's side) and transmission."""
    wo_u, wi_u, eta, _ = _upper(wo, wi, ior)
    cos_o = wo_u[:, 2]
    cos_i = wi_u[:, 2]
    ok = (cos_o > 0.0) & (cos_i != 0.0)
    is_t = cos_i < 0.0
    hv = np.where(is_t[:, None], wo_u + eta[:, None] * wi_u, wo_u + wi_u)
    hlen2 = np.sum(hv * hv, axis=1)
    ok &= hlen2 > 1e-300
    h = hv / np.sqrt(np.where(ok, hlen2, 1.0))[:, None]
    h = np.where((h[:, 2] < 0.0)[:, None], -h, h)
    c_o = np.sum(wo_u * h, axis=1)
    c_i = np.sum(wi_u * h, axis=1)
    # Microfacet must be front-facing for wo, and wi on the matching side of it.
    ok &= (c_o > 0.0) & np.where(is_t, c_i < 0.0, c_i > 0.0)
    f = fresnel_dielectric(c_o, eta)
    d = ggx_d(h[:, 2], alpha)
    lam_o = ggx_lambda(cos_o, alpha)
    lam_i = ggx_lambda(cos_i, alpha)
    safe_cos_o = np.where(ok, cos_o, 1.0)
    jac_t = eta * eta * np.abs(c_o * c_i) / np.where(ok, hlen2, 1.0)
    common = d / safe_cos_o * np.where(is_t, jac_t, 0.25)
    lobe = np.where(is_t, 1.0 - f, f)
    value = np.where(ok, lobe * common / (1.0 + lam_o + lam_i), 0.0)
    pdf = np.where(ok, lobe * common / (1.0 + lam_o), 0.0)
    return value, pdf


def sample_glass(wo: np.ndarray, alpha: np.ndarray, ior: np.ndarray, u_choice: np.ndarray,
                 u2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """wo: (n, 3) local; alpha, ior, u_choice: (n,); u2: (n, 2). Returns (wi (n, 3), refracted
    (n,) bool). Rough: visible-normal h, then reflect with probability F(wo·h). Delta (singular
    alpha): h = z, same choice; the weight of a white lobe is then exactly 1 either way. A rough
    sample may end on the wrong side (wi.z·wo.z ≤ 0 for a reflection, ≥ 0 for a refraction):
    the caller discards it."""
    wo_u, _, eta, flip = _upper(wo, None, ior)
    h = sample_microfacet_normal(wo_u, alpha, u2)
    c_o = np.sum(wo_u * h, axis=1)
    f = fresnel_dielectric(c_o, eta)
    refracted = u_choice >= f
    wi = np.where(refracted[:, None], refract(wo_u, h, eta), reflect(wo_u, h))
    wi[:, 2] = np.where(flip, -wi[:, 2], wi[:, 2])
    return wi, refracted
