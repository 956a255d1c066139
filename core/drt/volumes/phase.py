"""The Henyey-Greenstein phase function, Cycles's convention (closure/volume_henyey_greenstein.h).

cos θ is the cosine between the ray's *propagation* direction d and the scattered direction
wi: with DRT's ``wo = −d`` that is ``−dot(wo, wi)``; g > 0 scatters forward. The phase function
is normalised over the sphere (∫ p dω = 1, units 1/sr) and sampled exactly, so the sample's
weight p/pdf is 1. g is clamped to ±(1 − 1e-3) like Cycles (a |g| of 1 is a delta).
"""

from __future__ import annotations

import math

from ..kernels import kernel
from ..kernels.vec3 import build_frame, to_world
from ..sampling.trig import sincos

INV_4PI = 0.25 / math.pi
G_LIMIT = 1.0 - 1e-3


@kernel
def clamp_g(g):
    return min(max(g, -G_LIMIT), G_LIMIT)


@kernel
def hg_pdf(cos_theta, g):
    """HG density (1/sr) of scattering by angle θ from the propagation direction."""
    g = clamp_g(g)
    denom = 1.0 + g * g - 2.0 * g * cos_theta
    return INV_4PI * (1.0 - g * g) / (denom * math.sqrt(denom))


@kernel
def hg_sample_cos(g, u):
    """cos θ distributed as ``hg_pdf`` (inverse CDF) for u in [0, 1)."""
    g = clamp_g(g)
    if abs(g) < 1e-3:
        return 1.0 - 2.0 * u
    k = (1.0 - g * g) / (1.0 - g + 2.0 * g * u)
    c = (1.0 + g * g - k * k) / (2.0 * g)
    return min(max(c, -1.0), 1.0)


@kernel
def hg_sample(d, g, u0, u1):
    """A direction wi scattered from the propagation direction d (unit 3-tuple) and its pdf
    (= the phase function's value: weight 1)."""
    c = hg_sample_cos(g, u0)
    s = math.sqrt(max(0.0, 1.0 - c * c))
    sin_phi, cos_phi = sincos(2.0 * math.pi * u1)
    t_ax, b_ax = build_frame(d)
    wi = to_world((s * cos_phi, s * sin_phi, c), t_ax, b_ax, d)
    return wi, hg_pdf(c, g)


@kernel
def hg_sample_rows(d, g, u, wi, pdf):
    """``hg_sample`` for rows (tests, diagnostics): d (n, 3), u (n, 2) → wi (n, 3), pdf (n,)."""
    for k in range(d.shape[0]):
        w, p = hg_sample((d[k, 0], d[k, 1], d[k, 2]), g, u[k, 0], u[k, 1])
        wi[k, 0], wi[k, 1], wi[k, 2] = w[0], w[1], w[2]
        pdf[k] = p
