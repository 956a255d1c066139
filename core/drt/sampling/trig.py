"""sin and cos of one angle together, in a few multiply-adds instead of a libm call.

The samplers need both the sine and the cosine of an angle they just drew: the concentric
disk (every cosine-weighted BSDF sample, cones, disks) and the spherical rectangle (every
area-light sample). libm's ``sincos`` reduces any argument exactly and cost ~5 % of a
Cornell-box render (`benchmarks/kernel_profile.py`, 2026-12-07); these angles are small and
known in range, so a polynomial does it:

- `sincos_quarter(x)`, |x| ≤ π/4: Cephes's minimax polynomials (sin: x + x³·P(x²), cos:
  1 − x²/2 + x⁴·Q(x²), degree 13 and 14), within 1.2e-16 of the true values over the range
  (tests/test_trig.py checks them against libm on a dense grid).
- `sincos(x)`, |x| ≲ 1e5 (angles of a few turns): the nearest multiple k of π/2 is taken off in
  two parts (Cody and Waite: a 33-bit π/2 times k is exact, then the rest of π/2), the
  remainder, |r| ≤ π/4, goes through `sincos_quarter`, and k mod 4 rotates the pair. Within a
  few 1e-16 for the angles the samplers pass (< 2π).

Radians in, (sin, cos) out, float64.
"""

from __future__ import annotations

import math

import numpy as np

from ..kernels import kernel

# Cephes sin.c: sin x ≈ x + x³·(S0 + S1·z + … + S5·z⁵), cos x ≈ 1 − z/2 + z²·(C0 + … + C5·z⁵),
# z = x², on [−π/4, π/4]
_S0 = -1.66666666666666307295e-1
_S1 = 8.33333333332211858878e-3
_S2 = -1.98412698295895385996e-4
_S3 = 2.75573136213857245213e-6
_S4 = -2.50507477628578072866e-8
_S5 = 1.58962301576546568060e-10
_C0 = 4.16666666666665929218e-2
_C1 = -1.38888888888730564116e-3
_C2 = 2.48015872888517045348e-5
_C3 = -2.75573141792967388112e-7
_C4 = 2.08757008419747316778e-9
_C5 = -1.13585365213876817300e-11

# π/2 in two parts (fdlibm's pio2_1, pio2_1t): the first has 33 significant bits, so k·_PIO2_HI
# is exact for |k| < 2^20
_PIO2_HI = 1.57079632673412561417e+00
_PIO2_LO = 6.07710050650619224932e-11
_TWO_OVER_PI = 2.0 / math.pi


@kernel
def sincos_quarter(x):
    """(sin x, cos x) for |x| ≤ π/4 (radians)."""
    z = x * x
    # Estrin's scheme (pairs of coefficients in parallel, then powers of z²), not Horner's:
    # the samplers wait for this value, and Horner's rule chains all five multiply-adds
    z2 = z * z
    ps = (_S0 + z * _S1) + z2 * ((_S2 + z * _S3) + z2 * (_S4 + z * _S5))
    pc = (_C0 + z * _C1) + z2 * ((_C2 + z * _C3) + z2 * (_C4 + z * _C5))
    return x + x * z * ps, 1.0 - 0.5 * z + z2 * pc


@kernel
def sincos(x):
    """(sin x, cos x) for a finite angle of at most a few turns (radians; see the module
    docstring for the range). NaN in, NaN out."""
    kf = np.floor(x * _TWO_OVER_PI + 0.5)  # (a float: math.floor gives an int, undefined for inf)
    if not abs(kf) < 1e5:  # far outside the samplers' range, or NaN: libm's reduction
        return math.sin(x), math.cos(x)
    r = (x - kf * _PIO2_HI) - kf * _PIO2_LO
    s, c = sincos_quarter(r)
    q = int(kf) & 3
    if q == 0:
        return s, c
    if q == 1:
        return c, -s
    if q == 2:
        return -s, -c
    return -c, s
