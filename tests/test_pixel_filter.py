"""Pixel filter: Cycles's filter shapes and supports, chi-square of the importance sampling, and
the half-plane edge test of docs (blender-conventions.md, "Pixel filter")."""

import numpy as np
import pytest

from drt.sampling.pixel_filter import PixelFilter
from drt.sampling.sequences import Sampler
from stats_util import assert_within_ci, chi2_test_2d

KINDS = ["BLACKMAN_HARRIS", "GAUSSIAN", "BOX"]

#: the trapezoidal rule: numpy 2 renamed trapz (removed in 2.4), numpy 1.26 (bpy 5.0's) has only trapz
trapezoid = getattr(np, "trapezoid", None) or np.trapz


@pytest.mark.parametrize("kind,width,radius", [
    ("BLACKMAN_HARRIS", 1.5, 1.5), ("BLACKMAN_HARRIS", 3.0, 3.0),
    ("GAUSSIAN", 1.5, 2.25), ("GAUSSIAN", 1.0, 1.5),
    ("BOX", 1.0, 0.5), ("BOX", 1.5, 0.75),
])
def test_support_matches_cycles(kind, width, radius):
    f = PixelFilter(kind, width)
    assert f.radius == pytest.approx(radius)
    o = f.sample(np.random.default_rng(0).random((50_000, 2)))
    assert np.all(np.abs(o) <= radius)
    assert np.abs(o).max() > 0.9 * radius if kind == "BOX" else True
    assert f.eval_1d(np.array([radius * 1.0001]))[0] == 0.0


def test_filter_shapes():
    bh = PixelFilter("BLACKMAN_HARRIS", 1.5)
    # Cycles's filter_func_blackman_harris with width' = 2w: peak 1 at 0, ≈ 6e-5 at ±w
    assert bh.eval_1d(np.array([0.0]))[0] == pytest.approx(1.0)
    assert bh.eval_1d(np.array([1.5]))[0] == pytest.approx(0.35875 - 0.48829 + 0.14128 - 0.01168)
    x = np.linspace(-1.5, 1.5, 301)
    assert np.allclose(bh.eval_1d(x), bh.eval_1d(-x))
    g = PixelFilter("GAUSSIAN", 1.5)  # exp(−2(6x/(3w))²): σ = w/4
    assert g.eval_1d(np.array([0.375]))[0] == pytest.approx(np.exp(-0.5))
    assert g.eval_1d(np.array([2.25]))[0] == pytest.approx(np.exp(-18.0))


@pytest.mark.parametrize("kind", KINDS)
def test_pdf_normalized_and_cdf_consistent(kind):
    f = PixelFilter(kind, 1.5)
    x = np.linspace(-f.radius, f.radius, 20_001)
    assert trapezoid(f.pdf_1d(x), x) == pytest.approx(1.0, abs=1e-6)
    cdf = f.cdf_1d(x)
    assert cdf[0] == pytest.approx(0.0, abs=1e-12) and cdf[-1] == pytest.approx(1.0)
    trap = 0.5 * (f.pdf_1d(x[1:]) + f.pdf_1d(x[:-1])) * np.diff(x)
    num = np.concatenate([[0.0], np.cumsum(trap)])
    assert np.allclose(cdf, num, atol=1e-6)


@pytest.mark.parametrize("kind,width", [("BLACKMAN_HARRIS", 1.5), ("BLACKMAN_HARRIS", 2.5),
                                        ("GAUSSIAN", 1.5), ("BOX", 1.5)])
def test_sampling_chi2(kind, width):
    f = PixelFilter(kind, width)
    r = f.radius * (1 + 1e-9)
    p = chi2_test_2d(f.sample, f.pdf, 200_000, 24, 24, bounds=((-r, r), (-r, r)),
                     resolution=8)
    assert p > 0.01


@pytest.mark.parametrize("kind,width", [("BLACKMAN_HARRIS", 1.5), ("BLACKMAN_HARRIS", 4.0),
                                        ("GAUSSIAN", 1.5), ("BOX", 1.5)])
def test_sampling_inverts_the_exact_cdf(kind, width):
    # the tabulated inverse CDF (linear pieces, finer at both ends) against the closed-form
    # CDF: a sample drawn with u lands where the exact CDF is u, to within 1e-4 everywhere,
    # the ends included (one linear piece over u < 1/1024, as Cycles, is off by 7e-4 there)
    f = PixelFilter(kind, width)
    u = np.concatenate([np.random.default_rng(3).random(200_000), np.linspace(0.0, 1e-3, 2001),
                        np.linspace(1.0 - 1e-3, 1.0, 2001)[:-1]])
    err = np.abs(f.cdf_1d(f.sample_1d(u)) - u)
    assert err.max() < 1e-4, err.max()
    assert np.all(np.abs(f.sample_1d(np.array([0.0, 1.0 - 1e-16]))) <= f.radius)


@pytest.mark.parametrize("kind", KINDS)
def test_sampling_is_monotone_in_u(kind):
    f = PixelFilter(kind, 1.5)
    u = np.linspace(0.0, 1.0, 10_001, endpoint=False)
    x = f.sample_1d(u)
    assert np.all(np.diff(x) >= 0.0)
    assert x[5000] == pytest.approx(0.0, abs=1e-3)  # median at the pixel centre


def test_analytic_edge_value():
    # an edge on a pixel boundary, seen by the pixel centred 0.5 px outside it: the fraction of
    # that pixel's filter mass beyond 0.5 px (blender-conventions.md: predicted 0.1186,
    # Cycles measured 0.1182)
    f = PixelFilter("BLACKMAN_HARRIS", 1.5)
    value = 1.0 - f.cdf_1d(np.array([0.5]))[0]
    assert abs(value - 0.1186) < 0.001
    assert value == pytest.approx(0.1185917, abs=1e-6)


@pytest.mark.parametrize("kind", KINDS)
def test_half_plane_edge_sampled(kind):
    # half plane x > 0 has radiance 1; pixel centre at x = −0.5: every sample weighs 1, so the
    # pixel value is the fraction of samples landing in the bright half plane
    f = PixelFilter(kind, 1.5)
    expected = 1.0 - f.cdf_1d(np.array([0.5]))[0]
    # with i.i.d. samples: within the Monte-Carlo confidence interval
    u = np.random.default_rng(42).random((400_000, 2))
    x = -0.5 + f.sample(u)[:, 0]
    assert_within_ci((x > 0.0).astype(np.float64), expected, k=4)
    # with the renderer's samplers (pixels as independent trials): mean within CI as well
    for kind_s in ("SOBOL", "STRATIFIED"):
        s = Sampler(kind_s, seed=1, spp=64)
        pixel = np.repeat(np.arange(400, dtype=np.uint32), 64)
        index = np.tile(np.arange(64, dtype=np.uint32), 400)
        off = f.sample(s.sample_2d(pixel, index, 0))
        per_pixel = ((off[:, 0] - 0.5) > 0.0).reshape(400, 64).mean(axis=1)
        assert_within_ci(per_pixel, expected, k=4)


def test_gaussian_variance():
    f = PixelFilter("GAUSSIAN", 2.0)
    o = f.sample(np.random.default_rng(1).random((200_000, 2)))
    assert_within_ci(o ** 2, (2.0 / 4.0) ** 2)  # σ = w/4 (the ±1.5w = ±6σ truncation is negligible)


def test_bad_arguments():
    with pytest.raises(ValueError):
        PixelFilter("MITCHELL")
    with pytest.raises(ValueError):
        PixelFilter("BOX", 0.0)
    assert PixelFilter("gaussian").kind == "GAUSSIAN"
