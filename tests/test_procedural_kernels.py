"""Procedural texture kernels without Blender (drt.materials.procedural): the integer emulation
of Cycles's float32 bit casts and wrapping 32-bit hashes against numpy's own float32/uint32/
int32 arithmetic (an independent implementation: numpy wraps natively), and statistical
properties of the noises. Values against Cycles: tests/test_procedural_textures.py."""

from __future__ import annotations

import numpy as np

from drt.materials import procedural as P


def test_float_bits_equal_numpy_view():
    rng = np.random.default_rng(3)
    xs = np.concatenate([rng.normal(0, 10, 200), rng.normal(0, 1e-39, 20), [0.0, -0.0, 1.0, -2.5, 1e30, 3.4e38,
                                                                              1.17549435e-38, 1e-45]])
    want = xs.astype(np.float32).view(np.uint32).astype(np.int64)
    got = np.array([P.float_bits(float(x)) for x in xs])
    np.testing.assert_array_equal(got, want)


def _rot(x, k):
    return (x << np.uint32(k)) | (x >> np.uint32(32 - k))


def _lookup3_numpy(keys):
    """Jenkins lookup3 hash_uint{1,2,3,4} on uint32 arrays (numpy wraps)."""
    n = len(keys)
    a, b, c = (np.full(keys[0].shape, 0xDEADBEEF + (n << 2) + 13, np.uint32) for _ in range(3))
    with np.errstate(over="ignore"):
        if n == 4:  # mix(a, b, c) of the first three keys, then the fourth into a
            a, b, c = a + keys[0], b + keys[1], c + keys[2]
            a -= c; a ^= _rot(c, 4); c += b; b -= a; b ^= _rot(a, 6); a += c  # noqa: E702
            c -= b; c ^= _rot(b, 8); b += a; a -= c; a ^= _rot(c, 16); c += b  # noqa: E702
            b -= a; b ^= _rot(a, 19); a += c; c -= b; c ^= _rot(b, 4); b += a  # noqa: E702
            a = a + keys[3]
        else:
            if n == 3:
                c = c + keys[2]
            if n >= 2:
                b = b + keys[1]
            a = a + keys[0]
        c ^= b; c -= _rot(b, 14); a ^= c; a -= _rot(c, 11); b ^= a; b -= _rot(a, 25)  # noqa: E702
        c ^= b; c -= _rot(b, 16); a ^= c; a -= _rot(c, 4); b ^= a; b -= _rot(a, 14)  # noqa: E702
        c ^= b; c -= _rot(b, 24)  # noqa: E702
    return c


def test_lookup3_matches_wrapping_uint32():
    rng = np.random.default_rng(4)
    k = rng.integers(-2**31, 2**31, (4, 300)).astype(np.int64)
    ku = (k & 0xFFFFFFFF).astype(np.uint32)
    np.testing.assert_array_equal([P.hash_uint(int(x)) for x in k[0]], _lookup3_numpy([ku[0]]))
    np.testing.assert_array_equal([P.hash_uint2(int(x), int(y)) for x, y in k[:2].T], _lookup3_numpy([ku[0], ku[1]]))
    np.testing.assert_array_equal([P.hash_uint3(*map(int, v)) for v in k[:3].T], _lookup3_numpy(list(ku[:3])))
    np.testing.assert_array_equal([P.hash_uint4(*map(int, v)) for v in k.T], _lookup3_numpy(list(ku)))


def test_pcg3d_matches_wrapping_int32():
    rng = np.random.default_rng(5)
    v = rng.integers(-1000, 1000, (3, 200)).astype(np.int32)
    with np.errstate(over="ignore"):
        x, y, z = (c * np.int32(1664525) + np.int32(1013904223) for c in v)
        for rnd in range(2):
            x = x + y * z
            y = y + z * x
            z = z + x * y
            if rnd == 0:
                x, y, z = x ^ (x >> 16), y ^ (y >> 16), z ^ (z >> 16)
    want = np.stack([x, y, z]) & np.int32(0x7FFFFFFF)
    want = want.astype(np.float32).astype(np.float64) * 2.0 ** -31
    got = np.array([P.pcg(3, int(a), int(b), int(c), 0)[:3] for a, b, c in v.T]).T
    np.testing.assert_array_equal(got, want)


def test_white_noise_is_uniform_and_perlin_in_range():
    rng = np.random.default_rng(6)
    pts = rng.uniform(-50, 50, (4000, 4))
    h = np.array([P.hash_to_float(3, *p) for p in pts])
    counts = np.histogram(h, bins=20, range=(0, 1))[0]
    chi2 = float(((counts - 200.0) ** 2 / 200.0).sum())
    assert chi2 < 43.8  # 19 dof, p = 0.001
    for dim in (1, 2, 3, 4):
        n = np.array([P.snoise(dim, *p) for p in pts[:1500]])
        assert np.all(np.abs(n) <= 1.05) and abs(n.mean()) < 0.05 and n.std() > 0.1
        # the lattice: perlin is 0 at integer points
        assert P.perlin(dim, 3.0, -2.0, 5.0, 7.0) == 0.0


def _perlin_numpy(dim, p):
    """Cycles's perlin_{2,3,4}d in float64 over points p (N, dim), corner by corner with
    numpy's wrapping uint32 lookup3 and Cycles's grad2/3/4 branches (np.where)."""
    f = np.floor(p)
    r = p - f
    cell = f.astype(np.int64)
    fade = r * r * r * (r * (r * 6.0 - 15.0) + 10.0)
    vals = []
    for k in range(1 << dim):
        bits = [(k >> i) & 1 for i in range(dim)]
        h = _lookup3_numpy([((cell[:, i] + bits[i]) & 0xFFFFFFFF).astype(np.uint32) for i in range(dim)])
        g = [r[:, i] - bits[i] for i in range(dim)]
        if dim == 2:
            h = h & 7
            u, v = np.where(h < 4, g[0], g[1]), 2.0 * np.where(h < 4, g[1], g[0])
            terms = [(u, 1), (v, 2)]
        elif dim == 3:
            h = h & 15
            u = np.where(h < 8, g[0], g[1])
            v = np.where(h < 4, g[1], np.where((h == 12) | (h == 14), g[0], g[2]))
            terms = [(u, 1), (v, 2)]
        else:
            h = h & 31
            terms = [(np.where(h < 24, g[0], g[1]), 1), (np.where(h < 16, g[1], g[2]), 2),
                     (np.where(h < 8, g[2], g[3]), 4)]
        total = np.where(h & terms[0][1], -terms[0][0], terms[0][0])
        for t, bit in terms[1:]:
            total = total + np.where(h & bit, -t, t)
        vals.append(total)
    for i in range(dim):  # mix along x, then y, ...: pairs of corners differing in bit i
        t = fade[:, i]
        vals = [(1.0 - t) * vals[2 * j] + t * vals[2 * j + 1] for j in range(len(vals) // 2)]
    return vals[0]


def test_perlin_corners_in_simd_equal_scalar_lookup3():
    """perlin's vectorised corners (drt.materials.lattice_simd) give exactly the lookup3 hashes
    and gradients: every 2–4D value equal to a per-corner numpy evaluation, bit for bit, over
    negative, small and large (wrapping-range) coordinates."""
    rng = np.random.default_rng(11)
    pts = np.concatenate([rng.uniform(-20, 20, (400, 4)), rng.uniform(-1e5, 1e5, (200, 4)),
                          np.floor(rng.uniform(-5, 5, (20, 4)))])
    for dim in (2, 3, 4):
        got = np.array([P.perlin(dim, *p) for p in pts])
        q = np.column_stack([pts[:, 3]] if dim == 1 else [pts[:, i] for i in range(dim)])
        np.testing.assert_array_equal(got, _perlin_numpy(dim, q), err_msg=f"{dim}D")


def test_voronoi_octaves_in_simd_equal_the_scalar_scan():
    """The vectorised Euclidean F1/F2 octaves (all 3^dim cells as lanes) give exactly what the
    generic scalar octave (``voronoi_octave``, pruned F1 scan) gives: distance, colour and
    position, ties included (randomness 0 puts every feature point on a lattice corner)."""
    rng = np.random.default_rng(12)
    pts = np.concatenate([rng.uniform(-30, 30, (150, 3)), rng.uniform(-1e4, 1e4, (30, 3)),
                          np.floor(rng.uniform(-5, 5, (10, 3))) + 0.5]).astype(np.float32).astype(np.float64)
    for randomness in (1.0, 0.37, 0.0):
        for feature in (P.VORONOI_F1, P.VORONOI_F2):
            for x, y, z in pts:
                want3 = P.voronoi_octave(3, feature, P.METRIC_EUCLIDEAN, 1.0, randomness, 0.0, x, y, z, 0.0)
                assert P._octave_euclidean3(feature, randomness, x, y, z) == want3
                want2 = P.voronoi_octave(2, feature, P.METRIC_EUCLIDEAN, 1.0, randomness, 0.0, x, y, 0.0, 0.0)
                assert P._octave_euclidean2(feature, randomness, x, y) == want2
