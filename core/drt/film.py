"""Per-pixel accumulation of samples and the passes written out.

The pixel filter is importance-sampled (``sampling.pixel_filter``), so every camera sample has
weight 1 and belongs to exactly one pixel: a pixel's value is the plain mean of its samples, the
estimator Cycles uses. Sums are kept in float64 and added in a fixed order, so the result is
bit-identical for a given seed whatever the thread timing.

Arrays are stored **top row first** (row 0 is the top of the image, as in EXR).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


def luminance(rgb: np.ndarray) -> np.ndarray:
    """Rec.709 / linear sRGB luminance of (..., 3) radiance."""
    return rgb @ np.array([0.2126, 0.7152, 0.0722])


@dataclass
class SampleBatch:
    """What one batch of camera paths produced. pixel: (n,) flat pixel id (row-major from the
    TOP row); radiance (n,3); alpha (n,); depth (n,) (inf: nothing hit); normal (n,3) world;
    albedo (n,3)."""

    pixel: np.ndarray
    radiance: np.ndarray
    alpha: np.ndarray
    depth: np.ndarray
    normal: np.ndarray
    albedo: np.ndarray
    nan_count: int = 0


@dataclass
class Film:
    """Accumulated passes for a width × height image.

    ``combined`` (H, W, 4): mean RGBA (scene-linear radiance); ``depth`` (H, W): distance along
    the camera's view axis to the first hit (inf: none); ``normal`` (H, W, 3): mean world-space
    shading normal of first hits; ``albedo`` (H, W, 3); ``sample_count`` (H, W); ``variance``
    (H, W): estimated variance of the pixel mean's luminance (σ²/N).
    """

    width: int
    height: int
    sum_rgba: np.ndarray = None
    sum_lum2: np.ndarray = None
    sum_normal: np.ndarray = None
    sum_albedo: np.ndarray = None
    min_depth: np.ndarray = None
    count: np.ndarray = None
    nan_samples: int = 0
    meta: dict = field(default_factory=dict)

    def __post_init__(self):
        n = self.width * self.height
        if self.sum_rgba is None:
            self.sum_rgba = np.zeros((n, 4))
            self.sum_lum2 = np.zeros(n)
            self.sum_normal = np.zeros((n, 3))
            self.sum_albedo = np.zeros((n, 3))
            self.min_depth = np.full(n, np.inf)
            self.count = np.zeros(n, dtype=np.int64)

    def add(self, b: SampleBatch) -> None:
        n = self.width * self.height
        px = b.pixel
        for c in range(3):
            self.sum_rgba[:, c] += np.bincount(px, weights=b.radiance[:, c], minlength=n)
        self.sum_rgba[:, 3] += np.bincount(px, weights=b.alpha, minlength=n)
        self.sum_lum2 += np.bincount(px, weights=luminance(b.radiance) ** 2, minlength=n)
        for c in range(3):
            self.sum_normal[:, c] += np.bincount(px, weights=b.normal[:, c], minlength=n)
            self.sum_albedo[:, c] += np.bincount(px, weights=b.albedo[:, c], minlength=n)
        np.minimum.at(self.min_depth, px, b.depth)
        self.count += np.bincount(px, minlength=n)
        self.nan_samples += b.nan_count

    def merge(self, other: "Film") -> None:
        """Add another film of the same size (e.g. a disjoint sample range)."""
        self.sum_rgba += other.sum_rgba
        self.sum_lum2 += other.sum_lum2
        self.sum_normal += other.sum_normal
        self.sum_albedo += other.sum_albedo
        self.min_depth = np.minimum(self.min_depth, other.min_depth)
        self.count += other.count
        self.nan_samples += other.nan_samples

    def _mean(self, s: np.ndarray) -> np.ndarray:
        c = np.maximum(self.count, 1).reshape((-1,) + (1,) * (s.ndim - 1))
        return s / c

    def _image(self, flat: np.ndarray) -> np.ndarray:
        return flat.reshape((self.height, self.width) + flat.shape[1:]).astype(np.float32)

    @property
    def combined(self) -> np.ndarray:
        return self._image(self._mean(self.sum_rgba))

    @property
    def depth(self) -> np.ndarray:
        return self._image(self.min_depth)

    @property
    def normal(self) -> np.ndarray:
        nrm = self._mean(self.sum_normal)
        length = np.linalg.norm(nrm, axis=1, keepdims=True)
        return self._image(np.where(length > 0, nrm / np.where(length > 0, length, 1), 0.0))

    @property
    def albedo(self) -> np.ndarray:
        return self._image(self._mean(self.sum_albedo))

    @property
    def sample_count(self) -> np.ndarray:
        return self._image(self.count.astype(np.float64))

    @property
    def variance(self) -> np.ndarray:
        """Variance of each pixel's mean luminance: (E[L²] − E[L]²)/(N − 1)."""
        n = self.count.astype(np.float64)
        mean = luminance(self._mean(self.sum_rgba)[:, :3])
        m2 = self.sum_lum2 / np.maximum(n, 1)
        var = np.maximum(m2 - mean**2, 0.0) * n / np.maximum(n - 1, 1) / np.maximum(n, 1)
        return self._image(var)
