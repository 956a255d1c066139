"""Warps: chi-square of each warp against its pdf, round trips, frames, the midpoint rule.

Also checks the shared helpers in ``stats_util`` (chi-square survival function, pooling).
"""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from drt.sampling import warps as w
from stats_util import (assert_within_ci, chi2_pvalue, chi2_sf, chi2_test_2d, chi2_test_sphere,
                        mean_ci)

N = 100_000
ALPHA = 0.01


# --------------------------------------------------------------------------------- stats_util


@pytest.mark.parametrize("x,dof,expected", [
    (3.841458820694124, 1, 0.05), (18.307038053275146, 10, 0.05), (0.5, 3, 0.9188914116546758),
    (1074.6794, 1000, 0.05), (0.0, 4, 1.0), (50.0, 2, math.exp(-25.0)),
])
def test_chi2_sf_known_values(x, dof, expected):
    assert chi2_sf(x, dof) == pytest.approx(expected, rel=1e-4, abs=1e-12)


def test_chi2_pooling_and_zero_expected_cell():
    # the three low cells are pooled; the pool (1.0 < 5) then absorbs the next-smallest cell
    p, stat, dof, _ = chi2_pvalue([10, 10, 1, 0, 0], [10, 10, 0.5, 0.3, 0.2])
    assert dof == 1 and stat == pytest.approx(0.0) and p == pytest.approx(1.0)
    p, stat, dof, _ = chi2_pvalue([20, 10, 10], [10, 10, 20])
    assert dof == 2 and stat == pytest.approx(15.0) and p == pytest.approx(math.exp(-7.5))
    p, *_ = chi2_pvalue([10, 10, 3], [11.5, 11.5, 0.0])
    assert p == 0.0


def test_chi2_rejects_a_wrong_pdf():
    # samples of a cosine hemisphere tested against the uniform-hemisphere pdf must fail
    assert chi2_test_sphere(w.square_to_cosine_hemisphere, w.square_to_uniform_hemisphere_pdf,
                            20_000, 10, 20) < 1e-6
    assert chi2_test_2d(lambda u: u ** 1.05, lambda p: np.ones(len(p)), 100_000, 10, 10) < 1e-6


def test_mean_ci_and_assert_within_ci():
    v = np.random.default_rng(3).normal(2.0, 1.0, 10_000)
    m, se = mean_ci(v)
    assert se == pytest.approx(0.01, rel=0.05)
    assert_within_ci(v, 2.0)
    with pytest.raises(AssertionError):
        assert_within_ci(v, 2.1)
    assert_within_ci(np.full(10, 3.0), 3.0)  # zero variance, exact


# --------------------------------------------------------------------------------- chi-square


def test_disk_concentric_chi2():
    p = chi2_test_2d(w.square_to_disk_concentric, w.square_to_disk_concentric_pdf, N, 24, 24,
                     bounds=((-1, 1), (-1, 1)), resolution=16)
    assert p > ALPHA


@pytest.mark.parametrize("blades,rotation", [(3, 0.0), (5, 0.4), (6, -1.0), (8, 2.0)])
def test_polygon_chi2(blades, rotation):
    p = chi2_test_2d(lambda u: w.square_to_polygon(u, blades, rotation),
                     lambda x: w.square_to_polygon_pdf(x, blades, rotation), N, 24, 24,
                     bounds=((-1, 1), (-1, 1)), resolution=16)
    assert p > ALPHA


def test_polygon_matches_cycles_convention():
    # Cycles: corners at angles rotation + (2k+1)π/N; an edge faces +x at rotation 0.
    corners = w.square_to_polygon(np.array([[0.0, 0.0], [0.2, 0.0]]), 5, 0.0)
    assert np.allclose(corners[0], [np.cos(np.pi / 5), np.sin(np.pi / 5)])
    assert np.allclose(corners[1], [np.cos(3 * np.pi / 5), np.sin(3 * np.pi / 5)])
    p = w.square_to_polygon(np.random.default_rng(0).random((50_000, 2)), 6, 0.0)
    assert p[:, 0].max() <= np.cos(np.pi / 6) + 1e-12  # the +x edge (apothem)
    assert np.hypot(p[:, 0], p[:, 1]).max() <= 1.0 + 1e-12
    assert w.polygon_area(4) == pytest.approx(2.0)
    with pytest.raises(ValueError):
        w.square_to_polygon(np.zeros((1, 2)), 2)


def test_cosine_hemisphere_chi2():
    assert chi2_test_sphere(w.square_to_cosine_hemisphere, w.square_to_cosine_hemisphere_pdf,
                            N, 16, 32, theta_max=np.pi / 2) > ALPHA


def test_uniform_hemisphere_chi2():
    assert chi2_test_sphere(w.square_to_uniform_hemisphere, w.square_to_uniform_hemisphere_pdf,
                            N, 16, 32, theta_max=np.pi / 2) > ALPHA


def test_uniform_sphere_chi2():
    assert chi2_test_sphere(w.square_to_uniform_sphere, w.square_to_uniform_sphere_pdf,
                            N, 20, 40) > ALPHA


@pytest.mark.parametrize("cos_max", [0.9, 0.0, -0.5])
def test_uniform_cone_chi2(cos_max):
    theta_max = float(np.arccos(cos_max))
    p = chi2_test_sphere(lambda u: w.square_to_uniform_cone(u, cos_max),
                         lambda d: w.square_to_uniform_cone_pdf(d, cos_max), N, 16, 32,
                         theta_max=theta_max, resolution=12)
    assert p > ALPHA


def test_triangle_chi2():
    p = chi2_test_2d(lambda u: np.stack(w.square_to_triangle(u), axis=-1),
                     lambda b: w.square_to_triangle_pdf(b[:, 0], b[:, 1]), N, 20, 20,
                     resolution=16)
    assert p > ALPHA


# --------------------------------------------------------------------------------- pdfs


@pytest.mark.parametrize("sampler,pdf,measure", [
    (w.square_to_cosine_hemisphere, w.square_to_cosine_hemisphere_pdf, 2 * np.pi),
    (w.square_to_uniform_hemisphere, w.square_to_uniform_hemisphere_pdf, 2 * np.pi),
    (w.square_to_uniform_sphere, w.square_to_uniform_sphere_pdf, 4 * np.pi),
])
def test_direction_pdfs_integrate_to_one(sampler, pdf, measure):
    # uniform-sphere estimator of ∫ pdf dω (importance sampling against 1/(4π))
    d = w.square_to_uniform_sphere(np.random.default_rng(1).random((200_000, 2)))
    assert_within_ci(pdf(d) * 4 * np.pi, 1.0)


def test_pdf_zero_outside_support():
    below = np.array([[0.0, 0.6, -0.8]])
    assert w.square_to_cosine_hemisphere_pdf(below)[0] == 0.0
    assert w.square_to_uniform_hemisphere_pdf(below)[0] == 0.0
    assert w.square_to_uniform_cone_pdf(below, 0.5)[0] == 0.0
    assert w.square_to_disk_concentric_pdf(np.array([[0.8, 0.7]]))[0] == 0.0
    assert w.square_to_polygon_pdf(np.array([[0.95, 0.0]]), 6)[0] == 0.0
    assert w.square_to_triangle_pdf(np.array([0.7]), np.array([0.4]))[0] == 0.0


def test_cone_per_sample_cos_and_tiny_cone():
    u = np.random.default_rng(2).random((1000, 2))
    cmax = np.linspace(-0.9, 0.999999, 1000)
    d = w.square_to_uniform_cone(u, cmax)
    assert np.all(d[:, 2] >= cmax - 1e-12)
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0)
    tiny = 1.0 - 1e-10  # sun-sized cone: directions still unit and inside
    d = w.square_to_uniform_cone(u, tiny)
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0) and np.all(d[:, 2] >= tiny - 1e-15)


def test_output_shapes_and_dtypes():
    u = np.random.default_rng(0).random((7, 2)).astype(np.float32)
    for f in (w.square_to_cosine_hemisphere, w.square_to_uniform_hemisphere,
              w.square_to_uniform_sphere, lambda x: w.square_to_uniform_cone(x, 0.5)):
        d = f(u)
        assert d.shape == (7, 3) and d.dtype == np.float64
        assert np.allclose(np.linalg.norm(d, axis=1), 1.0)
    assert w.square_to_disk_concentric(u).shape == (7, 2)
    b1, b2 = w.square_to_triangle(u)
    assert b1.shape == (7,) and b2.shape == (7,)


# --------------------------------------------------------------------------------- round trips

unit_square = arrays(np.float64, (64, 2), elements=st.floats(0.0, 1.0, exclude_max=True))

ROUND_TRIPS = {
    "disk": (w.square_to_disk_concentric, w.disk_concentric_to_square),
    "cosine": (w.square_to_cosine_hemisphere, w.cosine_hemisphere_to_square),
    "hemisphere": (w.square_to_uniform_hemisphere, w.uniform_hemisphere_to_square),
    "sphere": (w.square_to_uniform_sphere, w.uniform_sphere_to_square),
    "cone": (lambda u: w.square_to_uniform_cone(u, 0.3),
             lambda d: w.uniform_cone_to_square(d, 0.3)),
    "polygon": (lambda u: w.square_to_polygon(u, 7, 0.25),
                lambda p: w.polygon_to_square(p, 7, 0.25)),
    "triangle": (lambda u: np.stack(w.square_to_triangle(u), axis=-1),
                 lambda b: w.triangle_to_square(b[:, 0], b[:, 1])),
}


@pytest.mark.parametrize("name", sorted(ROUND_TRIPS))
@settings(max_examples=30, deadline=None, database=None)
@given(u=unit_square)
def test_round_trip(name, u):
    fwd, inv = ROUND_TRIPS[name]
    x = fwd(u)
    back = inv(x)
    assert np.all((back >= 0.0) & (back < 1.0))
    # compare in the warped domain: the inverse is ill-conditioned where the map collapses
    # (disk centre, poles, triangle apex), but fwd(inv(x)) must reproduce x
    assert np.allclose(fwd(back), x, atol=1e-7)
    # and away from those singular sets (square edges and centre lines, wedge boundaries of the
    # polygon) the samples themselves come back
    m = 1e-3
    regular = np.all((np.abs(u - 0.5) > m) & (u > m) & (u < 1 - m), axis=1)
    if name == "polygon":
        frac = u[:, 0] * 7 - np.floor(u[:, 0] * 7)
        regular &= (frac > m) & (frac < 1 - m)
    assert np.allclose(back[regular], u[regular], atol=1e-6)


def test_round_trip_dense_grid():
    g = (np.stack(np.meshgrid(np.arange(64), np.arange(64), indexing="ij"), -1).reshape(-1, 2)
         + 0.37) / 64
    for name, (fwd, inv) in ROUND_TRIPS.items():
        assert np.allclose(inv(fwd(g)), g, atol=1e-9), name


# --------------------------------------------------------------------------------- frames


@settings(max_examples=50, deadline=None, database=None)
@given(u=unit_square)
def test_build_frame_orthonormal(u):
    n = w.square_to_uniform_sphere(u)
    n = np.concatenate([n, [[0, 0, 1.0], [0, 0, -1.0], [1.0, 0, 0], [0, 0, -0.0]]])
    n[-1] = [0.0, 1.0, -0.0]
    t, b = w.build_frame(n)
    for v in (t, b):
        assert np.allclose(np.linalg.norm(v, axis=1), 1.0)
    assert np.allclose(np.sum(t * b, axis=1), 0.0, atol=1e-12)
    assert np.allclose(np.sum(t * n, axis=1), 0.0, atol=1e-12)
    assert np.allclose(np.cross(t, b), n)  # right-handed


def test_to_local_to_world_inverse():
    rng = np.random.default_rng(5)
    n = w.square_to_uniform_sphere(rng.random((500, 2)))
    v = rng.normal(size=(500, 3))
    t, b = w.build_frame(n)
    loc = w.to_local(v, t, b, n)
    assert np.allclose(w.to_world(loc, t, b, n), v)
    assert np.allclose(w.to_local(n, t, b, n), [0.0, 0.0, 1.0])
    assert np.allclose(loc[:, 2], np.sum(v * n, axis=1))


def test_cosine_sampling_in_world_frame():
    # local samples mapped by the frame follow max(n·d, 0)/π around a tilted normal
    normal = np.array([0.3, -0.5, 0.81])
    normal /= np.linalg.norm(normal)

    def sample(u):
        nn = np.broadcast_to(normal, (len(u), 3))
        t, b = w.build_frame(nn)
        return w.to_world(w.square_to_cosine_hemisphere(u), t, b, nn)

    assert chi2_test_sphere(sample, lambda d: np.maximum(d @ normal, 0) / np.pi, N, 16,
                            32) > ALPHA


# --------------------------------------------------------------------------------- midpoint


def test_hemisphere_midpoint_grid():
    dirs, wts = w.hemisphere_midpoint_grid(8, 16)
    assert dirs.shape == (128, 3) and wts.shape == (128,)
    assert np.allclose(np.linalg.norm(dirs, axis=1), 1.0) and np.all(dirs[:, 2] > 0)
    # first cell: θ = Δθ/2, φ = Δφ/2; weight sinθ ΔθΔφ
    dth, dph = np.pi / 2 / 8, 2 * np.pi / 16
    assert np.allclose(dirs[0], [np.sin(dth / 2) * np.cos(dph / 2),
                                 np.sin(dth / 2) * np.sin(dph / 2), np.cos(dth / 2)])
    assert wts[0] == pytest.approx(np.sin(dth / 2) * dth * dph)
    # midpoint rule is second order: ∫cos θ dω = π, ∫ dω = 2π
    errs = []
    for m in (8, 16, 32):
        dirs, wts = w.hemisphere_midpoint_grid(m, 2 * m)
        errs.append(abs(np.sum(dirs[:, 2] * wts) - np.pi))
        assert np.sum(wts) == pytest.approx(2 * np.pi, rel=2e-3)
    assert errs[1] < errs[0] / 3.5 and errs[2] < errs[1] / 3.5
