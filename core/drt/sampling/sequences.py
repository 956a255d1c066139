"""Sample generators: RANDOM, STRATIFIED and SOBOL (Owen-scrambled), all stateless.

Every value is a pure function of (seed, pixel, index, dim) (and of ``spp`` for STRATIFIED, whose
strata depend on it): nothing is carried between calls, so any subset of samples can be drawn on
its own and a render of sample range [k, n) reproduces exactly those samples of a full render.
Samples come in 2-D *dimensions* (``dim``): dimension 0 is the pixel filter, 1 the lens, and so on
(the table lives in ``drt/integrator.py``).  All bit operations are vectorized numpy ``uint32``.

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

import numpy as np

__all__ = ["Sampler", "SAMPLER_KINDS", "hash_u32", "reverse_bits", "sobol_2d",
           "nested_uniform_scramble", "permute_index"]

SAMPLER_KINDS = ("SOBOL", "STRATIFIED", "RANDOM")

_U32 = np.uint32
_INV_2_32 = 1.0 / 4294967296.0  # uint32 -> [0, 1): (2^32 - 1)·2^-32 < 1 exactly in float64
_ONE_MINUS_EPS = np.nextafter(1.0, 0.0)


def _u32(x) -> np.ndarray:
    """Any integer array (or scalar) -> uint32 array (values taken mod 2^32)."""
    a = np.asarray(x)
    if a.dtype == np.uint32:
        return a
    return (a.astype(np.int64) & 0xFFFFFFFF).astype(np.uint32)


def hash_u32(x) -> np.ndarray:
    """A bijective 32-bit integer hash (Wellons's lowbias32).  x: uint32 array -> uint32 array."""
    x = _u32(x).copy()
    x ^= x >> _U32(16)
    x *= _U32(0x7FEB352D)
    x ^= x >> _U32(15)
    x *= _U32(0x846CA68B)
    x ^= x >> _U32(16)
    return x


def _hash_chain(*values) -> np.ndarray:
    """Hash of a sequence of uint32 values (broadcast together): h = hash(h ^ v) for each v."""
    h = hash_u32(_u32(0x9E3779B9) ^ _u32(values[0]))
    for v in values[1:]:
        h = hash_u32(h ^ _u32(v))
    return h


def _reverse_table_16() -> np.ndarray:
    """(65536,) uint32: the 16 bits of each index reversed."""
    b = np.arange(1 << 16, dtype=np.uint32)
    r = np.zeros(1 << 16, dtype=np.uint32)
    for j in range(16):
        r |= ((b >> j) & 1) << (15 - j)
    return r


_REV16 = _reverse_table_16()


def reverse_bits(x) -> np.ndarray:
    """Reverse the 32 bits of each uint32 (two lookups in a 16-bit table, 256 KiB: cheaper than
    bit twiddling in numpy, where every operation is a pass over the array)."""
    x = _u32(x)
    out = _REV16[x & _U32(0xFFFF)]
    out <<= _U32(16)
    out |= _REV16[x >> _U32(16)]
    return out


def _laine_karras_permutation(x: np.ndarray, seed: np.ndarray) -> np.ndarray:
    """Burley 2020's hash: each output bit depends only on the same and *lower* input bits."""
    x = x + seed
    x ^= x * _U32(0x6C50B47C)
    x ^= x * _U32(0xB82F1E52)
    x ^= x * _U32(0xC7AFE638)
    x ^= x * _U32(0x8D22F6E6)
    return x


def nested_uniform_scramble(x, seed) -> np.ndarray:
    """Owen (nested uniform) scramble of 32-bit fixed-point values / indices (Burley 2020).

    x, seed: uint32 arrays (broadcast).  Each bit of the result depends only on the same and
    *higher* bits of x, so aligned blocks of 2^k indices map onto aligned blocks of 2^k.
    """
    return reverse_bits(_laine_karras_permutation(reverse_bits(x), _u32(seed)))


def _sobol_dim1_matrix() -> np.ndarray:
    v = np.empty(32, dtype=np.uint32)
    v[0] = 1 << 31
    for i in range(1, 32):
        v[i] = v[i - 1] ^ (v[i - 1] >> 1)
    return v


_SOBOL_DIM1 = _sobol_dim1_matrix()


def _byte_xor_tables(v: np.ndarray) -> np.ndarray:
    """(4, 256) tables: entry [k, b] = XOR of v[8k + j] over the set bits j of byte b."""
    t = np.zeros((4, 256), dtype=np.uint32)
    b = np.arange(256)
    for k in range(4):
        for j in range(8):
            t[k] ^= np.where((b >> j) & 1, v[8 * k + j], 0).astype(np.uint32)
    return t


_SOBOL_DIM1_BYTES = _byte_xor_tables(_SOBOL_DIM1)


def sobol_2d(index) -> tuple[np.ndarray, np.ndarray]:
    """First two Sobol dimensions of ``index`` as 32-bit fixed-point uint32 (value·2^32).

    Dimension 0 is van der Corput (bit reversal); dimension 1 uses the direction numbers of the
    primitive polynomial x + 1 (v_0 = 2^31, v_i = v_{i-1} ^ (v_{i-1} >> 1)), applied a byte of
    the index at a time through precomputed XOR tables.
    """
    index = _u32(index)
    x = reverse_bits(index)
    t = _SOBOL_DIM1_BYTES
    y = t[0][index & _U32(0xFF)]
    hi = index >> _U32(8)
    if hi.any():
        y = y ^ t[1][hi & _U32(0xFF)] ^ t[2][(index >> _U32(16)) & _U32(0xFF)] ^ t[3][index >> _U32(24)]
    return x, y


def permute_index(i, n: int, key) -> np.ndarray:
    """Hashed permutation of [0, n) (Kensler 2013, "Correlated Multi-Jittered Sampling").

    i: uint32 array of values in [0, n); key: uint32 array (broadcast), one permutation per key.
    A bijection on the next power of two, cycle-walked into [0, n).
    """
    i = _u32(i).copy()
    p = _u32(key)
    i, p = np.broadcast_arrays(i, p)
    i = i.copy()
    if n <= 1:
        return np.zeros_like(i)
    w = n - 1
    for s in (1, 2, 4, 8, 16):
        w |= w >> s
    w = _U32(w)
    n_u = _U32(n)
    out = np.empty_like(i)
    todo = np.ones(i.shape, dtype=bool)
    cur = i
    for _ in range(4096):  # cycle walking: a few rounds, each vectorized over the samples
        x = cur[todo]
        q = p[todo]
        x ^= q
        x *= _U32(0xE170893D)
        x ^= q >> _U32(16)
        x ^= (x & w) >> _U32(4)
        x ^= q >> _U32(8)
        x *= _U32(0x0929EB3F)
        x ^= q >> _U32(23)
        x ^= (x & w) >> _U32(1)
        x *= _U32(1) | (q >> _U32(27))
        x *= _U32(0x6935FA69)
        x ^= (x & w) >> _U32(11)
        x *= _U32(0x74DCB303)
        x ^= (x & w) >> _U32(2)
        x *= _U32(0x9E501CC3)
        x ^= (x & w) >> _U32(2)
        x *= _U32(0xC860A3DF)
        x &= w
        x ^= x >> _U32(5)
        done = x < n_u
        idx = np.flatnonzero(todo)
        out.flat[idx[done]] = ((x[done].astype(np.uint64) + q[done]) % n).astype(np.uint32)
        cur = cur.copy()
        cur.flat[idx[~done]] = x[~done]
        todo.flat[idx[done]] = False
        if not todo.any():
            return out
    raise RuntimeError("permute_index did not converge")  # pragma: no cover


def _grid_shape(spp: int) -> tuple[int, int]:
    """(nx, ny) with nx·ny = spp, ny the largest divisor ≤ √spp (closest to square)."""
    ny = int(np.floor(np.sqrt(spp)))
    while spp % ny:
        ny -= 1
    return spp // ny, ny


def _to_unit(x: np.ndarray) -> np.ndarray:
    return x.astype(np.float64) * _INV_2_32


# salts that separate the hash streams of the different uses
_SALT_RANDOM = 0x52414E44      # "RAND"
_SALT_STRAT = 0x53545254       # "STRT"
_SALT_SOBOL = 0x534F424C       # "SOBL"


class Sampler:
    """Stateless sample generator: ``sample_2d(pixel, index, dim)``.

    kind: "SOBOL" | "STRATIFIED" | "RANDOM"; seed: int (mixed into every hash, e.g. the
    scene seed or frame number); spp: samples per pixel (STRATIFIED builds its strata from it;
    SOBOL and RANDOM ignore it).  Values depend only on (seed, pixel, index, dim) [+ spp for
    STRATIFIED].
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

    def __repr__(self) -> str:
        return f"Sampler(kind={self.kind!r}, seed={self.seed}, spp={self.spp})"

    def sample_2d(self, pixel, index, dim) -> np.ndarray:
        """2-D samples.

        pixel: (n,) uint32 pixel ids (y·W + x); index: (n,) uint32 sample numbers within the pixel;
        dim: int (or (n,) ints) dimension number.  Inputs broadcast; other integer dtypes are
        taken mod 2^32.  Returns (n, 2) float64 in [0, 1).
        """
        pixel, index, dim = np.broadcast_arrays(_u32(pixel), _u32(index), _u32(dim))
        shape = pixel.shape
        # work on 1-D arrays: numpy scalars would warn on the (intended) uint32 wrap-around
        pixel, index, dim = (a.reshape(-1) for a in (pixel, index, dim))
        if self.kind == "RANDOM":
            out = self._random(pixel, index, dim)
        elif self.kind == "STRATIFIED":
            out = self._stratified(pixel, index, dim)
        else:
            out = self._sobol(pixel, index, dim)
        return out.reshape(shape + (2,))

    def sample_1d(self, pixel, index, dim) -> np.ndarray:
        """First component of ``sample_2d``: (n,) float64 in [0, 1)."""
        return self.sample_2d(pixel, index, dim)[..., 0]

    # -- generators ------------------------------------------------------------------------

    def _random(self, pixel, index, dim) -> np.ndarray:
        h = _hash_chain(self.seed, _SALT_RANDOM, pixel, dim, index)
        x = hash_u32(h ^ _U32(0x68E31DA4))
        y = hash_u32(h ^ _U32(0xB5297A4D))
        return np.stack([_to_unit(x), _to_unit(y)], axis=-1)

    def _stratified(self, pixel, index, dim) -> np.ndarray:
        nx, ny = self._grid
        spp = self.spp
        rnd = index // _U32(spp)          # which set of spp samples
        slot = index % _U32(spp)
        key = _hash_chain(self.seed, _SALT_STRAT, pixel, dim, rnd)
        stratum = permute_index(slot, spp, key)
        jit = hash_u32(key ^ hash_u32(slot))
        jx = _to_unit(hash_u32(jit ^ _U32(0x1B873593)))
        jy = _to_unit(hash_u32(jit ^ _U32(0xCC9E2D51)))
        sx = (stratum % _U32(nx)).astype(np.float64)
        sy = (stratum // _U32(nx)).astype(np.float64)
        out = np.stack([(sx + jx) / nx, (sy + jy) / ny], axis=-1)
        return np.minimum(out, _ONE_MINUS_EPS)

    def _sobol(self, pixel, index, dim) -> np.ndarray:
        key = _hash_chain(self.seed, _SALT_SOBOL, pixel, dim)
        shuffled = nested_uniform_scramble(index, key)
        x, y = sobol_2d(shuffled)
        x = nested_uniform_scramble(x, hash_u32(key ^ _U32(0x2545F491)))
        y = nested_uniform_scramble(y, hash_u32(key ^ _U32(0x9E3779B9)))
        return np.stack([_to_unit(x), _to_unit(y)], axis=-1)
