"""sin and cos by polynomial (drt.sampling.trig) against libm, and the samplers that use them."""

from __future__ import annotations

import math

import numpy as np

from drt.kernels import kernel
from drt.sampling.trig import sincos, sincos_quarter
from drt.sampling.warps import disk_concentric


@kernel
def _pairs(fn_id, x, out):
    for k in range(x.shape[0]):
        if fn_id == 0:
            s, c = sincos_quarter(x[k])
        else:
            s, c = sincos(x[k])
        out[k, 0] = s
        out[k, 1] = c


def _eval(fn_id, x):
    x = np.ascontiguousarray(x, dtype=np.float64)
    out = np.empty((len(x), 2))
    _pairs(fn_id, x, out)
    return out


def test_sincos_on_a_quarter_turn_is_within_an_ulp_of_libm():
    x = np.linspace(-math.pi / 4, math.pi / 4, 400_001)
    out = _eval(0, x)
    assert np.max(np.abs(out[:, 0] - np.sin(x))) <= 1.2e-16
    assert np.max(np.abs(out[:, 1] - np.cos(x))) <= 1.2e-16
    # odd and even, and exact where libm is: 0 and tiny angles
    neg = _eval(0, -x)
    assert np.array_equal(neg[:, 0], -out[:, 0]) and np.array_equal(neg[:, 1], out[:, 1])
    assert tuple(_eval(0, [0.0, 1e-300])[:, 0]) == (0.0, 1e-300) and _eval(0, [0.0])[0, 1] == 1.0


def test_sincos_reduces_angles_of_a_few_turns_and_falls_back_beyond():
    rng = np.random.default_rng(7)
    x = np.concatenate([np.linspace(-4 * math.pi, 4 * math.pi, 200_001), rng.uniform(0.0, 2 * math.pi, 200_000),
                        [k * math.pi / 4 for k in range(-16, 17)], [100.0, -1234.5]])
    out = _eval(1, x)
    assert np.max(np.abs(out[:, 0] - np.sin(x))) <= 4e-16
    assert np.max(np.abs(out[:, 1] - np.cos(x))) <= 4e-16
    big = _eval(1, [1e6, -3e7])
    assert np.array_equal(big, np.stack([np.sin([1e6, -3e7]), np.cos([1e6, -3e7])], axis=1))
    assert np.isnan(_eval(1, [np.nan])).all() and np.isnan(_eval(1, [np.inf])).all()


@kernel
def _disk_rows(u, out):
    for k in range(u.shape[0]):
        out[k, 0], out[k, 1] = disk_concentric(u[k, 0], u[k, 1])


def test_the_concentric_disk_is_shirley_and_chius_map():
    """The same points as the map's textbook form with libm's cos and sin, to rounding."""
    u = np.random.default_rng(3).random((100_000, 2))
    out = np.empty_like(u)
    _disk_rows(u, out)
    a, b = 2 * u[:, 0] - 1, 2 * u[:, 1] - 1
    first = np.abs(a) > np.abs(b)
    r = np.where(first, a, b)
    with np.errstate(divide="ignore", invalid="ignore"):
        phi = np.where(first, np.pi / 4 * (b / a), np.pi / 2 - np.pi / 4 * (a / b))
    expect = np.stack([r * np.cos(phi), r * np.sin(phi)], axis=1)
    assert np.max(np.abs(out - expect)) < 1e-15
    assert np.all(np.hypot(out[:, 0], out[:, 1]) <= 1.0 + 1e-15)
