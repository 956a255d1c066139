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

F is the exact unpolarised dielectric Fresnel (1 at total internal reflection). As in Cycles's
``bsdf_microfacet_eval``, a transmission is evaluated for *every* pair of sides, with |wo·h| and
|wi·h|, also where Walter's model has no microfacet that refracts wo into wi (wo behind h, or wi
in front of it) and gives 0: Cycles does not test the configuration (its source says "TODO"),
and its rough glass is lit through those pairs by next-event estimation (docs/decisions.md).
Sampling still draws only refractions through the drawn h. The colour tints
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

Refraction BSDF (Cycles's refraction-only microfacet closure, ``refraction_eval`` /
``refraction_sample``): the transmission half of the above with no Fresnel factor — every sample
refracts, weight G2/G1 — except under total internal reflection, which gives nothing.

Scalar kernels (one sample, 3-tuples): ``fresnel``, ``refract_through``, ``glass_eval``,
``glass_sample``, ``refraction_eval``, ``refraction_sample``; ``fresnel_dielectric``, ``refract``, ``eval_glass`` and ``sample_glass`` apply
them to arrays.
"""

from __future__ import annotations

import math

import numpy as np

from ..kernels import kernel
from ..kernels.vec3 import dot, load, store
from .ggx import (
    elementwise,
    f64_array,
    ggx_ndf,
    ggx_smith_lambda,
    microfacet_normal,
    reflect_about,
    scalar_rows,
    vec3_rows,
)

#: |ior − 1| below which a glass lobe is a pass-through delta (Cycles: 1e-4).
IOR_ONE_EPS = 1e-4


# ---------------------------------------------------------------------------------------------
# scalar kernels
# ---------------------------------------------------------------------------------------------


@kernel
def fresnel(cos_i, eta):
    """Exact unpolarised Fresnel reflectance. cos_i: cosine between the incident direction and
    the (micro)normal on the incident side (sign ignored); eta: index of the far side relative to
    the incident side. Returns F in [0, 1]; 1 under total internal reflection. At normal
    incidence F = ((eta − 1) / (eta + 1))² exactly."""
    c = abs(cos_i)
    g2 = eta * eta - 1.0 + c * c
    if g2 <= 0.0:
        return 1.0
    g = math.sqrt(g2)
    a = (g - c) / (g + c)
    b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
    return 0.5 * a * a * (1.0 + b * b)


@kernel
def refract_through(wo, h, eta):
    """Refract wo (pointing away on h's side, wo·h > 0) through the interface with unit normal h
    into the medium of relative index eta. Returns wi, unit, on the far side of h; under total
    internal reflection NaN-free but meaningless (check F < 1 first)."""
    c = dot(wo, h)
    inv_eta = 1.0 / eta
    cos_t = math.sqrt(max(0.0, 1.0 - inv_eta * inv_eta * (1.0 - c * c)))
    k = inv_eta * c - cos_t
    return (-inv_eta * wo[0] + k * h[0], -inv_eta * wo[1] + k * h[1], -inv_eta * wo[2] + k * h[2])


@kernel
def glass_eval(wo, wi, alpha, ior):
    """White rough dielectric. wo, wi: local unit 3-tuples; alpha above the singular threshold;
    ior > 0, not ≈ 1. Returns (f·|cos θi|, pdf per unit solid angle of ``glass_sample``),
    reflection when wi is on wo's side, transmission otherwise."""
    return dielectric_eval(wo, wi, alpha, ior, False)


@kernel
def refraction_eval(wo, wi, alpha, ior):
    """Cycles's Refraction BSDF (``bsdf_microfacet_ggx_refraction_setup``: Fresnel NONE on a
    refraction-only closure): the glass transmission term without the (1 − F) factor, zero
    under total internal reflection, no reflection at all. Same arguments as ``glass_eval``;
    the pdf is ``refraction_sample``'s (every sample refracts)."""
    return dielectric_eval(wo, wi, alpha, ior, True)


@kernel
def dielectric_eval(wo, wi, alpha, ior, refraction_only):
    """``glass_eval`` (refraction_only False) or ``refraction_eval`` (True)."""
    # Upper frame: wo on +z, eta = index of the −z side relative to the +z side.
    flip = wo[2] < 0.0
    eta = 1.0 / ior if flip else ior
    cos_o = abs(wo[2])
    cos_i = -wi[2] if flip else wi[2]
    if not (cos_o > 0.0 and cos_i != 0.0):
        return 0.0, 0.0
    wo_u = (wo[0], wo[1], cos_o)
    wi_u = (wi[0], wi[1], cos_i)
    is_t = cos_i < 0.0
    if refraction_only and not is_t:
        return 0.0, 0.0
    if is_t:  # generalised half vector of a refraction (Walter et al. eq. 16)
        hv = (wo_u[0] + eta * wi_u[0], wo_u[1] + eta * wi_u[1], wo_u[2] + eta * wi_u[2])
    else:
        hv = (wo_u[0] + wi_u[0], wo_u[1] + wi_u[1], wo_u[2] + wi_u[2])
    hlen2 = hv[0] * hv[0] + hv[1] * hv[1] + hv[2] * hv[2]
    if not hlen2 > 1e-300:
        return 0.0, 0.0
    hl = math.sqrt(hlen2)
    h = (hv[0] / hl, hv[1] / hl, hv[2] / hl)
    if h[2] < 0.0:
        h = (-h[0], -h[1], -h[2])
    c_o = dot(wo_u, h)
    c_i = dot(wi_u, h)
    # Walter et al. require wo in front of the microfacet and a refracted wi behind it; Cycles's
    # bsdf_microfacet_eval does not check a refraction's configuration (its "TODO: check if the
    # refraction configuration is valid"), so pairs no microfacet can refract between still
    # transmit there, by the same formula with |wo·h| and |wi·h|. DRT evaluates as Cycles does:
    # next-event estimation through rough glass renders Cycles's picture (docs/decisions.md).
    # Sampling never draws such a pair (a refraction through the drawn h lies behind it).
    # (A reflection's h = normalize(wo + wi) is always in front of both.)
    f = fresnel(c_o, eta)
    if refraction_only:  # no Fresnel factor, but nothing refracts under TIR (Cycles)
        f = 1.0 if f >= 1.0 else 0.0
    d = ggx_ndf(h[2], alpha)
    lam_o = ggx_smith_lambda(cos_o, alpha)
    lam_i = ggx_smith_lambda(cos_i, alpha)
    if is_t:
        common = d / cos_o * (eta * eta * abs(c_o * c_i) / hlen2)
        lobe = 1.0 - f
    else:
        common = d / cos_o * 0.25
        lobe = f
    return lobe * common / (1.0 + lam_o + lam_i), lobe * common / (1.0 + lam_o)


@kernel
def glass_sample(wo, alpha, ior, u_choice, u0, u1):
    """wo: local unit 3-tuple; u_choice in [0, 1) picks reflect / refract; (u0, u1) in [0, 1)²
    picks h. Returns (wi, refracted). Rough: visible-normal h, then reflect with probability
    F(wo·h). Delta (singular alpha): h = z, same choice; the weight of a white lobe is then
    exactly 1 either way. A rough sample may end on the wrong side (wi.z·wo.z ≤ 0 for a
    reflection, ≥ 0 for a refraction): the caller discards it."""
    flip = wo[2] < 0.0
    eta = 1.0 / ior if flip else ior
    wo_u = (wo[0], wo[1], abs(wo[2]))
    h = microfacet_normal(wo_u, alpha, u0, u1)
    f = fresnel(dot(wo_u, h), eta)
    refracted = u_choice >= f
    if refracted:
        wi = refract_through(wo_u, h, eta)
    else:
        wi = reflect_about(wo_u, h)
    if flip:
        return (wi[0], wi[1], -wi[2]), refracted
    return wi, refracted


@kernel
def refraction_sample(wo, alpha, ior, u0, u1):
    """Cycles's Refraction BSDF: h from the visible normals of wo (delta: h = z), then always
    refract. Returns (wi, ok); ok is False under total internal reflection at h (Cycles returns
    no sample). Weight of a white lobe: G2/G1(wo) (1 in the delta case)."""
    flip = wo[2] < 0.0
    eta = 1.0 / ior if flip else ior
    wo_u = (wo[0], wo[1], abs(wo[2]))
    h = microfacet_normal(wo_u, alpha, u0, u1)
    if fresnel(dot(wo_u, h), eta) >= 1.0:
        return (0.0, 0.0, 0.0), False
    wi = refract_through(wo_u, h, eta)
    if flip:
        return (wi[0], wi[1], -wi[2]), True
    return wi, True


# ---------------------------------------------------------------------------------------------
# array wrappers
# ---------------------------------------------------------------------------------------------


@kernel
def _fresnel_rows(cos_i, eta, out):
    for i in range(cos_i.shape[0]):
        out[i] = fresnel(cos_i[i], eta[i])


@kernel
def _refract_rows(wo, h, eta, out):
    for i in range(wo.shape[0]):
        store(out, i, refract_through(load(wo, i), load(h, i), eta[i]))


@kernel
def _eval_glass_rows(wo, wi, alpha, ior, value, pdf):
    for i in range(wo.shape[0]):
        v, p = glass_eval(load(wo, i), load(wi, i), alpha[i], ior[i])
        value[i] = v
        pdf[i] = p


@kernel
def _sample_glass_rows(wo, alpha, ior, u_choice, u2, wi, refracted):
    for i in range(wo.shape[0]):
        w, r = glass_sample(load(wo, i), alpha[i], ior[i], u_choice[i], u2[i, 0], u2[i, 1])
        store(wi, i, w)
        refracted[i] = r


def fresnel_dielectric(cos_i: np.ndarray, eta: np.ndarray) -> np.ndarray:
    """Exact unpolarised Fresnel reflectance. cos_i: (n,) cosine between the incident direction
    and the (micro)normal on the incident side (sign ignored); eta: (n,) index of the far side
    relative to the incident side. Returns F (n,) in [0, 1]; 1 under total internal reflection.
    At normal incidence F = ((eta − 1) / (eta + 1))² exactly."""
    return elementwise(_fresnel_rows, cos_i, eta)


def refract(wo: np.ndarray, h: np.ndarray, eta: np.ndarray) -> np.ndarray:
    """Refract wo (n, 3, pointing away on h's side, wo·h > 0) through the interface with normal h
    into the medium of relative index eta. Returns wi (n, 3) unit, on the far side of h; rows under
    total internal reflection are NaN-free but meaningless (check F < 1 first)."""
    wo = vec3_rows(wo)
    out = np.empty_like(wo)
    _refract_rows(wo, vec3_rows(h), scalar_rows(eta, wo.shape[0]), out)
    return out


def eval_glass(wo: np.ndarray, wi: np.ndarray, alpha: np.ndarray,
               ior: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """White rough dielectric. wo, wi: (n, 3) local; alpha: (n,) above the singular threshold;
    ior: (n,) > 0, not ≈ 1. Returns (f·|cos θi| (n,), pdf (n,) per unit solid angle of
    ``sample_glass``), covering both reflection (wi on wo's side) and transmission."""
    wo = vec3_rows(wo)
    n = wo.shape[0]
    value = np.empty(n)
    pdf = np.empty(n)
    _eval_glass_rows(wo, vec3_rows(wi), scalar_rows(alpha, n), scalar_rows(ior, n), value, pdf)
    return value, pdf


def sample_glass(wo: np.ndarray, alpha: np.ndarray, ior: np.ndarray, u_choice: np.ndarray,
                 u2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """wo: (n, 3) local; alpha, ior, u_choice: (n,); u2: (n, 2). Returns (wi (n, 3), refracted
    (n,) bool). Rough: visible-normal h, then reflect with probability F(wo·h). Delta (singular
    alpha): h = z, same choice; the weight of a white lobe is then exactly 1 either way. A rough
    sample may end on the wrong side (wi.z·wo.z ≤ 0 for a reflection, ≥ 0 for a refraction):
    the caller discards it."""
    wo = vec3_rows(wo)
    n = wo.shape[0]
    wi = np.empty_like(wo)
    refracted = np.empty(n, dtype=np.bool_)
    _sample_glass_rows(wo, scalar_rows(alpha, n), scalar_rows(ior, n), scalar_rows(u_choice, n),
                       f64_array(u2), wi, refracted)
    return wi, refracted
