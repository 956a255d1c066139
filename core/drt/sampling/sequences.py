"""Sample generators: RANDOM, STRATIFIED and SOBOL (Owen-scrambled), all stateless.

Every value is a pure function of (seed, pixel, index, dim) (and of ``spp`` for STRATIFIED, whose
strata depend on it): nothing is carried between calls, so any subset of samples can be drawn on
its own and a render of sample range [k, n) reproduces exactly those samples of a full render.
Samples come in 2-D *dimensions* (``dim``): dimension 0 is the pixel filter, 1 the lens, and so on
(the table lives in ``drt/path_stages.py``).  The generators are scalar compiled kernels
(``sample_2d(sd, pixel, index, dim)`` with ``sd = Sampler.data``) doing uint32 arithmetic in int64
(every product masked to 32 bits); the numpy functions below are thin wrappers over them.

* RANDOM: a counter-based hash (Wellons's "lowbias32" integer finalizer chained over seed, pixel,
  dim, index and component), 32 random bits per value.
* STRATIFIED: jittered strata, padded per dimension: the first ``spp`` samples of a pixel fall one
  per cell of an nx × ny grid (nx·ny = spp, the factorization closest to square, nx ≥ ny), with the
  stratum order shuffled per (pixel, dim) by a hashed permutation of the index (Kensler 2013), so
  dimensions are decorrelated.  Samples spp..2spp-1 form another, independently shuffled and
  jittered set, and so on.
* SOBOL: Burley 2020, "Practical Hash-based Owen Scrambling": per (pixel, dim) seed, the index is
  shuffled by a nested-uniform (Owen) scramble, then the first two Sobol dimensions (van der
  Corput and the x+1 polynomial) are each Owen-scrambled with a Laine-Karras style hash.  For
  spp = 2^k the samples of a pixel form a (0, k, 2)-net in each dimension pair.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np

from ..kernels import inline_kernel, kernel

__all__ = ["Sampler", "SamplerData", "SAMPLER_KINDS", "sample_2d", "sample_3d", "sample_5d", "sample_2d_batch",
           "hash_u32", "reverse_bits", "sobol_2d", "nested_uniform_scramble", "permute_index"]

SAMPLER_KINDS = ("SOBOL", "STRATIFIED", "RANDOM")
KIND_SOBOL, KIND_STRATIFIED, KIND_RANDOM = 0, 1, 2  # SamplerData.kind

_INV_2_32 = 1.0 / 4294967296.0  # uint32 -> [0, 1): (2^32 - 1)·2^-32 < 1 exactly in float64
_ONE_MINUS_EPS = float(np.nextafter(1.0, 0.0))
_MASK = 0xFFFFFFFF

# salts that separate the hash streams of the different uses
_SALT_RANDOM = 0x52414E44      # "RAND"
_SALT_STRAT = 0x53545254       # "STRT"
_SALT_SOBOL = 0x534F424C       # "SOBL"


SamplerData = namedtuple("SamplerData", ["kind", "seed", "spp", "nx", "ny", "prefix"])
SamplerData.__doc__ = """Per-render sampler constants for the kernels (all Python ints → int64).

kind: 0 SOBOL, 1 STRATIFIED, 2 RANDOM; seed: the 32-bit seed; spp: samples per pixel;
nx, ny: STRATIFIED's grid (nx·ny = spp); prefix: the hash chain of (seed, the kind's salt), the
common start of every per-sample hash."""


# ---------------------------------------------------------------------------------------------
# scalar kernels: uint32 values held in int64 (inputs taken mod 2^32; every product is formed
# without signed overflow and masked back to 32 bits)
# ---------------------------------------------------------------------------------------------


@kernel
def mul32(a, b):
    """(a·b) mod 2^32 for a, b in [0, 2^32), as int64. The product is formed in uint64, whose
    multiply wraps (numba's signed multiply may not overflow: it is marked no-signed-wrap)."""
    return np.int64((np.uint64(a) * np.uint64(b)) & np.uint64(0xFFFFFFFF))


@kernel
def hash32(x):
    """A bijective 32-bit integer hash (Wellons's lowbias32), x in [0, 2^32)."""
    x ^= x >> 16
    x = mul32(x, 0x7FEB352D)
    x ^= x >> 15
    x = mul32(x, 0x846CA68B)
    x ^= x >> 16
    return x


@kernel
def reverse32(x):
    """The 32 bits of x reversed."""
    x = ((x >> 1) & 0x55555555) | ((x & 0x55555555) << 1)
    x = ((x >> 2) & 0x33333333) | ((x & 0x33333333) << 2)
    x = ((x >> 4) & 0x0F0F0F0F) | ((x & 0x0F0F0F0F) << 4)
    x = ((x >> 8) & 0x00FF00FF) | ((x & 0x00FF00FF) << 8)
    return ((x >> 16) & 0xFFFF) | ((x & 0xFFFF) << 16)


@kernel
def laine_karras32(x, seed):
    """Burley 2020's hash: each output bit depends only on the same and *lower* input bits."""
    x = (x + seed) & 0xFFFFFFFF
    x ^= mul32(x, 0x6C50B47C)
    x ^= mul32(x, 0xB82F1E52)
    x ^= mul32(x, 0xC7AFE638)
    x ^= mul32(x, 0x8D22F6E6)
    return x


@kernel
def nested_uniform_scramble32(x, seed):
    """Owen (nested uniform) scramble of a 32-bit fixed-point value / index (Burley 2020): each
    bit of the result depends only on the same and *higher* bits of x."""
    return reverse32(laine_karras32(reverse32(x), seed))


@kernel
def sobol_dim1(index):
    """Second Sobol dimension (primitive polynomial x + 1: v_0 = 2^31, v_i = v_{i-1} ^
    (v_{i-1} >> 1)) of index, as 32-bit fixed point."""
    r = 0
    v = 0x80000000
    while index != 0:
        if index & 1:
            r ^= v
        index >>= 1
        v ^= v >> 1
    return r


@kernel
def sobol_poly(index, s, a1, a2, v1, v2, v3):
    """A Sobol dimension of index (32-bit fixed point) for a primitive polynomial of degree
    s ≤ 3: x^s + a1·x^(s−1) + a2·x^(s−2) + … + 1, with initial direction numbers v1 … vs
    (m_k << (32 − k)). Later ones follow Bratley & Fox's recurrence
    v_k = a1·v_{k−1} ⊕ a2·v_{k−2} ⊕ v_{k−s} ⊕ (v_{k−s} >> s)."""
    r = 0
    p1 = 0
    p2 = 0
    p3 = 0
    k = 1
    while index != 0:
        if k == 1:
            v = v1
        elif k <= s:
            v = v2 if k == 2 else v3
        else:
            q = p1 if s == 1 else (p2 if s == 2 else p3)
            v = q ^ (q >> s)
            if a1 and s >= 2:
                v ^= p1
            if a2 and s >= 3:
                v ^= p2
        if index & 1:
            r ^= v
        index >>= 1
        p3 = p2
        p2 = p1
        p1 = v
        k += 1
    return r


@kernel
def sobol_dim2(index):
    """Third Sobol dimension (Joe & Kuo: x² + x + 1, m = 1, 3)."""
    return sobol_poly(index, 2, 1, 0, 0x80000000, 0xC0000000, 0)


@kernel
def sobol_dim3(index):
    """Fourth Sobol dimension (Joe & Kuo: x³ + x + 1, m = 1, 3, 1)."""
    return sobol_poly(index, 3, 0, 1, 0x80000000, 0xC0000000, 0x20000000)


@kernel
def sobol_dim4(index):
    """Fifth Sobol dimension (Joe & Kuo: x³ + x² + 1, m = 1, 1, 1)."""
    return sobol_poly(index, 3, 1, 0, 0x80000000, 0x40000000, 0x20000000)


def _direction_numbers(dimension, *poly):
    """The 32 direction numbers v_1 … v_32 of a Sobol dimension: its value at index 2^(k−1).
    ``dimension``: ``sobol_dim1`` or ``sobol_poly`` (with ``poly`` = its (s, a1, a2, v1, v2, v3));
    their plain-Python bodies run, so building the tables compiles nothing."""
    return [int(dimension.py_func(1 << k, *poly)) for k in range(32)]


def _xor_bytes(v):
    """(4, 256) int64: entry [b, x] is the XOR of v[8b + i] over the set bits i of byte x (the
    contribution of byte position b of a 32-bit index to a GF(2)-linear map whose value at
    bit k is v[k])."""
    bits = (np.arange(256)[:, None] >> np.arange(8)) & 1
    v = np.asarray(v, np.int64).reshape(4, 8)
    return np.bitwise_xor.reduce(np.where(bits[None, :, :] == 1, v[:, None, :], 0), axis=2)


def _byte_tables():
    """SOBOL_BYTES[d − 1, b, x]: the XOR of the direction numbers of Sobol dimension d (1–4) over
    the set bits of byte x at byte position b of the index. A Sobol value is linear over GF(2) in
    the index's bits, so four lookups give it exactly; the bit loop of ``sobol_dim1`` /
    ``sobol_poly`` over a scrambled 32-bit index mispredicts a branch per bit (measured: a SOBOL
    ``sample_2d`` 35 → 12 ns, ``sample_5d`` 95 → 22 ns). Built with numpy at import (a Python
    loop over the 32 768 (dimension, byte, value, bit) cases was ~10 ms of every start-up)."""
    dims = [_direction_numbers(sobol_dim1),
            _direction_numbers(sobol_poly, 2, 1, 0, 0x80000000, 0xC0000000, 0),
            _direction_numbers(sobol_poly, 3, 0, 1, 0x80000000, 0xC0000000, 0x20000000),
            _direction_numbers(sobol_poly, 3, 1, 0, 0x80000000, 0x40000000, 0x20000000)]
    return np.stack([_xor_bytes(v) for v in dims])


SOBOL_BYTES = _byte_tables()


def _reversed_byte_tables():
    """SOBOL_BYTES_REV[d − 1, b, x]: ``reverse32`` of Sobol dimension d of ``reverse32(r)``, for
    the bits of byte x at byte position b of r. Bit reversal is linear over GF(2) too, so with
    r the *bit-reversed* index, reverse32(sobol(reverse32(r))) is the XOR of four lookups. The
    samplers keep the Owen-shuffled index bit-reversed (the form Laine-Karras hashing leaves it
    in) and need the Sobol value bit-reversed (the form the next Laine-Karras hash takes): the
    tables give that directly, without the two ``reverse32`` around every lookup (~12 integer
    operations each; the values are bit-identical, tests/test_sequences.py). Bit 8b + i of r is
    bit 31 − 8b − i of the index, whose direction number is SOBOL_BYTES[d − 1, ·, single bit];
    reversal distributes over XOR, so each table is ``_xor_bytes`` of the reversed numbers."""
    t = np.empty((4, 4, 256), np.int64)
    for d in range(4):
        v = [int(SOBOL_BYTES[d, k // 8, 1 << (k % 8)]) for k in range(32)]
        t[d] = _xor_bytes([reverse32.py_func(v[31 - k]) for k in range(32)])
    return t


SOBOL_BYTES_REV = _reversed_byte_tables()


@kernel
def sobol_fast(d, index):
    """Sobol dimension d (1–4: ``sobol_dim1`` … ``sobol_dim4``) of a 32-bit index, by table."""
    t = SOBOL_BYTES
    return (t[d - 1, 0, index & 255] ^ t[d - 1, 1, (index >> 8) & 255] ^ t[d - 1, 2, (index >> 16) & 255]
            ^ t[d - 1, 3, (index >> 24) & 255])


@kernel
def sobol_rev(d, r):
    """``reverse32(sobol_fast(d, reverse32(r)))``: Sobol dimension d, bit-reversed, of the
    bit-reversed 32-bit index r, by table (``SOBOL_BYTES_REV``)."""
    t = SOBOL_BYTES_REV
    return (t[d - 1, 0, r & 255] ^ t[d - 1, 1, (r >> 8) & 255] ^ t[d - 1, 2, (r >> 16) & 255]
            ^ t[d - 1, 3, (r >> 24) & 255])


@kernel
def permute32(i, n, key):
    """Hashed permutation of [0, n) (Kensler 2013), i in [0, n), one permutation per key: a
    bijection on the next power of two, cycle-walked into [0, n)."""
    if n <= 1:
        return 0
    w = n - 1
    w |= w >> 1
    w |= w >> 2
    w |= w >> 4
    w |= w >> 8
    w |= w >> 16
    p = key
    x = i
    for _ in range(4096):
        x ^= p
        x = mul32(x, 0xE170893D)
        x ^= p >> 16
        x ^= (x & w) >> 4
        x ^= p >> 8
        x = mul32(x, 0x0929EB3F)
        x ^= p >> 23
        x ^= (x & w) >> 1
        x = mul32(x, 1 | (p >> 27))
        x = mul32(x, 0x6935FA69)
        x ^= (x & w) >> 11
        x = mul32(x, 0x74DCB303)
        x ^= (x & w) >> 2
        x = mul32(x, 0x9E501CC3)
        x ^= (x & w) >> 2
        x = mul32(x, 0xC860A3DF)
        x &= w
        x ^= x >> 5
        if x < n:
            return (x + p) % n
    raise RuntimeError("permute_index did not converge")  # pragma: no cover


@inline_kernel
def random_2d(sd, pixel, index, dim):
    """``sample_2d`` of the RANDOM sampler: a hash of (prefix, pixel, dim, index), no
    stratification; also for callers that want independent numbers at any sampler (the
    subsurface walk's later steps)."""
    h = hash32(hash32(hash32(sd.prefix ^ (pixel & 0xFFFFFFFF)) ^ (dim & 0xFFFFFFFF)) ^ (index & 0xFFFFFFFF))
    return float(hash32(h ^ 0x68E31DA4)) * _INV_2_32, float(hash32(h ^ 0xB5297A4D)) * _INV_2_32


@kernel
def sample_2d(sd, pixel, index, dim):
    """One 2-D sample (u0, u1) in [0, 1)² of (pixel, index, dim) (ints, taken mod 2^32);
    sd = ``Sampler.data``."""
    if sd.kind == 2:  # RANDOM
        return random_2d(sd, pixel, index, dim)
    pixel &= 0xFFFFFFFF
    index &= 0xFFFFFFFF
    dim &= 0xFFFFFFFF
    h = hash32(hash32(sd.prefix ^ pixel) ^ dim)
    if sd.kind == 1:  # STRATIFIED
        spp = sd.spp
        rnd = index // spp          # which set of spp samples
        slot = index % spp
        key = hash32(h ^ rnd)
        stratum = permute32(slot, spp, key)
        jit = hash32(key ^ hash32(slot))
        jx = float(hash32(jit ^ 0x1B873593)) * _INV_2_32
        jy = float(hash32(jit ^ 0xCC9E2D51)) * _INV_2_32
        sx = float(stratum % sd.nx)
        sy = float(stratum // sd.nx)
        return (min((sx + jx) / sd.nx, _ONE_MINUS_EPS),
                min((sy + jy) / sd.ny, _ONE_MINUS_EPS))
    # SOBOL: the shuffled index is kept bit-reversed (see ``_sobol_shuffled``)
    r = laine_karras32(reverse32(index), h)
    return _owen_rev(reverse32(r), h, _SEED_U0), _owen_rev(sobol_rev(1, r), h, _SEED_U1)


#: seeds of the Owen scramble of each Sobol dimension of a sample (one per dimension, so the
#: dimensions are scrambled independently)
_SEED_U0 = 0x2545F491
_SEED_U1 = 0x9E3779B9
_SEED_U2 = 0x5BD1E995
_SEED_U3 = 0x27D4EB2F
_SEED_U4 = 0x165667B1


@kernel
def _owen_rev(bits_rev, h, seed):
    """One Sobol dimension's 32 bits, Owen-scrambled with the pixel/dimension hash h and the
    dimension's seed, as a float in [0, 1); given *bit-reversed* (``bits_rev``): the scramble,
    ``nested_uniform_scramble32``, is reverse32 ∘ Laine-Karras ∘ reverse32, and the samplers
    hold every value bit-reversed already, so the first reversal is skipped."""
    return float(reverse32(laine_karras32(bits_rev, hash32(h ^ seed)))) * _INV_2_32


@kernel
def _sobol_shuffled(sd, pixel, index, dim):
    """(h, r) of a SOBOL sample: the hash of (prefix, pixel, dim) and the sample index
    Owen-shuffled by it (Burley 2020), *bit-reversed* (r = reverse32 of the shuffled index:
    ``sobol_rev`` reads every Sobol dimension of the sample from it)."""
    pixel &= 0xFFFFFFFF
    index &= 0xFFFFFFFF
    dim &= 0xFFFFFFFF
    h = hash32(hash32(sd.prefix ^ pixel) ^ dim)
    return h, laine_karras32(reverse32(index), h)


@kernel
def sample_5d(sd, pixel, index, dim, with_lens, with_fifth):
    """A 5-D sample (u0 … u4) of (pixel, index) for the dimensions (dim, dim + 1, dim + 2),
    jointly stratified: SOBOL takes the first five Sobol dimensions of one shuffled index (Burley
    2020's padding in higher dimensions; the camera's pixel filter, lens and shutter time, whose
    image depends on all of them together), each Owen-scrambled on its own; (u0, u1) equals
    ``sample_2d(sd, pixel, index, dim)``. (u2, u3) are computed only ``with_lens`` and u4 only
    ``with_fifth`` (else 0: a pinhole camera or a still scene does not pay for them; the values
    that are computed do not depend on the flags).
    STRATIFIED and RANDOM pad 2-D samples: (dim), (dim + 1), (dim + 2)[0]."""
    if sd.kind != KIND_SOBOL:
        u0, u1 = sample_2d(sd, pixel, index, dim)
        u2, u3 = sample_2d(sd, pixel, index, dim + 1) if with_lens else (0.0, 0.0)
        u4 = sample_2d(sd, pixel, index, dim + 2)[0] if with_fifth else 0.0
        return u0, u1, u2, u3, u4
    h, r = _sobol_shuffled(sd, pixel, index, dim)
    u2 = _owen_rev(sobol_rev(2, r), h, _SEED_U2) if with_lens else 0.0
    u3 = _owen_rev(sobol_rev(3, r), h, _SEED_U3) if with_lens else 0.0
    u4 = _owen_rev(sobol_rev(4, r), h, _SEED_U4) if with_fifth else 0.0
    return (_owen_rev(reverse32(r), h, _SEED_U0), _owen_rev(sobol_rev(1, r), h, _SEED_U1),
            u2, u3, u4)


#: offset of the padded dimension that gives STRATIFIED and RANDOM the third value of a
#: ``sample_3d`` (far above every dimension the integrator and the media use)
PAD_3D = 1 << 28


@kernel
def sample_3d(sd, pixel, index, dim):
    """A 3-D sample (u0, u1, u2) of (pixel, index) for dimension ``dim``; (u0, u1) equals
    ``sample_2d(sd, pixel, index, dim)``. SOBOL: u2 is the third Sobol dimension of the same
    shuffled index, Owen-scrambled on its own, so the three are jointly stratified (Cycles's
    3-D ``path_state_rng_3D`` for a BSDF's lobe choice and direction, a light's selection and
    position). STRATIFIED and RANDOM: u2 = ``sample_2d(dim + PAD_3D)[0]``, padded."""
    if sd.kind != KIND_SOBOL:
        u0, u1 = sample_2d(sd, pixel, index, dim)
        return u0, u1, sample_2d(sd, pixel, index, dim + PAD_3D)[0]
    h, r = _sobol_shuffled(sd, pixel, index, dim)
    return (_owen_rev(reverse32(r), h, _SEED_U0), _owen_rev(sobol_rev(1, r), h, _SEED_U1),
            _owen_rev(sobol_rev(2, r), h, _SEED_U2))


@kernel
def _sample_3d_rows(sd, pixel, index, dim, out):
    for k in range(pixel.shape[0]):
        a, b, c = sample_3d(sd, pixel[k], index[k], dim)
        out[k, 0] = a
        out[k, 1] = b
        out[k, 2] = c


@kernel
def _sample_5d_rows(sd, pixel, index, dim, out):
    for k in range(pixel.shape[0]):
        a, b, c, e, f = sample_5d(sd, pixel[k], index[k], dim, True, True)
        out[k, 0] = a
        out[k, 1] = b
        out[k, 2] = c
        out[k, 3] = e
        out[k, 4] = f


@kernel
def sample_2d_batch(sd, pixel, index, dim, out):
    """``sample_2d`` for rows: pixel, index, dim (n,) int64 -> out (n, 2) float64."""
    for k in range(pixel.shape[0]):
        u0, u1 = sample_2d(sd, pixel[k], index[k], dim[k])
        out[k, 0] = u0
        out[k, 1] = u1


# ---------------------------------------------------------------------------------------------
# numpy wrappers
# ---------------------------------------------------------------------------------------------


@kernel
def _hash_rows(x, out):
    for k in range(x.shape[0]):
        out[k] = hash32(x[k] & 0xFFFFFFFF)


@kernel
def _reverse_rows(x, out):
    for k in range(x.shape[0]):
        out[k] = reverse32(x[k] & 0xFFFFFFFF)


@kernel
def _scramble_rows(x, seed, out):
    for k in range(x.shape[0]):
        out[k] = nested_uniform_scramble32(x[k] & 0xFFFFFFFF, seed[k] & 0xFFFFFFFF)


@kernel
def _sobol_rows(index, out_x, out_y):
    for k in range(index.shape[0]):
        i = index[k] & 0xFFFFFFFF
        out_x[k] = reverse32(i)
        out_y[k] = sobol_fast(1, i)


@kernel
def _permute_rows(i, n, key, out):
    for k in range(i.shape[0]):
        out[k] = permute32(i[k] & 0xFFFFFFFF, n, key[k] & 0xFFFFFFFF)


def _i64(x) -> np.ndarray:
    """Any integer array (or scalar) -> int64 array (the kernels take it mod 2^32)."""
    a = np.asarray(x)
    return a if a.dtype == np.int64 else a.astype(np.int64)


def _flat(*arrays) -> tuple[tuple, list[np.ndarray]]:
    """Broadcast int arrays together -> (shape, contiguous writeable 1-D int64 arrays): one
    compiled signature for every call."""
    arrays = [_i64(a) for a in arrays]
    shape = np.broadcast_shapes(*(a.shape for a in arrays))
    out = []
    for a in arrays:
        if a.shape != shape:
            a = np.broadcast_to(a, shape)
        a = np.ascontiguousarray(a).reshape(-1)
        out.append(a if a.flags.writeable else a.copy())
    return shape, out


def _u32_out(out: np.ndarray, shape) -> np.ndarray:
    return out.astype(np.uint32).reshape(shape)


def hash_u32(x) -> np.ndarray:
    """A bijective 32-bit integer hash (Wellons's lowbias32).  x: uint32 array -> uint32 array."""
    shape, (x,) = _flat(x)
    out = np.empty_like(x)
    _hash_rows(x, out)
    return _u32_out(out, shape)


def reverse_bits(x) -> np.ndarray:
    """Reverse the 32 bits of each uint32."""
    shape, (x,) = _flat(x)
    out = np.empty_like(x)
    _reverse_rows(x, out)
    return _u32_out(out, shape)


def nested_uniform_scramble(x, seed) -> np.ndarray:
    """Owen (nested uniform) scramble of 32-bit fixed-point values / indices (Burley 2020).

    x, seed: uint32 arrays (broadcast).  Each bit of the result depends only on the same and
    *higher* bits of x, so aligned blocks of 2^k indices map onto aligned blocks of 2^k.
    """
    shape, (x, seed) = _flat(x, seed)
    out = np.empty_like(x)
    _scramble_rows(x, seed, out)
    return _u32_out(out, shape)


def sobol_2d(index) -> tuple[np.ndarray, np.ndarray]:
    """First two Sobol dimensions of ``index`` as 32-bit fixed-point uint32 (value·2^32).

    Dimension 0 is van der Corput (bit reversal); dimension 1 uses the direction numbers of the
    primitive polynomial x + 1 (v_0 = 2^31, v_i = v_{i-1} ^ (v_{i-1} >> 1)).
    """
    shape, (index,) = _flat(index)
    x = np.empty_like(index)
    y = np.empty_like(index)
    _sobol_rows(index, x, y)
    return _u32_out(x, shape), _u32_out(y, shape)


def permute_index(i, n: int, key) -> np.ndarray:
    """Hashed permutation of [0, n) (Kensler 2013, "Correlated Multi-Jittered Sampling").

    i: uint32 array of values in [0, n); key: uint32 array (broadcast), one permutation per key.
    A bijection on the next power of two, cycle-walked into [0, n).
    """
    shape, (i, key) = _flat(i, key)
    out = np.empty_like(i)
    _permute_rows(i, int(n), key, out)
    return _u32_out(out, shape)


def _grid_shape(spp: int) -> tuple[int, int]:
    """(nx, ny) with nx·ny = spp, ny the largest divisor ≤ √spp (closest to square)."""
    ny = int(np.floor(np.sqrt(spp)))
    while spp % ny:
        ny -= 1
    return spp // ny, ny


def _hash_prefix(seed: int, salt: int) -> int:
    h = int(hash_u32(0x9E3779B9 ^ (seed & _MASK)))
    return int(hash_u32(h ^ salt))


class Sampler:
    """Stateless sample generator: ``sample_2d(pixel, index, dim)``.

    kind: "SOBOL" | "STRATIFIED" | "RANDOM"; seed: int (mixed into every hash, e.g. the
    scene seed or frame number); spp: samples per pixel (STRATIFIED builds its strata from it;
    SOBOL and RANDOM ignore it).  Values depend only on (seed, pixel, index, dim) [+ spp for
    STRATIFIED].  ``data`` is the ``SamplerData`` the compiled ``sample_2d`` takes.
    """

    def __init__(self, kind: str = "SOBOL", seed: int = 0, spp: int = 1):
        kind = str(kind).upper()
        if kind not in SAMPLER_KINDS:
            raise ValueError(f"unknown sampler kind {kind!r}; expected one of {SAMPLER_KINDS}")
        if int(spp) < 1:
            raise ValueError(f"spp must be >= 1 (got {spp})")
        self.kind = kind
        self.seed = int(seed) & 0xFFFFFFFF
        self.spp = int(spp)
        self._grid = _grid_shape(self.spp)
        code = SAMPLER_KINDS.index(kind)
        salt = (_SALT_SOBOL, _SALT_STRAT, _SALT_RANDOM)[code]
        self.data = SamplerData(kind=int(code), seed=int(self.seed), spp=int(self.spp),
                                nx=int(self._grid[0]), ny=int(self._grid[1]),
                                prefix=_hash_prefix(self.seed, salt))

    def sample_5d(self, pixel, index, dim) -> np.ndarray:
        """pixel, index: (n,) ints; dim: int. Returns (n, 5) float64: the jointly stratified
        samples of dimensions (dim, dim + 1, dim + 2) (see the ``sample_5d`` kernel)."""
        pixel = np.ascontiguousarray(np.asarray(pixel, dtype=np.int64).reshape(-1))
        index = np.ascontiguousarray(np.broadcast_to(np.asarray(index, dtype=np.int64), pixel.shape))
        out = np.empty((len(pixel), 5))
        _sample_5d_rows(self.data, pixel, index, int(dim), out)
        return out

    def sample_3d(self, pixel, index, dim) -> np.ndarray:
        """pixel, index: (n,) ints; dim: int. Returns (n, 3) float64 (see the ``sample_3d``
        kernel: SOBOL's three values are jointly stratified)."""
        pixel = np.ascontiguousarray(np.asarray(pixel, dtype=np.int64).reshape(-1))
        index = np.ascontiguousarray(np.broadcast_to(np.asarray(index, dtype=np.int64), pixel.shape))
        out = np.empty((len(pixel), 3))
        _sample_3d_rows(self.data, pixel, index, int(dim), out)
        return out

    def __repr__(self) -> str:
        return f"Sampler(kind={self.kind!r}, seed={self.seed}, spp={self.spp})"

    def sample_2d(self, pixel, index, dim) -> np.ndarray:
        """2-D samples.

        pixel: (n,) uint32 pixel ids (y·W + x); index: (n,) uint32 sample numbers within the pixel;
        dim: int (or (n,) ints) dimension number.  Inputs broadcast; other integer dtypes are
        taken mod 2^32.  Returns (n, 2) float64 in [0, 1).
        """
        shape, (pixel, index, dim) = _flat(pixel, index, dim)
        out = np.empty((pixel.shape[0], 2))
        sample_2d_batch(self.data, pixel, index, dim, out)
        return out.reshape(shape + (2,))

    def sample_1d(self, pixel, index, dim) -> np.ndarray:
        """First component of ``sample_2d``: (n,) float64 in [0, 1)."""
        return self.sample_2d(pixel, index, dim)[..., 0]
