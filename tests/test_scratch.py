"""drt.scratch and the render loop's reuse of its arrays: the tracer's queries into a thread's
scratch answer what fresh arrays answer, batches take up the workspaces earlier batches gave
back, and a render's transient memory does not grow with its samples."""

import gc
import sys
import tracemalloc

import numpy as np
import pytest

from drt.geometry import build_geometry
from drt.render import prepare, render
from drt.scene import scene_from_dict
from drt.scratch import FRESH, Scratch
from drt.trace import Tracer
from scene_builders import cornell_box
from test_trace import _random_rays, _spinning_scene, _without_direct


def test_take_reuses_a_buffer_and_grows_it_when_asked_for_more():
    sc = Scratch()
    a = sc.take("t", 100)
    b = sc.take("t", 60)
    assert b.base is a.base and b.shape == (60,) and b.flags.c_contiguous
    c = sc.take("t", 200)  # longer: a new buffer, kept for later takes
    assert c.base is not a.base and sc.take("t", 150).base is c.base
    rows = sc.take("p", 10, (3,), np.float32)
    assert rows.shape == (10, 3) and rows.dtype == np.float32
    assert sc.take("p", 10, (3,), np.float64).dtype == np.float64  # another dtype: another buffer
    assert FRESH.take("t", 5).base is None or FRESH.take("t", 5).base is not FRESH.take("t", 5).base


def _check_same_hits(tr, o, d, tau, tmax):
    fresh = tr.intersect(o, d, tau=tau, tmax=tmax)
    sc = Scratch()
    for _ in range(2):  # the second query writes over the first one's arrays
        got = tr.intersect(o, d, tau=tau, tmax=tmax, scratch=sc)
        hit = fresh.prim >= 0
        assert 100 < hit.sum() < len(hit)
        for name in ("t", "prim", "b1", "b2", "p", "ng", "moving_linear", "normal_xform", "moving"):
            a, b = getattr(fresh, name), getattr(got, name)
            assert (a is None) == (b is None), name
            if a is not None:  # (a miss's normal and transforms are left unwritten)
                rows = slice(None) if name in ("t", "prim", "b1", "b2", "p") else hit
                np.testing.assert_array_equal(a[rows], b[rows], err_msg=name)
    blocked_fresh = tr.occluded(o, d, tmax, tau)
    for _ in range(2):
        np.testing.assert_array_equal(tr.occluded(o, d, tmax, tau, scratch=sc), blocked_fresh)


def test_queries_into_a_scratch_answer_what_fresh_arrays_answer():
    rng = np.random.default_rng(3)
    h, a = cornell_box(8, 8, 1)
    static = Tracer(build_geometry(scene_from_dict(h, a)))
    o = rng.uniform(-0.9, 0.9, size=(3000, 3)) + np.array([0.0, 3.9, 0.0])  # inside the box
    d = rng.normal(size=(3000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    tmax = rng.uniform(0.1, 3.0, 3000)
    _check_same_hits(static, o, d, None, tmax)
    for deforming in (False, True):  # moving objects (rigid, and a deforming mesh), through
        o, d, tau = _random_rays(rng, 3000)  # Embree from kernels and through embreex's batches
        tr = _spinning_scene(deforming)
        for tracer in (tr, _without_direct(tr)):
            _check_same_hits(tracer, o, d, tau, np.full(3000, 20.0))


def test_batches_take_up_the_workspaces_earlier_batches_gave_back():
    """Every render starts new worker threads; their batches still find the arrays of the
    batches before them (no fresh pages): a second render with the same context makes no new
    workspace, and its image equals the first one's to the bit."""
    h, a = cornell_box(32, 32, 4)
    scene = scene_from_dict(h, a)
    ctx = prepare(scene, seed=2)
    first = render(scene, spp=8, threads=2, context=ctx, max_batch_paths=1024)
    pool = list(ctx.integrator._idle_workspaces)
    assert 1 <= len(pool) <= 2
    second = render(scene, spp=8, threads=2, context=ctx, max_batch_paths=1024)
    assert sorted(map(id, ctx.integrator._idle_workspaces)) == sorted(map(id, pool))
    assert np.array_equal(first.combined, second.combined)
    assert np.array_equal(first.combined, render(scene, spp=8, threads=1, seed=2).combined)


def test_a_renders_transient_memory_does_not_grow_with_its_samples():
    """Batches are slices of the pixel list, expanded by the worker into its own arrays: the
    render loop used to expand every batch of a pass at once (24 bytes a path: 12 MB for a
    64-spp pass of this frame), so its peak grew with the samples."""
    h, a = cornell_box(128, 128, 4)
    scene = scene_from_dict(h, a)
    ctx = prepare(scene, seed=5)
    render(scene, spp=4, threads=1, context=ctx, max_batch_paths=4096)  # workspaces, compile
    peaks = {16: [], 64: []}
    for _ in range(3):  # (the least of three: tracemalloc also sees other threads of the process)
        for spp in peaks:
            gc.collect()
            tracemalloc.start()
            try:
                render(scene, spp=spp, threads=1, context=ctx, max_batch_paths=4096)
                peaks[spp].append(tracemalloc.get_traced_memory()[1])
            finally:
                tracemalloc.stop()
    assert min(peaks[64]) < 1.5 * min(peaks[16]), peaks


def test_a_new_films_sums_are_disjoint_views_of_one_block_that_start_empty():
    """The film's six per-pixel sums share one allocation (a render's new film then reuses the
    last one's memory instead of faulting in six fresh ones): each must start empty and be
    written independently of the others."""
    from drt.film import Film

    f = Film(5, 3)
    n = 15
    sums = {"sum_rgba": (n, 4), "sum_lum2": (n,), "sum_normal": (n, 3), "sum_albedo": (n, 3),
            "min_depth": (n,), "count": (n,)}
    for name, shape in sums.items():
        a = getattr(f, name)
        assert a.shape == shape and a.flags.c_contiguous, name
    assert f.count.dtype == np.int64 and np.all(f.count == 0)
    assert np.all(f.min_depth == np.inf)
    assert not any(np.any(getattr(f, k)) for k in ("sum_rgba", "sum_lum2", "sum_normal", "sum_albedo"))
    for k, name in enumerate(sums):
        getattr(f, name)[...] = k + 1
    for k, name in enumerate(sums):
        assert np.all(getattr(f, name) == k + 1), name


def _minor_faults() -> int:
    import resource

    return resource.getrusage(getattr(resource, "RUSAGE_THREAD", resource.RUSAGE_SELF)).ru_minflt


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="counts the kernel's page faults (Linux)")
def test_a_new_films_sums_are_written_when_it_is_made_not_when_the_first_batches_land():
    """A render's film is made before its threads start; its pages must be written then, not
    faulted in page by page by the first batches the main thread adds while every core runs
    (docs/kernels.md: ~4x the CPU per fault there). So are the passes a render reserves."""
    from drt.film import Film, zeroed

    z = zeroed((1000, 3), np.float32)
    assert z.shape == (1000, 3) and z.dtype == np.float32 and not np.any(z)
    f = Film(512, 512)  # 13 × 2 MB of sums: fresh pages from any allocator
    f.reserve(mist=True, light=True, data=True)
    before = _minor_faults()
    for name in ("sum_rgba", "sum_lum2", "sum_normal", "sum_albedo", "min_depth", "count", "sum_mist",
                 "sum_light", "sum_data"):
        getattr(f, name)[...] += 1
    faults = _minor_faults() - before
    pages = 512 * 512 * (13 + 1 + 12 + 9) * 8 // 4096
    assert faults < pages // 20, (faults, pages)
    assert f.sum_crypto is None  # (no Cryptomatte layers: nothing to reserve)
