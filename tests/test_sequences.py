"""Samplers: uniformity, determinism, subset independence, stratification, decorrelation and
convergence rate of a smooth 2-D integral."""

import numpy as np
import pytest

from drt.sampling.sequences import (Sampler, hash_u32, nested_uniform_scramble, permute_index,
                                    reverse_bits, sobol_2d)
from stats_util import chi2_pvalue

KINDS = ["SOBOL", "STRATIFIED", "RANDOM"]


def grid(n_pixels: int, spp: int, first_pixel: int = 0):
    """(pixel, index) uint32 arrays for spp samples in each of n_pixels pixels (pixel-major)."""
    pixel = np.repeat(np.arange(first_pixel, first_pixel + n_pixels, dtype=np.uint32), spp)
    index = np.tile(np.arange(spp, dtype=np.uint32), n_pixels)
    return pixel, index


# ------------------------------------------------------------------------- building blocks


def test_bit_helpers():
    x = np.array([1, 0x80000000, 0x12345678], dtype=np.uint32)
    assert reverse_bits(x).tolist() == [0x80000000, 1, 0x1E6A2C48]
    assert np.array_equal(reverse_bits(reverse_bits(x)), x)
    # hash is a bijection: no collisions on a range
    h = hash_u32(np.arange(1 << 16, dtype=np.uint32))
    assert np.unique(h).size == 1 << 16
    # Sobol dimensions 0 and 1 (direct, not Gray-code, order)
    x, y = sobol_2d(np.arange(8, dtype=np.uint32))
    assert (x.astype(np.float64) / 2**32).tolist() == [0, .5, .25, .75, .125, .625, .375, .875]
    assert (y.astype(np.float64) / 2**32).tolist() == [0, .5, .75, .25, .625, .125, .375, .875]


@pytest.mark.parametrize("n", [1, 2, 3, 5, 16, 17, 100])
def test_permute_index_is_a_permutation(n):
    keys = np.arange(30, dtype=np.uint32) * np.uint32(0x9E3779B1)
    i = np.tile(np.arange(n, dtype=np.uint32), (30, 1))
    p = permute_index(i, n, keys[:, None])
    assert np.all(np.sort(p, axis=1) == np.arange(n))
    if n > 3:  # and different keys give different permutations
        assert len({tuple(r) for r in p.tolist()}) > 20


def test_nested_uniform_scramble_maps_blocks_to_blocks():
    # an aligned block of 2^k indices maps onto an aligned block of 2^k: the (0,2) property of
    # every prefix survives the index shuffle
    for seed in (0, 1, 0xDEADBEEF):
        s = nested_uniform_scramble(np.arange(64, dtype=np.uint32), np.uint32(seed))
        assert np.unique(s >> np.uint32(6)).size == 1
        assert np.unique(s & np.uint32(63)).size == 64


# ------------------------------------------------------------------------- basic properties


@pytest.mark.parametrize("kind", KINDS)
def test_range_shape_dtype(kind):
    s = Sampler(kind, seed=1, spp=16)
    pixel, index = grid(64, 16)
    u = s.sample_2d(pixel, index, 3)
    assert u.shape == (pixel.size, 2) and u.dtype == np.float64
    assert np.all((u >= 0.0) & (u < 1.0))
    assert s.sample_1d(pixel, index, 3).shape == (pixel.size,)
    assert np.array_equal(s.sample_1d(pixel, index, 3), u[:, 0])
    # other integer dtypes are accepted and mean the same thing
    assert np.array_equal(s.sample_2d(pixel.astype(np.int64), index.astype(np.int32), 3), u)


@pytest.mark.parametrize("kind", KINDS)
def test_uniformity_chi2(kind):
    s = Sampler(kind, seed=7, spp=64)
    pixel, index = grid(500, 64)
    for dim in (0, 5):
        u = s.sample_2d(pixel, index, dim)
        obs, _, _ = np.histogram2d(u[:, 0], u[:, 1], bins=16, range=[[0, 1], [0, 1]])
        p, *_ = chi2_pvalue(obs, np.full(obs.shape, u.shape[0] / obs.size))
        assert p > 0.01, (kind, dim, p)


@pytest.mark.parametrize("kind", KINDS)
def test_deterministic(kind):
    pixel, index = grid(50, 8)
    a = Sampler(kind, seed=3, spp=8).sample_2d(pixel, index, 2)
    b = Sampler(kind, seed=3, spp=8).sample_2d(pixel, index, 2)
    assert np.array_equal(a, b)
    c = Sampler(kind, seed=4, spp=8).sample_2d(pixel, index, 2)
    assert not np.any(np.all(a == c, axis=1)), "seed must change every sample"


@pytest.mark.parametrize("kind", KINDS)
def test_subset_independence(kind):
    s = Sampler(kind, seed=11, spp=10)
    pixel, index = grid(30, 10)
    full = s.sample_2d(pixel, index, 1).reshape(30, 10, 2)
    # samples 5..9 alone, in shuffled order, with pixels interleaved
    sub_px, sub_ix = np.meshgrid(np.arange(30, dtype=np.uint32),
                                 np.arange(5, 10, dtype=np.uint32), indexing="ij")
    order = np.random.default_rng(0).permutation(sub_px.size)
    part = s.sample_2d(sub_px.ravel()[order], sub_ix.ravel()[order], 1)
    expect = full[:, 5:10].reshape(-1, 2)[order]
    assert np.array_equal(part, expect)


def test_unknown_kind_and_bad_spp():
    with pytest.raises(ValueError):
        Sampler("HALTON")
    with pytest.raises(ValueError):
        Sampler("SOBOL", spp=0)


# ------------------------------------------------------------------------- stratification


@pytest.mark.parametrize("spp,shape", [(16, (4, 4)), (8, (4, 2)), (12, (4, 3)), (7, (7, 1))])
def test_stratified_one_sample_per_stratum(spp, shape):
    nx, ny = shape
    s = Sampler("STRATIFIED", seed=2, spp=spp)
    pixel, index = grid(40, 2 * spp)  # two rounds of spp samples
    for dim in (0, 1, 9):
        u = s.sample_2d(pixel, index, dim).reshape(40, 2, spp, 2)
        cell = np.floor(u[..., 0] * nx) + nx * np.floor(u[..., 1] * ny)
        assert np.all(np.sort(cell, axis=-1) == np.arange(spp)), (spp, dim)


def test_stratified_order_differs_between_dimensions_and_pixels():
    s = Sampler("STRATIFIED", seed=0, spp=16)
    pixel, index = grid(20, 16)
    cells = []
    for dim in (0, 1):
        u = s.sample_2d(pixel, index, dim).reshape(20, 16, 2)
        cells.append(np.floor(u[..., 0] * 4) + 4 * np.floor(u[..., 1] * 4))
    assert np.mean(cells[0] == cells[1]) < 0.2       # ≈ 1/16 by chance
    assert len({tuple(r) for r in cells[0].tolist()}) == 20


@pytest.mark.parametrize("k", [0, 1, 2, 4, 6, 8])
def test_sobol_elementary_intervals(k):
    spp = 1 << k
    s = Sampler("SOBOL", seed=5, spp=spp)
    pixel, index = grid(25, spp, first_pixel=1000)
    for dim in (0, 3):
        u = s.sample_2d(pixel, index, dim).reshape(25, spp, 2)
        # 1-D projections: one sample per interval of length 2^-k
        for c in (0, 1):
            cells = np.floor(u[..., c] * spp)
            assert np.all(np.sort(cells, axis=-1) == np.arange(spp))
        # every 2-D elementary interval shape 2^-a × 2^-(k-a) holds one sample: (0, k, 2)-net
        for a in range(k + 1):
            cells = np.floor(u[..., 0] * (1 << a)) * (1 << (k - a)) + np.floor(
                u[..., 1] * (1 << (k - a)))
            assert np.all(np.sort(cells, axis=-1) == np.arange(spp)), (k, a)


def test_sobol_later_blocks_are_nets_too():
    # samples [64, 128) of a pixel also form a (0, 6, 2)-net (progressive rendering)
    s = Sampler("SOBOL", seed=9)
    pixel = np.repeat(np.arange(10, dtype=np.uint32), 64)
    index = np.tile(np.arange(64, 128, dtype=np.uint32), 10)
    u = s.sample_2d(pixel, index, 4).reshape(10, 64, 2)
    for a in range(7):
        cells = np.floor(u[..., 0] * (1 << a)) * (1 << (6 - a)) + np.floor(
            u[..., 1] * (1 << (6 - a)))
        assert np.all(np.sort(cells, axis=-1) == np.arange(64))


# ------------------------------------------------------------------------- decorrelation


@pytest.mark.parametrize("kind", KINDS)
def test_decorrelation_across_pixels_and_dims(kind):
    n_pix, spp = 2000, 8
    s = Sampler(kind, seed=1, spp=spp)
    pixel, index = grid(n_pix, spp)
    d0 = s.sample_2d(pixel, index, 0)
    d1 = s.sample_2d(pixel, index, 1)
    nb = s.sample_2d(pixel + np.uint32(1), index, 0)  # neighbouring pixel, same index
    n = d0.shape[0]
    limit = 4.0 / np.sqrt(n)
    pairs = {
        "dim0.x vs dim1.x": (d0[:, 0], d1[:, 0]),
        "dim0.y vs dim1.y": (d0[:, 1], d1[:, 1]),
        "dim0.x vs dim1.y": (d0[:, 0], d1[:, 1]),
        "pixel vs next pixel (x)": (d0[:, 0], nb[:, 0]),
        "pixel vs next pixel (y)": (d0[:, 1], nb[:, 1]),
        "x vs y": (d0[:, 0], d0[:, 1]),
    }
    for name, (a, b) in pairs.items():
        r = np.corrcoef(a, b)[0, 1]
        assert abs(r) < limit, (kind, name, r)
    # and the two dimensions are not the same point set in a different order
    assert not np.allclose(np.sort(d0[:spp, 0]), np.sort(d1[:spp, 0]))


# ------------------------------------------------------------------------- convergence


def _f(x, y):
    bump = np.exp(-((x - 0.3) ** 2) - 2.0 * (y - 0.6) ** 2)
    return bump * (1.0 + 0.5 * np.cos(3.0 * x + 2.0 * y))


def _exact_integral():
    t, wts = np.polynomial.legendre.leggauss(64)
    t = 0.5 * (t + 1.0)
    wts = 0.5 * wts
    x, y = np.meshgrid(t, t, indexing="ij")
    return float(np.sum(_f(x, y) * wts[:, None] * wts[None, :]))


@pytest.mark.parametrize("kind,slope_range", [
    ("SOBOL", (-3.0, -0.75)), ("STRATIFIED", (-3.0, -0.75)), ("RANDOM", (-0.65, -0.35)),
])
def test_rmse_convergence_rate(kind, slope_range):
    exact = _exact_integral()
    ns = [16, 32, 64, 128, 256, 512, 1024]
    n_trials = 50  # pixels as independent trials
    rmse = []
    for n in ns:
        s = Sampler(kind, seed=21, spp=n)
        pixel, index = grid(n_trials, n, first_pixel=300)
        u = s.sample_2d(pixel, index, 2)
        est = _f(u[:, 0], u[:, 1]).reshape(n_trials, n).mean(axis=1)
        rmse.append(np.sqrt(np.mean((est - exact) ** 2)))
    slope = np.polyfit(np.log(ns), np.log(rmse), 1)[0]
    lo, hi = slope_range
    assert lo < slope < hi, (kind, slope, rmse)


def test_sample_5d_is_jointly_stratified_and_extends_sample_2d():
    """The camera's sample (pixel filter, lens, shutter time): each of the 5 dimensions is
    stratified on its own over a pixel's first 2^m samples, the (filter x, filter y) pair is a
    (0, m, 2)-net, every other pair puts at most 4 points in an elementary interval of area 2^-m
    (t ≤ 2), and the first two values are sample_2d's for the same dimension."""
    s = Sampler("SOBOL", 3, 256)
    for m in (4, 6, 8):
        n = 1 << m
        u = s.sample_5d(np.full(n, 77), np.arange(n), 0)
        for k in range(5):
            assert len(np.unique(np.floor(u[:, k] * n))) == n, (m, k)
        for a in range(5):
            for b in range(a + 1, 5):
                worst = 0
                for i in range(m + 1):
                    cells = np.floor(u[:, a] * 2 ** i) * 2 ** (m - i) + np.floor(u[:, b] * 2 ** (m - i))
                    worst = max(worst, np.bincount(cells.astype(int), minlength=n).max())
                assert worst <= (1 if (a, b) == (0, 1) else 4), (m, a, b, worst)
    pix, idx = np.arange(50), np.arange(50) * 7
    assert np.array_equal(s.sample_5d(pix, idx, 0)[:, :2], s.sample_2d(pix, idx, 0))
    for kind in ("STRATIFIED", "RANDOM"):
        other = Sampler(kind, 3, 16)
        five = other.sample_5d(pix, idx % 16, 0)
        assert np.array_equal(five[:, 2:4], other.sample_2d(pix, idx % 16, 1))
        assert np.array_equal(five[:, 4], other.sample_2d(pix, idx % 16, 2)[:, 0])


def test_sample_3d_is_jointly_stratified_and_extends_sample_2d():
    """The per-bounce BSDF sample (direction u, v and lobe choice) and light sample (position,
    selection): over a pixel's first 2^m SOBOL samples every elementary box of volume 2^(1−m)
    holds exactly 2 points (a (1, m, 3)-net), so the directions that pick one lobe are
    stratified too; a padded third value (STRATIFIED, RANDOM) is not."""
    s = Sampler("SOBOL", 5, 256)
    for m in (4, 6, 8):
        n = 1 << m
        for pixel in (3, 1234):
            u = s.sample_3d(np.full(n, pixel), np.arange(n), 9)
            for i in range(m):
                for j in range(m - i):
                    k = m - 1 - i - j
                    cells = (np.floor(u[:, 0] * 2 ** i) * 2 ** (j + k) + np.floor(u[:, 1] * 2 ** j) * 2 ** k
                             + np.floor(u[:, 2] * 2 ** k))
                    counts = np.bincount(cells.astype(int), minlength=n // 2)
                    assert counts.min() == counts.max() == 2, (m, pixel, i, j, k)
    pix, idx = np.arange(50), np.arange(50) * 7
    assert np.array_equal(s.sample_3d(pix, idx, 9)[:, :2], s.sample_2d(pix, idx, 9))
    from drt.sampling.sequences import PAD_3D

    for kind in ("STRATIFIED", "RANDOM"):
        other = Sampler(kind, 3, 16)
        three = other.sample_3d(pix, idx % 16, 9)
        assert np.array_equal(three[:, :2], other.sample_2d(pix, idx % 16, 9))
        assert np.array_equal(three[:, 2], other.sample_2d(pix, idx % 16, 9 + PAD_3D)[:, 0])
    # padding loses the joint stratification: with an independent third value a box of the
    # same (4 × 4 × 2) partition is empty in ~88 % of pixels (each 2-D cell's 4 jittered points
    # all fall in one half with probability 1/8; 1 − (7/8)^16), never with SOBOL
    st = Sampler("STRATIFIED", 5, 64)
    empty = 0
    for pixel in range(100):
        v = st.sample_3d(np.full(64, pixel), np.arange(64), 9)
        cells = np.floor(v[:, 0] * 4) * 8 + np.floor(v[:, 1] * 4) * 2 + np.floor(v[:, 2] * 2)
        empty += np.bincount(cells.astype(int), minlength=32).min() == 0
    assert empty > 50, empty


def test_sobol_byte_tables_equal_the_bit_loops():
    """The table lookups the samplers use (``sobol_fast``) give exactly the direction-number
    recurrences' values (``sobol_dim1`` … ``sobol_dim4``), for small and scrambled 32-bit
    indices."""
    from drt.sampling import sequences as S

    rng = np.random.default_rng(11)
    idx = np.concatenate([np.arange(300), rng.integers(0, 2**32, 300), [2**32 - 1, 2**31]]).astype(np.int64)
    loops = (S.sobol_dim1, S.sobol_dim2, S.sobol_dim3, S.sobol_dim4)
    for d, loop in enumerate(loops, start=1):
        want = [loop(int(i)) for i in idx]
        assert [S.sobol_fast(d, int(i)) for i in idx] == want, d


def test_sobol_samples_equal_the_scramble_formula_bit_for_bit():
    """SOBOL ``sample_2d`` / ``sample_3d`` / ``sample_5d`` equal Burley's construction written out
    with the plain building blocks — h = hash(hash(prefix ^ pixel) ^ dim), the index shuffled by
    ``nested_uniform_scramble(index, h)``, Sobol dimension k of it (``sobol_fast``; dimension 0 is
    the bit reversal), each Owen-scrambled with hash(h ^ seed_k) — exactly, although the kernels
    keep the shuffled index and the Sobol values bit-reversed (``SOBOL_BYTES_REV``)."""
    from drt.sampling import sequences as S

    rng = np.random.default_rng(5)
    n = 400
    pixel = rng.integers(0, 2**32, n).astype(np.int64)
    index = np.concatenate([np.arange(200), rng.integers(0, 2**32, n - 200)]).astype(np.int64)
    dim = rng.integers(0, 2**31, n).astype(np.int64)
    st = Sampler("SOBOL", seed=1234, spp=64)
    prefix = np.uint32(st.data.prefix)
    seeds = [S._SEED_U0, S._SEED_U1, S._SEED_U2, S._SEED_U3, S._SEED_U4]
    want = np.empty((n, 5))
    for k in range(n):
        h = hash_u32(hash_u32(prefix ^ np.uint32(pixel[k])) ^ np.uint32(dim[k]))
        shuffled = nested_uniform_scramble(np.uint32(index[k]), h)
        bits = [int(reverse_bits(shuffled))] + [S.sobol_fast(d, int(shuffled)) for d in range(1, 5)]
        for j in range(5):
            scrambled = nested_uniform_scramble(np.uint32(bits[j]), hash_u32(h ^ np.uint32(seeds[j])))
            want[k, j] = float(scrambled) / 2.0**32
    got5 = np.stack([st.sample_5d(pixel[k:k + 1], index[k:k + 1], int(dim[k]))[0] for k in range(n)])
    got3 = np.stack([st.sample_3d(pixel[k:k + 1], index[k:k + 1], int(dim[k]))[0] for k in range(n)])
    got2 = np.stack([st.sample_2d(pixel[k:k + 1], index[k:k + 1], int(dim[k]))[0] for k in range(n)])
    assert np.array_equal(got5, want)
    assert np.array_equal(got3, want[:, :3])
    assert np.array_equal(got2, want[:, :2])
    # the reversed tables are the plain ones conjugated by the bit reversal
    r = rng.integers(0, 2**32, 200).astype(np.int64)
    for d in range(1, 5):
        assert [S.sobol_rev(d, int(x)) for x in r] == [
            int(reverse_bits(np.uint32(S.sobol_fast(d, int(reverse_bits(np.uint32(x))))))) for x in r]
