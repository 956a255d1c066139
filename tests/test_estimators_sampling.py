"""Every random decision of a path comes from the sample generator (pixel, lens, time, light
selection, light position, lobe, BSDF direction, roulette), so RANDOM / STRATIFIED / SOBOL apply
to all of them and a render is a pure function of the seed; and stratification's advantage
fades with path depth (the "high-dimensional paths" failure mode)."""

import collections

import numpy as np
import pytest

from drt.integrator import D_BOUNCE0, D_LENS, D_PIXEL, D_TIME, DIMS_PER_BOUNCE, RR_START_BOUNCE
from drt.render import prepare, render
from drt.scene import scene_from_dict
from scene_builders import cornell_box


def _recording_render(monkeypatch, header, arrays, spp=4):
    """Render with the path stages run as plain Python (their ``py_func``), so that a spy can
    stand in for the compiled sampler they call and record every dimension drawn."""
    import drt.path_stages as stages

    used = set()
    original = stages.sample_2d

    def spy(sd, pixel, index, dim):
        used.add(int(dim))
        return original(sd, pixel, index, dim)

    original_5d = stages.sample_5d

    def spy_5d(sd, pixel, index, dim, with_lens, with_time):
        used.update((int(dim),) + ((int(dim) + 1,) if with_lens else ()) + ((int(dim) + 2,) if with_time else ()))
        return original_5d(sd, pixel, index, dim, with_lens, with_time)

    original_3d = stages.sample_3d

    def spy_3d(sd, pixel, index, dim):
        used.add(int(dim))
        return original_3d(sd, pixel, index, dim)

    monkeypatch.setattr(stages, "sample_2d", spy)
    monkeypatch.setattr(stages, "sample_3d", spy_3d)
    monkeypatch.setattr(stages, "sample_5d", spy_5d)
    monkeypatch.setattr(stages, "camera_stage", stages.camera_stage.py_func)
    monkeypatch.setattr(stages, "shade", stages.shade.py_func)
    rng_calls = []
    monkeypatch.setattr(np.random, "random", lambda *a, **k: rng_calls.append(a))
    monkeypatch.setattr(np.random, "default_rng", lambda *a, **k: rng_calls.append(a))
    film = render(scene_from_dict(header, arrays), spp=spp, threads=1)
    return used, rng_calls, film


def test_every_dimension_comes_from_the_sampler(monkeypatch):
    h, a = cornell_box(8, 8, 4)
    h["camera"]["dof"] = {"use": True, "fstop": 2.0, "focus_distance": 3.0}
    h["render"].update(shutter=[-0.25, 0.25], max_bounces=5)
    m = np.asarray(h["objects"][-1]["matrix_world"], float)
    moved = m.copy()
    moved[0, 3] += 0.1
    h["objects"][-1]["motion"] = {"matrix_open": m.tolist(), "matrix_close": moved.tolist()}
    used, rng_calls, _ = _recording_render(monkeypatch, h, a)
    assert not rng_calls  # no hidden numpy randomness
    assert {D_PIXEL, D_LENS, D_TIME} <= used
    for b in range(RR_START_BOUNCE + 1):
        base = D_BOUNCE0 + DIMS_PER_BOUNCE * b
        assert {base + 1, base + 2} <= used, (b, sorted(used))  # light, BSDF (3-D samples)
    assert D_BOUNCE0 + DIMS_PER_BOUNCE * (RR_START_BOUNCE - 1) + 3 in used  # Russian roulette


@pytest.mark.parametrize("kind", ["RANDOM", "STRATIFIED", "SOBOL"])
def test_render_is_a_function_of_the_seed(kind):
    h, a = cornell_box(8, 8, 4)
    scene = scene_from_dict(h, a)
    one = render(scene, spp=4, threads=1, sampler=kind, seed=5).combined
    two = render(scene, spp=4, threads=2, sampler=kind, seed=5).combined
    other = render(scene, spp=4, threads=1, sampler=kind, seed=6).combined
    assert np.array_equal(one, two) and not np.array_equal(one, other)


@pytest.mark.slow
def test_stratification_gain_fades_with_path_depth():
    """Cornell box, direct light only vs. indirect only (deep paths): the MSE ratio
    RANDOM / SOBOL at 16 spp is large for the 4-dimensional direct-light integrand and near 1
    once paths use dozens of dimensions. Documented in docs/estimators.md."""
    ratios = {}
    for label, bounces in (("direct", 0), ("deep", 6)):
        h, a = cornell_box(24, 24, 16)
        h["render"].update(max_bounces=bounces, diffuse_bounces=bounces)
        scene = scene_from_dict(h, a)
        ref = render(scene, spp=1024, seed=77, threads=2).combined
        mse = {}
        for kind in ("RANDOM", "SOBOL"):
            errs = [np.mean((render(scene, spp=16, seed=s, threads=2, sampler=kind).combined - ref)[..., :3] ** 2)
                    for s in range(3)]
            mse[kind] = float(np.mean(errs))
        ratios[label] = mse["RANDOM"] / mse["SOBOL"]
    assert ratios["direct"] > 1.5 * ratios["deep"], ratios


def test_image_is_bit_identical_for_any_thread_count_and_batch_cut():
    """Batches are cut smaller when there are more threads (so every thread gets work); each
    pixel's samples of a pass stay in one batch, so the film adds them in the same order and
    the image is the same to the bit."""
    from drt.render import BATCH_PATHS, MIN_BATCH_PATHS

    h, a = cornell_box(128, 128, 4)
    scene = scene_from_dict(h, a)
    assert 128 * 128 // (2 * 3) < BATCH_PATHS and 128 * 128 // (2 * 3) < 128 * 128 // 2
    assert MIN_BATCH_PATHS < 128 * 128 // 2  # 1 and 3 threads really cut the passes differently
    one = render(scene, spp=4, threads=1, seed=3)
    three = render(scene, spp=4, threads=3, seed=3)
    assert np.array_equal(one.combined, three.combined)
    assert np.array_equal(one.variance, three.variance) and np.array_equal(one.depth, three.depth)


def test_an_absurd_thread_count_is_cut_to_a_few_per_core(monkeypatch):
    """``--threads 999`` on a small machine: each worker thread holds a batch's path arrays
    (~18 MB), so the render runs at most MAX_THREADS_PER_CORE per core, with the same image."""
    from drt import render as render_module

    monkeypatch.setattr(render_module.os, "cpu_count", lambda: 2)
    h, a = cornell_box(64, 64, 4)
    scene = scene_from_dict(h, a)
    many = render(scene, spp=4, threads=999, seed=3)
    assert many.stats.threads == render_module.MAX_THREADS_PER_CORE * 2
    assert np.array_equal(many.combined, render(scene, spp=4, threads=2, seed=3).combined)


def test_batches_reuse_returned_output_buffers_without_changing_the_image(monkeypatch):
    """The render loop gives each batch's output arrays back once the film has added them
    (``SampleBatch.release``) and later batches write into them: the image equals, to the bit,
    one rendered with fresh arrays for every batch, also with three threads and many batches in
    flight; and the buffers really are reused (far fewer allocated than batches rendered)."""
    from drt import integrator as integrator_module
    from drt import render as render_module
    from drt.render import prepare

    h, a = cornell_box(64, 64, 4)
    scene = scene_from_dict(h, a)
    ctx = prepare(scene, seed=5)
    allocated = []
    original = integrator_module.Integrator._outputs

    def counting(self, n):
        buffers, views, pixel = original(self, n)
        if not any(buffers is b for b in allocated):  # (the list keeps them alive: no id reuse)
            allocated.append(buffers)
        return buffers, views, pixel

    monkeypatch.setattr(integrator_module.Integrator, "_outputs", counting)
    reused = render(scene, spp=16, threads=3, context=ctx, max_batch_paths=4096)
    batches = 16 * 64 * 64 // 4096
    in_flight = 3 * (1 + render_module.BATCHES_QUEUED_PER_THREAD) + 1  # (render()'s bound)
    assert 0 < len(allocated) <= in_flight + 1 < batches

    class Dropping(collections.deque):
        def append(self, item):  # nothing comes back: every batch gets fresh arrays
            pass

    ctx.integrator._returned_outputs = Dropping()
    fresh = render(scene, spp=16, threads=3, context=ctx, max_batch_paths=4096)
    assert np.array_equal(reused.combined, fresh.combined)
    assert np.array_equal(reused.normal, fresh.normal) and np.array_equal(reused.depth, fresh.depth)
