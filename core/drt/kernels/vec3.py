"""3-vectors as tuples ``(x, y, z)`` of float64 inside compiled kernels.

Tuples live in registers: no allocation per operation, unlike small numpy arrays. Every function
here is a ``@kernel`` and may be called from other kernels (numba inlines them when it pays).
"""

from __future__ import annotations

import math

from . import kernel


@kernel
def add(a, b):
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


@kernel
def sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@kernel
def scale(a, s):
    return (a[0] * s, a[1] * s, a[2] * s)


@kernel
def mul(a, b):
    """Component-wise product (colours)."""
    return (a[0] * b[0], a[1] * b[1], a[2] * b[2])


@kernel
def neg(a):
    return (-a[0], -a[1], -a[2])


@kernel
def madd(a, b, s):
    """a + s·b."""
    return (a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2])


@kernel
def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@kernel
def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@kernel
def length(a):
    return math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


@kernel
def normalize(a):
    """(unit vector, length); a zero vector stays zero (length 0)."""
    n = math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    if n > 0.0:
        inv = 1.0 / n
        return (a[0] * inv, a[1] * inv, a[2] * inv), n
    return (0.0, 0.0, 0.0), 0.0


@kernel
def max_component(a):
    return max(a[0], max(a[1], a[2]))


@kernel
def load(arr, i):
    """Row i of an (n, 3) array as a tuple."""
    return (float(arr[i, 0]), float(arr[i, 1]), float(arr[i, 2]))


@kernel
def store(arr, i, v):
    """Write tuple v into row i of an (n, 3) array."""
    arr[i, 0] = v[0]
    arr[i, 1] = v[1]
    arr[i, 2] = v[2]


@kernel
def build_frame(n):
    """Tangents (t, b) with (t, b, n) right-handed orthonormal for a unit n (Duff et al. 2017,
    branchless; the same construction as ``drt.sampling.warps.build_frame``)."""
    sign = math.copysign(1.0, n[2])
    a = -1.0 / (sign + n[2])
    bxy = n[0] * n[1] * a
    t = (1.0 + sign * n[0] * n[0] * a, sign * bxy, -sign * n[0])
    b = (bxy, sign + n[1] * n[1] * a, -n[1])
    return t, b


@kernel
def to_local(v, t, b, n):
    """World vector → (v·t, v·b, v·n)."""
    return (dot(v, t), dot(v, b), dot(v, n))


@kernel
def to_world(v, t, b, n):
    """Local vector → v.x·t + v.y·b + v.z·n."""
    return (v[0] * t[0] + v[1] * b[0] + v[2] * n[0],
            v[0] * t[1] + v[1] * b[1] + v[2] * n[1],
            v[0] * t[2] + v[1] * b[2] + v[2] * n[2])


@kernel
def load_col3(arr, i, c):
    """Columns c, c+1, c+2 of row i of a 2-D array as a tuple (a vector stored in a packed table)."""
    return (float(arr[i, c]), float(arr[i, c + 1]), float(arr[i, c + 2]))
