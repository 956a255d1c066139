"""The lecture's direct-light estimators (drt.estimators) against closed forms.

Unbiasedness: every random estimator's mean lies within 4 standard errors of Lambert's polygon
formula (irradiance under a rectangle) and of a white-furnace value, for several seeds and
sample generators. The midpoint rule is deterministic: its error shrinks as the grid refines.
Convergence: RMSE over independent points against N, fitted on log-log axes.
"""

import math

import numpy as np
import pytest

from drt.estimators import METHODS, DirectLight, ShadingPoints, midpoint_grid_shape, polygon_irradiance, theta_phi_cells
from drt.lights import LightSet
from drt.materials import MaterialTable
from scene_builders import translation

RANDOM_METHODS = [m for m in METHODS if m != "MIDPOINT"]
ALBEDO = 0.8
LUM = np.array([0.2126, 0.7152, 0.0722])


def _materials():
    return MaterialTable.from_scene([{"name": "white", "lobes": [{"type": "DIFFUSE", "color": [ALBEDO] * 3}],
                                      "emission": [0, 0, 0]}])


def rectangle_setup(n_points=64):
    """A 1 × 0.5 m rectangle light (100 W), offset from a diffuse point's normal."""
    power, size_x, size_y, cx, d = 100.0, 1.0, 0.5, 0.3, 2.0
    light = {"type": "AREA", "matrix_world": translation(cx, 0, d), "color": [1, 1, 1], "power": power,
             "shape": "RECTANGLE", "size": size_x, "size_y": size_y}
    L = power / (math.pi * size_x * size_y)
    corners = [(cx + sx * size_x / 2, sy * size_y / 2, d) for sx, sy in [(-1, -1), (1, -1), (1, 1), (-1, 1)]]
    expected = ALBEDO / math.pi * polygon_irradiance(L, corners)
    pts = ShadingPoints(np.zeros((n_points, 3)), (0, 0, 1), (0.0, -0.6, 0.8), 0)
    return DirectLight(LightSet([light]), _materials()), pts, expected


def furnace_setup(n_points=64):
    """A diffuse point under a constant white world: reflected radiance = albedo."""
    pts = ShadingPoints(np.zeros((n_points, 3)), (0, 0, 1), (0.0, 0.6, 0.8), 0)
    return DirectLight(LightSet([], (1.0, 1.0, 1.0)), _materials()), pts, ALBEDO


def assert_unbiased(samples, expected, k=4.0):
    per_point = samples @ LUM  # (n, K): every point is an independent estimate
    est = per_point.mean(axis=1)
    mean = est.mean()
    se = est.std(ddof=1) / math.sqrt(len(est))
    assert abs(mean - expected) <= k * se + 1e-9 * expected, f"mean {mean:.6g} vs {expected:.6g} (se {se:.2g})"


@pytest.mark.parametrize("method", RANDOM_METHODS)
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_unbiased_under_a_rectangle(method, seed):
    dl, pts, expected = rectangle_setup()
    assert_unbiased(dl.direct_samples(method, pts, 64, seed=seed), expected)


@pytest.mark.parametrize("method", RANDOM_METHODS)
@pytest.mark.parametrize("sampler", ["STRATIFIED", "SOBOL"])
def test_unbiased_with_every_sample_generator(method, sampler):
    dl, pts, expected = rectangle_setup()
    assert_unbiased(dl.direct_samples(method, pts, 16, sampler=sampler, seed=3), expected)


@pytest.mark.parametrize("method", RANDOM_METHODS)
@pytest.mark.parametrize("seed", [0, 1])
def test_unbiased_in_a_furnace(method, seed):
    dl, pts, expected = furnace_setup()
    assert_unbiased(dl.direct_samples(method, pts, 64, seed=seed), expected)


def test_cosine_and_light_sampling_are_exact_in_a_furnace():
    """Cosine-weighted directions (and cosine-weighted world sampling) cancel a Lambert
    integrand exactly: zero variance."""
    dl, pts, expected = furnace_setup(4)
    for method in ("COSINE", "BSDF", "LIGHT"):
        s = dl.direct_samples(method, pts, 32) @ LUM
        assert np.allclose(s, expected, rtol=1e-12), method


def test_midpoint_rule_converges():
    """The rule is biased for a finite grid and, on a light with sharp edges, its error jumps
    around as cells fall in or out of the light (the structured error the lecture randomizes
    away); it still shrinks roughly as 1/M."""
    dl, pts, expected = rectangle_setup(1)
    errors = {}
    for m in (4, 8, 16, 32, 64, 128, 256):
        est = dl.estimate_direct("MIDPOINT", pts, 0, grid=(m, 4 * m)) @ LUM
        errors[m] = abs(est[0] - expected) / expected
    assert max(errors[64], errors[128], errors[256]) < 0.01 and errors[256] < 0.003, errors
    assert errors[8] > 0.1, errors  # coarse grids alias badly
    # furnace: the rule integrates cos θ sin θ to O(1/M²)
    dl, pts, expected = furnace_setup(1)
    est = dl.estimate_direct("MIDPOINT", pts, 0, grid=(16, 64)) @ LUM
    assert abs(est[0] - expected) < 2e-3


def test_theta_phi_cells_cover_the_hemisphere():
    dirs, w = theta_phi_cells(6, 24)
    assert dirs.shape == (144, 3) and np.isclose(w.sum(), 2 * math.pi, rtol=1e-2)
    assert np.allclose(np.linalg.norm(dirs, axis=1), 1.0) and np.all(dirs[:, 2] > 0)
    assert midpoint_grid_shape(64) == (4, 16)


def test_unknown_method_is_rejected():
    dl, pts, _ = furnace_setup(1)
    with pytest.raises(ValueError, match="unknown estimator"):
        dl.direct_samples("NOPE", pts, 4)


# ---------------------------------------------------------------------------------- convergence


def rmse_slope(dl, pts, expected, method, sampler, counts):
    errs = []
    for n in counts:
        est = dl.estimate_direct(method, pts, n, sampler=sampler, seed=11) @ LUM
        errs.append(math.sqrt(np.mean((est - expected) ** 2)))
    slope = np.polyfit(np.log(counts), np.log(errs), 1)[0]
    return slope, errs


COUNTS = [4, 16, 64, 256, 1024]


def test_random_sampling_converges_as_inverse_square_root():
    dl, pts, expected = rectangle_setup(256)
    slope, errs = rmse_slope(dl, pts, expected, "LIGHT", "RANDOM", COUNTS)
    assert -0.6 < slope < -0.4, (slope, errs)


@pytest.mark.parametrize("sampler", ["STRATIFIED", "SOBOL"])
def test_stratified_and_low_discrepancy_converge_faster_on_smooth_direct_light(sampler):
    """Light sampling of a rectangle by solid angle leaves a smooth integrand (f cos θ L Ω):
    jittered strata give RMSE ~ N^-1, Owen-scrambled Sobol ~ N^-1.5 (Owen 1997)."""
    dl, pts, expected = rectangle_setup(256)
    slope, errs = rmse_slope(dl, pts, expected, "LIGHT", sampler, COUNTS)
    assert slope < -0.85, (slope, errs)


def test_lecture_stratification_helps_with_a_discontinuity():
    """The lecture's jittered (θ, φ) cells on the same light seen by uniform directions: the
    light's edge is a discontinuity, so the gain is smaller (~N^-0.75) but still beats N^-0.5."""
    dl, pts, expected = rectangle_setup(256)
    slope_u, _ = rmse_slope(dl, pts, expected, "UNIFORM", "RANDOM", COUNTS)
    slope_s, errs = rmse_slope(dl, pts, expected, "STRATIFIED", "RANDOM", [16, 64, 256, 1024])
    assert -0.6 < slope_u < -0.4
    assert slope_s < -0.65, (slope_s, errs)
