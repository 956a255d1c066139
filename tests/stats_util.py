"""Statistical helpers shared by the test suite (no scipy).

Import from a test module as ``from stats_util import ...`` (pytest puts ``tests/`` on sys.path).

Chi-square goodness-of-fit tests in the style of Mitsuba 3's ``chi2.py``:

* ``chi2_test_sphere(sample_fn, pdf_fn, n_samples, bins_theta, bins_phi, ...)`` for *directions*
  (unit vectors, z-up, pdf per unit **solid angle**), binned in spherical coordinates
  (theta from +z in [0, theta_max], phi = atan2(y, x) in [0, 2 pi)).
* ``chi2_test_2d(sample_fn, pdf_fn, n_samples, bins_x, bins_y, bounds=...)`` for *points* in a
  rectangle (pdf per unit **area**).  If ``sample_fn`` returns (n, 3) vectors it forwards to
  ``chi2_test_sphere`` (bins_x -> theta, bins_y -> phi), so either name works for directions.

Both draw ``u = rng.random((n_samples, sample_dim))`` with a fixed seed, call ``sample_fn(u)``,
histogram the result and compare with the expected counts ``n_samples * integral of pdf over the
bin`` (midpoint rule on a ``resolution x resolution`` sub-grid per bin, ``refine`` times finer in
cells on the edge of the pdf's support).  ``sample_fn`` may return
either the samples, or ``(samples, valid)`` with ``valid`` an (n,) bool mask; non-finite or zero
rows also count as invalid.  Invalid samples are simply not counted (as in Mitsuba), so a pdf that
integrates to less than one (energy lost, e.g. below the horizon) is tested correctly.

Cells with expected count < ``min_expected`` (5) are pooled, smallest first, exactly like Mitsuba;
an observed sample in a cell with zero expected count fails the test (p = 0).  The functions
return the p-value (a float); pass ``return_details=True`` for a ``Chi2Result``.
Typical use: ``assert chi2_test_sphere(...) > 0.01``.

Monte-Carlo estimate checks: ``mean_ci(values) -> (mean, standard_error)`` and
``assert_within_ci(estimate_samples, expected, k=4)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

__all__ = [
    "Chi2Result",
    "chi2_sf",
    "chi2_pvalue",
    "chi2_test_sphere",
    "chi2_test_directions",
    "chi2_test_2d",
    "sidak_alpha",
    "mean_ci",
    "assert_within_ci",
]

# --------------------------------------------------------------------------------------------
# chi-square distribution
# --------------------------------------------------------------------------------------------

_EPS = 1e-15
_FPMIN = 1e-300


def _gamma_p_series(a: float, x: float) -> float:
    """Regularized lower incomplete gamma P(a, x) by its power series (good for x < a + 1)."""
    term = 1.0 / a
    total = term
    ap = a
    for _ in range(100000):
        ap += 1.0
        term *= x / ap
        total += term
        if abs(term) < abs(total) * _EPS:
            break
    return total * math.exp(-x + a * math.log(x) - math.lgamma(a))


def _gamma_q_cf(a: float, x: float) -> float:
    """Regularized upper incomplete gamma Q(a, x) by Lentz's continued fraction (x >= a + 1)."""
    b = x + 1.0 - a
    c = 1.0 / _FPMIN
    d = 1.0 / b
    h = d
    for i in range(1, 100000):
        an = -i * (i - a)
        b += 2.0
        d = an * d + b
        if abs(d) < _FPMIN:
            d = _FPMIN
        c = b + an / c
        if abs(c) < _FPMIN:
            c = _FPMIN
        d = 1.0 / d
        delta = d * c
        h *= delta
        if abs(delta - 1.0) < _EPS:
            break
    return math.exp(-x + a * math.log(x) - math.lgamma(a)) * h


def gamma_q(a: float, x: float) -> float:
    """Regularized upper incomplete gamma function Q(a, x) = Gamma(a, x) / Gamma(a), a > 0."""
    if a <= 0:
        raise ValueError("gamma_q needs a > 0")
    if x <= 0:
        return 1.0
    if x < a + 1.0:
        return max(0.0, 1.0 - _gamma_p_series(a, x))
    return min(1.0, _gamma_q_cf(a, x))


def chi2_sf(x: float, dof: int | float) -> float:
    """Survival function 1 - CDF of the chi-square distribution with ``dof`` degrees of freedom."""
    if dof <= 0:
        raise ValueError("chi2_sf needs dof > 0")
    return gamma_q(0.5 * dof, 0.5 * x)


def sidak_alpha(alpha: float, n_tests: int) -> float:
    """Per-test significance that keeps the family-wise rate at ``alpha`` over ``n_tests`` tests."""
    return 1.0 - (1.0 - alpha) ** (1.0 / n_tests)


@dataclass
class Chi2Result:
    """Outcome of a chi-square test.

    p_value: float (0 when a sample fell in a cell with zero expected count);
    statistic, dof: Pearson statistic after pooling and its degrees of freedom;
    observed, expected: the un-pooled histograms (float64, shape of the binning);
    n_valid: samples counted; pdf_integral: integral of the pdf over the whole domain (≈ 1 for a
    normalized pdf; ≈ n_valid / n_samples when the sampler drops samples consistently);
    message: why it failed, if it did.
    """

    p_value: float
    statistic: float
    dof: int
    observed: np.ndarray
    expected: np.ndarray
    n_valid: int
    n_samples: int
    pdf_integral: float
    message: str = ""
    extra: dict = field(default_factory=dict)


def chi2_pvalue(observed, expected, min_expected: float = 5.0) -> tuple[float, float, int, str]:
    """Pearson chi-square with Mitsuba's pooling of low-expected cells.

    observed, expected: arrays of the same size (any shape; flattened).  Cells are visited in
    increasing order of expected count; cells with expected < ``min_expected`` are pooled into one
    cell (and further cells join the pool while it is still below ``min_expected``).
    Returns (p_value, statistic, dof, message).  A cell with zero expected count but observed
    samples (more than 1e-5 of the total) gives p = 0.
    """
    obs = np.asarray(observed, dtype=np.float64).ravel()
    exp = np.asarray(expected, dtype=np.float64).ravel()
    if obs.shape != exp.shape:
        raise ValueError("observed and expected must have the same size")
    total = max(obs.sum(), 1.0)
    order = np.argsort(exp, kind="stable")
    chsq = 0.0
    dof = 0
    pooled_obs = 0.0
    pooled_exp = 0.0
    for i in order:
        o, e = obs[i], exp[i]
        if e <= 0.0:
            if o > total * 1e-5:
                return 0.0, math.inf, 0, (
                    f"{int(o)} samples in a cell with zero expected count (flat index {i})")
            continue
        if e < min_expected or (0.0 < pooled_exp < min_expected):
            pooled_obs += o
            pooled_exp += e
        else:
            chsq += (o - e) ** 2 / e
            dof += 1
    if pooled_exp > 0.0:
        chsq += (pooled_obs - pooled_exp) ** 2 / pooled_exp
        dof += 1
    elif pooled_obs > 0.0:
        return 0.0, math.inf, 0, "samples in pooled cells with zero expected count"
    dof -= 1
    if dof < 1:
        return 0.0, chsq, dof, "too few cells with enough expected samples (dof < 1)"
    return chi2_sf(chsq, dof), chsq, dof, ""


# --------------------------------------------------------------------------------------------
# sampling helpers
# --------------------------------------------------------------------------------------------


def _draw(sample_fn: Callable, n_samples: int, sample_dim: int, seed: int):
    rng = np.random.default_rng(seed)
    u = rng.random((n_samples, sample_dim))
    out = sample_fn(u)
    if isinstance(out, tuple):
        x, valid = out
        x = np.asarray(x, dtype=np.float64)
        valid = np.asarray(valid, dtype=bool).reshape(-1)
    else:
        x = np.asarray(out, dtype=np.float64)
        valid = np.ones(x.shape[0], dtype=bool)
    if x.ndim != 2 or x.shape[0] != n_samples:
        raise ValueError(f"sample_fn must return (n, k) samples, got shape {x.shape}")
    valid &= np.all(np.isfinite(x), axis=1)
    valid &= np.any(x != 0.0, axis=1)
    return x, valid


def _integrate_grid(density, lo0, hi0, lo1, hi1, bins0, bins1, resolution, refine,
                    chunk=1 << 18):
    """(bins0, bins1) integrals of ``density(x0, x1)`` (flat arrays in, flat array out, per unit
    dx0·dx1) over equal cells of [lo0, hi0] × [lo1, hi1], by the midpoint rule on a
    ``resolution²`` sub-grid per cell.

    Cells on the edge of the density's support (a zero sub-sample with a non-zero one in the cell
    or in a neighbouring cell) are integrated again on a ``(resolution·refine)²`` sub-grid: a
    discontinuous pdf (disk, polygon, cone edge) would otherwise give thin slivers of support an
    expected count of zero, or a biased one.
    """
    h0 = (hi0 - lo0) / bins0
    h1 = (hi1 - lo1) / bins1

    def cells(i0, i1, res):
        # integrals over the cells (i0[k], i1[k]) with a res × res midpoint grid each
        off = (np.arange(res) + 0.5) / res
        out = np.empty(i0.size)
        zero = np.empty(i0.size, dtype=bool)
        nonzero = np.empty(i0.size, dtype=bool)
        per = max(1, chunk // (res * res))
        for s in range(0, i0.size, per):  # chunks of cells, not samples
            a = (lo0 + (i0[s:s + per, None, None] + off[None, :, None]) * h0)
            b = (lo1 + (i1[s:s + per, None, None] + off[None, None, :]) * h1)
            a, b = np.broadcast_arrays(a, b)
            f = np.asarray(density(a.ravel(), b.ravel()), dtype=np.float64).reshape(a.shape)
            f = np.where(np.isfinite(f), f, 0.0)
            out[s:s + per] = f.sum(axis=(1, 2)) * (h0 * h1) / (res * res)
            zero[s:s + per] = np.any(f == 0.0, axis=(1, 2))
            nonzero[s:s + per] = np.any(f != 0.0, axis=(1, 2))
        return out, zero, nonzero

    g0, g1 = np.meshgrid(np.arange(bins0), np.arange(bins1), indexing="ij")
    integ, zero, nonzero = cells(g0.ravel(), g1.ravel(), resolution)
    integ = integ.reshape(bins0, bins1)
    zero = zero.reshape(bins0, bins1)
    nz = np.pad(nonzero.reshape(bins0, bins1), 1)
    near_support = np.zeros((bins0, bins1), dtype=bool)
    for d0 in (0, 1, 2):
        for d1 in (0, 1, 2):
            near_support |= nz[d0:d0 + bins0, d1:d1 + bins1]
    edge = zero & near_support
    if refine > 1 and np.any(edge):
        e0, e1 = np.nonzero(edge)
        integ[e0, e1] = cells(e0, e1, resolution * refine)[0]
    return integ


def _sph_dirs(theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
    st = np.sin(theta)
    return np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)], axis=-1)


def _integrate_sphere(pdf_fn, th_lo, th_hi, bins_theta, bins_phi, resolution, refine):
    """(bins_theta, bins_phi) integrals of pdf(d) dω = pdf sinθ dθ dφ over theta/phi cells."""
    def density(th, ph):
        return np.asarray(pdf_fn(_sph_dirs(th, ph)), dtype=np.float64).reshape(-1) * np.sin(th)
    return _integrate_grid(density, th_lo, th_hi, 0.0, 2.0 * np.pi, bins_theta, bins_phi,
                           resolution, refine)


def chi2_test_sphere(sample_fn: Callable, pdf_fn: Callable, n_samples: int = 200_000,
                     bins_theta: int = 20, bins_phi: int = 40, *, theta_max: float = np.pi,
                     sample_dim: int = 2, seed: int = 0, resolution: int = 8, refine: int = 8,
                     min_expected: float = 5.0, return_details: bool = False):
    """Chi-square test of a direction sampler against its solid-angle pdf.

    sample_fn(u) -> (n, 3) unit vectors (z-up; optionally ``(dirs, valid)``), u: (n, sample_dim)
    float64 uniform in [0, 1).  pdf_fn(d) -> (m,) pdf per unit solid angle for d: (m, 3) unit
    vectors.  Bins: ``bins_theta`` equal steps of theta in [0, theta_max] (theta measured from +z)
    times ``bins_phi`` equal steps of phi = atan2(y, x) in [0, 2 pi).  With theta_max < pi the
    rest of the sphere is one extra cell (its expected count integrated the same way), so a
    hemisphere sampler that leaks below the horizon fails.
    Returns the p-value, or a ``Chi2Result`` if ``return_details``.
    Raises ValueError if a valid sample is not unit length (|1 - |d|| > 1e-3).
    """
    d, valid = _draw(sample_fn, n_samples, sample_dim, seed)
    if d.shape[1] != 3:
        raise ValueError(f"directions must be (n, 3), got {d.shape}")
    d = d[valid]
    norms = np.linalg.norm(d, axis=1)
    if d.shape[0] and np.max(np.abs(norms - 1.0)) > 1e-3:
        raise ValueError(f"sampled directions are not unit vectors (max |1-|d|| = "
                         f"{np.max(np.abs(norms - 1.0)):.3g})")
    d = d / norms[:, None]
    theta = np.arccos(np.clip(d[:, 2], -1.0, 1.0))
    phi = np.mod(np.arctan2(d[:, 1], d[:, 0]), 2.0 * np.pi)
    inside = theta <= theta_max
    ti = np.minimum((theta[inside] / theta_max * bins_theta).astype(np.int64), bins_theta - 1)
    pj = np.minimum((phi[inside] / (2 * np.pi) * bins_phi).astype(np.int64), bins_phi - 1)
    observed = np.zeros((bins_theta, bins_phi))
    np.add.at(observed, (ti, pj), 1.0)
    integ = _integrate_sphere(pdf_fn, 0.0, theta_max, bins_theta, bins_phi, resolution, refine)
    expected = integ * n_samples
    obs_cells = [observed.ravel()]
    exp_cells = [expected.ravel()]
    total_integral = float(integ.sum())
    if theta_max < np.pi:
        out_int = float(_integrate_sphere(pdf_fn, theta_max, np.pi, bins_theta, bins_phi,
                                          resolution, refine).sum())
        total_integral += out_int
        obs_cells.append(np.array([float(np.count_nonzero(~inside))]))
        exp_cells.append(np.array([out_int * n_samples]))
    p, stat, dof, msg = chi2_pvalue(np.concatenate(obs_cells), np.concatenate(exp_cells),
                                    min_expected)
    if not return_details:
        return p
    return Chi2Result(p, stat, dof, observed, expected, int(valid.sum()), n_samples,
                      total_integral, msg)


chi2_test_directions = chi2_test_sphere


def chi2_test_2d(sample_fn: Callable, pdf_fn: Callable, n_samples: int = 200_000,
                 bins_x: int = 32, bins_y: int = 32, *,
                 bounds=((0.0, 1.0), (0.0, 1.0)), sample_dim: int = 2, seed: int = 0,
                 resolution: int = 8, refine: int = 8, min_expected: float = 5.0,
                 return_details: bool = False, **sphere_kwargs):
    """Chi-square test of a 2-D point sampler against its pdf per unit area.

    sample_fn(u) -> (n, 2) points (optionally ``(points, valid)``), u: (n, sample_dim) uniform.
    pdf_fn(p) -> (m,) density per unit area for p: (m, 2).  The rectangle
    ``bounds = ((x0, x1), (y0, y1))`` (half-open) is split into bins_x × bins_y equal cells; it
    must contain the pdf's support: a point outside it fails the test (p = 0).
    If sample_fn returns (n, 3) vectors, this forwards to ``chi2_test_sphere`` with
    bins_theta = bins_x, bins_phi = bins_y (``bounds`` ignored; pass ``theta_max=`` if needed).
    Returns the p-value, or a ``Chi2Result`` if ``return_details``.
    """
    x, valid = _draw(sample_fn, n_samples, sample_dim, seed)
    if x.shape[1] == 3:
        return chi2_test_sphere(lambda _u: (x, valid), pdf_fn, n_samples, bins_x, bins_y,
                                sample_dim=sample_dim, seed=seed, resolution=resolution,
                                refine=refine, min_expected=min_expected,
                                return_details=return_details,
                                **sphere_kwargs)
    if x.shape[1] != 2:
        raise ValueError(f"points must be (n, 2), got {x.shape}")
    # zero rows are legitimate points in 2-D: only non-finite / flagged rows are invalid here
    finite = np.all(np.isfinite(x), axis=1)
    (x0, x1), (y0, y1) = bounds
    pts = x[_valid_2d(x, valid, finite)]
    inside = (pts[:, 0] >= x0) & (pts[:, 0] < x1) & (pts[:, 1] >= y0) & (pts[:, 1] < y1)
    pi = pts[inside]
    ix = np.clip(((pi[:, 0] - x0) / (x1 - x0) * bins_x).astype(np.int64), 0, bins_x - 1)
    iy = np.clip(((pi[:, 1] - y0) / (y1 - y0) * bins_y).astype(np.int64), 0, bins_y - 1)
    observed = np.zeros((bins_x, bins_y))
    np.add.at(observed, (ix, iy), 1.0)
    integ = _integrate_grid(
        lambda a, b: np.asarray(pdf_fn(np.stack([a, b], axis=1)), dtype=np.float64).reshape(-1),
        x0, x1, y0, y1, bins_x, bins_y, resolution, refine)
    expected = integ * n_samples
    total_integral = float(integ.sum())
    out_exp = 0.0  # bounds must contain the support: any point outside fails the test
    obs_all = np.concatenate([observed.ravel(), [float(np.count_nonzero(~inside))]])
    exp_all = np.concatenate([expected.ravel(), [out_exp]])
    pv, stat, dof, msg = chi2_pvalue(obs_all, exp_all, min_expected)
    if not return_details:
        return pv
    return Chi2Result(pv, stat, dof, observed, expected, int(pts.shape[0]), n_samples,
                      total_integral, msg)


def _valid_2d(x: np.ndarray, valid: np.ndarray, finite: np.ndarray) -> np.ndarray:
    # _draw marked all-zero rows invalid (right for directions); for points keep them unless the
    # sampler flagged them or they are non-finite.
    zero_rows = ~np.any(x != 0.0, axis=1)
    return (valid | (zero_rows & finite)) & finite


# --------------------------------------------------------------------------------------------
# Monte-Carlo estimates
# --------------------------------------------------------------------------------------------


def mean_ci(values) -> tuple:
    """Sample mean and its standard error along axis 0.

    values: (n,) or (n, ...) array of i.i.d. per-sample estimates.
    Returns (mean, standard_error) (floats for 1-D input, arrays otherwise); the standard error
    uses the unbiased variance, std(ddof=1) / sqrt(n).
    """
    v = np.asarray(values, dtype=np.float64)
    n = v.shape[0]
    if n < 2:
        raise ValueError("mean_ci needs at least two samples")
    mean = v.mean(axis=0)
    se = v.std(axis=0, ddof=1) / math.sqrt(n)
    if v.ndim == 1:
        return float(mean), float(se)
    return mean, se


def assert_within_ci(estimate_samples, expected, k: float = 4.0, atol: float = 1e-12,
                     label: str = "") -> None:
    """Assert |mean(estimate_samples) − expected| ≤ k · standard error (+ atol), per component.

    estimate_samples: (n,) or (n, ...) per-sample estimates (e.g. f(x)/pdf(x)); expected: scalar or
    broadcastable to the trailing shape.  ``atol`` covers zero-variance estimators.
    """
    mean, se = mean_ci(estimate_samples)
    mean = np.asarray(mean)
    se = np.asarray(se)
    exp = np.asarray(expected, dtype=np.float64)
    err = np.abs(mean - exp)
    tol = k * se + atol * np.maximum(1.0, np.abs(exp))
    if not np.all(err <= tol):
        raise AssertionError(
            f"{label + ': ' if label else ''}MC mean {mean} differs from expected {exp} by {err}, "
            f"more than {k} standard errors ({se}) ")


def refractable(wo, dirs, ior):
    """(m,) bool: wi = dirs reflects, or refracts through some microfacet of a glass of ``ior``
    seen from wo (local frame; Walter et al.: wo in front of h ∝ ±(wo + η wi), wi behind it).
    A glass lobe's ``eval`` also transmits between the other pairs, as Cycles's does
    (drt.materials.dielectric); sampling reaches only these."""
    wo = np.asarray(wo, float)
    flip = wo[2] < 0
    eta = 1.0 / ior if flip else ior
    s = np.array([1.0, 1.0, -1.0 if flip else 1.0])
    wo_u = wo * s
    wi_u = np.asarray(dirs, float) * s
    h = wo_u + eta * wi_u
    h *= np.where(h[:, 2:3] < 0, -1.0, 1.0)
    return (wi_u[:, 2] > 0) | ((h @ wo_u > 0) & (np.einsum("ij,ij->i", h, wi_u) < 0))


def material_chi_square(table, mat: int, wo: np.ndarray, n: int, rng, z_lo: float = 0.0,
                        bins_z: int = 10, bins_phi: int = 20, refine: int = 48, coat_normal=None,
                        reachable=None):
    """Chi-square of a MaterialTable material's sampled directions against its own eval pdf.

    ``wo`` (n, 3) local-frame outgoing directions (all equal); cells are uniform in cos θ over
    [z_lo, 1] (0: the upper hemisphere; −1: the whole sphere, for transmission) × φ, expected
    counts from ``eval``'s pdf averaged over ``refine``² points per cell (dω = dz dφ).
    Returns (p-value, fraction of samples valid, expected mass in the grid, observed mass in
    the cells too small to test). ``coat_normal``: passed to the table's sample and eval;
    ``reachable``: dirs (m, 3) → (m,) bool, the directions sampling can reach (``refractable``
    for a glass lobe), the pdf counted there only."""
    s = table.sample(np.full(n, mat), wo, rng.random(n), rng.random((n, 2)), coat_normal=coat_normal)
    wi = s.wi[s.valid]
    span = 1.0 - z_lo
    iz = np.clip(((wi[:, 2] - z_lo) / span * bins_z).astype(int), 0, bins_z - 1)
    ip = ((np.arctan2(wi[:, 1], wi[:, 0]) + np.pi) / (2 * np.pi) * bins_phi).astype(int) % bins_phi
    obs = np.bincount(iz * bins_phi + ip, minlength=bins_z * bins_phi)
    zz = z_lo + (np.arange(bins_z * refine) + 0.5) / (bins_z * refine) * span
    pp = (np.arange(bins_phi * refine) + 0.5) / (bins_phi * refine) * 2 * np.pi - np.pi
    Z, P = np.meshgrid(zz, pp, indexing="ij")
    r = np.sqrt(1 - Z * Z)
    dirs = np.stack([r * np.cos(P), r * np.sin(P), Z], -1).reshape(-1, 3)
    _, pdf = table.eval(np.full(len(dirs), mat), np.tile(wo[0], (len(dirs), 1)), dirs, coat_normal=coat_normal)
    if reachable is not None:
        pdf = pdf * reachable(dirs)
    cell = pdf.reshape(bins_z, refine, bins_phi, refine).mean(axis=(1, 3)) * (span / bins_z) \
        * (2 * np.pi / bins_phi)
    exp = cell.ravel() * n
    keep = exp > 20
    stat = ((obs[keep] - exp[keep]) ** 2 / exp[keep]).sum()
    return chi2_sf(stat, keep.sum() - 1), s.valid.mean(), exp.sum() / n, obs[~keep].sum() / n
