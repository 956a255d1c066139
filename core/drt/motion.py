"""Rigid-motion interpolation over the shutter, the way Cycles does it.

A transform at shutter open and one at close are decomposed into translation, rotation (unit
quaternion) and scale; at shutter fraction τ ∈ [0, 1] translation and scale interpolate linearly
and rotation by quaternion slerp. Every ray carries its own τ, so motion blur is exact for rigid
motion: no time slices, no banding.

The interpolation is the scalar kernel ``motion_at(md, tau)`` (``md = RigidMotion.data``, a
``MotionData``); ``RigidMotion.at`` applies it to arrays of τ.
"""

from __future__ import annotations

import math
from collections import namedtuple
from dataclasses import dataclass

import numpy as np

from .kernels import kernel

MotionData = namedtuple("MotionData", ["q0", "q1", "omega", "scale0", "scale1",
                                       "trans0", "trans1"])
MotionData.__doc__ = """A rigid motion for the kernels: unit quaternions (w, x, y, z) q0, q1 (4,) float64
at shutter open / close (q1 on q0's side), omega (float64) the angle between them, scale0, scale1
(3,) float64 and trans0, trans1 (3,) float64."""


@kernel
def motion_at(md, tau):
    """The transform at shutter fraction tau: (row0, row1, row2, translation), 3-tuples; the
    linear part is R(slerp(q0, q1, τ))·diag(lerp(scale0, scale1, τ))."""
    om = md.omega
    q0 = md.q0
    q1 = md.q1
    if om < 1e-8:
        a = 1.0 - tau
        w = a * q0[0] + tau * q1[0]
        x = a * q0[1] + tau * q1[1]
        y = a * q0[2] + tau * q1[2]
        z = a * q0[3] + tau * q1[3]
    else:
        # 1/sin ω: one division for the four components (a division costs ~5 multiplies; the
        # object's ω is the same for every ray of a batch, so LLVM computes it once)
        inv_so = 1.0 / math.sin(om)
        a = math.sin((1.0 - tau) * om) * inv_so
        b = math.sin(tau * om) * inv_so
        w = a * q0[0] + b * q1[0]
        x = a * q0[1] + b * q1[1]
        y = a * q0[2] + b * q1[2]
        z = a * q0[3] + b * q1[3]
    inv_norm = 1.0 / math.sqrt(w * w + x * x + y * y + z * z)
    w *= inv_norm
    x *= inv_norm
    y *= inv_norm
    z *= inv_norm
    c = 1.0 - tau
    s0 = c * md.scale0[0] + tau * md.scale1[0]
    s1 = c * md.scale0[1] + tau * md.scale1[1]
    s2 = c * md.scale0[2] + tau * md.scale1[2]
    t = (c * md.trans0[0] + tau * md.trans1[0],
         c * md.trans0[1] + tau * md.trans1[1],
         c * md.trans0[2] + tau * md.trans1[2])
    r0 = ((1 - 2 * (y * y + z * z)) * s0, 2 * (x * y - z * w) * s1, 2 * (x * z + y * w) * s2)
    r1 = (2 * (x * y + z * w) * s0, (1 - 2 * (x * x + z * z)) * s1, 2 * (y * z - x * w) * s2)
    r2 = (2 * (x * z - y * w) * s0, 2 * (y * z + x * w) * s1, (1 - 2 * (x * x + y * y)) * s2)
    return r0, r1, r2, t


@kernel
def apply_rows(r0, r1, r2, v):
    """Matrix (rows r0, r1, r2) × vector v."""
    return (r0[0] * v[0] + r0[1] * v[1] + r0[2] * v[2],
            r1[0] * v[0] + r1[1] * v[1] + r1[2] * v[2],
            r2[0] * v[0] + r2[1] * v[1] + r2[2] * v[2])


@kernel
def _motion_at_rows(md, tau, linear, translation):
    for k in range(tau.shape[0]):
        r0, r1, r2, t = motion_at(md, tau[k])
        for j in range(3):
            linear[k, 0, j] = r0[j]
            linear[k, 1, j] = r1[j]
            linear[k, 2, j] = r2[j]
            translation[k, j] = t[j]


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
        f64 = lambda a: np.ascontiguousarray(a, dtype=np.float64).copy()  # noqa: E731
        self.data = MotionData(q0=f64(q0), q1=f64(q1), omega=float(self._omega),
                               scale0=f64(self.open.scale), scale1=f64(self.close.scale),
                               trans0=f64(self.open.translation),
                               trans1=f64(self.close.translation))

    def at(self, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Transforms at shutter fractions ``tau`` (n,): linear parts (n, 3, 3) and translations (n, 3)."""
        tau = np.ascontiguousarray(np.asarray(tau, dtype=np.float64).reshape(-1))
        if not tau.flags.writeable:
            tau = tau.copy()
        linear = np.empty((tau.shape[0], 3, 3))
        translation = np.empty((tau.shape[0], 3))
        _motion_at_rows(self.data, tau, linear, translation)
        return linear, translation


def static_motion_data() -> MotionData:
    """The identity as a ``MotionData`` (a placeholder where nothing moves, so data namedtuples
    keep one type)."""
    q = np.array([1.0, 0.0, 0.0, 0.0])
    one = np.ones(3)
    zero = np.zeros(3)
    return MotionData(q0=q, q1=q.copy(), omega=0.0, scale0=one, scale1=one.copy(),
                      trans0=zero, trans1=zero.copy())


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


def invert_affine(matrix) -> np.ndarray | None:
    """Inverse of a 4×4 affine matrix (bottom row 0 0 0 1; Blender's object and camera
    matrices), None when its 3×3 part is singular (`invert_linear`'s test) or the matrix is not
    affine.

    Not ``np.linalg.inv``: that is LAPACK's ``dgesv``, which OpenBLAS runs on its own threads
    even for a 4×4 matrix; those threads then spin for ~0.1 s beside the render's (docs/
    decisions.md, "No BLAS or LAPACK on a render's path")."""
    (a, b, c, x), (d, e, f, y), (g, h, i, z), bottom = np.asarray(matrix, dtype=np.float64).reshape(4, 4).tolist()
    if bottom != [0.0, 0.0, 0.0, 1.0]:
        return None
    # cofactors of the 3×3 part, as rows of its adjugate (Python floats: one 4×4 costs
    # microseconds, where numpy's per-call overhead would cost ~0.1 ms)
    adj = ((e * i - f * h, c * h - b * i, b * f - c * e),
           (f * g - d * i, a * i - c * g, c * d - a * f),
           (d * h - e * g, b * g - a * h, a * e - b * d))
    det = a * adj[0][0] + b * adj[1][0] + c * adj[2][0]
    scale = max(abs(v) for v in (a, b, c, d, e, f, g, h, i))
    if not abs(det) > 1e-12 * max(scale, 1e-300) ** 3:  # invert_linear's test
        return None
    out = np.zeros((4, 4))
    out[:3, :3] = np.array(adj) / det
    out[:3, 3] = -(out[:3, :3] * (x, y, z)).sum(axis=1)
    out[3, 3] = 1.0
    return out
