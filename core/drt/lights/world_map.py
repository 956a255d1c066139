"""A textured world: its radiance from the world program, and importance sampling of it.

The world's node tree is a program (``drt.materials.programs``) run for directions instead of
surface points: as Cycles's ``shader_setup_from_background``, its Generated and Object
coordinates are the ray direction and UV is zero (`world_radiance_at`). The program's register
``ld.world_reg`` is the radiance (Background colour × strength) arriving along −d.

**Importance map** (Cycles's ``scene/light.cpp`` background map, ``kernel/light/background.h``):
the program is evaluated at the centres of a W × H equirectangular grid of directions (pixel
(i, j) at u = (i + ½)/W, v = (j + ½)/H, `drt.sampling.spherical_maps`) and at its corners; each
pixel's weight is the largest average of |r|, |g|, |b| among its centre and corners (Cycles:
the centre's) times sin θ of its row centre. Rows are sampled ∝ their sums
(marginal CDF), then a column within the row (conditional CDF), then uniformly within the
pixel in (u, v). The solid-angle pdf of direction d is then

    pdf(d) = f(pixel of d) / (2π² · sin θ(d) · Σ f / (W·H))

(the 2π² sin θ is the Jacobian of the (u, v) → direction map), zero at the poles.

Tables, packed as Cycles packs them (function value, CDF) per entry:
``wm_cond`` (H, W + 1, 2): row j's pixel values and normalised CDF, entry W holding the row's
integral (Σ f / W) and 1; ``wm_marg`` (H + 1, 2): the rows' integrals and their normalised CDF,
entry H holding the total integral. A constant world has (0, 1, 2) and (1, 2) zero tables.
"""

from __future__ import annotations

import math

import numpy as np

from ..kernels import inline_kernel, kernel
from ..materials.program_format import (POINT_GENERATED, POINT_I, POINT_N, POINT_NG, POINT_NSMOOTH, POINT_OBJECT,
                                        POINT_P, POINT_ROWS, POINT_SHADOW, POINT_UV, POINT_XFORM,
                                        POINT_OBJECT_XFORM)
from ..materials.programs import run_program
from ..sampling.spherical_maps import direction_to_equirectangular, equirectangular_to_direction

#: Cycles's default World > Settings > Map Resolution (the map is R × R/2)
DEFAULT_MAP_RESOLUTION = 1024
_TWO_PI_SQ = 2.0 * math.pi * math.pi


def empty_world_map() -> tuple[np.ndarray, np.ndarray]:
    """The (wm_cond, wm_marg) of a world without a map."""
    return np.zeros((0, 1, 2)), np.zeros((1, 2))


# ------------------------------------------------------------------- the world program
@inline_kernel
def world_radiance_at(pd, regs, prog, reg, d, point):
    """Run world program ``prog`` for the direction d and return register ``reg`` (radiance
    along −d, clamped ≥ 0). ``point`` (POINT_ROWS, 3) gets the direction's rows as Cycles's
    ``shader_setup_from_background``: Generated = Object = P = d, UV 0, N = Ng = I = −d; the
    Light Path rows are the caller's (zero for the importance map)."""
    for c in range(3):
        point[POINT_GENERATED, c] = d[c]
        point[POINT_OBJECT, c] = d[c]
        point[POINT_UV, c] = 0.0
        point[POINT_P, c] = d[c]
        point[POINT_N, c] = -d[c]
        point[POINT_NG, c] = -d[c]
        point[POINT_I, c] = -d[c]
        point[POINT_NSMOOTH, c] = -d[c]
        point[POINT_SHADOW, c] = 0.0
        for r in range(3):  # no object: Texture Coordinate Normal is N itself (a hit left its own)
            point[POINT_OBJECT_XFORM + r, c] = 1.0 if r == c else 0.0
    run_program(pd, regs, prog, -1, 0.0, 0.0, point)
    return (max(regs[reg, 0], 0.0), max(regs[reg, 1], 0.0), max(regs[reg, 2], 0.0))


@kernel
def _shade_pixels(pd, regs, point, prog, reg, width, height, out):
    for j in range(height):
        for i in range(width):
            d = equirectangular_to_direction((i + 0.5) / width, (j + 0.5) / height)
            c = world_radiance_at(pd, regs, prog, reg, d, point)
            out[j, i, 0] = c[0]
            out[j, i, 1] = c[1]
            out[j, i, 2] = c[2]


@kernel
def _shade_corners(pd, regs, point, prog, reg, width, height, out):
    for j in range(height + 1):
        for i in range(width + 1):
            d = equirectangular_to_direction(i / width, j / height)
            c = world_radiance_at(pd, regs, prog, reg, d, point)
            out[j, i, 0] = c[0]
            out[j, i, 1] = c[1]
            out[j, i, 2] = c[2]


@kernel
def _radiance_rows(pd, regs, point, prog, reg, d, out):
    for r in range(d.shape[0]):
        c = world_radiance_at(pd, regs, prog, reg, (d[r, 0], d[r, 1], d[r, 2]), point)
        out[r, 0] = c[0]
        out[r, 1] = c[1]
        out[r, 2] = c[2]


def register_file(n_registers: int) -> np.ndarray:
    """A register file for programs of up to ``n_registers`` registers."""
    return np.zeros((max(int(n_registers), 1), 3))


def point_rows() -> np.ndarray:
    """A shading-point array for a direction (identity normal transform, Light Path rows 0)."""
    point = np.zeros((POINT_ROWS, 3))
    point[POINT_XFORM:POINT_XFORM + 3] = np.eye(3)
    point[POINT_OBJECT_XFORM:POINT_OBJECT_XFORM + 3] = np.eye(3)
    return point


def shade_directions(pd, prog: int, reg: int, n_registers: int, d) -> np.ndarray:
    """(m, 3) world radiance along −d for directions d (m, 3) (tests, the viewport)."""
    d = np.ascontiguousarray(d, dtype=np.float64).reshape(-1, 3)
    out = np.zeros((len(d), 3))
    _radiance_rows(pd, register_file(n_registers), point_rows(), prog, reg, d, out)
    return out


def shade_map(pd, prog: int, reg: int, n_registers: int, width: int, height: int) -> np.ndarray:
    """(height, width, 3) world radiance at the equirectangular pixel centres (row 0: v ≈ 0,
    straight down)."""
    out = np.zeros((height, width, 3))
    _shade_pixels(pd, register_file(n_registers), point_rows(), prog, reg, width, height, out)
    return out


def shade_map_corners(pd, prog: int, reg: int, n_registers: int, width: int, height: int) -> np.ndarray:
    """(height + 1, width + 1, 3) world radiance at the equirectangular pixel corners."""
    out = np.zeros((height + 1, width + 1, 3))
    _shade_corners(pd, register_file(n_registers), point_rows(), prog, reg, width, height, out)
    return out


# ------------------------------------------------------------------- the importance map
def build_world_map(pixels: np.ndarray, corners: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, float]:
    """(wm_cond, wm_marg, average radiance) of equirectangular radiance ``pixels`` (H, W, 3) at
    the pixel centres, as Cycles builds them (float64 here). With ``corners`` (H + 1, W + 1, 3),
    the radiance at the pixel corners, a pixel weighs the largest of its centre's and its four
    corners' channel averages instead of its centre's alone (see docs/decisions.md: a pixel
    whose centre is dark but whose edge touches an interpolated sun made NEE samples of
    L/pdf ~ 10⁵). The average is ∫ lum(L) dω / 4π with Rec.709 luminance of the centres (for
    light selection; Cycles's is the channel average)."""
    from .common import luminance

    pixels = np.asarray(pixels, dtype=np.float64)
    h, w = pixels.shape[:2]
    sin_theta = np.sin(np.pi * (np.arange(h) + 0.5) / h)
    value = np.abs(pixels).mean(axis=2)
    if corners is not None:
        c = np.abs(np.asarray(corners, dtype=np.float64)).mean(axis=2)
        value = np.maximum.reduce([value, c[:-1, :-1], c[:-1, 1:], c[1:, :-1], c[1:, 1:]])
    f = value * sin_theta[:, None]
    cond = np.zeros((h, w + 1, 2))
    cond[:, :w, 0] = f
    run = np.concatenate([np.zeros((h, 1)), np.cumsum(f / w, axis=1)], axis=1)  # (H, W + 1)
    row_total = run[:, w]
    cond[:, w, 0] = row_total
    with np.errstate(invalid="ignore", divide="ignore"):
        cdf = np.where(row_total[:, None] > 0.0, run / row_total[:, None], 0.0)
    cond[:, :, 1] = cdf
    cond[:, w, 1] = 1.0
    marg = np.zeros((h + 1, 2))
    marg[:h, 0] = row_total
    mrun = np.concatenate([[0.0], np.cumsum(row_total / h)])
    total = mrun[h]
    marg[h, 0] = total
    marg[:, 1] = mrun / total if total > 0.0 else 0.0
    marg[h, 1] = 1.0
    lum = luminance(pixels.reshape(-1, 3)).reshape(h, w)
    average = float(np.sum(lum * sin_theta[:, None]) / (w * h) * (np.pi / 2.0))
    return np.ascontiguousarray(cond), np.ascontiguousarray(marg), average


@inline_kernel
def world_map_sample(ld, u0, u1):
    """(direction, solid-angle pdf) sampled from the importance map with (u0, u1) (u1 picks
    the row, u0 the column, as Cycles's ``background_map_sample``)."""
    cond, marg = ld.wm_cond, ld.wm_marg
    h = cond.shape[0]
    w = cond.shape[1] - 1
    # marginal: rows
    first = 0
    count = h
    while count > 0:
        step = count >> 1
        middle = first + step
        if marg[middle, 1] < u1:
            first = middle + 1
            count -= step + 1
        else:
            count = step
    iv = max(0, first - 1)
    c0, c1 = marg[iv, 1], marg[iv + 1, 1]
    dv = (u1 - c0) / (c1 - c0) if c1 != c0 else 0.0
    v = (iv + dv) / h
    first = 0
    count = w
    while count > 0:
        step = count >> 1
        middle = first + step
        if cond[iv, middle, 1] < u0:
            first = middle + 1
            count -= step + 1
        else:
            count = step
    iu = max(0, first - 1)
    c0, c1 = cond[iv, iu, 1], cond[iv, iu + 1, 1]
    du = (u0 - c0) / (c1 - c0) if c1 != c0 else 0.0
    u = (iu + du) / w
    sin_theta = math.sin(math.pi * v)
    denom = _TWO_PI_SQ * sin_theta * cond[iv, w, 0] * marg[h, 0]
    pdf = 0.0
    if sin_theta != 0.0 and denom != 0.0:
        pdf = cond[iv, iu, 0] * marg[iv, 0] / denom
    return equirectangular_to_direction(u, v), pdf


@inline_kernel
def world_map_pdf(ld, d):
    """Solid-angle pdf of `world_map_sample` producing the unit direction d."""
    cond, marg = ld.wm_cond, ld.wm_marg
    h = cond.shape[0]
    w = cond.shape[1] - 1
    u, v = direction_to_equirectangular(d[0], d[1], d[2])
    sin_theta = math.sin(v * math.pi)
    if sin_theta == 0.0:
        return 0.0
    iu = min(max(int(u * w), 0), w - 1)
    iv = min(max(int(v * h), 0), h - 1)
    denom = _TWO_PI_SQ * sin_theta * cond[iv, w, 0] * marg[h, 0]
    if denom == 0.0:
        return 0.0
    return cond[iv, iu, 0] * marg[iv, 0] / denom


@kernel
def _sample_rows(ld, u, d, pdf):
    for r in range(u.shape[0]):
        dd, p = world_map_sample(ld, u[r, 0], u[r, 1])
        d[r, 0], d[r, 1], d[r, 2] = dd
        pdf[r] = p


@kernel
def _pdf_rows(ld, d, pdf):
    for r in range(d.shape[0]):
        pdf[r] = world_map_pdf(ld, (d[r, 0], d[r, 1], d[r, 2]))


def sample_map(ld, u) -> tuple[np.ndarray, np.ndarray]:
    """Directions (m, 3) and pdfs (m,) for uniform points u (m, 2) (tests)."""
    u = np.ascontiguousarray(u, dtype=np.float64).reshape(-1, 2)
    d, pdf = np.zeros((len(u), 3)), np.zeros(len(u))
    _sample_rows(ld, u, d, pdf)
    return d, pdf


def map_pdf(ld, d) -> np.ndarray:
    """(m,) pdfs of unit directions d (m, 3) (tests)."""
    d = np.ascontiguousarray(d, dtype=np.float64).reshape(-1, 3)
    out = np.zeros(len(d))
    _pdf_rows(ld, d, out)
    return out
