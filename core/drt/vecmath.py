"""Row-wise vector helpers for (n, 3) float64 arrays, written for numpy's speed.

``np.linalg.norm(v, axis=1)`` squares into a temporary and reduces it (~3× slower than one
``einsum`` pass); these helpers avoid that. Values are the same to the last bit or two. (Rows
through a matrix are `drt.geometry`'s kernels, not ``v @ m``: BLAS would run a large product
on OpenBLAS's threads, which spin on beside the render's.)
"""

from __future__ import annotations

import numpy as np


def row_norm(v: np.ndarray) -> np.ndarray:
    """(..., 3) → (...) Euclidean length of each row."""
    return np.sqrt(np.einsum("...j,...j->...", v, v))


def row_dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(n, 3), (n, 3) → (n,) row-wise dot products."""
    return np.einsum("ij,ij->i", a, b)
