"""Cycles's "microfiber" sheen (Sheen BSDF, the Principled BSDF's sheen layer): a linearly
transformed cosine (LTC) lobe fitted to a volumetric fibre layer (Zeltner, Burley, Chiang 2022).

Per unit colour, for wo, wi in the local shading frame (mirrored when wo.z < 0, like the diffuse
lobe), with (a, b, A) = the tabulated LTC coefficients and albedo at (roughness r, mu = |cos θo|)
and wi expressed in the frame whose x axis points toward wo's tangential direction:

    D(wi)  = wi.z · (a / ((a·x + b·z)² + (a·y)² + z²))² / π        (wi.z > 0, else 0)
    f·cos  = A(r, mu) · D(wi),      pdf = D(wi)

so the sampling weight f·cos/pdf is A, the directional albedo. D is the cosine distribution
transformed by M = [[1, 0, −b], [0, 1, 0], [0, 0, a]]: sampling maps a cosine-distributed
direction o to normalize(M o); directions that land below the horizon are lost (D integrates to
≤ 1 over the hemisphere). The roughness is clamped to [1e-3, 1]; a hit whose |a| or A is below
1e-5 has no sheen (Cycles drops the closure).

Tables (sheen_tables.npz, scripts/make_sheen_tables.py): ltc[k, r index, mu index], k = a, b, A,
32 × 32 nodes i/31, read bilinearly like ``dielectric_specular.table_2d``.

The material table stores a SHEEN lobe's roughness squared in ``lobe_alpha`` (as every other
lobe, so textured roughness goes through the same register path); ``sheen_rough`` undoes it.
"""

from __future__ import annotations

import math
import os

import numpy as np

from ..kernels import kernel
from .dielectric_specular import table_2d

_TAB = np.load(os.path.join(os.path.dirname(__file__), "sheen_tables.npz"))["sheen_ltc"]
SHEEN_A = np.ascontiguousarray(_TAB[0], dtype=np.float64)
SHEEN_B = np.ascontiguousarray(_TAB[1], dtype=np.float64)
SHEEN_ALBEDO = np.ascontiguousarray(_TAB[2], dtype=np.float64)

INV_PI = 1.0 / math.pi
#: below these Cycles drops the closure (bsdf_sheen_setup)
SHEEN_CUTOFF = 1e-5


@kernel
def sheen_rough(alpha):
    """Sheen roughness from the stored alpha (= roughness²), clamped as Cycles."""
    return min(max(math.sqrt(max(alpha, 0.0)), 1e-3), 1.0)


@kernel
def sheen_albedo(alpha, cos_o):
    """Directional albedo A(r, |cos θo|) of a white sheen lobe (0 where Cycles drops it): what
    its sampling weight is, and what the layers under a sheen lose (× the layer weight)."""
    r = sheen_rough(alpha)
    mu = min(abs(cos_o), 1.0)
    a = table_2d(SHEEN_A, mu, r)
    alb = table_2d(SHEEN_ALBEDO, mu, r)
    if abs(a) < SHEEN_CUTOFF or alb < SHEEN_CUTOFF:
        return 0.0
    return alb


@kernel
def _frame(wo):
    """Unit x axis (tx, ty) of the LTC frame: wo's tangential direction (any if wo ∥ z)."""
    ln = math.sqrt(wo[0] * wo[0] + wo[1] * wo[1])
    if ln < 1e-7:
        return 1.0, 0.0
    return wo[0] / ln, wo[1] / ln


@kernel
def _ltc_density(a, b, x, y, z):
    if z <= 0.0:
        return 0.0
    ln = (a * x + b * z) ** 2 + (a * y) ** 2 + z * z
    q = a / ln
    return INV_PI * z * q * q


@kernel
def sheen_eval(wo, wi, alpha):
    """White-weight sheen: (f·|cos θi|, pdf of ``sheen_sample``); 0 where wi is not on wo's
    side or the lobe is dropped at this wo."""
    if wo[2] * wi[2] <= 0.0:
        return 0.0, 0.0
    r = sheen_rough(alpha)
    mu = min(abs(wo[2]), 1.0)
    a = table_2d(SHEEN_A, mu, r)
    alb = table_2d(SHEEN_ALBEDO, mu, r)
    if abs(a) < SHEEN_CUTOFF or alb < SHEEN_CUTOFF:
        return 0.0, 0.0
    b = table_2d(SHEEN_B, mu, r)
    tx, ty = _frame(wo)
    x = wi[0] * tx + wi[1] * ty
    y = wi[1] * tx - wi[0] * ty
    d = _ltc_density(a, b, x, y, abs(wi[2]))
    return alb * d, d


@kernel
def sheen_sample(wo, alpha, u0, u1):
    """wi drawn from the LTC lobe on wo's side (z = 0 when the lobe is dropped; a direction below
    the horizon is returned as is: eval gives it 0)."""
    r = sheen_rough(alpha)
    mu = min(abs(wo[2]), 1.0)
    a = table_2d(SHEEN_A, mu, r)
    if abs(a) < SHEEN_CUTOFF or table_2d(SHEEN_ALBEDO, mu, r) < SHEEN_CUTOFF:
        return (0.0, 0.0, 0.0)
    b = table_2d(SHEEN_B, mu, r)
    rad = math.sqrt(u0)
    phi = 2.0 * math.pi * u1
    dx = rad * math.cos(phi)
    dy = rad * math.sin(phi)
    dz = math.sqrt(max(1.0 - rad * rad, 0.0))
    lx = dx - dz * b
    ly = dy
    lz = dz * a
    ln = math.sqrt(lx * lx + ly * ly + lz * lz)
    lx /= ln
    ly /= ln
    lz /= ln
    tx, ty = _frame(wo)
    s = 1.0 if wo[2] >= 0.0 else -1.0
    return (lx * tx - ly * ty, lx * ty + ly * tx, s * lz)


def average_albedo(alpha: float) -> float:
    """Cosine-weighted average 2∫ A(r, mu) mu dmu of a white sheen lobe (lobe selection, the
    albedo pass, the average share its lower layers keep)."""
    mu = (np.arange(64) + 0.5) / 64
    return float(2.0 * np.mean([sheen_albedo(alpha, m) * m for m in mu]))


# ---------------------------------------------------------------------------------------------
# Ashikhmin velvet (the Sheen BSDF's "Ashikhmin" distribution, the legacy Velvet BSDF), as
# Cycles's bsdf_ashikhmin_velvet: with h = normalize(wo + wi), sigma = max(Roughness, 0.01),
#   D = exp(−cot²θh / σ²) / (π σ² sin⁴θh),  G = min(1, 2 (cosθh/|h·wo|) cosθo, 2 (…) cosθi)
#   f·cos θi = D·G / (4 cos θo),   sampled uniformly over wo's hemisphere (pdf 1/(2π)).
# Stored alpha = sigma² (lobe_alpha, as the other lobes' roughness²).
# ---------------------------------------------------------------------------------------------


@kernel
def velvet_eval(wo, wi, alpha):
    """White-weight velvet: (f·|cos θi|, pdf 1/(2π) of ``velvet_sample``); mirrored when
    wo.z < 0, 0 when wi is on the other side."""
    if wo[2] * wi[2] <= 0.0:
        return 0.0, 0.0
    s = 1.0 if wo[2] > 0.0 else -1.0
    cos_o = abs(wo[2])
    cos_i = abs(wi[2])
    hx = wo[0] + wi[0]
    hy = wo[1] + wi[1]
    hz = s * (wo[2] + wi[2])
    hn = math.sqrt(hx * hx + hy * hy + hz * hz)
    pdf = 0.5 * INV_PI
    if not hn > 0.0:
        return 0.0, pdf
    cos_nh = hz / hn
    cos_ho = abs(wo[0] * hx + wo[1] * hy + s * wo[2] * hz) / hn
    if not (abs(cos_nh) < 1.0 - 1e-5 and cos_ho > 1e-5):
        return 0.0, pdf
    sigma = max(math.sqrt(max(alpha, 0.0)), 0.01)
    inv_s2 = 1.0 / (sigma * sigma)
    q = max(cos_nh / cos_ho, 1e-5)
    g = min(1.0, 2.0 * q * cos_o, 2.0 * q * cos_i)
    sin2 = 1.0 - cos_nh * cos_nh
    d = math.exp(-(cos_nh * cos_nh / sin2) * inv_s2) * inv_s2 * INV_PI / (sin2 * sin2)
    return 0.25 * d * g / cos_o, pdf


@kernel
def velvet_sample(wo, u0, u1):
    """wi uniform over wo's hemisphere (pdf 1/(2π))."""
    z = u0
    r = math.sqrt(max(1.0 - z * z, 0.0))
    phi = 2.0 * math.pi * u1
    return (r * math.cos(phi), r * math.sin(phi), z if wo[2] >= 0.0 else -z)


def velvet_average_albedo(alpha: float) -> float:
    """Cosine-weighted average albedo of a white velvet lobe (lobe selection, albedo pass)."""
    rng = np.random.default_rng(0)
    n = 4096
    mu = np.sqrt(rng.random(n))
    z = rng.random(n)
    ph = 2 * np.pi * rng.random(n)
    r = np.sqrt(1 - z * z)
    tot = 0.0
    for k in range(n):
        v, _ = velvet_eval((math.sqrt(1 - mu[k] ** 2), 0.0, mu[k]),
                           (r[k] * math.cos(ph[k]), r[k] * math.sin(ph[k]), z[k]), alpha)
        tot += v * 2 * math.pi
    return float(min(tot / n, 1.0))
