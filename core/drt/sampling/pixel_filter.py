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

import functools
import math
from collections import namedtuple

import numpy as np

from ..kernels import inline_kernel, kernel

__all__ = ["PixelFilter", "FilterData", "FILTER_KINDS", "filter_sample", "filter_sample_1d"]

FILTER_KINDS = ("BLACKMAN_HARRIS", "GAUSSIAN", "BOX")
KIND_BLACKMAN_HARRIS, KIND_GAUSSIAN, KIND_BOX = 0, 1, 2  # FilterData.kind

FilterData = namedtuple("FilterData", ["kind", "width", "radius", "inverse", "tail_lo", "tail_hi"])
FilterData.__doc__ = """The pixel filter for the kernels: kind (int64: 0 BLACKMAN_HARRIS, 1 GAUSSIAN,
2 BOX), width and radius (float64, px), and the inverse of the filter's CDF (px, from −radius to
radius), which a sample interpolates linearly (as Cycles's ``filter_table``): inverse (m + 1,) at
u = k/m, and the first and last of its m intervals tabulated again, finer: tail_lo (t + 1,) over
u ∈ [0, 1/m], tail_hi (t + 1,) over [(m − 1)/m, 1]."""

#: intervals of the tabulated inverse CDF, and of each of its two end intervals. A sample is
#: one lookup and a lerp per axis (searching a forward CDF cost ~16 ns a value). The ends are
#: where the filter's density is tiny and its inverse CDF steep: one linear piece across the
#: first 1/m of u would spread those samples evenly over the outer third of a Gaussian's
#: support (Cycles does that, with m = 1024); a finer table there keeps the distribution exact
#: to |CDF(x(u)) − u| < 1e-4 (tests/test_pixel_filter.py).
INVERSE_SIZE = 2048
TAIL_SIZE = 1024


@kernel
def lerp_table(u, table):
    """Linear interpolation of ``table`` (m + 1 values at u = k/m) at u ∈ [0, 1]; clamped to
    the two entries it lies between, so it is monotone in u however the products round."""
    m = table.shape[0] - 1
    t = u * m
    k = int(t) if t >= 0.0 else 0
    if k >= m:
        k = m - 1
    a = table[k]
    b = table[k + 1]
    return min(max(a + (t - k) * (b - a), a), b)


@kernel
def filter_sample_1d(fd, u):
    """One offset (px) along one axis, distributed ∝ the filter; monotone in u ∈ [0, 1)."""
    if fd.kind == 2:  # BOX
        return (u - 0.5) * fd.width
    m = fd.inverse.shape[0] - 1
    t = u * m
    if t < 1.0:
        return lerp_table(t, fd.tail_lo)
    if t >= m - 1:
        return lerp_table(t - (m - 1), fd.tail_hi)
    return lerp_table(u, fd.inverse)


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


@functools.lru_cache(maxsize=8)
def shared_pixel_filter(kind: str = "BLACKMAN_HARRIS", width: float = 1.5) -> "PixelFilter":
    """The `PixelFilter` of ``kind`` and ``width``, built once per process: its tables are only
    read after construction, and building them (~1.5 ms: 4 096 cells × 8 Gauss–Legendre points)
    was a seventh of a small scene's `drt.render.prepare`, paid by every F12."""
    return PixelFilter(kind, width)


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
                               radius=float(self.radius), **self._inverse_tables())

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

    def _inverse_tables(self) -> dict:
        """FilterData's inverse, tail_lo and tail_hi: the forward table's piecewise-linear
        inverse read at their knots; the tails' outer knots are the main table's, so the three
        join without a step."""
        def invert(u):
            x = np.interp(u, self._cdf, self._edges)
            return _f64(np.clip(x, -self.radius, self.radius))

        knots = np.linspace(0.0, 1.0, INVERSE_SIZE + 1)
        return dict(inverse=invert(knots), tail_lo=invert(np.linspace(0.0, knots[1], TAIL_SIZE + 1)),
                    tail_hi=invert(np.linspace(knots[-2], 1.0, TAIL_SIZE + 1)))

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
