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
        words = np.zeros(ed.BUFFER_WORDS + 4, np.uint32)[shift:shift + ed.BUFFER_WORDS]
        t, prim, u, v = np.empty(64), np.empty(64, np.int64), np.empty(64), np.empty(64)
        ed.trace_rows(ed.intersect1_address(), ed.scene_address(scene), words, o, d, tmax, t, prim, u, v)
        out.append((t, prim))
    for t, prim in out[1:]:
        np.testing.assert_array_equal(prim, out[0][1])
        np.testing.assert_array_equal(t, out[0][0])
    assert (out[0][1] >= 0).mean() > 0.5


def test_cached_direct_kernels_load_without_numba_array_module():
    """A process that loads ``trace_rows`` from the cache does not import ``numba.np.arrayobj``
    (tens of milliseconds of every render's start-up for scenes with moving objects or
    subsurface walks): the scratch's float fields are bitcast, not read through ``view``."""
    import os
    import subprocess
    import sys

    pos, tri, _ = _soup(3)
    scene = triangle_scene(pos, tri)
    o, d = np.zeros((4, 3)), np.tile([0.0, 0.0, 1.0], (4, 1))
    out = np.empty(4), np.empty(4, np.int64), np.empty(4), np.empty(4)
    ed.trace_rows(ed.intersect1_address(), ed.scene_address(scene), ed.scratch(), o, d, np.full(4, np.inf), *out)
    code = (
        "import sys, numpy as np\n"
        "from drt import embree_direct as ed\n"
        "from drt.embree_mesh import triangle_scene\n"
        "rng = np.random.default_rng(3)\n"
        "pos = rng.normal(size=(300, 3)); tri = rng.integers(0, 300, (400, 3))\n"
        "o, d = np.zeros((4, 3)), np.tile([0.0, 0.0, 1.0], (4, 1))\n"
        "out = np.empty(4), np.empty(4, np.int64), np.empty(4), np.empty(4)\n"
        "scene = triangle_scene(pos, tri)  # (kept alive while Embree reads it)\n"
        "ed.trace_rows(ed.intersect1_address(), ed.scene_address(scene), ed.scratch(),\n"
        "              o, d, np.full(4, np.inf), *out)\n"
        "print('numba.np.arrayobj' in sys.modules, sum(ed.trace_rows.dispatcher().stats.cache_misses.values()))\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=dict(os.environ),
                         timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    # (the second figure: kernels compiled instead of loaded, which imports numba's compiler and
    # would make the first say nothing)
    assert res.stdout.split() == ["False", "0"], res.stdout
