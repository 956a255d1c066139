"""Rigid-motion interpolation over the shutter, the way Cycles does it.

A transform at shutter open and one at close are decomposed into translation, rotation (unit
quaternion) and scale; at shutter fraction τ ∈ [0, 1] translation and scale interpolate linearly
and rotation by quaternion slerp. Every ray carries its own τ, so motion blur is exact for rigid
motion: no time slices, no banding.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def _quat_from_rotation(r: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a proper rotation matrix (3, 3)."""
    tr = np.trace(r)
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = [0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s]
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        s = 2.0 * np.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2])
        q = [(r[2, 1] - r[1, 2]) / s, 0.25 * s, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s]
    elif r[1, 1] > r[2, 2]:
        s = 2.0 * np.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2])
        q = [(r[0, 2] - r[2, 0]) / s, (r[0, 1] + r[1, 0]) / s, 0.25 * s, (r[1, 2] + r[2, 1]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1])
        q = [(r[1, 0] - r[0, 1]) / s, (r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, 0.25 * s]
    q = np.asarray(q, dtype=np.float64)
    return q / np.linalg.norm(q)


def _rotation_from_quats(q: np.ndarray) -> np.ndarray:
    """(n, 4) unit quaternions (w, x, y, z) → (n, 3, 3) rotation matrices."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    r = np.empty((len(q), 3, 3))
    r[:, 0, 0] = 1 - 2 * (y * y + z * z)
    r[:, 0, 1] = 2 * (x * y - z * w)
    r[:, 0, 2] = 2 * (x * z + y * w)
    r[:, 1, 0] = 2 * (x * y + z * w)
    r[:, 1, 1] = 1 - 2 * (x * x + z * z)
    r[:, 1, 2] = 2 * (y * z - x * w)
    r[:, 2, 0] = 2 * (x * z - y * w)
    r[:, 2, 1] = 2 * (y * z + x * w)
    r[:, 2, 2] = 1 - 2 * (x * x + y * y)
    return r


@dataclass
class Decomposed:
    """matrix = T · R · S with translation (3,), rotation quaternion (4,) (w, x, y, z), scale (3,)."""

    translation: np.ndarray
    rotation: np.ndarray
    scale: np.ndarray


def decompose(m: np.ndarray) -> Decomposed:
    """Split an affine 4×4 (no shear assumed, as Blender object transforms) into T, R, S."""
    a = np.asarray(m, dtype=np.float64)[:3, :3]
    scale = np.linalg.norm(a, axis=0)
    scale = np.where(scale > 0, scale, 1e-30)
    if np.linalg.det(a) < 0:  # a mirror: put the reflection into the x scale
        scale[0] = -scale[0]
    rot = a / scale
    return Decomposed(np.asarray(m, dtype=np.float64)[:3, 3].copy(), _quat_from_rotation(rot), scale)


class RigidMotion:
    """Interpolates an object (or camera) transform between shutter open and close."""

    def __init__(self, matrix_open: np.ndarray, matrix_close: np.ndarray):
        self.open = decompose(matrix_open)
        self.close = decompose(matrix_close)
        q0, q1 = self.open.rotation, self.close.rotation
        if np.dot(q0, q1) < 0:  # take the short way round
            q1 = -q1
        self._q0, self._q1 = q0, q1
        self._omega = np.arccos(np.clip(np.dot(q0, q1), -1.0, 1.0))

    def at(self, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Transforms at shutter fractions ``tau`` (n,): linear parts (n, 3, 3) and translations (n, 3)."""
        tau = np.asarray(tau, dtype=np.float64)[:, None]
        om = self._omega
        if om < 1e-8:
            q = (1 - tau) * self._q0 + tau * self._q1
        else:
            q = (np.sin((1 - tau) * om) * self._q0 + np.sin(tau * om) * self._q1) / np.sin(om)
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        scale = (1 - tau) * self.open.scale + tau * self.close.scale
        translation = (1 - tau) * self.open.translation + tau * self.close.translation
        linear = _rotation_from_quats(q) * scale[:, None, :]
        return linear, translation


def apply_linear(linear: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Per-ray matrix × vector: (n,3,3) @ (n,3) → (n,3)."""
    return np.einsum("nij,nj->ni", linear, v)


def apply_linear_transposed(linear: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Per-ray matrixᵀ × vector."""
    return np.einsum("nji,nj->ni", linear, v)


def invert_linear(linear: np.ndarray) -> np.ndarray:
    """Inverse of (n,3,3) (or (3,3)) linear maps; a singular one (an object scaled to zero,
    legal in Blender) gets the zero matrix, so rays mapped through it have no direction and
    hit nothing, and normals through it vanish (np.linalg.inv would raise LinAlgError).

    Computed from cofactors with plain array arithmetic: for many small matrices this is
    several times faster than np.linalg.inv's per-matrix LAPACK calls."""
    m = np.asarray(linear, dtype=np.float64)
    a = m.reshape(-1, 3, 3)
    c0 = np.cross(a[:, 1], a[:, 2])  # cofactor rows: the inverse's columns
    c1 = np.cross(a[:, 2], a[:, 0])
    c2 = np.cross(a[:, 0], a[:, 1])
    det = np.einsum("ij,ij->i", a[:, 0], c0)
    scale = np.max(np.abs(a), axis=(1, 2))
    ok = np.abs(det) > 1e-12 * np.maximum(scale, 1e-300) ** 3
    inv_det = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    out = np.stack([c0, c1, c2], axis=2) * inv_det[:, None, None]
    return out.reshape(m.shape)
