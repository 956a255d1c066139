"""The Principled BSDF's dielectric specular layer (Cycles 5.0 "Principled v2"): GGX reflection
× a dielectric Fresnel term, optional multiple-scattering energy compensation, and the
directional albedo that attenuates the layers below it (diffuse, subsurface).

Lobe (per unit colour ``color``), for wo, wi in the local shading frame (either side, mirrored
like ``ggx.glossy_eval``), h = normalize(wo + wi):

    f = color · k(wo) · F(h·wo) · D(h) G2(wo, wi) / (4 |cos θo| |cos θi|)
    F(c) = mix(f0·tint, 1, saturate((F_real(c, eta) − F0(eta)) / (1 − F0(eta))))   per channel

F_real is the exact unpolarised dielectric Fresnel, F0(eta) = ((eta−1)/(eta+1))², eta the IOR
after Specular IOR Level (Cycles: ``interpolate``/generalized Schlick with exponent −eta).
k(wo) = 1 for "GGX"; for "Multiscatter GGX" (Cycles's ``microfacet_ggx_preserve_energy``)
k = 1 + Fms·(1 − E)/E with E = E(r, cos θo), Fms = Fss·E_avg/(1 − Fss·(1 − E_avg)),
Fss = mix(f0·tint, 1, saturate(inverse_lerp(F0, 1, Fss_real(eta)))) (Kulla-Conty fit).

Layering (Cycles's ``closure_layering_weight``): lobes below are scaled by
    1 − max_c d_c(wo)·mix(f0·tint, 1, s(r, cos θo, eta))_c   (clamped to [0, 1])
with d = k·E for Multiscatter GGX (Cycles's "darkening", the part of k folded into the closure
weight), 1 for GGX.
where s is the tabulated mean Fresnel remap over visible normals (``ggx_gen_schlick_ior_s``).

Tables (dielectric_specular_tables.npz, made by scripts/make_dielectric_tables.py with our own
Monte Carlo; they agree with Cycles's to 6e-4 in E): E (32×32, [mu, r]), E_avg (32,),
s (16×16×16, [z, mu, r]) with z = sqrt((eta − 1)/(eta + 1)). Read with (tri)linear
interpolation on the node grid i/(n−1), like Cycles's lookup_table_read.

Per-lobe parameters (``MaterialData.lobe_fresnel`` (M, L, 4)): f0·tint RGB (saturated) and
the multiscatter flag (1.0 / 0.0); alpha in lobe_alpha, eta in lobe_ior.
"""

from __future__ import annotations

import math
import os

import numpy as np

from ..kernels import kernel
from .dielectric import fresnel
from .ggx import glossy_eval

_TABLES = np.load(os.path.join(os.path.dirname(__file__), "dielectric_specular_tables.npz"))
#: (32, 32) GGX directional albedo E[mu index, roughness index]
GGX_E = np.ascontiguousarray(_TABLES["ggx_E"], dtype=np.float64)
#: (32,) cosine-weighted average albedo E_avg[roughness index]
GGX_EAVG = np.ascontiguousarray(_TABLES["ggx_Eavg"], dtype=np.float64)
#: (16, 16, 16) mean Fresnel remap s[z index, mu index, roughness index]
GEN_SCHLICK_IOR_S = np.ascontiguousarray(_TABLES["gen_schlick_ior_s"], dtype=np.float64)


@kernel
def _coord(x, n):
    """(i0, i1, t) of x ∈ [0, 1] on an n-node grid, clamped."""
    f = min(max(x, 0.0), 1.0) * (n - 1)
    i0 = min(int(f), n - 1)
    i1 = min(i0 + 1, n - 1)
    return i0, i1, f - i0


@kernel
def table_1d(tab, x):
    i0, i1, t = _coord(x, tab.shape[0])
    return tab[i0] * (1.0 - t) + tab[i1] * t


@kernel
def table_2d(tab, x, y):
    """tab[y, x], bilinear."""
    x0, x1, tx = _coord(x, tab.shape[1])
    y0, y1, ty = _coord(y, tab.shape[0])
    a = tab[y0, x0] * (1.0 - tx) + tab[y0, x1] * tx
    b = tab[y1, x0] * (1.0 - tx) + tab[y1, x1] * tx
    return a * (1.0 - ty) + b * ty


@kernel
def table_3d(tab, x, y, z):
    """tab[z, y, x], trilinear."""
    z0, z1, tz = _coord(z, tab.shape[0])
    return table_2d(tab[z0], x, y) * (1.0 - tz) + table_2d(tab[z1], x, y) * tz


@kernel
def f0_from_ior(eta):
    r = (eta - 1.0) / (eta + 1.0)
    return r * r


@kernel
def specular_eta_f0(ior, level):
    """The Principled specular layer's (eta, F0) from IOR (≥ 1) and Specular IOR Level
    (≥ 0): Cycles's "Apply IOR adjustment" — F0 of the IOR scaled by 2·level, clamped to
    [0, 0.99], and back to an IOR; level 0.5 leaves both as they are. The exporter does the same
    for constant inputs; ``programs.eval_material`` calls this per hit for textured ones."""
    f0 = f0_from_ior(ior)
    if level == 0.5:
        return ior, f0
    f0s = min(max(f0 * 2.0 * level, 0.0), 0.99)
    r = math.sqrt(f0s)
    return (1.0 + r) / (1.0 - r), f0s


@kernel
def fss_real(eta):
    """Cosine-weighted average of the real dielectric Fresnel (Kulla-Conty fit, Cycles's
    ``fresnel_dielectric_Fss``)."""
    if eta < 1.0:
        return 0.997118 + eta * (0.1014 - eta * (0.965241 + eta * 0.130607))
    return (eta - 1.0) / (4.08567 + 1.00071 * eta)


@kernel
def glass_select_weight(c, k, eta):
    """Lobe-selection weight of a Principled glass lobe (``reflection_weight`` set): its
    refraction's mean colour c and its untinted reflection's weight k, mixed by the
    cosine-averaged Fresnel of the IOR eta (``fss_real``). The colour alone would give a black
    glass (k·sqrt(black) = 0) no chance of being sampled, and its reflection none of being seen
    by BSDF rays."""
    f = min(max(fss_real(eta), 0.0), 1.0)
    return c * (1.0 - f) + k * f


@kernel
def remap(f_real, f0_real):
    """saturate(inverse_lerp(f0_real, 1, f_real))."""
    if f0_real >= 1.0:
        return 1.0
    return min(max((f_real - f0_real) / (1.0 - f0_real), 0.0), 1.0)


@kernel
def energy_factor(alpha, eta, f0t, multiscatter, cos_o):
    """k(wo) per channel (3-tuple): the multiscatter compensation × darkening (1 for GGX)."""
    if not multiscatter:
        return (1.0, 1.0, 1.0)
    rough = math.sqrt(alpha)
    e = max(table_2d(GGX_E, rough, abs(cos_o)), 1e-6)
    e_avg = table_1d(GGX_EAVG, rough)
    s = remap(fss_real(eta), f0_from_ior(eta))
    missing = (1.0 - e) / e
    return (_compensation(f0t[0], s, e_avg, missing), _compensation(f0t[1], s, e_avg, missing),
            _compensation(f0t[2], s, e_avg, missing))


@kernel
def _compensation(f0, s, e_avg, missing):
    """One channel of k: 1 + Fms·(1 − E)/E."""
    fss = f0 + (1.0 - f0) * s
    fms = fss * e_avg / (1.0 - fss * (1.0 - e_avg))
    return 1.0 + fms * missing


@kernel
def layer_weight(alpha, eta, f0t, multiscatter, cos_o):
    """Scale of the lobes under the layer for this wo: 1 − max_c albedo_c (clamped)."""
    return min(max(1.0 - layer_albedo_max(alpha, eta, f0t, multiscatter, cos_o), 0.0), 1.0)


@kernel
def layer_albedo_max(alpha, eta, f0t, multiscatter, cos_o):
    """max_c of the layer's albedo estimate for this wo (per unit weight): what the lobes under
    it lose (Cycles's bsdf_microfacet_estimate_albedo × the multiscatter darkening)."""
    rough = math.sqrt(alpha)
    z = math.sqrt(abs((eta - 1.0) / (eta + 1.0)))
    s = table_3d(GEN_SCHLICK_IOR_S, rough, min(abs(cos_o), 1.0), z)
    # both factors of a channel's albedo grow with its f0, so the largest is the largest f0's
    f0 = max(f0t[0], f0t[1], f0t[2])
    a = f0 + (1.0 - f0) * s
    if multiscatter:
        # Cycles scales the closure weight by the darkening d = k·E = E + Fms·(1 − E) only
        # (energy_scale 1/E is applied at evaluation), and the layering reads that weight
        e = max(table_2d(GGX_E, rough, abs(cos_o)), 1e-6)
        e_avg = table_1d(GGX_EAVG, rough)
        s_avg = remap(fss_real(eta), f0_from_ior(eta))
        a *= e + _fms(f0, s_avg, e_avg) * (1.0 - e)
    return a


@kernel
def _fms(f0, s_avg, e_avg):
    """Kulla-Conty Fms of one channel: Fss·E_avg / (1 − Fss·(1 − E_avg))."""
    fss = f0 + (1.0 - f0) * s_avg
    return fss * e_avg / (1.0 - fss * (1.0 - e_avg))


@kernel
def fresnel_color(cos_h, eta, f0t):
    """F(h·wo) per channel: the generalized-Schlick remap of the real Fresnel."""
    s = remap(fresnel(cos_h, eta), f0_from_ior(eta))
    return (f0t[0] + (1.0 - f0t[0]) * s, f0t[1] + (1.0 - f0t[1]) * s, f0t[2] + (1.0 - f0t[2]) * s)


@kernel
def dielectric_spec_eval(wo, wi, alpha, alpha_energy, eta, f0t, multiscatter):
    """White-weight lobe: (f·|cos θi| 3-tuple, pdf of ``glossy_sample``); alpha above the
    singular threshold. ``alpha_energy``: the alpha the multiscatter compensation is read at —
    the lobe's own, also where Filter Glossy widened ``alpha`` (Cycles fixes a closure's
    energy_scale when it is set up, before the blur)."""
    v, p = glossy_eval(wo, wi, alpha)
    if not v > 0.0:
        return (0.0, 0.0, 0.0), p
    hx = wo[0] + wi[0]
    hy = wo[1] + wi[1]
    hz = wo[2] + wi[2]
    hn = math.sqrt(hx * hx + hy * hy + hz * hz)
    cos_h = abs(wo[0] * hx + wo[1] * hy + wo[2] * hz) / hn if hn > 0.0 else 1.0
    fc = fresnel_color(cos_h, eta, f0t)
    k = energy_factor(alpha_energy, eta, f0t, multiscatter, wo[2])
    return (v * fc[0] * k[0], v * fc[1] * k[1], v * fc[2] * k[2]), p


@kernel
def dielectric_spec_delta_weight(cos_o, eta, f0t, multiscatter):
    """Weight factor (3-tuple) of the mirror limit: F(cos θo) (k of alpha 0)."""
    fc = fresnel_color(cos_o, eta, f0t)
    k = energy_factor(0.0, eta, f0t, multiscatter, cos_o)
    return (fc[0] * k[0], fc[1] * k[1], fc[2] * k[2])


def average_albedo(alpha: float, eta: float, f0t, multiscatter: bool) -> np.ndarray:
    """Cosine-averaged albedo estimate (3,) of a white lobe (for lobe selection, albedo pass)."""
    if eta == 1.0:
        return np.zeros(3)
    s = float(remap(fss_real(eta), f0_from_ior(eta)))
    f0t = np.asarray(f0t, np.float64)
    fss = f0t + (1.0 - f0t) * s
    if not multiscatter:
        return fss * float(table_1d(GGX_EAVG, math.sqrt(alpha)))
    return fss


# ---------------------------------------------------------------------------------------------
# The Principled BSDF's metallic lobe: GGX × Cycles's F82-tint conductor Fresnel
#   F(c) = saturate(mix(F0, 1, (1 − c)⁵) − B·c·(1 − c)⁶),  B = F_schlick(1/7)·7/(f⁶)·(1 − tint)
# with f = 6/7, F0 = the clamped base colour, tint = min(Specular Tint, 1) ("F82 tint"), and
# Multiscatter GGX compensation with Fss = mix(F0, 1, 1/21) − B/126 (fresnel_f82_Fss).
# ---------------------------------------------------------------------------------------------

_F82_F = 6.0 / 7.0
_F82_F5 = _F82_F ** 5


@kernel
def f82_b(f0, tint):
    """B of one channel (Cycles's fresnel_f82tint_B; 0 for a white tint)."""
    if tint == 1.0:
        return 0.0
    fs = f0 + (1.0 - f0) * _F82_F5
    return fs * (7.0 / (_F82_F5 * _F82_F)) * (1.0 - tint)


@kernel
def f82_channel(c, f0, b):
    s = min(max(1.0 - abs(c), 0.0), 1.0)
    s5 = s * s * s * s * s
    return min(max(f0 + (1.0 - f0) * s5 - b * abs(c) * s5 * s, 0.0), 1.0)


@kernel
def metal_energy(alpha, f0, b, multiscatter, cos_o):
    """k(wo) per channel of the metallic lobe (1 for GGX)."""
    if not multiscatter:
        return (1.0, 1.0, 1.0)
    rough = math.sqrt(alpha)
    e = max(table_2d(GGX_E, rough, abs(cos_o)), 1e-6)
    e_avg = table_1d(GGX_EAVG, rough)
    missing = (1.0 - e) / e
    return (_metal_comp(f0[0], b[0], e_avg, missing), _metal_comp(f0[1], b[1], e_avg, missing),
            _metal_comp(f0[2], b[2], e_avg, missing))


@kernel
def _metal_comp(f0, b, e_avg, missing):
    return energy_comp(f0 + (1.0 - f0) * (1.0 / 21.0) - b * (1.0 / 126.0), e_avg, missing)


@kernel
def energy_comp(fss, e_avg, missing):
    """Cycles's Multiscatter GGX factor on a single-scattering lobe (microfacet_ggx_preserve_energy,
    after Kulla & Conty): 1 + Fms·(1 − E)/E with Fms = Fss·E_avg / (1 − Fss·(1 − E_avg)), Fss
    the lobe's average Fresnel (one channel), ``missing`` = (1 − E)/E."""
    fms = fss * e_avg / (1.0 - fss * (1.0 - e_avg))
    return 1.0 + fms * missing


@kernel
def glossy_energy(alpha, cos_o, fss):
    """k(wo) per channel of a Glossy BSDF with Cycles's Multiscatter GGX: constant Fresnel, so
    Fss is the node's colour (``fss``, a 3-tuple in [0, 1]); cos_o about the lobe's normal."""
    rough = math.sqrt(alpha)
    e = max(table_2d(GGX_E, rough, abs(cos_o)), 1e-6)
    e_avg = table_1d(GGX_EAVG, rough)
    missing = (1.0 - e) / e
    return (energy_comp(fss[0], e_avg, missing), energy_comp(fss[1], e_avg, missing),
            energy_comp(fss[2], e_avg, missing))


@kernel
def metallic_eval(wo, wi, alpha, alpha_energy, f0, tint, multiscatter):
    """White-weight metallic lobe: (f·|cos θi| 3-tuple, pdf of ``glossy_sample``); f0 the base
    colour (clamped to [0, 1]), tint the F82 tint; ``alpha_energy`` as ``dielectric_spec_eval``'s."""
    v, p = glossy_eval(wo, wi, alpha)
    if not v > 0.0:
        return (0.0, 0.0, 0.0), p
    hx = wo[0] + wi[0]
    hy = wo[1] + wi[1]
    hz = wo[2] + wi[2]
    hn = math.sqrt(hx * hx + hy * hy + hz * hz)
    cos_h = abs(wo[0] * hx + wo[1] * hy + wo[2] * hz) / hn if hn > 0.0 else 1.0
    b = (f82_b(f0[0], tint[0]), f82_b(f0[1], tint[1]), f82_b(f0[2], tint[2]))
    k = metal_energy(alpha_energy, f0, b, multiscatter, wo[2])
    return (v * f82_channel(cos_h, f0[0], b[0]) * k[0], v * f82_channel(cos_h, f0[1], b[1]) * k[1],
            v * f82_channel(cos_h, f0[2], b[2]) * k[2]), p


@kernel
def metallic_delta_weight(cos_o, f0, tint):
    """Weight factor (3-tuple) of a smooth metal: F(cos θo)."""
    return (f82_channel(cos_o, f0[0], f82_b(f0[0], tint[0])), f82_channel(cos_o, f0[1], f82_b(f0[1], tint[1])),
            f82_channel(cos_o, f0[2], f82_b(f0[2], tint[2])))


def metallic_average_albedo(f0, tint) -> np.ndarray:
    """Fss (3,) of the metallic lobe per unit weight (for lobe selection and the albedo pass)."""
    f0 = np.clip(np.asarray(f0, np.float64), 0.0, 1.0)
    b = np.array([f82_b(float(a), float(t)) for a, t in zip(f0, tint)])
    return np.clip(f0 + (1.0 - f0) / 21.0 - b / 126.0, 0.0, 1.0)
