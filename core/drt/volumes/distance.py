"""Sampling a distance t on a ray segment [0, L) (L may be inf) inside a homogeneous medium.

* exponential ("distance") sampling in one colour channel with extinction σ: density
  σ·e^(−σt) / (1 − e^(−σL)) on [0, L) (uniform 1/L where σ = 0 and L is finite); chromatic
  media pick the channel first and report the channel-averaged pdf (one-sample MIS over the
  channels, as Cycles's volume_sample_channel + dot(pdf, channel_pdf));
* equiangular sampling toward a point c (Kulla & Fajardo 2012): t = Δ + D·tan θ with θ uniform
  between the angles of the segment's ends seen from c, density D / ((θb − θa)(D² + (t − Δ)²)),
  Δ = (c − o)·d, D the distance of c from the ray's line.
"""

from __future__ import annotations

import math

from ..kernels import kernel


@kernel
def channel_probs(w0, w1, w2):
    """Channel-selection probabilities ∝ non-negative weights (uniform when all are 0)."""
    w0, w1, w2 = max(w0, 0.0), max(w1, 0.0), max(w2, 0.0)
    s = w0 + w1 + w2
    if not s > 0.0 or not math.isfinite(s):
        return (1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0)
    return (w0 / s, w1 / s, w2 / s)


@kernel
def pick_channel(p, u):
    """Channel c with probability p[c]; returns (c, u rescaled into [0, 1))."""
    if u < p[0] or (p[1] <= 0.0 and p[2] <= 0.0):
        return 0, min(u / p[0], 1.0 - 1e-16) if p[0] > 0.0 else 0.0
    if u < p[0] + p[1] or p[2] <= 0.0:
        return 1, min((u - p[0]) / p[1], 1.0 - 1e-16) if p[1] > 0.0 else 0.0
    return 2, min((u - p[0] - p[1]) / p[2], 1.0 - 1e-16)


@kernel
def exp_sample(u, sigma, length):
    """t on [0, length) with density ∝ e^(−σt) (see ``exp_pdf``); inf if nothing can be drawn."""
    if sigma > 0.0:
        # 1 − e^(−σL) computed as −expm1(−σL) keeps precision for thin media (σL ≪ 1)
        mass = -math.expm1(-sigma * length) if math.isfinite(length) else 1.0
        return -math.log1p(-u * mass) / sigma
    if math.isfinite(length):
        return u * length
    return math.inf


@kernel
def exp_pdf(t, sigma, length):
    """Density of ``exp_sample`` at t (0 outside [0, length))."""
    if not (t >= 0.0 and t < length):
        return 0.0
    if sigma > 0.0:
        mass = -math.expm1(-sigma * length) if math.isfinite(length) else 1.0
        return sigma * math.exp(-sigma * t) / mass
    return 1.0 / length if math.isfinite(length) else 0.0


@kernel
def equiangular_setup(o, d, c, length):
    """(Δ, D, θa, θb) of the segment o + t·d, t ∈ [0, length), seen from the point c."""
    dx, dy, dz = c[0] - o[0], c[1] - o[1], c[2] - o[2]
    delta = dx * d[0] + dy * d[1] + dz * d[2]
    px, py, pz = dx - delta * d[0], dy - delta * d[1], dz - delta * d[2]
    dist = math.sqrt(px * px + py * py + pz * pz)
    theta_a = math.atan2(-delta, dist)
    theta_b = math.atan2(length - delta, dist) if math.isfinite(length) else 0.5 * math.pi
    return delta, dist, theta_a, theta_b


@kernel
def equiangular_sample(u, delta, dist, theta_a, theta_b):
    """t with the equiangular density (``equiangular_pdf``); needs dist > 0 and θb > θa."""
    theta = theta_a + u * (theta_b - theta_a)
    return delta + dist * math.tan(theta)


@kernel
def equiangular_pdf(t, delta, dist, theta_a, theta_b, length):
    """Density of ``equiangular_sample`` at t (0 outside the segment or when degenerate)."""
    span = theta_b - theta_a
    if not (dist > 0.0 and span > 0.0 and t >= 0.0 and t < length):
        return 0.0
    x = t - delta
    return dist / (span * (dist * dist + x * x))
