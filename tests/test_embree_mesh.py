"""Embree reads the tracer's mesh arrays in place (drt.embree_mesh): same hits as embreex's
copying TriangleMesh, and the arrays live as long as the scene."""

import gc

import numpy as np
from embreex import rtcore_scene as rtcs
from embreex.mesh_construction import TriangleMesh

from drt import embree_mesh


def _sphere(segments=96, rings=48):
    """A closed UV sphere of radius 1: (V, 3) float64 positions, (T, 3) int64 triangles."""
    th = np.linspace(0.0, np.pi, rings)[:, None]
    ph = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)[None, :]
    pos = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th) * np.ones_like(ph)], -1)
    i, j = np.arange(rings - 1)[:, None], np.arange(segments)[None, :]
    a, b = i * segments + j, i * segments + (j + 1) % segments
    c, d = a + segments, b + segments
    tri = np.concatenate([np.stack([a, b, d], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3)])
    return pos.reshape(-1, 3), tri


def _rays(n=20000, seed=3):
    """Rays from a shell of radius ~3 toward points inside the unit sphere (most hit), float32."""
    rng = np.random.default_rng(seed)
    o = rng.normal(size=(n, 3)) * 3.0
    d = rng.normal(size=(n, 3)) * 0.8 - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return o.astype(np.float32), d.astype(np.float32)


def _trace(scene, o, d):
    hits = scene.run(o, d, dists=np.full(len(o), 1e30, np.float32), output=1)
    occluded = scene.run(o, d, dists=np.full(len(o), 1e30, np.float32), query="OCCLUDED")
    return hits, occluded


def test_shared_buffers_give_the_same_hits_as_embreex_copy():
    pos, tri = _sphere()
    assert embree_mesh._handles() is not None, "embreex's layout check failed: the copying path is used"
    shared = embree_mesh.triangle_scene(pos, tri)
    assert hasattr(shared, "shared_buffers")
    copied = rtcs.EmbreeScene()
    TriangleMesh(copied, pos.astype(np.float32), tri.astype(np.int32))
    o, d = _rays()
    (h1, occ1), (h2, occ2) = _trace(shared, o, d), _trace(copied, o, d)
    assert 0.3 < np.mean(h1["primID"] >= 0) < 0.95  # hits and misses both tested
    for key in ("primID", "geomID", "tfar", "u", "v", "Ng"):
        assert np.array_equal(h1[key], h2[key]), key
    assert np.array_equal(occ1, occ2)


def test_scene_keeps_its_arrays_after_the_inputs_are_gone():
    pos, tri = _sphere()
    o, d = _rays(seed=5)
    expected, _ = _trace(embree_mesh.triangle_scene(pos, tri), o, d)
    scene = embree_mesh.triangle_scene(pos.copy(), tri.copy())
    gc.collect()
    junk = [np.full(pos.size * 4, 7.0) for _ in range(8)]  # reuse the freed memory if it was freed
    got, _ = _trace(scene, o, d)
    del junk
    assert np.array_equal(got["primID"], expected["primID"]) and np.array_equal(got["tfar"], expected["tfar"])


def test_copying_fallback_when_the_layout_check_fails(monkeypatch):
    pos, tri = _sphere(32, 16)
    monkeypatch.setattr(embree_mesh, "_api", False)
    scene = embree_mesh.triangle_scene(pos, tri)
    assert not hasattr(scene, "shared_buffers")
    o, d = _rays(2000)
    monkeypatch.setattr(embree_mesh, "_api", None)
    ref, _ = _trace(embree_mesh.triangle_scene(pos, tri), o, d)
    got, _ = _trace(scene, o, d)
    assert np.array_equal(got["primID"], ref["primID"]) and (got["primID"] >= 0).any()


def test_fast_build_gives_the_same_hits():
    """Embree's low-quality (Morton) BVH is another tree over the same triangles: the same
    closest hits, distances and occlusion as the default build."""
    pos, tri = _sphere()
    fast, default = embree_mesh.triangle_scene(pos, tri, fast_build=True), embree_mesh.triangle_scene(pos, tri)
    o, d = _rays(seed=7)
    (h1, occ1), (h2, occ2) = _trace(fast, o, d), _trace(default, o, d)
    assert 0.3 < np.mean(h1["primID"] >= 0) < 0.95
    for key in ("primID", "tfar", "u", "v", "Ng"):
        assert np.array_equal(h1[key], h2[key]), key
    assert np.array_equal(occ1, occ2)


def test_tracer_builds_fast_only_when_few_samples_reach_each_triangle(monkeypatch):
    from drt import trace
    from drt.geometry import SceneGeometry

    pos, tri = _sphere()
    geom = SceneGeometry(np.zeros(3), pos.astype(np.float32), tri.astype(np.int32))
    asked = []

    def spy(positions, triangles, fast_build=False, device=None):
        asked.append(fast_build)
        return embree_mesh.triangle_scene(positions, triangles, fast_build, device)

    monkeypatch.setattr(trace, "triangle_scene", spy)
    per_triangle = trace.FAST_BUILD_SAMPLES_PER_TRIANGLE
    for samples, fast in ((None, False), (per_triangle * len(tri) - 1, True), (per_triangle * len(tri), False)):
        asked.clear()
        trace.Tracer(geom, expected_samples=samples)
        assert asked == [fast], samples
