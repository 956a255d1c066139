"""The volume stack (Cycles's kernel/integrator/volume_stack.h semantics).

Every path carries the media it is inside as a small array of *keys* ``object·stride + row``
(``row``: the material's medium row, ``stride``: rows incl. the world's, see
``drt.volumes.media``), −1 in unused slots. A ray crossing a triangle whose material has a
medium *enters* it when it crosses the front face (d·ng < 0) and *leaves* it through the back
face; a key is added once only (Cycles: "don't add volumes twice"), so closed, overlapping and
nested objects work and a mesh entered twice is left when its last face is crossed. The world's
medium (if any) sits in every stack from the start and is never left. The coefficients of a
segment are the sums over the keys of its stack (overlapping media add, as in Cycles).

The camera's stack (``camera_stack``) is found once per scene by following a ray from the camera
to infinity: an object whose faces that ray leaves through (back faces) more often than it
enters through (front faces) contains the camera (Cycles's volume_stack_init instead traces
toward the scene from the camera; the count is equivalent for closed meshes).
"""

from __future__ import annotations

import numpy as np

from ..kernels import inline_kernel, kernel
from .media import STACK_SIZE


@kernel
def stack_key(vd, prim, mat):
    """The stack key of a triangle (−1: its material has no medium)."""
    if not vd.is_medium[mat]:
        return -1
    return int(vd.tri_object[prim]) * vd.stride + mat


@kernel
def stack_nonempty(stack, i):
    return stack[i, 0] >= 0


@kernel
def stack_copy(src, i, dst, j):
    for s in range(src.shape[1]):
        dst[j, s] = src[i, s]


@kernel
def stack_enter(stack, j, key):
    """Add key to row j unless present (a full stack drops it, as Cycles does)."""
    n = stack.shape[1]
    for s in range(n):
        if stack[j, s] == key:
            return
        if stack[j, s] < 0:
            stack[j, s] = key
            return


@kernel
def stack_leave(stack, j, key):
    """Remove key from row j (keeping the order of the others)."""
    n = stack.shape[1]
    found = False
    for s in range(n):
        if not found and stack[j, s] == key:
            found = True
        if found:
            stack[j, s] = stack[j, s + 1] if s + 1 < n else -1


@inline_kernel
def stack_cross(vd, stack, j, prim, mat, d, ng):
    """Update row j for a ray with direction d crossing triangle prim (geometric normal ng)."""
    key = stack_key(vd, prim, mat)
    if key < 0:
        return
    if d[0] * ng[0] + d[1] * ng[1] + d[2] * ng[2] < 0.0:
        stack_enter(stack, j, key)
    else:
        stack_leave(stack, j, key)


@inline_kernel
def stack_coefficients(vd, stack, i):
    """Summed (σs, σt, emission) 3-tuples and the σs-weighted HG g of row i's media."""
    s0 = s1 = s2 = 0.0
    t0 = t1 = t2 = 0.0
    e0 = e1 = e2 = 0.0
    gw = 0.0
    for s in range(stack.shape[1]):
        key = stack[i, s]
        if key < 0:
            break
        r = key % vd.stride
        s0 += vd.sigma_s[r, 0]
        s1 += vd.sigma_s[r, 1]
        s2 += vd.sigma_s[r, 2]
        t0 += vd.sigma_t[r, 0]
        t1 += vd.sigma_t[r, 1]
        t2 += vd.sigma_t[r, 2]
        e0 += vd.emission[r, 0]
        e1 += vd.emission[r, 1]
        e2 += vd.emission[r, 2]
        gw += vd.g[r] * (vd.sigma_s[r, 0] + vd.sigma_s[r, 1] + vd.sigma_s[r, 2])
    ssum = s0 + s1 + s2
    g = gw / ssum if ssum > 0.0 else 0.0
    return (s0, s1, s2), (t0, t1, t2), (e0, e1, e2), g


def camera_stack(vd, tracer, origin=(0.0, 0.0, 0.0), direction=(0.2672612, 0.5345225, 0.8017837),
                 max_crossings: int = 4096) -> np.ndarray:
    """The stack of rays leaving the camera at ``origin`` (shifted world frame), see the module
    docstring; ``tracer`` answers closest hits (``drt.trace.Tracer``)."""
    from ..trace import offset_origin

    stack = np.full(STACK_SIZE, -1, np.int64)
    n = 0
    if vd.world_key >= 0:
        stack[0] = vd.world_key
        n = 1
    if not vd.enabled:
        return stack
    count: dict[int, int] = {}
    order: list[int] = []
    o = np.asarray(origin, dtype=np.float64).reshape(1, 3)
    d = np.asarray(direction, dtype=np.float64).reshape(1, 3)
    d = d / np.linalg.norm(d)
    for _ in range(max_crossings):
        hits = tracer.intersect(o, d, np.zeros(1))
        prim = int(hits.prim[0])
        if prim < 0:
            break
        mat = int(tracer.geom.material[prim])
        if vd.is_medium[mat]:
            key = int(vd.tri_object[prim]) * vd.stride + mat
            if key not in count:
                count[key] = 0
                order.append(key)
            count[key] += 1 if float(np.dot(d[0], hits.ng[0])) > 0.0 else -1
        o = offset_origin(hits.p, hits.ng, d)
    for key in order:
        if count[key] > 0 and n < STACK_SIZE:
            stack[n] = key
            n += 1
    return stack
