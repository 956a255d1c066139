"""Textured emission as a light for next-event estimation (issue 11; docs/lights.md,
"Textured emitters").

A material whose emission is driven by its program (an image or procedural texture on an
Emission colour or strength) joins the emissive-triangle group like a constant emitter: each of
its static triangles is chosen ∝ area × luminance of its *average* emission, estimated at load
by running the program at a stratified set of points on the triangle (``estimate_emission``),
then a point uniform on it. The shade stage evaluates the program at the sampled point for the
radiance the shadow ray carries (``textured_light_radiance``); a BSDF ray that hits such a
triangle gets the MIS weight of the same pdf (``emissive_pdf``, unchanged). The estimate only
shapes the pdf: the estimator stays unbiased whatever it is (a triangle estimated black has
pdf 0 and is found by BSDF rays alone, with MIS weight 1).

Only emission that depends on the surface alone can be evaluated at a light sample: a
material whose emission reads shading-point rows (Light Path, Geometry, Fresnel, Layer Weight,
a Bump...) keeps the BSDF-hit-only path (``emission_reads_point``).
"""

from __future__ import annotations

import numpy as np

from ..kernels import inline_kernel, kernel
from ..materials.program_format import MAX_REGISTERS, POINT_OPS
from ..materials.programs import run_program
from ..sampling.warps import uniform_triangle

#: program evaluations at load for the estimates (points per triangle shrink to keep within it)
ESTIMATE_BUDGET = 1 << 20
MAX_POINTS_SIDE = 4  # up to 4 × 4 stratified points per triangle


@kernel
def triangle_barycentrics(pd, tri, q):
    """(b1, b2) of point q (tracer space) on static triangle ``tri`` (Embree's convention:
    q = (1 − b1 − b2)·v0 + b1·v1 + b2·v2), by projection onto the triangle's plane."""
    t = pd.triangles[tri]
    a = pd.positions[t[0]]
    b = pd.positions[t[1]]
    c = pd.positions[t[2]]
    e1 = (float(b[0]) - float(a[0]), float(b[1]) - float(a[1]), float(b[2]) - float(a[2]))
    e2 = (float(c[0]) - float(a[0]), float(c[1]) - float(a[1]), float(c[2]) - float(a[2]))
    w = (q[0] - float(a[0]), q[1] - float(a[1]), q[2] - float(a[2]))
    d11 = e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2]
    d12 = e1[0] * e2[0] + e1[1] * e2[1] + e1[2] * e2[2]
    d22 = e2[0] * e2[0] + e2[1] * e2[1] + e2[2] * e2[2]
    dw1 = w[0] * e1[0] + w[1] * e1[1] + w[2] * e1[2]
    dw2 = w[0] * e2[0] + w[1] * e2[1] + w[2] * e2[2]
    det = d11 * d22 - d12 * d12
    if not det > 0.0:
        return 0.0, 0.0
    b1 = (d22 * dw1 - d12 * dw2) / det
    b2 = (d11 * dw2 - d12 * dw1) / det
    # the sampled point lies on the triangle: clamp rounding only
    b1 = min(max(b1, 0.0), 1.0)
    b2 = min(max(b2, 0.0), 1.0 - b1)
    return b1, b2


@kernel
def emission_at(pd, regs, point, mat, tri, b1, b2):
    """Material ``mat``'s program emission (≥ 0) at barycentrics (b1, b2) of triangle ``tri``."""
    run_program(pd, regs, pd.prog_of[mat], tri, b1, b2, point)
    r = pd.emission_reg[mat]
    return (max(regs[r, 0], 0.0), max(regs[r, 1], 0.0), max(regs[r, 2], 0.0))


@inline_kernel
def textured_light_radiance(pd, regs, point, mat, tri, q):
    """Radiance of a next-event sample at point q (tracer space) of textured emitter ``tri``.
    Overwrites ``regs`` (the hit's parameters are already in the thread's material row)."""
    b1, b2 = triangle_barycentrics(pd, tri, q)
    return emission_at(pd, regs, point, mat, tri, b1, b2)


@kernel
def _estimate(pd, regs, point, mats, tris, side, out):
    n = side * side
    for i in range(tris.shape[0]):
        a0 = a1 = a2 = 0.0
        for s in range(n):
            if side == 1:
                b1, b2 = 1.0 / 3.0, 1.0 / 3.0
            else:
                b1, b2 = uniform_triangle(((s % side) + 0.5) / side, ((s // side) + 0.5) / side)
            e = emission_at(pd, regs, point, mats[i], tris[i], b1, b2)
            a0 += e[0]
            a1 += e[1]
            a2 += e[2]
        out[i, 0] = a0 / n
        out[i, 1] = a1 / n
        out[i, 2] = a2 / n


def emission_reads_point(pd, mat: int) -> bool:
    """Whether material ``mat``'s emission register depends on a shading-point row (a
    ``POINT_OPS`` operation upstream of it): such emission cannot be evaluated at a light
    sample (no incoming ray there)."""
    prog = int(pd.prog_of[mat])
    reg = int(pd.emission_reg[mat])
    if prog < 0 or reg < 0:
        return False
    tainted = set()
    for row in pd.ops[pd.op_start[prog]:pd.op_start[prog + 1]]:
        op = int(row[0])
        ins = {int(r) for r in row[4:10] if r >= 0}
        if op in POINT_OPS or ins & tainted:
            tainted.update(int(r) for r in row[2:4] if r >= 0)
            if op == 52 and row[10] >= 0:  # Voronoi's Position output register
                tainted.add(int(row[10]))
    return reg in tainted


def textured_emitters(pd, material: np.ndarray, static_count: int, no_light=None):
    """(global triangle ids (K,), average emission estimates (K, 3)) of the static triangles
    whose material has point-independent program emission; None if there are none.
    ``material``: (T,) material of every global triangle; ``no_light`` (M,) bool: materials
    that must not be lights (Emission Sampling None)."""
    if pd is None or pd.prog_of.shape[0] == 0:
        return None
    ok = np.zeros(pd.prog_of.shape[0], bool)
    for m in range(pd.prog_of.shape[0]):
        ok[m] = pd.prog_of[m] >= 0 and pd.emission_reg[m] >= 0 and not emission_reads_point(pd, m) \
            and not (no_light is not None and m < len(no_light) and no_light[m])
    if not ok.any():
        return None
    mat = np.asarray(material[:static_count], np.int64)
    tris = np.nonzero(ok[np.clip(mat, 0, len(ok) - 1)] & (mat < len(ok)))[0].astype(np.int64)
    if len(tris) == 0:
        return None
    side = int(max(1, min(MAX_POINTS_SIDE, np.sqrt(ESTIMATE_BUDGET / len(tris)))))
    from .world_map import point_rows, register_file

    out = np.zeros((len(tris), 3))
    _estimate(pd, register_file(MAX_REGISTERS), point_rows(), mat[tris], tris, side, out)
    return tris, out
