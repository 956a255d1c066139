"""Ray queries: deforming meshes are intersected exactly at each ray's time; rigid motion too."""

from types import SimpleNamespace

import numpy as np
import pytest

from drt.geometry import build_geometry
from drt.scene import scene_from_dict
from drt.trace import Tracer, _intersect_deforming
from scene_builders import add_material, add_mesh, base_header, quad, translation


def brute_force(mm, o, d, tau):
    best = np.full(len(o), np.inf)
    prim = np.full(len(o), -1)
    for j, corners in enumerate(mm.triangles):
        v = (1 - tau)[:, None, None] * mm.positions[corners][None] + tau[:, None, None] * mm.positions_close[corners][None]
        e1, e2 = v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]
        pv = np.cross(d, e2)
        det = (e1 * pv).sum(1)
        tv = o - v[:, 0]
        u = (tv * pv).sum(1) / det
        qv = np.cross(tv, e1)
        w = (d * qv).sum(1) / det
        t = (e2 * qv).sum(1) / det
        ok = (u >= 0) & (w >= 0) & (u + w <= 1) & (t > 0) & (t < best)
        best[ok], prim[ok] = t[ok], j
    return best, prim


def test_deforming_mesh_hits_equal_brute_force():
    rng = np.random.default_rng(1)
    T = 200
    p0 = rng.random((T * 3, 3))
    mm = SimpleNamespace(positions=p0, positions_close=p0 + rng.normal(scale=0.05, size=p0.shape),
                         triangles=np.arange(T * 3).reshape(T, 3))
    n = 2000
    o = rng.random((n, 3)) * 2 - 0.5
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    tau = rng.random(n)
    t, prim, *_ = _intersect_deforming(mm, o, d, tau, np.full(n, np.inf))
    t_ref, prim_ref = brute_force(mm, o, d, tau)
    assert (prim_ref >= 0).sum() > 200
    assert np.array_equal(prim, prim_ref)
    hit = prim_ref >= 0
    np.testing.assert_allclose(t[hit], t_ref[hit], rtol=1e-12)


def test_rigidly_moving_quad_is_hit_where_it_is_at_the_ray_time():
    h = base_header()
    a = {}
    m = add_material(h, "m", [{"type": "DIFFUSE", "color": [1, 1, 1]}])
    motion = {"matrix_open": translation(0, 0, 0), "matrix_close": translation(10, 0, 0)}
    add_mesh(h, a, "q", *quad((0, 0, 0), (0.5, 0, 0), (0, 0.5, 0)), material=m, motion=motion)
    h["render"]["shutter"] = [0.0, 1.0]
    h["camera"]["matrix_world"] = translation(0, 0, 5)
    scene = scene_from_dict(h, a)
    geom = build_geometry(scene)
    tr = Tracer(geom)
    # rays straight down at x = 0..10 (camera-relative frame: the camera sits at the origin)
    xs = np.linspace(0, 10, 11)
    o = np.column_stack([xs, np.zeros(11), np.zeros(11)])
    d = np.tile([0.0, 0.0, -1.0], (11, 1))
    at_own_time = tr.intersect(o, d, tau=xs / 10.0)
    assert np.all(at_own_time.hit)
    np.testing.assert_allclose(at_own_time.t, 5.0)
    assert np.all(at_own_time.ng[:, 2] > 0.999)
    too_early = tr.intersect(o, d, tau=np.clip(xs / 10.0 - 0.2, 0, 1))
    assert not np.any(too_early.hit[3:])


def _spinning_scene(deforming: bool):
    """A cube-ish blob that translates, turns 170° and grows 3× over the shutter (rigid), or
    also deforms."""
    from scene_builders import uv_sphere
    h = base_header()
    a = {}
    m = add_material(h, "m", [{"type": "DIFFUSE", "color": [1, 1, 1]}])
    pos, tri, _ = uv_sphere(0.5, center=(0.6, 0.0, 0.0), rings=6, segments=8)
    c, s = np.cos(np.radians(170)), np.sin(np.radians(170))
    close = np.array([[3 * c, -3 * s, 0, 2.0], [3 * s, 3 * c, 0, 1.0], [0, 0, 3, 0.5], [0, 0, 0, 1]])
    motion = {"matrix_open": translation(0, 0, 0), "matrix_close": close.tolist()}
    pos_close = pos * np.array([1.0, 1.3, 0.7]) if deforming else None
    add_mesh(h, a, "blob", pos, tri, material=m, motion=motion, positions_close=pos_close)
    h["render"]["shutter"] = [0.0, 1.0]
    h["camera"]["matrix_world"] = translation(0, 0, 0)
    return Tracer(build_geometry(scene_from_dict(h, a)))


def test_swept_box_culling_never_loses_a_hit():
    """Rays that miss a moving object's swept box skip it; the box must hold the object at
    every τ. Against the same tracer with culling disabled, over rays aimed at random points of
    the object's path (rotation, scale and translation all change)."""
    rng = np.random.default_rng(4)
    for deforming in (False, True):
        tr = _spinning_scene(deforming)
        n = 4000
        target = rng.uniform(-3.5, 4.5, size=(n, 3))
        o = rng.uniform(-8, 8, size=(n, 3))
        d = target - o
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        tau = rng.random(n)
        culled = tr.intersect(o, d, tau=tau)
        for obj in tr.moving:  # no culling: an infinite swept box makes every ray a candidate
            obj.box_lo[:] = -np.inf
            obj.box_hi[:] = np.inf
        full = tr.intersect(o, d, tau=tau)
        assert full.hit.sum() > 200, deforming
        assert np.array_equal(culled.prim, full.prim), deforming
        np.testing.assert_array_equal(culled.t, full.t)
        blocked = tr.occluded(o, d, np.full(n, np.inf), tau)
        assert np.array_equal(blocked, full.hit)


def _random_rays(rng, n):
    target = rng.uniform(-3.5, 4.5, size=(n, 3))
    o = rng.uniform(-8, 8, size=(n, 3))
    d = target - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return o, d, rng.random(n)


def test_moving_hit_points_normals_and_transforms():
    """Hit points lie on their rays; normals are the world triangle's (vertices at the ray's τ
    mapped by the object's transform at τ), unit, counter-clockwise front; moving_linear holds
    that transform for moving hits and the identity elsewhere, and is None without moving hits."""
    rng = np.random.default_rng(7)
    for deforming in (False, True):
        tr = _spinning_scene(deforming)
        mm = tr.geom.moving[0]
        o, d, tau = _random_rays(rng, 3000)
        hits = tr.intersect(o, d, tau=tau)
        hit = hits.hit
        assert hit.sum() > 100 and not hit.all()
        # Embree's t and barycentrics are float32; the exact deforming test (the fallback without
        # Embree's C handles) is float64
        exact = deforming and tr.moving[0].direct is None
        np.testing.assert_allclose(hits.p[hit], o[hit] + hits.t[hit, None] * d[hit],
                                   atol=1e-9 if exact else 2e-5)
        lin, trans = mm.motion.at(tau[hit])
        np.testing.assert_array_equal(hits.moving_linear[hit], lin)
        np.testing.assert_array_equal(hits.moving_linear[~hit], np.broadcast_to(np.eye(3), ((~hit).sum(), 3, 3)))
        tri = mm.triangles[hits.prim[hit] - mm.prim_offset]
        v = mm.positions[tri]
        if deforming:
            w = tau[hit][:, None, None]
            v = (1 - w) * v + w * mm.positions_close[tri]
        world = np.einsum("nij,nkj->nki", lin, v) + trans[:, None]
        n_ref = np.cross(world[:, 1] - world[:, 0], world[:, 2] - world[:, 0])
        n_ref /= np.linalg.norm(n_ref, axis=1, keepdims=True)
        np.testing.assert_allclose(hits.ng[hit], n_ref, atol=1e-9)
        # the shading normals' map: the inverse transpose of the hit's transform, on moving hits
        np.testing.assert_array_equal(hits.moving, hit)
        np.testing.assert_allclose(hits.normal_xform[hit], np.linalg.inv(lin).transpose(0, 2, 1),
                                   rtol=1e-12, atol=1e-12)
        # misses end where they start
        np.testing.assert_array_equal(hits.p[~hit], o[~hit])
        assert np.isinf(hits.t[~hit]).all() and (hits.prim[~hit] == -1).all()
        # rays that miss everything: no moving hit, no transforms
        far = tr.intersect(o[~hit], d[~hit], tau=tau[~hit])
        assert not far.hit.any() and far.moving_linear is None and far.normal_xform is None


def test_occlusion_of_moving_objects_respects_tmax():
    rng = np.random.default_rng(8)
    for deforming in (False, True):
        tr = _spinning_scene(deforming)
        o, d, tau = _random_rays(rng, 3000)
        hits = tr.intersect(o, d, tau=tau)
        tmax = np.where(rng.random(len(o)) < 0.5, hits.t * 0.999, hits.t * 1.001)
        tmax[~hits.hit] = rng.uniform(0, 20, (~hits.hit).sum())
        expect = hits.hit & (hits.t < tmax)
        assert expect.sum() > 50 and (hits.hit & ~expect).sum() > 50
        np.testing.assert_array_equal(tr.occluded(o, d, tmax, tau), expect)
        limited = tr.intersect(o, d, tau=tau, tmax=tmax)
        np.testing.assert_array_equal(limited.hit, expect)


def test_concurrent_queries_match_serial():
    """Several threads query one tracer at once (the render loop does): no shared scratch."""
    rng = np.random.default_rng(9)
    tr = _spinning_scene(True)
    _parallel_matches_serial(tr, [_random_rays(rng, 2000) for _ in range(8)])


def _parallel_matches_serial(tr, batches):
    """Four threads querying ``tr`` at once with ``batches`` (three times over) get what one
    thread gets: hits, distances, points and occlusion."""
    from concurrent.futures import ThreadPoolExecutor

    def query(b):
        o, d, tau = b
        h = tr.intersect(o, d, tau=tau)
        return h.prim, h.t, h.p, tr.occluded(o, d, np.full(len(o), np.inf), tau)

    serial = [query(b) for b in batches]
    with ThreadPoolExecutor(4) as pool:
        parallel = list(pool.map(query, batches * 3))
    for k, got in enumerate(parallel):
        for a, b in zip(serial[k % len(batches)], got):
            np.testing.assert_array_equal(a, b)


def _without_direct(tr):
    """The same tracer's objects on the batch / exact path (as without Embree's C handles)."""
    import copy

    other = copy.copy(tr)
    other.moving = [copy.copy(obj) for obj in tr.moving]
    other.instanced = None
    for obj in other.moving:
        obj.direct = None
    return other


def test_kernels_trace_rigid_objects_exactly_as_the_batches_do():
    """A rigidly moving object queried by Embree from inside the kernel (``_moving_hits``)
    gives the batch path's answers bit for bit: same float32 rays, same hits, same occlusion."""
    from drt import embree_direct

    if not embree_direct.intersect1_address():
        pytest.skip("Embree's C handles not confirmed here")
    rng = np.random.default_rng(11)
    tr = _spinning_scene(False)
    assert tr.moving[0].direct is not None and tr.moving[0].direct[4] is False
    batch = _without_direct(tr)
    o, d, tau = _random_rays(rng, 4000)
    a, b = tr.intersect(o, d, tau=tau), batch.intersect(o, d, tau=tau)
    assert a.hit.sum() > 200
    for name in ("t", "prim", "b1", "b2", "p", "ng", "moving_linear", "moving"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    # (the shading normals' map is written for moving hits only)
    np.testing.assert_array_equal(a.normal_xform[a.moving], b.normal_xform[b.moving])
    tmax = np.where(a.hit, a.t * np.where(rng.random(len(o)) < 0.5, 0.999, 1.001), 5.0)
    np.testing.assert_array_equal(tr.occluded(o, d, tmax, tau), batch.occluded(o, d, tmax, tau))


def test_deforming_mesh_through_embree_motion_blur_matches_the_exact_intersector():
    """A deforming mesh is an Embree scene with two time steps queried at each ray's τ: the
    same triangles as the exact float64 intersector (all but rays grazing an edge, where float32
    may pick the neighbour), t within float32 error, and the same occlusion."""
    from drt import embree_direct

    if not embree_direct.intersect1_address():
        pytest.skip("Embree's C handles not confirmed here")
    rng = np.random.default_rng(12)
    tr = _spinning_scene(True)
    assert tr.moving[0].direct is not None and tr.moving[0].direct[4] is True
    exact = _without_direct(tr)
    o, d, tau = _random_rays(rng, 12000)
    a, b = tr.intersect(o, d, tau=tau), exact.intersect(o, d, tau=tau)
    assert b.hit.sum() > 500
    same = a.prim == b.prim
    assert same.mean() > 0.995, same.mean()
    both = same & b.hit
    np.testing.assert_allclose(a.t[both], b.t[both], rtol=2e-5, atol=2e-5)
    np.testing.assert_allclose(a.p[both], b.p[both], atol=5e-5)
    blocked = tr.occluded(o, d, np.full(len(o), np.inf), tau)
    assert (blocked == b.hit).mean() > 0.995
    # a far larger deforming mesh costs what Embree's hierarchy costs, not a scan of its clusters
    # (the exact path's time grows with the mesh): checked through the answers only here


def test_a_failing_probe_leaves_the_object_on_the_batch_path(monkeypatch):
    """Whatever goes wrong while checking an object's Embree scene for the kernels, the tracer
    is still built and answers through the batch / exact path."""
    import drt.trace as trace_mod

    def broken(*args, **kwargs):
        raise RuntimeError("no Embree here")

    monkeypatch.setattr(trace_mod.embree_direct, "matches_embreex", broken)
    monkeypatch.setattr(trace_mod, "deforming_scene", broken)
    rng = np.random.default_rng(13)
    for deforming in (False, True):
        tr = _spinning_scene(deforming)
        assert tr.moving[0].direct is None
        o, d, tau = _random_rays(rng, 2000)
        assert tr.intersect(o, d, tau=tau).hit.sum() > 50


def _moving_crowd(count=12, deforming_every=4, static_floor=True):
    """``count`` moving blobs in a row: each translates, turns (up to 170°) and scales (some
    mirrored, every ``deforming_every``-th also deforms), over an optional static floor."""
    from scene_builders import uv_sphere
    h = base_header()
    a = {}
    m = add_material(h, "m", [{"type": "DIFFUSE", "color": [1, 1, 1]}])
    if static_floor:
        add_mesh(h, a, "floor", *quad((0, 0, -1.5), (8, 0, 0), (0, 8, 0)), material=m)
    pos, tri, _ = uv_sphere(0.5, center=(0.3, 0.0, 0.0), rings=6, segments=8)
    for k in range(count):
        x = -5.0 + 10.0 * k / max(count - 1, 1)
        angle = np.radians(170.0 * ((k % 5) / 4.0))
        c, s = np.cos(angle), np.sin(angle)
        grow = 1.0 + 0.5 * (k % 3)
        mirror = -1.0 if k % 6 == 5 else 1.0
        close = np.array([[grow * c, -grow * s, 0, x + 0.8], [grow * s, grow * c, 0, 0.4 * (k % 2)],
                          [0, 0, mirror * grow, 0.3], [0, 0, 0, 1]])
        motion = {"matrix_open": translation(x, 0, 0), "matrix_close": close.tolist()}
        deforming = deforming_every and k % deforming_every == 0
        add_mesh(h, a, f"blob{k}", pos, tri, material=m, motion=motion,
                 positions_close=pos * np.array([1.0, 1.3, 0.7]) if deforming else None)
    h["render"]["shutter"] = [0.0, 1.0]
    h["camera"]["matrix_world"] = translation(0, 0, 0)
    return h, a


def _crowd_rays(rng, n):
    target = rng.uniform([-6.5, -2.5, -1.6], [6.5, 2.5, 2.5], size=(n, 3))
    o = rng.uniform(-9, 9, size=(n, 3))
    d = target - o
    d /= np.sqrt((d * d).sum(axis=1, keepdims=True))
    return o, d, rng.random(n)


def _per_object(tr):
    """The same tracer answering object by object (the path before scenes of instances)."""
    import copy

    other = copy.copy(tr)
    other.instanced = None
    return other


def test_many_moving_objects_are_one_scene_of_instances():
    """With several moving objects every ray is one Embree query against a scene of instances,
    each object under its own motion at the ray's τ. It answers as the per-object path does (the
    oracle: DRT's float64 transforms, each object's swept box): the same triangles but for rays
    grazing an edge (Embree evaluates the instances' motion in float32), t to float32 error,
    the same transforms, points, normals and normal maps, and the same occlusion."""
    from drt import embree_direct

    if not embree_direct.intersect1_address():
        pytest.skip("Embree's C handles not confirmed here")
    rng = np.random.default_rng(21)
    tr = Tracer(build_geometry(scene_from_dict(*_moving_crowd())))
    assert tr.instanced is not None
    ref = _per_object(tr)
    o, d, tau = _crowd_rays(rng, 20000)
    a, b = tr.intersect(o, d, tau=tau), ref.intersect(o, d, tau=tau)
    moving_ref = b.hit & (b.prim >= tr.geom.static_count)
    assert moving_ref.sum() > 2000 and (b.hit & ~moving_ref).sum() > 2000
    same = a.prim == b.prim
    assert same.mean() > 0.998, same.mean()
    both = same & b.hit
    np.testing.assert_allclose(a.t[both], b.t[both], rtol=2e-5, atol=1e-4)
    np.testing.assert_allclose(a.p[both], b.p[both], atol=2e-4)
    np.testing.assert_array_equal(a.ng[both], b.ng[both])
    np.testing.assert_array_equal(a.moving[both], b.moving[both])
    mv = both & b.moving
    np.testing.assert_array_equal(a.moving_linear[both], b.moving_linear[both])
    np.testing.assert_array_equal(a.normal_xform[mv], b.normal_xform[mv])
    # the point is on the ray where Embree's t says, and off it by far less than the spawn
    # offset along the normal: rays leaving a moving surface do not hit it again
    np.testing.assert_allclose(a.p[a.hit], o[a.hit] + a.t[a.hit, None] * d[a.hit], atol=2e-4)
    from drt.trace import OFFSET_ABSOLUTE, OFFSET_RELATIVE, offset_origin
    h = a.hit & a.moving
    off = np.abs(((o[h] + a.t[h, None] * d[h] - a.p[h]) * a.ng[h]).sum(axis=1))
    assert off.max() < 0.5 * (OFFSET_ABSOLUTE + OFFSET_RELATIVE * np.abs(a.p[h]).max(axis=1)).min()
    out = rng.normal(size=(h.sum(), 3))
    out /= np.sqrt((out * out).sum(axis=1, keepdims=True))
    facing = np.where(((out * a.ng[h]).sum(axis=1) * (-(d[h] * a.ng[h]).sum(axis=1)) < 0)[:, None], -out, out)
    again = tr.intersect(offset_origin(a.p[h], a.ng[h], facing), facing, tau=tau[h])
    assert not np.any((again.prim == a.prim[h]) & (again.t < 1e-3))
    np.testing.assert_array_equal(a.p[~a.hit], o[~a.hit])
    assert np.isinf(a.t[~a.hit]).all()
    tmax = np.where(b.hit, b.t * np.where(rng.random(len(o)) < 0.5, 0.999, 1.001), 30.0)
    agree = tr.occluded(o, d, tmax, tau) == ref.occluded(o, d, tmax, tau)
    assert agree.mean() > 0.998, agree.mean()
    limited = tr.intersect(o, d, tau=tau, tmax=tmax)
    assert (limited.hit == (b.hit & (b.t < tmax))).mean() > 0.998


def test_instances_only_for_several_moving_objects(monkeypatch):
    """One moving object keeps the per-object path (a lone instance is not culled by Embree's
    tree: every ray would pay its transform); so does any failure while building or checking
    the scene of instances, and the answers stay right."""
    import drt.trace as trace_mod

    assert _spinning_scene(False).instanced is None
    assert _spinning_scene(True).instanced is None
    header, arrays = _moving_crowd(count=5)
    geom = build_geometry(scene_from_dict(header, arrays))
    rng = np.random.default_rng(22)
    o, d, tau = _crowd_rays(rng, 3000)

    def broken(*args, **kwargs):
        raise RuntimeError("no instances here")

    expect = _per_object(Tracer(geom)).intersect(o, d, tau=tau)
    for name, patch in (("instance_scene", broken), ("instance_scene", lambda *a, **k: None),
                        ("_instances_agree", lambda *a, **k: False)):
        with monkeypatch.context() as mp:
            mp.setattr(trace_mod, name, patch)
            tr = Tracer(geom)
            assert tr.instanced is None, name
            got = tr.intersect(o, d, tau=tau)
            np.testing.assert_array_equal(got.prim, expect.prim)
            np.testing.assert_array_equal(got.t, expect.t)


def test_instances_without_static_geometry_and_concurrent_queries():
    """Only moving objects (no static instance): still one scene; several threads querying it
    at once get what one thread gets."""
    from drt import embree_direct

    if not embree_direct.intersect1_address():
        pytest.skip("Embree's C handles not confirmed here")
    tr = Tracer(build_geometry(scene_from_dict(*_moving_crowd(count=6, static_floor=False))))
    assert tr.static is None and tr.instanced is not None
    rng = np.random.default_rng(23)
    batches = [_crowd_rays(rng, 2000) for _ in range(6)]
    ref = _per_object(tr)
    o, d, tau = batches[0]
    assert (tr.intersect(o, d, tau=tau).prim == ref.intersect(o, d, tau=tau).prim).mean() > 0.998
    _parallel_matches_serial(tr, batches)


def test_a_moving_crowd_far_from_the_camera():
    """Far from the camera (the frame's origin) Embree's float32 instance transforms err by more
    than near it; the check allows that error up to half the spawn offset, so a crowd 10 km away
    still uses the scene of instances, and rays spawned from its surfaces do not hit them again."""
    from drt import embree_direct
    from drt.trace import offset_origin

    if not embree_direct.intersect1_address():
        pytest.skip("Embree's C handles not confirmed here")
    far = 1e4
    header, arrays = _moving_crowd(count=8)
    def moved(m):  # (a new list: builders may share one matrix list between objects)
        m = np.array(m, dtype=np.float64)
        m[0, 3] += far
        return m.tolist()

    for obj in header["objects"]:
        obj["matrix_world"] = moved(obj["matrix_world"])
        if obj.get("motion"):
            obj["motion"] = {k: moved(m) for k, m in obj["motion"].items()}
    geom = build_geometry(scene_from_dict(header, arrays))  # the camera stays at the origin
    tr = Tracer(geom)
    assert tr.instanced is not None
    rng = np.random.default_rng(24)
    o, d, tau = _crowd_rays(rng, 20000)
    o = o + np.array([far, 0.0, 0.0]) - geom.origin_shift
    a, b = tr.intersect(o, d, tau=tau), _per_object(tr).intersect(o, d, tau=tau)
    assert (a.prim == b.prim).mean() > 0.995
    h = a.hit & a.moving
    assert h.sum() > 1000
    out = rng.normal(size=(h.sum(), 3))
    out /= np.sqrt((out * out).sum(axis=1, keepdims=True))
    facing = np.where(((out * a.ng[h]).sum(axis=1) * (-(d[h] * a.ng[h]).sum(axis=1)) < 0)[:, None], -out, out)
    again = tr.intersect(offset_origin(a.p[h], a.ng[h], facing), facing, tau=tau[h])
    assert not np.any((again.prim == a.prim[h]) & (again.t < 1.0))
