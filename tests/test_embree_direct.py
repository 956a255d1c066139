"""Single rays traced by Embree from compiled kernels (drt.embree_direct): the same answers as
embreex's batch queries, bit for bit, so walks that use them render the same image."""

import numpy as np
import pytest

from drt import embree_direct as ed
from drt.embree_mesh import triangle_scene

pytestmark = pytest.mark.skipif(not ed.intersect1_address(), reason="Embree's C handles not confirmed here")


def _soup(seed, n_tri=400):
    rng = np.random.default_rng(seed)
    pos = rng.normal(size=(300, 3))
    return pos, rng.integers(0, 300, (n_tri, 3)), rng


def test_trace1_matches_embreex_bit_for_bit():
    """Rays from inside and outside a triangle soup, bounded and unbounded, ~half of them
    missing: the same prim, t, u, v as embreex's ``run`` (misses: t = inf, prim = −1)."""
    pos, tri, rng = _soup(1)
    scene = triangle_scene(pos, tri)
    n = 4000
    o = rng.normal(size=(n, 3)) * np.where(rng.random((n, 1)) < 0.5, 0.3, 6.0)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    tmax = np.where(rng.random(n) < 0.5, np.inf, rng.random(n) * 3.0)
    ref = scene.run(o.astype(np.float32), d.astype(np.float32),
                    dists=np.minimum(tmax, 3e38).astype(np.float32), output=1)
    hit = ref["primID"] >= 0
    assert 0.2 < hit.mean() < 0.8  # both outcomes are exercised
    t, prim, u, v = np.empty(n), np.empty(n, np.int64), np.empty(n), np.empty(n)
    ed.trace_rows(ed.intersect1_address(), ed.scene_address(scene), ed.scratch(),
                  o.astype(np.float32).astype(np.float64), d.astype(np.float32).astype(np.float64),
                  tmax, t, prim, u, v)
    np.testing.assert_array_equal(prim, np.where(hit, ref["primID"], -1))
    np.testing.assert_array_equal(t[hit], ref["tfar"][hit])
    np.testing.assert_array_equal(u[hit], ref["u"][hit])
    np.testing.assert_array_equal(v[hit], ref["v"][hit])
    assert np.isinf(t[~hit]).all()
    assert ed.matches_embreex(scene, o, d, tmax)


def test_scratch_alignment_any_offset():
    """The RTCRayHit is placed 16-byte aligned inside whatever scratch numpy gives, also a
    scratch that starts 4 bytes off alignment."""
    pos, tri, rng = _soup(2)
    scene = triangle_scene(pos, tri)
    o = np.zeros((64, 3))
    d = rng.normal(size=(64, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    tmax = np.full(64, np.inf)
    out = []
    for shift in range(4):
        words = np.zeros(ed.BUFFER_WORDS + 4, np.float32)[shift:shift + ed.BUFFER_WORDS]
        t, prim, u, v = np.empty(64), np.empty(64, np.int64), np.empty(64), np.empty(64)
        ed.trace_rows(ed.intersect1_address(), ed.scene_address(scene), words, o, d, tmax, t, prim, u, v)
        out.append((t, prim))
    for t, prim in out[1:]:
        np.testing.assert_array_equal(prim, out[0][1])
        np.testing.assert_array_equal(t, out[0][0])
    assert (out[0][1] >= 0).mean() > 0.5
