"""Importance sampling of the pixel filter (Blackman-Harris, Gaussian, box), Cycles's way.

Cycles does not weight samples by the filter: it draws each sample's position inside the filter
footprint with density ∝ the filter (separably in x and y, from a tabulated inverse CDF) and gives
every sample weight 1.  A pixel's value is then the plain average of its samples, and an edge
spreads into neighbouring pixels exactly as the filter says.

Filters and widths match ``intern/cycles/scene/film.cpp`` (``filter_func_*`` and the width
scaling in ``filter_table``, which tabulates |x| in [0, width'/2]), with ``width`` = Blender's
``filter_width`` in pixels:

* BLACKMAN_HARRIS: width' = 2w; f(x) = 0.35875 − 0.48829 cos v + 0.14128 cos 2v − 0.01168 cos 3v,
  v = 2π(x/width' + ½).  Support ±w (3 px across for the default 1.5), peak at 0.
* GAUSSIAN: width' = 3w; f(x) = exp(−2(6x/width')²) = exp(−8x²/w²), i.e. σ = w/4; support ±1.5w.
* BOX: f = 1 on ±w/2.

Offsets are in pixels from the pixel centre, x to the right and y up (the continuous pixel
convention of ``docs/architecture.md``); the filter is symmetric so the sign convention of y
does not matter.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from ..kernels import inline_kernel, kernel

__all__ = ["PixelFilter", "FilterData", "FILTER_KINDS", "filter_sample", "filter_sample_1d"]

FILTER_KINDS = ("BLACKMAN_HARRIS", "GAUSSIAN", "BOX")
KIND_BLACKMAN_HARRIS, KIND_GAUSSIAN, KIND_BOX = 0, 1, 2  # FilterData.kind

FilterData = namedtuple("FilterData", ["kind", "width", "radius", "cdf", "edges", "guide"])
FilterData.__doc__ = """The pixel filter for the kernels: kind (int64: 0 BLACKMAN_HARRIS, 1 GAUSSIAN,
2 BOX), width and radius (float64, px), and the tabulated forward CDF: cdf (m + 1,) float64 at the
cell edges (m + 1,) float64 (px) of [−radius, radius]; guide (G,) int64: for u in [k/G, (k+1)/G)
the search for u's cell starts at guide[k], the last edge j with cdf[j] ≤ k/G (a few steps
instead of a binary search over the m cells)."""

#: guide-table entries (≈ the number of CDF cells: the walk from a guide entry is a step or two)
GUIDE_SIZE = 4096


def _guide_table(cdf: np.ndarray, size: int = GUIDE_SIZE) -> np.ndarray:
    """(size,) int64: the last j with cdf[j] ≤ k/size, for each k (0 where none is)."""
    k = np.arange(size, dtype=np.float64) / size
    return np.maximum(np.searchsorted(cdf, k, side="right") - 1, 0).astype(np.int64)


@kernel
def _interp_cell(x, xp, fp, j):
    """np.interp's value at x in cell j (xp[j] ≤ x, j the last such), with its NaN fallbacks."""
    if j == xp.shape[0] - 1 or xp[j] == x:
        return fp[j]
    slope = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j])
    r = slope * (x - xp[j]) + fp[j]
    if r != r:
        r = slope * (x - xp[j + 1]) + fp[j + 1]
        if r != r and fp[j] == fp[j + 1]:
            r = fp[j]
    return r


@kernel
def _interp(x, xp, fp):
    """``np.interp(x, xp, fp)`` for one x (numpy's algorithm: the cell j with xp[j] ≤ x <
    xp[j + 1], the same slope formula and its NaN fallbacks), so results are bit-identical."""
    n = xp.shape[0]
    if x != x:
        return x
    if x < xp[0]:
        return fp[0]
    if x > xp[n - 1]:
        return fp[n - 1]
    lo = 0
    hi = n
    while lo < hi:  # largest j with xp[j] <= x
        mid = lo + ((hi - lo) >> 1)
        if x >= xp[mid]:
            lo = mid + 1
        else:
            hi = mid
    return _interp_cell(x, xp, fp, lo - 1)


@kernel
def _interp_guided(x, xp, fp, guide):
    """``_interp`` with the cell found from the guide table (the same cell, the same value)."""
    n = xp.shape[0]
    if x != x or x < xp[0] or x > xp[n - 1]:
        return _interp(x, xp, fp)
    g = guide.shape[0]
    k = int(x * g)
    if k >= g:
        k = g - 1
    if k < 0:
        k = 0
    j = guide[k]  # xp[j] <= k/g <= x: walk to the largest j with xp[j] <= x
    while j + 1 < n and xp[j + 1] <= x:
        j += 1
    return _interp_cell(x, xp, fp, j)


@kernel
def filter_sample_1d(fd, u):
    """One offset (px) along one axis, distributed ∝ the filter; monotone in u ∈ [0, 1)."""
    if fd.kind == 2:  # BOX
        return (u - 0.5) * fd.width
    # piecewise-linear inversion of the tabulated CDF (uniform inside each cell)
    return _interp_guided(u, fd.cdf, fd.edges, fd.guide)


@inline_kernel
def filter_sample(fd, u0, u1):
    """Pixel-filter offset (dx, dy) in pixels from the pixel centre for (u0, u1) ∈ [0, 1)²;
    fd = ``PixelFilter.data``.  Every sample carries weight 1."""
    return filter_sample_1d(fd, u0), filter_sample_1d(fd, u1)


@kernel
def _sample_1d_rows(fd, u, out):
    for k in range(u.shape[0]):
        out[k] = filter_sample_1d(fd, u[k])


@kernel
def _sample_rows(fd, u, out):
    for k in range(u.shape[0]):
        dx, dy = filter_sample(fd, u[k, 0], u[k, 1])
        out[k, 0] = dx
        out[k, 1] = dy


def _f64(x) -> np.ndarray:
    """float64, C-contiguous, writeable (one compiled signature for every call)."""
    a = np.ascontiguousarray(x, dtype=np.float64)
    return a if a.flags.writeable else a.copy()

_BH = (0.35875, 0.48829, 0.14128, 0.01168)
_erf = np.vectorize(math.erf, otypes=[np.float64])


class PixelFilter:
    """A separable pixel filter f(x)·f(y) and its importance sampling.

    kind: "BLACKMAN_HARRIS" | "GAUSSIAN" | "BOX"; width: Blender's filter width in pixels (> 0);
    table_size: cells of the tabulated CDF over [−radius, radius].

    Attributes: ``kind``, ``width``, ``radius`` (half-width of the support in pixels: w, 1.5w
    or w/2).
    """

    def __init__(self, kind: str = "BLACKMAN_HARRIS", width: float = 1.5,
                 table_size: int = 4096):
        kind = str(kind).upper()
        if kind not in FILTER_KINDS:
            raise ValueError(f"unknown pixel filter {kind!r}; expected one of {FILTER_KINDS}")
        width = float(width)
        if not width > 0.0:
            raise ValueError(f"filter width must be > 0 px (got {width})")
        self.kind = kind
        self.width = width
        if kind == "BLACKMAN_HARRIS":
            self.radius = width
        elif kind == "GAUSSIAN":
            self.radius = 1.5 * width
        else:
            self.radius = 0.5 * width
        self._norm = self._integral()
        self._build_table(int(table_size))
        self.data = FilterData(kind=int(FILTER_KINDS.index(kind)), width=float(self.width),
                               radius=float(self.radius), cdf=self._cdf, edges=self._edges,
                               guide=_guide_table(self._cdf))

    def __repr__(self) -> str:
        return f"PixelFilter(kind={self.kind!r}, width={self.width})"

    # -- the filter -------------------------------------------------------------------------

    def eval_1d(self, x) -> np.ndarray:
        """Un-normalized 1-D filter f(x) as Cycles's ``filter_func_*`` (peak value 1 at x = 0 for
        all three); 0 outside [−radius, radius].  x: (n,) px -> (n,) float64."""
        x = np.asarray(x, dtype=np.float64)
        inside = np.abs(x) <= self.radius
        if self.kind == "BLACKMAN_HARRIS":
            v = 2.0 * np.pi * (x / (2.0 * self.width) + 0.5)
            a0, a1, a2, a3 = _BH
            f = a0 - a1 * np.cos(v) + a2 * np.cos(2.0 * v) - a3 * np.cos(3.0 * v)
        elif self.kind == "GAUSSIAN":
            t = x * (6.0 / (3.0 * self.width))
            f = np.exp(-2.0 * t * t)
        else:
            f = np.ones_like(x)
        return np.where(inside, f, 0.0)

    def _integral(self) -> float:
        """∫ f over the support (closed forms)."""
        if self.kind == "BLACKMAN_HARRIS":
            return 2.0 * self.width * _BH[0]  # the cosines integrate over whole periods
        if self.kind == "GAUSSIAN":
            sigma = self.width / 4.0
            s = sigma * math.sqrt(2.0)
            return s * math.sqrt(math.pi) * math.erf(self.radius / s)
        return self.width

    def pdf_1d(self, x) -> np.ndarray:
        """Normalized 1-D density f(x)/∫f, per pixel.  x: (n,) -> (n,) float64."""
        return self.eval_1d(x) / self._norm

    def pdf(self, offsets) -> np.ndarray:
        """Density of ``sample`` per unit pixel area: pdf_1d(x)·pdf_1d(y).

        offsets: (n, 2) px from the pixel centre -> (n,) float64.
        """
        o = np.asarray(offsets, dtype=np.float64)
        return self.pdf_1d(o[..., 0]) * self.pdf_1d(o[..., 1])

    def cdf_1d(self, x) -> np.ndarray:
        """P(offset ≤ x) for one axis, exact (closed form; Gaussian via erf).  x: (n,) -> (n,)."""
        x = np.clip(np.asarray(x, dtype=np.float64), -self.radius, self.radius)
        if self.kind == "BLACKMAN_HARRIS":
            w = self.width
            a0, a1, a2, a3 = _BH

            def antideriv(xx):
                v = 2.0 * np.pi * (xx / (2.0 * w) + 0.5)
                return (w / np.pi) * (a0 * v - a1 * np.sin(v) + a2 / 2.0 * np.sin(2.0 * v)
                                      - a3 / 3.0 * np.sin(3.0 * v))

            return (antideriv(x) - antideriv(-self.radius)) / self._norm
        if self.kind == "GAUSSIAN":
            s = self.width / 4.0 * math.sqrt(2.0)
            e0 = math.erf(-self.radius / s)
            return (_erf(x / s) - e0) / (math.erf(self.radius / s) - e0)
        return (x + self.radius) / self.width

    # -- sampling ---------------------------------------------------------------------------

    def _build_table(self, size: int) -> None:
        """Forward CDF of f on ``size`` equal cells of [−radius, radius]; each cell's mass by
        8-point Gauss-Legendre, so the tabulated distribution is exact up to the piecewise-
        uniform placement inside a cell."""
        r = self.radius
        edges = np.linspace(-r, r, size + 1)
        h = edges[1] - edges[0]
        t, wts = np.polynomial.legendre.leggauss(8)
        pts = edges[:-1, None] + (0.5 * (t[None, :] + 1.0)) * h
        mass = (self.eval_1d(pts) * (0.5 * h * wts[None, :])).sum(axis=1)
        cdf = np.concatenate([[0.0], np.cumsum(mass)])
        cdf /= cdf[-1]
        self._edges = edges
        self._cdf = cdf
        self._cell = h

    def sample_1d(self, u) -> np.ndarray:
        """Offsets along one axis, distributed ∝ f.  u: (n,) in [0, 1) -> (n,) px in
        [−radius, radius].  Monotone in u (keeps the strata of stratified / Sobol samples)."""
        u = np.asarray(u, dtype=np.float64)
        flat = _f64(u.reshape(-1))
        out = np.empty_like(flat)
        _sample_1d_rows(self.data, flat, out)
        return out.reshape(u.shape)

    def sample(self, u) -> np.ndarray:
        """Pixel-filter offsets.

        u: (n, 2) float in [0, 1) (sample dimension 0).  Returns (n, 2) float64 offsets in pixels
        from the pixel centre, x and y drawn independently ∝ the filter; every sample carries
        weight 1 (Cycles's convention), so the film just averages.
        """
        u = np.asarray(u, dtype=np.float64)
        lead = u.shape[:-1]
        flat = _f64(u[..., :2].reshape(-1, 2))
        out = np.empty_like(flat)
        _sample_rows(self.data, flat, out)
        return out.reshape(lead + (2,))
