"""The SUBSURFACE lobe's constants, Cycles's radius / albedo → coefficient maps and the entry
bounce (see ``drt.subsurface`` for the whole design and docs/subsurface.md)."""

from __future__ import annotations

import math

import numpy as np

from ..kernels import inline_kernel, kernel
from ..kernels.vec3 import dot, normalize
from ..sampling.warps import cosine_hemisphere
from .dielectric import refract_through
from .ggx import microfacet_normal

BSSRDF_MIN_RADIUS = 1e-8
MIN_ALPHA = 0.2
#: largest single-scattering albedo (Cycles clamps to 0.999999 "because of numerical precision")
MAX_ALPHA = 0.999999

# methods (scene-format.md order)
SSS_METHODS = ("RANDOM_WALK", "RANDOM_WALK_SKIN", "BURLEY")
METHOD_RANDOM_WALK, METHOD_SKIN, METHOD_BURLEY = 0, 1, 2


# ----------------------------------------------------------------------------- coefficients

def dipole_rd(alpha_prime, fourthird_a):
    """Diffuse reflectance of the classical dipole for reduced albedo α' (Cycles's
    ``bssrdf_dipole_compute_Rd``)."""
    s = math.sqrt(3.0 * (1.0 - alpha_prime))
    return 0.5 * alpha_prime * (1.0 + math.exp(-fourthird_a * s)) * math.exp(-s)


def dipole_alpha_prime(rd, fourthird_a):
    """α' with dipole_rd(α') = rd: 12 bisection steps as Cycles (0 below 1e-4, 0.999999 from
    0.995)."""
    if rd < 1e-4:
        return 0.0
    if rd >= 0.995:
        return 0.999999
    x0, x1, xmid = 0.0, 1.0, 0.5
    for _ in range(12):
        xmid = 0.5 * (x0 + x1)
        if dipole_rd(xmid, fourthird_a) < rd:
            x0 = xmid
        else:
            x1 = xmid
    return xmid


def effective_radius(radius, albedo, ior, method) -> np.ndarray:
    """Cycles's ``bssrdf_setup_radius``: the user radius (× scale, metres, per channel) → the
    radius the walk uses. ``method``: a name of SSS_METHODS; ``ior`` already clamped."""
    radius = np.asarray(radius, dtype=np.float64)
    if method != "RANDOM_WALK_SKIN":
        return radius * (0.25 / math.pi)
    inv_eta = 1.0 / ior
    f_dr = inv_eta * (-1.440 * inv_eta + 0.710) + 0.668 + 0.0636 * ior
    fourthird_a = (4.0 / 3.0) * (1.0 + f_dr) / (1.0 - f_dr)
    ap = np.array([dipole_alpha_prime(float(a), fourthird_a) for a in np.broadcast_to(albedo, 3)])
    return radius * np.sqrt(3.0 * (1.0 - ap))


@kernel
def remap(albedo, d, g):
    """Chiang et al. 2016 (Cycles's ``subsurface_random_walk_remap``): multiple-scattering
    albedo and radius d (one channel) with anisotropy g → (σt, single-scattering albedo α)."""
    g2 = g * g
    g3 = g2 * g
    g4 = g3 * g
    g5 = g4 * g
    g6 = g5 * g
    g7 = g6 * g
    a = (1.8260523782 - 1.28451056436 * g - 1.79904629312 * g2 + 9.19393289202 * g3
         - 22.8215585862 * g4 + 32.0234874259 * g5 - 23.6264803333 * g6 + 7.21067002658 * g7)
    b = 4.98511194385 + 0.127355959438 * math.exp(
        31.1491581433 * g - 201.847017512 * g2 + 841.576016723 * g3 - 2018.09288505 * g4
        + 2731.71560286 * g5 - 1935.41424244 * g6 + 559.009054474 * g7)
    c = (1.09686102424 - 0.394704063468 * g + 1.05258115941 * g2 - 8.83963712726 * g3
         + 28.8643230661 * g4 - 46.8802913581 * g5 + 38.5402837518 * g6 - 12.7181042538 * g7)
    dd = (0.496310210422 + 0.360146581622 * g - 2.15139309747 * g2 + 17.8896899217 * g3
          - 55.2984010333 * g4 + 82.065982243 * g5 - 58.5106008578 * g6 + 15.8478295021 * g7)
    e = 4.23190299701 + 0.00310603949088 * math.exp(
        76.7316253952 * g - 594.356773233 * g2 + 2448.8834203 * g3 - 5576.68528998 * g4
        + 7116.60171912 * g5 - 4763.54467887 * g6 + 1303.5318055 * g7)
    f = (2.40602999408 - 2.51814844609 * g + 9.18494908356 * g2 - 79.2191708682 * g3
         + 259.082868209 * g4 - 403.613804597 * g5 + 302.85712436 * g6 - 87.4370473567 * g7)
    blend = albedo ** 0.25
    alpha = (1.0 - blend) * a * math.atan(b * albedo) ** c + blend * dd * math.atan(e * albedo) ** f
    alpha = min(max(alpha, 0.0), MAX_ALPHA)
    sigma_t = 1.0 / max(d, 1e-16) / (1.0 - g)
    return sigma_t, alpha


def coefficients(albedo, radius, g):
    """Numpy front end of ``remap`` per channel: (σt (3,), α (3,), throughput factor (3,)) —
    the factor is 1/albedo (0 where the albedo is 0) times the α < 0.2 compensation, exactly
    what the walk multiplies the path throughput by before its first step."""
    albedo = np.broadcast_to(np.asarray(albedo, dtype=np.float64), 3)
    radius = np.broadcast_to(np.asarray(radius, dtype=np.float64), 3)
    st, al, fac = np.empty(3), np.empty(3), np.empty(3)
    for c in range(3):
        st[c], al[c] = remap(float(albedo[c]), float(radius[c]), float(g))
        fac[c] = 1.0 / albedo[c] if albedo[c] != 0.0 else 0.0
        if al[c] < MIN_ALPHA:
            fac[c] *= al[c] / MIN_ALPHA
            al[c] = MIN_ALPHA
    return st, al, fac


# ----------------------------------------------------------------------------- entry bounce

@inline_kernel
def sss_entry_sample(method, alpha, ior, wo, u_choice, u0, u1):
    """Entry direction (local frame, z = shading normal) for a path arriving from wo. Returns
    (wi, ok); wi points into the surface (opposite side of wo). RANDOM_WALK (and BURLEY):
    refraction through a GGX (alpha) microfacet normal with relative IOR ``ior``; SKIN: a
    cosine direction with probability ½ (u_choice < ½), else the same refraction with alpha 1."""
    side = 1.0 if wo[2] >= 0.0 else -1.0
    if wo[2] == 0.0:
        return (0.0, 0.0, 0.0), False
    if method == METHOD_SKIN:
        if u_choice < 0.5:
            d = cosine_hemisphere(u0, u1)
            return (d[0], d[1], -side * d[2]), True
        alpha = 1.0
    wu = (wo[0], wo[1], side * wo[2])  # the upper frame, wo.z > 0
    h = microfacet_normal(wu, alpha, u0, u1)
    if dot(h, wu) <= 0.0:
        return (0.0, 0.0, 0.0), False
    wi = refract_through(wu, h, ior)
    wi, n = normalize(wi)
    if not n > 0.0:
        return (0.0, 0.0, 0.0), False
    return (wi[0], wi[1], side * wi[2]), True


