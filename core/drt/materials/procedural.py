"""Procedural texture kernels of the material programs: hashes, Perlin noise, the Noise (fBM,
multifractal, hybrid/ridged multifractal, hetero terrain), White Noise, Voronoi, Wave, Magic and
Brick textures, with Blender 5.0's values (Cycles's ``kernel/svm/{noise,fractal_noise,noisetex,
white_noise,voronoi,wave,magic,brick}.h`` and ``util/hash.h`` at v5.0; facts, own code).

Conventions:

- A point is four floats (x, y, z, w) plus its dimension ``dim`` (1: the w coordinate alone, as
  Blender's 1D textures read W; 2: x, y; 3: x, y, z; 4: all four). One function serves every
  dimension; unused components are ignored.
- Cycles evaluates in float32, and some results depend on the float32 *bits*: the cell of a
  Perlin/Voronoi lattice is the floor of a float32 coordinate, the 1D Voronoi and White Noise
  hash the coordinates' bit patterns, and the random offsets of distortion/colour are float32.
  So coordinates are rounded to float32 (``f32``) wherever Cycles forms them (scale products,
  offsets, octave scaling), and the hashes take float32 bit patterns (``float_bits``); the
  smooth arithmetic between cells runs in float64 (differences ~1e-7 relative).
- Float bit patterns come from an LLVM bitcast (``_bitcast_f32``, a numba intrinsic).
- Integer hashes work on int64 values masked to 32 bits (numba has no wrapping uint32):
  ``hash_uint*`` is Bob Jenkins's lookup3 (seed 0xdeadbeef + (n << 2) + 13), ``pcg*`` the
  signed PCG hashes Voronoi uses in 2–4D since Blender 5.0.
"""

from __future__ import annotations

import math

import numpy as np
from llvmlite import ir
from numba import types
from numba.extending import intrinsic

from ..kernels import inline_kernel, kernel
from .lattice_simd import (cell_distances2, cell_distances2_sq, cell_distances3, cell_distances3_sq,
                           corner_gradients2, corner_gradients3, corner_gradients4)
from .program_format import RAMP_TABLE_SIZE

M32 = 0xFFFFFFFF
FLT_MAX = 3.4028234663852886e38

# Noise types (mode bits 2..4 of OP_NOISE), Voronoi features and metrics: our own numbering,
# the compiler maps Blender's enum names (addon/export/node_programs.py).
NOISE_MULTIFRACTAL, NOISE_FBM, NOISE_HYBRID, NOISE_RIDGED, NOISE_HETERO = 0, 1, 2, 3, 4
VORONOI_F1, VORONOI_F2, VORONOI_SMOOTH_F1, VORONOI_EDGE, VORONOI_RADIUS = 0, 1, 2, 3, 4
METRIC_EUCLIDEAN, METRIC_MANHATTAN, METRIC_CHEBYCHEV, METRIC_MINKOWSKI = 0, 1, 2, 3


# --- float32 emulation and bit patterns ---------------------------------------------------------

@inline_kernel
def f32(x):
    """x rounded to float32 (as a float64). A float64 op on float32 values rounded once to
    float32 is the float32 IEEE result (+, −, ×, ÷), so chains of f32(...) emulate float32."""
    return float(np.float32(x))


@inline_kernel
def floor64(x):
    """⌊x⌋ as a float64, for a float32 or float64 x: one rounding instruction (LLVM's floor
    intrinsic), where numba's ``math.floor`` calls the C library and converts to an int64 —
    1.4 % of the procedural scene's render time in that call alone. Exact either way."""
    return np.floor(np.float64(x))


@intrinsic
def _bitcast_f32(typingctx, x):
    """The bits of a float32 as a uint32 (an LLVM bitcast: Cycles's ``__float_as_uint``)."""
    if x != types.float32:
        return None

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.IntType(32))
    return types.uint32(types.float32), codegen


@kernel
def float_bits(x):
    """The IEEE-754 bit pattern (uint32, as int64) of x rounded to float32 (Cycles's
    ``__float_as_uint``)."""
    return np.int64(_bitcast_f32(np.float32(x)))


# --- Jenkins lookup3 ----------------------------------------------------------------------------

@inline_kernel
def _rot(x, k):
    return ((x << k) | (x >> (32 - k))) & M32


@kernel
def _final(a, b, c):
    c ^= b
    c = (c - _rot(b, 14)) & M32
    a ^= c
    a = (a - _rot(c, 11)) & M32
    b ^= a
    b = (b - _rot(a, 25)) & M32
    c ^= b
    c = (c - _rot(b, 16)) & M32
    a ^= c
    a = (a - _rot(c, 4)) & M32
    b ^= a
    b = (b - _rot(a, 14)) & M32
    c ^= b
    c = (c - _rot(b, 24)) & M32
    return a, b, c


@kernel
def hash_uint(kx):
    a = b = c = (0xDEADBEEF + (1 << 2) + 13) & M32
    a = (a + (kx & M32)) & M32
    a, b, c = _final(a, b, c)
    return c


@kernel
def hash_uint2(kx, ky):
    a = b = c = (0xDEADBEEF + (2 << 2) + 13) & M32
    b = (b + (ky & M32)) & M32
    a = (a + (kx & M32)) & M32
    a, b, c = _final(a, b, c)
    return c


@kernel
def hash_uint3(kx, ky, kz):
    a = b = c = (0xDEADBEEF + (3 << 2) + 13) & M32
    c = (c + (kz & M32)) & M32
    b = (b + (ky & M32)) & M32
    a = (a + (kx & M32)) & M32
    a, b, c = _final(a, b, c)
    return c


@kernel
def hash_uint4(kx, ky, kz, kw):
    a = b = c = (0xDEADBEEF + (4 << 2) + 13) & M32
    a = (a + (kx & M32)) & M32
    b = (b + (ky & M32)) & M32
    c = (c + (kz & M32)) & M32
    # mix(a, b, c)
    a = (a - c) & M32
    a ^= _rot(c, 4)
    c = (c + b) & M32
    b = (b - a) & M32
    b ^= _rot(a, 6)
    a = (a + c) & M32
    c = (c - b) & M32
    c ^= _rot(b, 8)
    b = (b + a) & M32
    a = (a - c) & M32
    a ^= _rot(c, 16)
    c = (c + b) & M32
    b = (b - a) & M32
    b ^= _rot(a, 19)
    a = (a + c) & M32
    c = (c - b) & M32
    c ^= _rot(b, 4)
    b = (b + a) & M32
    a = (a + (kw & M32)) & M32
    a, b, c = _final(a, b, c)
    return c


@inline_kernel
def _unit(h):
    """Cycles's uint_to_float_incl: (float)h · (1/(float)0xFFFFFFFF) = f32(h)·2⁻³²."""
    return f32(h) * 2.3283064365386963e-10


@kernel
def hash_f1(x):
    return _unit(hash_uint(float_bits(x)))


@kernel
def hash_f2(x, y):
    return _unit(hash_uint2(float_bits(x), float_bits(y)))


@kernel
def hash_f3(x, y, z):
    return _unit(hash_uint3(float_bits(x), float_bits(y), float_bits(z)))


@kernel
def hash_f4(x, y, z, w):
    return _unit(hash_uint4(float_bits(x), float_bits(y), float_bits(z), float_bits(w)))


@kernel
def hash_to_float(dim, x, y, z, w):
    """White Noise's Value: hash_float{,2,3,4}_to_float of the point."""
    if dim == 1:
        return hash_f1(w)
    if dim == 2:
        return hash_f2(x, y)
    if dim == 3:
        return hash_f3(x, y, z)
    return hash_f4(x, y, z, w)


@kernel
def hash_to_float3(dim, x, y, z, w):
    """White Noise's Color: hash_float{,2,3,4}_to_float3 of the point."""
    if dim == 1:
        return hash_f1(w), hash_f2(w, 1.0), hash_f2(w, 2.0)
    if dim == 2:
        return hash_f2(x, y), hash_f3(x, y, 1.0), hash_f3(x, y, 2.0)
    if dim == 3:
        return hash_f3(x, y, z), hash_f4(x, y, z, 1.0), hash_f4(x, y, z, 2.0)
    return hash_f4(x, y, z, w), hash_f4(z, x, w, y), hash_f4(w, z, y, x)


# --- PCG (Voronoi 2–4D) -------------------------------------------------------------------------

@inline_kernel
def _i32(x):
    """x wrapped to a signed 32-bit integer (C's int overflow)."""
    return ((x + 0x80000000) & M32) - 0x80000000


@kernel
def pcg(dim, x, y, z, w):
    """hash_pcg{2,3,4}d_i of the int cell (x, y[, z[, w]]) → four floats in [0, 1] (f32(h)·2⁻³¹
    as Cycles's hash_int*_to_float*; unused components 0)."""
    x = _i32(x * 1664525 + 1013904223)
    y = _i32(y * 1664525 + 1013904223)
    z = _i32(z * 1664525 + 1013904223)
    w = _i32(w * 1664525 + 1013904223)
    for rnd in range(2):
        if dim == 2:
            x = _i32(x + y * 1664525)
            y = _i32(y + x * 1664525)
        elif dim == 3:
            x = _i32(x + y * z)
            y = _i32(y + z * x)
            z = _i32(z + x * y)
        else:
            x = _i32(x + y * w)
            y = _i32(y + z * x)
            z = _i32(z + x * y)
            w = _i32(w + y * z)
        if rnd == 0:
            x ^= x >> 16
            y ^= y >> 16
            z ^= z >> 16
            w ^= w >> 16
    s = 4.656612873077393e-10  # 1 / (float)0x7FFFFFFF = 2⁻³¹
    x, y, z, w = x & 0x7FFFFFFF, y & 0x7FFFFFFF, z & 0x7FFFFFFF, w & 0x7FFFFFFF
    if dim == 2:
        return f32(x) * s, f32(y) * s, 0.0, 0.0
    if dim == 3:
        return f32(x) * s, f32(y) * s, f32(z) * s, 0.0
    return f32(x) * s, f32(y) * s, f32(z) * s, f32(w) * s


# --- Perlin noise -------------------------------------------------------------------------------

@inline_kernel
def _fade(t):
    return t * t * t * (t * (t * 6.0 - 15.0) + 10.0)


def _gradient_tables():
    """Cycles's grad1/2/3/4 as coefficient tables over the hash's low bits (a dot product with
    coefficients in {0, ±1, ±2}: exactly the same sums, without data-dependent branches, which
    mispredict on random hashes — measured 3× slower Perlin noise)."""
    g1 = np.array([(-1.0 if h & 8 else 1.0) * (1 + (h & 7)) for h in range(16)])
    g2 = np.zeros((8, 2))
    for h in range(8):
        u, v = (0, 1) if h < 4 else (1, 0)
        g2[h, u] += -1.0 if h & 1 else 1.0
        g2[h, v] += -2.0 if h & 2 else 2.0
    g3 = np.zeros((16, 3))
    for h in range(16):
        u = 0 if h < 8 else 1
        v = 1 if h < 4 else (0 if h in (12, 14) else 2)
        g3[h, u] += -1.0 if h & 1 else 1.0
        g3[h, v] += -1.0 if h & 2 else 1.0
    g4 = np.zeros((32, 4))
    for h in range(32):
        u, v, s = (0 if h < 24 else 1), (1 if h < 16 else 2), (2 if h < 8 else 3)
        g4[h, u] += -1.0 if h & 1 else 1.0
        g4[h, v] += -1.0 if h & 2 else 1.0
        g4[h, s] += -1.0 if h & 4 else 1.0
    return g1, g2, g3, g4


GRAD1, GRAD2, GRAD3, GRAD4 = _gradient_tables()


@inline_kernel
def _grad(dim, h, x, y, z, w):
    if dim == 1:
        return GRAD1[h & 15] * w
    if dim == 2:
        k = h & 7
        return GRAD2[k, 0] * x + GRAD2[k, 1] * y
    if dim == 3:
        k = h & 15
        return GRAD3[k, 0] * x + GRAD3[k, 1] * y + GRAD3[k, 2] * z
    k = h & 31
    return GRAD4[k, 0] * x + GRAD4[k, 1] * y + GRAD4[k, 2] * z + GRAD4[k, 3] * w


@inline_kernel
def _lerp(a, b, t):
    return (1.0 - t) * a + t * b


@kernel
def perlin(dim, x, y, z, w):
    """Cycles's perlin_{1,2,3,4}d (unscaled): gradients at the 2^dim lattice corners around the
    point, blended with the quintic fade (bi/tri/quad_mix). The corners' hashes and gradients
    of 2–4D come from ``lattice_simd`` (all corners at once, as vector lanes; the same values as
    ``hash_uint*`` and ``_grad``)."""
    if dim == 1:
        fw = floor64(w)
        W = int(fw)
        rw = w - fw
        return _lerp(_grad(1, hash_uint(W), 0.0, 0.0, 0.0, rw),
                     _grad(1, hash_uint(W + 1), 0.0, 0.0, 0.0, rw - 1.0), _fade(rw))
    fx, fy = floor64(x), floor64(y)
    X, Y = int(fx), int(fy)
    rx, ry = x - fx, y - fy
    u, v = _fade(rx), _fade(ry)
    if dim == 2:
        g = corner_gradients2(X, Y, rx, ry)
        return _lerp(_lerp(g[0], g[1], u), _lerp(g[2], g[3], u), v)
    fz = floor64(z)
    Z = int(fz)
    rz = z - fz
    t = _fade(rz)
    if dim == 3:
        g = corner_gradients3(X, Y, Z, rx, ry, rz)
        return _lerp(_lerp(_lerp(g[0], g[1], u), _lerp(g[2], g[3], u), v),
                     _lerp(_lerp(g[4], g[5], u), _lerp(g[6], g[7], u), v), t)
    fw = floor64(w)
    W = int(fw)
    rw = w - fw
    s = _fade(rw)
    g = corner_gradients4(X, Y, Z, W, rx, ry, rz, rw)
    a = _lerp(_lerp(_lerp(g[0], g[1], u), _lerp(g[2], g[3], u), v),
              _lerp(_lerp(g[4], g[5], u), _lerp(g[6], g[7], u), v), t)
    b = _lerp(_lerp(_lerp(g[8], g[9], u), _lerp(g[10], g[11], u), v),
              _lerp(_lerp(g[12], g[13], u), _lerp(g[14], g[15], u), v), t)
    return a * (1.0 - s) + b * s


@inline_kernel
def _wrap_coord(p):
    """Cycles's snoise wrapping: fmod(p, 100000) + 0.5 when |p| ≥ 1e6 (float32); the identity
    below 100000 (fmod is slow: skipped there)."""
    p = f32(p)
    if abs(p) < 100000.0:
        return p
    corr = 0.5 if abs(p) >= 1000000.0 else 0.0
    return f32(np.fmod(p, 100000.0) + corr)


@kernel
def snoise(dim, x, y, z, w):
    """Signed noise in about [−1, 1]: Cycles's snoise_{1,2,3,4}d (scaled perlin)."""
    if dim == 1 or dim == 4:
        w = _wrap_coord(w)
    if dim > 1:
        x, y = _wrap_coord(x), _wrap_coord(y)
        if dim > 2:
            z = _wrap_coord(z)
    r = perlin(dim, x, y, z, w)
    if dim == 1:
        return 0.25 * r
    if dim == 2:
        return 0.6616 * r
    if dim == 3:
        return 0.9820 * r
    return 0.8344 * r


# --- fractal noise ------------------------------------------------------------------------------

@kernel
def noise_fbm(dim, x, y, z, w, detail, roughness, lacunarity, normalize):
    fscale = 1.0
    amp = 1.0
    maxamp = 0.0
    total = 0.0
    for _ in range(int(detail) + 1):
        t = snoise(dim, f32(fscale * x), f32(fscale * y), f32(fscale * z), f32(fscale * w))
        total += t * amp
        maxamp += amp
        amp = f32(amp * roughness)
        fscale = f32(fscale * lacunarity)
    rmd = detail - floor64(detail)
    if rmd != 0.0:
        t = snoise(dim, f32(fscale * x), f32(fscale * y), f32(fscale * z), f32(fscale * w))
        sum2 = total + t * amp
        if normalize:
            a = 0.5 * total / maxamp + 0.5
            b = 0.5 * sum2 / (maxamp + amp) + 0.5
            return (1.0 - rmd) * a + rmd * b
        return (1.0 - rmd) * total + rmd * sum2
    return 0.5 * total / maxamp + 0.5 if normalize else total


@kernel
def noise_multi_fractal(dim, x, y, z, w, detail, roughness, lacunarity):
    value = 1.0
    pwr = 1.0
    for _ in range(int(detail) + 1):
        value *= pwr * snoise(dim, x, y, z, w) + 1.0
        pwr = f32(pwr * roughness)
        x, y, z, w = f32(x * lacunarity), f32(y * lacunarity), f32(z * lacunarity), f32(w * lacunarity)
    rmd = detail - floor64(detail)
    if rmd != 0.0:
        value *= rmd * pwr * snoise(dim, x, y, z, w) + 1.0
    return value


@kernel
def noise_hetero_terrain(dim, x, y, z, w, detail, roughness, lacunarity, offset):
    pwr = roughness
    value = offset + snoise(dim, x, y, z, w)
    x, y, z, w = f32(x * lacunarity), f32(y * lacunarity), f32(z * lacunarity), f32(w * lacunarity)
    for _ in range(1, int(detail) + 1):
        value += (snoise(dim, x, y, z, w) + offset) * pwr * value
        pwr = f32(pwr * roughness)
        x, y, z, w = f32(x * lacunarity), f32(y * lacunarity), f32(z * lacunarity), f32(w * lacunarity)
    rmd = detail - floor64(detail)
    if rmd != 0.0:
        value += rmd * ((snoise(dim, x, y, z, w) + offset) * pwr * value)
    return value


@kernel
def noise_hybrid_multi_fractal(dim, x, y, z, w, detail, roughness, lacunarity, offset, gain):
    pwr = 1.0
    value = 0.0
    weight = 1.0
    i = 0
    while weight > 0.001 and i <= int(detail):
        weight = min(weight, 1.0)
        signal = (snoise(dim, x, y, z, w) + offset) * pwr
        pwr = f32(pwr * roughness)
        value += weight * signal
        weight *= gain * signal
        x, y, z, w = f32(x * lacunarity), f32(y * lacunarity), f32(z * lacunarity), f32(w * lacunarity)
        i += 1
    rmd = detail - floor64(detail)
    if rmd != 0.0 and weight > 0.001:
        weight = min(weight, 1.0)
        value += rmd * weight * ((snoise(dim, x, y, z, w) + offset) * pwr)
    return value


@kernel
def noise_ridged_multi_fractal(dim, x, y, z, w, detail, roughness, lacunarity, offset, gain):
    pwr = roughness
    signal = offset - abs(snoise(dim, x, y, z, w))
    signal *= signal
    value = signal
    for _ in range(1, int(detail) + 1):
        x, y, z, w = f32(x * lacunarity), f32(y * lacunarity), f32(z * lacunarity), f32(w * lacunarity)
        weight = min(max(signal * gain, 0.0), 1.0)
        signal = offset - abs(snoise(dim, x, y, z, w))
        signal *= signal
        signal *= weight
        value += signal * pwr
        pwr = f32(pwr * roughness)
    return value


@kernel
def noise_select(kind, dim, x, y, z, w, detail, roughness, lacunarity, offset, gain, normalize):
    if kind == NOISE_MULTIFRACTAL:
        return noise_multi_fractal(dim, x, y, z, w, detail, roughness, lacunarity)
    if kind == NOISE_FBM:
        return noise_fbm(dim, x, y, z, w, detail, roughness, lacunarity, normalize)
    if kind == NOISE_HYBRID:
        return noise_hybrid_multi_fractal(dim, x, y, z, w, detail, roughness, lacunarity, offset, gain)
    if kind == NOISE_RIDGED:
        return noise_ridged_multi_fractal(dim, x, y, z, w, detail, roughness, lacunarity, offset, gain)
    return noise_hetero_terrain(dim, x, y, z, w, detail, roughness, lacunarity, offset)


@kernel
def _offset(dim, seed):
    """random_float{,2,3,4}_offset(seed) as (x, y, z, w), 100 + 100·hash in float32 (1D: the w
    component; unused components 0)."""
    if dim == 1:
        return 0.0, 0.0, 0.0, f32(100.0 + f32(hash_f1(seed) * 100.0))
    ox = f32(100.0 + f32(hash_f2(seed, 0.0) * 100.0))
    oy = f32(100.0 + f32(hash_f2(seed, 1.0) * 100.0))
    oz = f32(100.0 + f32(hash_f2(seed, 2.0) * 100.0)) if dim > 2 else 0.0
    ow = f32(100.0 + f32(hash_f2(seed, 3.0) * 100.0)) if dim > 3 else 0.0
    return ox, oy, oz, ow


@kernel
def noise_texture(kind, dim, x, y, z, w, detail, roughness, lacunarity, offset, gain, distortion,
                  normalize, want_color):
    """Cycles's noise_texture_{1,2,3,4}d on the scaled point: (value, g, b); the Color output is
    (value, g, b) (g = b = 0 unless want_color)."""
    if distortion != 0.0:
        d0 = d1 = d2 = d3 = 0.0
        for i in range(dim):
            o = _offset(dim, float(i))
            n = snoise(dim, f32(x + o[0]), f32(y + o[1]), f32(z + o[2]), f32(w + o[3])) * distortion
            if dim == 1 or i == 3:
                d3 = n
            elif i == 0:
                d0 = n
            elif i == 1:
                d1 = n
            else:
                d2 = n
        x, y, z, w = f32(x + d0), f32(y + d1), f32(z + d2), f32(w + d3)
    value = noise_select(kind, dim, x, y, z, w, detail, roughness, lacunarity, offset, gain, normalize)
    g = b = 0.0
    if want_color:
        o = _offset(dim, float(dim))
        g = noise_select(kind, dim, f32(x + o[0]), f32(y + o[1]), f32(z + o[2]), f32(w + o[3]), detail,
                         roughness, lacunarity, offset, gain, normalize)
        o = _offset(dim, float(dim + 1))
        b = noise_select(kind, dim, f32(x + o[0]), f32(y + o[1]), f32(z + o[2]), f32(w + o[3]), detail,
                         roughness, lacunarity, offset, gain, normalize)
    return value, g, b


# --- Voronoi ------------------------------------------------------------------------------------

@kernel
def _vdist(dim, metric, exponent, dx, dy, dz, dw, bound):
    """voronoi_distance (bound: voronoi_distance_bound, the comparison-only form) of the
    difference vector over the first ``dim`` components (dim 1: |dw|)."""
    if dim == 1:
        return abs(dw)
    if dim < 3:
        dz = 0.0
    if dim < 4:
        dw = 0.0
    if metric == METRIC_EUCLIDEAN:
        s = dx * dx + dy * dy + dz * dz + dw * dw
        return s if bound else math.sqrt(s)
    ax, ay, az, aw = abs(dx), abs(dy), abs(dz), abs(dw)
    if metric == METRIC_MANHATTAN:
        return ax + ay + az + aw
    if metric == METRIC_CHEBYCHEV:
        return max(max(ax, ay), max(az, aw))
    s = math.pow(ax, exponent) + math.pow(ay, exponent)
    if dim >= 3:
        s += math.pow(az, exponent)
    if dim == 4:
        s += math.pow(aw, exponent)
    return s if bound else math.pow(s, 1.0 / exponent)


@kernel
def _cell_point(dim, cx, cy, cz, cw, randomness):
    """The feature point of integer cell (cx..cw) relative to the cell's corner (for dim 1 the
    cell is cw, hashed by its float bits as Cycles's 1D Voronoi)."""
    if dim == 1:
        return 0.0, 0.0, 0.0, hash_f1(float(cw)) * randomness
    h = pcg(dim, cx, cy, cz, cw)
    return h[0] * randomness, h[1] * randomness, h[2] * randomness, h[3] * randomness


@kernel
def _cell_color(dim, cx, cy, cz, cw):
    if dim == 1:
        c = float(cw)
        return hash_f1(c), hash_f2(c, 1.0), hash_f2(c, 2.0)
    if dim == 2:
        h = pcg(3, cx, cy, 0, 0)
    else:
        h = pcg(dim, cx, cy, cz, cw)
    return h[0], h[1], h[2]


@inline_kernel
def _span(dim, axis, r):
    """Offsets −r..r along an axis the dimension uses, else just 0."""
    used = (axis == 3) if dim == 1 else axis < dim
    return r if used else 0


@inline_kernel
def _gap(o, local, randomness):
    """Distance along one axis from ``local`` to the span [o, o + randomness] of a neighbour
    cell's feature point (0 inside)."""
    return max(0.0, o - local, local - (o + randomness))


@kernel
def voronoi_octave(dim, feature, metric, exponent, randomness, smoothness, x, y, z, w):
    """One octave (F1, F2 or smooth F1) at the point: (distance, colour r, g, b, position x, y,
    z, w) — Cycles's voronoi_f1 / voronoi_f2 / voronoi_smooth_f1."""
    fx, fy, fz, fw = floor64(x), floor64(y), floor64(z), floor64(w)
    cx, cy, cz, cw = int(fx), int(fy), int(fz), int(fw)
    lx, ly, lz, lw = x - fx, y - fy, z - fz, w - fw
    if feature == VORONOI_SMOOTH_F1:
        r = 2
        sd = 0.0
        sc0 = sc1 = sc2 = 0.0
        sp0 = sp1 = sp2 = sp3 = 0.0
        h = -1.0
        for ow in range(-_span(dim, 3, r), _span(dim, 3, r) + 1):
            for oz in range(-_span(dim, 2, r), _span(dim, 2, r) + 1):
                for oy in range(-_span(dim, 1, r), _span(dim, 1, r) + 1):
                    for ox in range(-_span(dim, 0, r), _span(dim, 0, r) + 1):
                        p = _cell_point(dim, cx + ox, cy + oy, cz + oz, cw + ow, randomness)
                        px, py, pz, pw = ox + p[0], oy + p[1], oz + p[2], ow + p[3]
                        d = _vdist(dim, metric, exponent, px - lx, py - ly, pz - lz, pw - lw, False)
                        if h == -1.0:
                            h = 1.0
                        else:
                            e = 0.5 + 0.5 * (sd - d) / smoothness
                            h = 0.0 if e < 0.0 else (1.0 if e >= 1.0 else (3.0 - 2.0 * e) * (e * e))
                        corr = smoothness * h * (1.0 - h)
                        sd = (1.0 - h) * sd + h * d - corr
                        corr /= 1.0 + 3.0 * smoothness
                        col = _cell_color(dim, cx + ox, cy + oy, cz + oz, cw + ow)
                        sc0 = (1.0 - h) * sc0 + h * col[0] - corr
                        sc1 = (1.0 - h) * sc1 + h * col[1] - corr
                        sc2 = (1.0 - h) * sc2 + h * col[2] - corr
                        sp0 = (1.0 - h) * sp0 + h * px - corr
                        sp1 = (1.0 - h) * sp1 + h * py - corr
                        sp2 = (1.0 - h) * sp2 + h * pz - corr
                        sp3 = (1.0 - h) * sp3 + h * pw - corr
        pos = _position(dim, fx + sp0, fy + sp1, fz + sp2, fw + sp3)
        return sd, sc0, sc1, sc2, pos[0], pos[1], pos[2], pos[3]
    # F1 (searching with the bound distance in 2–4D, as Cycles) or F2
    bound = feature == VORONOI_F1 and dim > 1
    d1 = d2 = FLT_MAX
    o1 = (0, 0, 0, 0)
    o2 = (0, 0, 0, 0)
    p1 = (0.0, 0.0, 0.0, 0.0)
    p2 = (0.0, 0.0, 0.0, 0.0)
    # F1 prunes: a cell whose nearest possible point (its points lie in [o, o + randomness] per
    # axis) is farther than the centre cell's point cannot hold the minimum, and skipping it does
    # not change which cell first reaches the minimum (Cycles's strict '<' scan order)
    limit = FLT_MAX
    if bound:
        p = _cell_point(dim, cx, cy, cz, cw, randomness)
        limit = _vdist(dim, metric, exponent, p[0] - lx, p[1] - ly, p[2] - lz, p[3] - lw, True)
    for ow in range(-_span(dim, 3, 1), _span(dim, 3, 1) + 1):
        for oz in range(-_span(dim, 2, 1), _span(dim, 2, 1) + 1):
            for oy in range(-_span(dim, 1, 1), _span(dim, 1, 1) + 1):
                for ox in range(-_span(dim, 0, 1), _span(dim, 0, 1) + 1):
                    if bound and _vdist(dim, metric, exponent, _gap(ox, lx, randomness), _gap(oy, ly, randomness),
                                        _gap(oz, lz, randomness), _gap(ow, lw, randomness), True) > limit:
                        continue
                    p = _cell_point(dim, cx + ox, cy + oy, cz + oz, cw + ow, randomness)
                    pp = (ox + p[0], oy + p[1], oz + p[2], ow + p[3])
                    d = _vdist(dim, metric, exponent, pp[0] - lx, pp[1] - ly, pp[2] - lz, pp[3] - lw, bound)
                    if d < d1:
                        d2, o2, p2 = d1, o1, p1
                        d1, o1, p1 = d, (ox, oy, oz, ow), pp
                    elif d < d2:
                        d2, o2, p2 = d, (ox, oy, oz, ow), pp
    if feature == VORONOI_F1:
        d, o, pp = d1, o1, p1
        if bound:
            d = _vdist(dim, metric, exponent, pp[0] - lx, pp[1] - ly, pp[2] - lz, pp[3] - lw, False)
    else:
        d, o, pp = d2, o2, p2
    col = _cell_color(dim, cx + o[0], cy + o[1], cz + o[2], cw + o[3])
    pos = _position(dim, pp[0] + fx, pp[1] + fy, pp[2] + fz, pp[3] + fw)
    return d, col[0], col[1], col[2], pos[0], pos[1], pos[2], pos[3]


@inline_kernel
def _position(dim, x, y, z, w):
    """voronoi_position: the output point as (x, y, z, w) with unused components 0."""
    if dim == 1:
        return 0.0, 0.0, 0.0, w
    if dim == 2:
        return x, y, 0.0, 0.0
    if dim == 3:
        return x, y, z, 0.0
    return x, y, z, w


# The common Euclidean F1 / F2 cases in 2D and 3D: the 3^dim cells' hashes and distances as
# vector lanes (``lattice_simd.cell_distances*``), then the same strict-'<' scan in Cycles's
# order over them (no pruning needed: all distances are there), the same final steps as
# ``voronoi_octave``. Same values (tests/test_procedural_kernels.py compares the two).

@inline_kernel
def _nearest_two(d):
    """(F1 distance, its cell, F2 distance, its cell) of a tuple of cell distances, scanned in
    order with strict '<' (Cycles's tie rule)."""
    d1 = d2 = FLT_MAX
    k1 = k2 = len(d) // 2  # (the centre cell when nothing is nearer, as the scalar scan)
    for k in range(len(d)):
        if d[k] < d1:
            d2, k2 = d1, k1
            d1, k1 = d[k], k
        elif d[k] < d2:
            d2, k2 = d[k], k
    return d1, k1, d2, k2


@kernel
def _octave_result(dim, feature, randomness, cx, cy, cz, fx, fy, fz, lx, ly, lz, k, dist):
    """voronoi_octave's outputs for the chosen cell k (x fastest) of the 3^dim around (cx, cy, cz);
    an F1 distance is recomputed unsquared from the point, as the scalar octave does."""
    ox, oy, oz = k % 3 - 1, (k // 3) % 3 - 1, (k // 9) - 1 if dim == 3 else 0
    p = _cell_point(dim, cx + ox, cy + oy, cz + oz, 0, randomness)
    px, py, pz = ox + p[0], oy + p[1], oz + p[2]
    if feature == VORONOI_F1:
        dist = _vdist(dim, METRIC_EUCLIDEAN, 1.0, px - lx, py - ly, pz - lz, 0.0, False)
    col = _cell_color(dim, cx + ox, cy + oy, cz + oz, 0)
    pos = _position(dim, px + fx, py + fy, pz + fz, 0.0)
    return dist, col[0], col[1], col[2], pos[0], pos[1], pos[2], pos[3]


@kernel
def _octave_euclidean2(feature, randomness, x, y):
    fx, fy = floor64(x), floor64(y)
    cx, cy = int(fx), int(fy)
    lx, ly = x - fx, y - fy
    if feature == VORONOI_F1:
        d = cell_distances2_sq(cx, cy, lx, ly, randomness)
    else:
        d = cell_distances2(cx, cy, lx, ly, randomness)
    d1, k1, d2, k2 = _nearest_two(d)
    return _octave_result(2, feature, randomness, cx, cy, 0, fx, fy, 0.0, lx, ly, 0.0,
                          k1 if feature == VORONOI_F1 else k2, d1 if feature == VORONOI_F1 else d2)


@kernel
def _octave_euclidean3(feature, randomness, x, y, z):
    fx, fy, fz = floor64(x), floor64(y), floor64(z)
    cx, cy, cz = int(fx), int(fy), int(fz)
    lx, ly, lz = x - fx, y - fy, z - fz
    if feature == VORONOI_F1:
        d = cell_distances3_sq(cx, cy, cz, lx, ly, lz, randomness)
    else:
        d = cell_distances3(cx, cy, cz, lx, ly, lz, randomness)
    d1, k1, d2, k2 = _nearest_two(d)
    return _octave_result(3, feature, randomness, cx, cy, cz, fx, fy, fz, lx, ly, lz,
                          k1 if feature == VORONOI_F1 else k2, d1 if feature == VORONOI_F1 else d2)


@inline_kernel
def _octave(dim, feature, metric, exponent, randomness, smoothness, x, y, z, w):
    """``voronoi_octave``, through a specialised copy where there is one."""
    if metric == METRIC_EUCLIDEAN and (dim == 2 or dim == 3) and (feature == VORONOI_F1 or feature == VORONOI_F2):
        if dim == 3:
            return _octave_euclidean3(feature, randomness, x, y, z)
        return _octave_euclidean2(feature, randomness, x, y)
    return voronoi_octave(dim, feature, metric, exponent, randomness, smoothness, x, y, z, w)


@kernel
def voronoi_edge(dim, randomness, x, y, z, w):
    """Cycles's voronoi_distance_to_edge (Euclidean, whatever the metric)."""
    fx, fy, fz, fw = floor64(x), floor64(y), floor64(z), floor64(w)
    cx, cy, cz, cw = int(fx), int(fy), int(fz), int(fw)
    lx, ly, lz, lw = x - fx, y - fy, z - fz, w - fw
    if dim == 1:
        mid = hash_f1(fw) * randomness
        left = -1.0 + hash_f1(fw - 1.0) * randomness
        right = 1.0 + hash_f1(fw + 1.0) * randomness
        return min(abs((mid + left) / 2.0 - lw), abs((mid + right) / 2.0 - lw))
    best = FLT_MAX
    vx = vy = vz = vw = 0.0
    for ow in range(-_span(dim, 3, 1), _span(dim, 3, 1) + 1):
        for oz in range(-_span(dim, 2, 1), _span(dim, 2, 1) + 1):
            for oy in range(-_span(dim, 1, 1), _span(dim, 1, 1) + 1):
                for ox in range(-_span(dim, 0, 1), _span(dim, 0, 1) + 1):
                    p = _cell_point(dim, cx + ox, cy + oy, cz + oz, cw + ow, randomness)
                    ax, ay, az, aw = ox + p[0] - lx, oy + p[1] - ly, oz + p[2] - lz, ow + p[3] - lw
                    if dim < 4:
                        aw = 0.0
                    if dim < 3:
                        az = 0.0
                    d = ax * ax + ay * ay + az * az + aw * aw
                    if d < best:
                        best = d
                        vx, vy, vz, vw = ax, ay, az, aw
    best = FLT_MAX
    for ow in range(-_span(dim, 3, 1), _span(dim, 3, 1) + 1):
        for oz in range(-_span(dim, 2, 1), _span(dim, 2, 1) + 1):
            for oy in range(-_span(dim, 1, 1), _span(dim, 1, 1) + 1):
                for ox in range(-_span(dim, 0, 1), _span(dim, 0, 1) + 1):
                    p = _cell_point(dim, cx + ox, cy + oy, cz + oz, cw + ow, randomness)
                    ax, ay, az, aw = ox + p[0] - lx, oy + p[1] - ly, oz + p[2] - lz, ow + p[3] - lw
                    if dim < 4:
                        aw = 0.0
                    if dim < 3:
                        az = 0.0
                    qx, qy, qz, qw = ax - vx, ay - vy, az - vz, aw - vw
                    q2 = qx * qx + qy * qy + qz * qz + qw * qw
                    if q2 > 0.0001:
                        inv = 1.0 / math.sqrt(q2)
                        e = ((vx + ax) * qx + (vy + ay) * qy + (vz + az) * qz + (vw + aw) * qw) * 0.5 * inv
                        best = min(best, e)
    return best


@kernel
def voronoi_radius(dim, randomness, x, y, z, w):
    """Cycles's voronoi_n_sphere_radius: half the distance from the nearest feature point to its
    own nearest neighbour (Euclidean)."""
    fx, fy, fz, fw = floor64(x), floor64(y), floor64(z), floor64(w)
    cx, cy, cz, cw = int(fx), int(fy), int(fz), int(fw)
    lx, ly, lz, lw = x - fx, y - fy, z - fz, w - fw
    best = FLT_MAX
    cp = (0.0, 0.0, 0.0, 0.0)
    co = (0, 0, 0, 0)
    for ow in range(-_span(dim, 3, 1), _span(dim, 3, 1) + 1):
        for oz in range(-_span(dim, 2, 1), _span(dim, 2, 1) + 1):
            for oy in range(-_span(dim, 1, 1), _span(dim, 1, 1) + 1):
                for ox in range(-_span(dim, 0, 1), _span(dim, 0, 1) + 1):
                    p = _cell_point(dim, cx + ox, cy + oy, cz + oz, cw + ow, randomness)
                    pp = (ox + p[0], oy + p[1], oz + p[2], ow + p[3])
                    d = _vdist(dim, METRIC_EUCLIDEAN, 1.0, pp[0] - lx, pp[1] - ly, pp[2] - lz, pp[3] - lw, True)
                    if d < best:
                        best, cp, co = d, pp, (ox, oy, oz, ow)
    best = FLT_MAX
    q = (0.0, 0.0, 0.0, 0.0)
    for ow in range(-_span(dim, 3, 1), _span(dim, 3, 1) + 1):
        for oz in range(-_span(dim, 2, 1), _span(dim, 2, 1) + 1):
            for oy in range(-_span(dim, 1, 1), _span(dim, 1, 1) + 1):
                for ox in range(-_span(dim, 0, 1), _span(dim, 0, 1) + 1):
                    if ox == 0 and oy == 0 and oz == 0 and ow == 0:
                        continue
                    ax, ay, az, aw = ox + co[0], oy + co[1], oz + co[2], ow + co[3]
                    p = _cell_point(dim, cx + ax, cy + ay, cz + az, cw + aw, randomness)
                    pp = (ax + p[0], ay + p[1], az + p[2], aw + p[3])
                    d = _vdist(dim, METRIC_EUCLIDEAN, 1.0, cp[0] - pp[0], cp[1] - pp[1], cp[2] - pp[2],
                               cp[3] - pp[3], True)
                    if d < best:
                        best, q = d, pp
    return _vdist(dim, METRIC_EUCLIDEAN, 1.0, q[0] - cp[0], q[1] - cp[1], q[2] - cp[2], q[3] - cp[3],
                  False) / 2.0


@kernel
def voronoi_texture(dim, feature, metric, normalize, x, y, z, w, scale, detail, roughness,
                    lacunarity, smoothness, exponent, randomness):
    """Cycles's svm_node_tex_voronoi on the *unscaled* point: (distance or radius, colour r, g,
    b, position x, y, z, w), fractal over ``detail`` octaves (Blender 4.0+)."""
    detail = min(max(detail, 0.0), 15.0)
    roughness = min(max(roughness, 0.0), 1.0)
    randomness = min(max(randomness, 0.0), 1.0)
    smoothness = min(max(smoothness / 2.0, 0.0), 0.5)
    x, y, z, w = f32(x * scale), f32(y * scale), f32(z * scale), f32(w * scale)
    zero_input = detail == 0.0 or roughness == 0.0
    n_oct = int(math.ceil(detail)) + 1
    if feature == VORONOI_RADIUS:
        return voronoi_radius(dim, randomness, x, y, z, w), 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    r = 0.5 + 0.5 * randomness
    if feature == VORONOI_EDGE:
        max_d = r
        amp = 1.0
        maxamp = max_d
        sc = 1.0
        dist = 8.0
        for i in range(n_oct):
            od = voronoi_edge(dim, randomness, f32(x * sc), f32(y * sc), f32(z * sc), f32(w * sc))
            if zero_input:
                dist = od
                break
            if i <= detail:
                maxamp = (1.0 - amp) * maxamp + amp * (max_d / sc)
                dist = (1.0 - amp) * dist + amp * min(dist, od / sc)
                sc = f32(sc * lacunarity)
                amp = f32(amp * roughness)
            else:
                rem = detail - floor64(detail)
                if rem != 0.0:
                    la = (1.0 - amp) * maxamp + amp * (max_d / sc)
                    maxamp = (1.0 - rem) * maxamp + rem * la
                    ld = (1.0 - amp) * dist + amp * min(dist, od / sc)
                    dist = (1.0 - rem) * dist + rem * min(dist, ld)
        if normalize:
            dist /= maxamp
        return dist, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    if dim == 1:
        max_d = r
    else:
        max_d = _vdist(dim, metric, exponent, r, r, r, r, False)
    if feature == VORONOI_F2:
        max_d *= 2.0
    feat = VORONOI_F1 if (feature == VORONOI_SMOOTH_F1 and smoothness == 0.0) else feature
    amp = 1.0
    maxamp = 0.0
    sc = 1.0
    od = c0 = c1 = c2 = 0.0
    q0 = q1 = q2 = q3 = 0.0
    for i in range(n_oct):
        o = _octave(dim, feat, metric, exponent, randomness, smoothness,
                    f32(x * sc), f32(y * sc), f32(z * sc), f32(w * sc))
        if zero_input:
            maxamp = 1.0
            od, c0, c1, c2, q0, q1, q2, q3 = o
            break
        if i <= detail:
            maxamp += amp
            od += o[0] * amp
            c0 += o[1] * amp
            c1 += o[2] * amp
            c2 += o[3] * amp
            q0 = (1.0 - amp) * q0 + amp * (o[4] / sc)
            q1 = (1.0 - amp) * q1 + amp * (o[5] / sc)
            q2 = (1.0 - amp) * q2 + amp * (o[6] / sc)
            q3 = (1.0 - amp) * q3 + amp * (o[7] / sc)
            sc = f32(sc * lacunarity)
            amp = f32(amp * roughness)
        else:
            rem = detail - floor64(detail)
            if rem != 0.0:
                maxamp = (1.0 - rem) * maxamp + rem * (maxamp + amp)
                od = (1.0 - rem) * od + rem * (od + o[0] * amp)
                c0 = (1.0 - rem) * c0 + rem * (c0 + o[1] * amp)
                c1 = (1.0 - rem) * c1 + rem * (c1 + o[2] * amp)
                c2 = (1.0 - rem) * c2 + rem * (c2 + o[3] * amp)
                q0 = (1.0 - rem) * q0 + rem * ((1.0 - amp) * q0 + amp * (o[4] / sc))
                q1 = (1.0 - rem) * q1 + rem * ((1.0 - amp) * q1 + amp * (o[5] / sc))
                q2 = (1.0 - rem) * q2 + rem * ((1.0 - amp) * q2 + amp * (o[6] / sc))
                q3 = (1.0 - rem) * q3 + rem * ((1.0 - amp) * q3 + amp * (o[7] / sc))
    if normalize:
        od /= maxamp * max_d
        c0 /= maxamp
        c1 /= maxamp
        c2 /= maxamp
    if scale != 0.0:
        q0, q1, q2, q3 = q0 / scale, q1 / scale, q2 / scale, q3 / scale
    else:
        q0 = q1 = q2 = q3 = 0.0
    return od, c0, c1, c2, q0, q1, q2, q3


# --- Wave, Magic, Brick -------------------------------------------------------------------------

@kernel
def wave(kind, bands_dir, rings_dir, profile, x, y, z, distortion, detail, dscale, droughness, phase):
    """Cycles's svm_wave on the scaled point (kind 0 bands / 1 rings; directions X, Y, Z,
    diagonal|spherical = 0..3; profile sine/saw/triangle = 0..2)."""
    x, y, z = f32(f32(x + 0.000001) * 0.999999), f32(f32(y + 0.000001) * 0.999999), f32(f32(z + 0.000001) * 0.999999)
    if kind == 0:
        if bands_dir == 0:
            n = x * 20.0
        elif bands_dir == 1:
            n = y * 20.0
        elif bands_dir == 2:
            n = z * 20.0
        else:
            n = (x + y + z) * 10.0
    else:
        rx, ry, rz = x, y, z
        if rings_dir == 0:
            rx = 0.0
        elif rings_dir == 1:
            ry = 0.0
        elif rings_dir == 2:
            rz = 0.0
        n = math.sqrt(rx * rx + ry * ry + rz * rz) * 20.0
    n += phase
    if distortion != 0.0:
        # w and normalize typed as noise_select passes them (float32, int): one compiled noise_fbm
        n += distortion * (noise_fbm(3, f32(x * dscale), f32(y * dscale), f32(z * dscale), f32(0.0), detail,
                                     droughness, 2.0, 1) * 2.0 - 1.0)
    if profile == 0:
        return 0.5 + 0.5 * math.sin(n - math.pi / 2.0)
    n /= 2.0 * math.pi
    if profile == 1:
        return n - floor64(n)
    return abs(n - floor64(n + 0.5)) * 2.0


@inline_kernel
def _s(x):
    """sinf of a float32 argument, rounded to float32 (glibc's sinf is correctly rounded in
    practice: float64 sin then one rounding gives the same float)."""
    return f32(math.sin(x))


@inline_kernel
def _c(x):
    return f32(math.cos(x))


@inline_kernel
def _fmod_2pi(x):
    """fmodf(x, M_2PI_F) of x rounded to float32; fmod is the identity below the modulus (and a
    libm call costs ~10 ns), so that case skips it: the same value."""
    tau = 6.2831854820251465  # M_2PI_F
    x = f32(x)
    if abs(x) < tau:
        return x
    return f32(np.fmod(x, tau))


@kernel
def magic(x, y, z, scale, depth, distortion):
    """Cycles 5.0's svm_magic (the periodic reduction before the scale, as 5.0 does), in
    emulated float32: every operation rounds to float32 like Cycles's, because at high depth and
    distortion (> 1) the iteration is chaotic and float64 would drift to another value."""
    px, py, pz = _fmod_2pi(x), _fmod_2pi(y), _fmod_2pi(z)
    s5 = f32(5.0)
    scale = f32(scale)
    d = f32(distortion)
    a = _s(f32(f32(f32(f32(px + py) + pz) * s5) * scale))
    b = _c(f32(f32(f32(f32(-px + py) - pz) * s5) * scale))
    c = -_c(f32(f32(f32(f32(-px - py) + pz) * s5) * scale))
    if depth > 0:
        a = f32(a * d)
        b = f32(b * d)
        c = f32(c * d)
        b = f32(-_c(f32(f32(a - b) + c)) * d)
        if depth > 1:
            a = f32(_c(f32(f32(a - b) - c)) * d)
            if depth > 2:
                c = f32(_s(f32(f32(-a - b) - c)) * d)
                if depth > 3:
                    a = f32(-_c(f32(f32(-a + b) - c)) * d)
                    if depth > 4:
                        b = f32(-_s(f32(f32(-a + b) + c)) * d)
                        if depth > 5:
                            b = f32(-_c(f32(f32(-a + b) + c)) * d)
                            if depth > 6:
                                a = f32(_c(f32(f32(a + b) + c)) * d)
                                if depth > 7:
                                    c = f32(_s(f32(f32(a + b) - c)) * d)
                                    if depth > 8:
                                        a = f32(-_c(f32(f32(-a - b) + c)) * d)
                                        if depth > 9:
                                            b = f32(-_s(f32(f32(a - b) + c)) * d)
    if d != 0.0:
        d2 = f32(d * 2.0)
        a = f32(a / d2)
        b = f32(b / d2)
        c = f32(c / d2)
    return 0.5 - a, 0.5 - b, 0.5 - c


@kernel
def brick_noise(n):
    """Cycles's integer brick noise on a uint32 (int64 masked)."""
    n = (n + 1013) & 0x7FFFFFFF
    n = (n >> 13) ^ n
    inner = ((((n * n) & M32) * 60493) + 19990303) & M32
    nn = ((n * inner) + 1376312589) & 0x7FFFFFFF
    return 0.5 * (f32(nn) / 1073741824.0)


@kernel
def brick(x, y, mortar_size, mortar_smooth, bias, brick_width, row_height, offset_amount,
          offset_frequency, squash_amount, squash_frequency):
    """Cycles's svm_brick on the scaled point: (tint, mortar factor)."""
    x, y = f32(x), f32(y)
    rownum = int(floor64(f32(y / row_height)))
    offset = 0.0
    if offset_frequency and squash_frequency:
        if rownum % squash_frequency == 0:
            brick_width = f32(brick_width * squash_amount)
        offset = 0.0 if rownum % offset_frequency else f32(brick_width * offset_amount)
    xo = f32(x + offset)
    bricknum = int(floor64(f32(xo / brick_width)))
    bx = f32(xo - f32(brick_width * bricknum))
    by = f32(y - f32(row_height * rownum))
    tint = min(max(brick_noise(((rownum << 16) + (bricknum & 0xFFFF)) & M32) + bias, 0.0), 1.0)
    min_dist = min(min(bx, by), min(brick_width - bx, row_height - by))
    if min_dist >= mortar_size:
        mortar = 0.0
    elif mortar_smooth == 0.0:
        mortar = 1.0
    else:
        t = (1.0 - min_dist / mortar_size) / mortar_smooth
        if t <= 0.0:
            mortar = 0.0
        elif t >= 1.0:
            mortar = 1.0
        else:
            tt = t * t
            mortar = 3.0 * tt - 2.0 * tt * t
    return tint, mortar


# --- curves (RGB / Vector / Float Curve) --------------------------------------------------------

@kernel
def curve_lookup(data, off, ch, f, extrapolate):
    """Channel ``ch`` of the curve table at data[off + 4:] (RAMP_TABLE_SIZE RGBA entries) at
    f ∈ [0, 1] (Cycles's rgb_ramp_lookup with interpolation; outside [0, 1] it extrapolates
    linearly from the end segment when ``extrapolate``, else clamps)."""
    size = RAMP_TABLE_SIZE
    t0k = off + 4
    if (f < 0.0 or f > 1.0) and extrapolate:
        if f < 0.0:
            t0 = data[t0k + ch]
            dy = t0 - data[t0k + 4 + ch]
            f = -f
        else:
            t0 = data[t0k + 4 * (size - 1) + ch]
            dy = t0 - data[t0k + 4 * (size - 2) + ch]
            f = f - 1.0
        return t0 + dy * f * (size - 1)
    if f != f:
        f = 0.0
    f = min(max(f, 0.0), 1.0) * (size - 1)
    i = min(max(int(f), 0), size - 1)
    t = f - i
    a = data[t0k + 4 * i + ch]
    if t > 0.0:
        a = (1.0 - t) * a + t * data[t0k + 4 * (i + 1) + ch]
    return a


# --- the program operations ---------------------------------------------------------------------

@kernel
def procedural_op(procedural, regs, data, op, mode, o0, o1, i0, i1, i2, i3, i4, i5, param):
    """One procedural operation of ``run_program`` (opcodes 50–56 of program_format), reading
    and writing the register file ``regs`` (R, 3). Packed inputs are registers holding three
    scalars (see docs/materials.md, "Procedural textures"). ``procedural``: the scene's
    ``ProgramData.procedural``; None (no program has a procedural opcode) compiles this kernel
    to nothing."""
    if procedural is None:
        # numba prunes the rest on the argument's type before typing it: the variant of the
        # kernels without procedural nodes neither compiles nor links the textures below
        return
    vx, vy, vz = regs[i0, 0], regs[i0, 1], regs[i0, 2]
    if op == 50:  # Noise: mode = dim−1 | type << 2 | normalize << 5 | colour << 6
        dim = (mode & 3) + 1
        w, scale, detail = regs[i1, 0], regs[i1, 1], regs[i1, 2]
        rough, lac, offs = regs[i2, 0], regs[i2, 1], regs[i2, 2]
        gain, dist = regs[i3, 0], regs[i3, 1]
        detail = min(max(detail, 0.0), 15.0)
        rough = max(rough, 0.0)
        s = f32(scale)
        v, g, b = noise_texture((mode >> 2) & 7, dim, f32(f32(vx) * s), f32(f32(vy) * s), f32(f32(vz) * s),
                                f32(f32(w) * s), detail, rough, lac, offs, gain, dist, (mode >> 5) & 1,
                                (mode >> 6) & 1)
        regs[o0, 0] = regs[o0, 1] = regs[o0, 2] = v
        if o1 >= 0:
            regs[o1, 0] = v
            regs[o1, 1] = g
            regs[o1, 2] = b
    elif op == 51:  # White Noise: mode = dim
        w = regs[i1, 0]
        v = hash_to_float(mode, vx, vy, vz, w)
        regs[o0, 0] = regs[o0, 1] = regs[o0, 2] = v
        if o1 >= 0:
            c = hash_to_float3(mode, vx, vy, vz, w)
            regs[o1, 0] = c[0]
            regs[o1, 1] = c[1]
            regs[o1, 2] = c[2]
    elif op == 52:  # Voronoi: mode = dim−1 | feature << 2 | metric << 5 | normalize << 7
        dim = (mode & 3) + 1
        r = voronoi_texture(dim, (mode >> 2) & 7, (mode >> 5) & 3, (mode >> 7) & 1, vx, vy, vz,
                            regs[i1, 0], regs[i1, 1], regs[i1, 2], regs[i2, 0], regs[i2, 1],
                            regs[i2, 2], regs[i3, 0], regs[i3, 1])
        regs[o0, 0] = r[1]
        regs[o0, 1] = r[2]
        regs[o0, 2] = r[3]
        regs[o1, 0] = r[0]  # (distance or radius, W, 0)
        regs[o1, 1] = r[7]
        regs[o1, 2] = 0.0
        if param >= 0:
            regs[param, 0] = r[4]
            regs[param, 1] = r[5]
            regs[param, 2] = r[6]
    elif op == 53:  # Wave: mode = type | bands << 1 | rings << 3 | profile << 5
        s = f32(regs[i1, 0])
        f = wave(mode & 1, (mode >> 1) & 3, (mode >> 3) & 3, (mode >> 5) & 3, f32(f32(vx) * s),
                 f32(f32(vy) * s), f32(f32(vz) * s), regs[i1, 1], regs[i1, 2], regs[i2, 0],
                 regs[i2, 1], regs[i2, 2])
        regs[o0, 0] = regs[o0, 1] = regs[o0, 2] = f
        if o1 >= 0:
            regs[o1, 0] = regs[o1, 1] = regs[o1, 2] = f
    elif op == 54:  # Magic: mode = depth
        c = magic(vx, vy, vz, regs[i1, 0], mode, regs[i1, 1])
        regs[o0, 0] = c[0]
        regs[o0, 1] = c[1]
        regs[o0, 2] = c[2]
        if o1 >= 0:
            regs[o1, 0] = regs[o1, 1] = regs[o1, 2] = (c[0] + c[1] + c[2]) * (1.0 / 3.0)
    elif op == 55:  # Brick: data[param:] = offset amount, offset frequency, squash, squash freq.
        s = f32(regs[i4, 0])
        tint, f = brick(f32(vx) * s, f32(vy) * s, regs[i4, 1], regs[i4, 2], regs[i5, 0], regs[i5, 1],
                        regs[i5, 2], data[param], int(data[param + 1]), data[param + 2],
                        int(data[param + 3]))
        c1r, c1g, c1b = regs[i1, 0], regs[i1, 1], regs[i1, 2]
        if f != 1.0:
            m = 1.0 - tint
            c1r = m * c1r + tint * regs[i2, 0]
            c1g = m * c1g + tint * regs[i2, 1]
            c1b = m * c1b + tint * regs[i2, 2]
        regs[o0, 0] = c1r * (1.0 - f) + regs[i3, 0] * f
        regs[o0, 1] = c1g * (1.0 - f) + regs[i3, 1] * f
        regs[o0, 2] = c1b * (1.0 - f) + regs[i3, 2] * f
        if o1 >= 0:
            regs[o1, 0] = regs[o1, 1] = regs[o1, 2] = f
    elif op == 56:  # curves: in0 Fac, in1 colour/value; mode 0 colour/vector, 1 float
        fac = regs[i0, 0]
        lo, hi, ext = data[param], data[param + 1], data[param + 2] != 0.0
        rng = hi - lo
        for ch in range(3):
            x = regs[i1, ch]
            t = (x - lo) / rng if rng != 0.0 else 0.0
            y = curve_lookup(data, param, 0 if mode == 1 else ch, t, ext)
            regs[o0, ch] = (1.0 - fac) * x + fac * y
