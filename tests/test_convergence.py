"""The estimator converges at the expected rate and has no bias trend with sample count."""

import math

import numpy as np
import pytest

from drt.render import prepare, render
from drt.scene import scene_from_dict
from scene_builders import add_material, add_mesh, base_header, quad, translation

PLANE_SIZE = 16


def soft_shadow_scene(sampler, spp):
    """A Lambert plane under a rectangular light, partly shadowed by a blocker; an orthographic
    window 5 cm wide inside the penumbra, light sampling only: each pixel integrates the 2-D
    light-area visibility (the lecture's soft shadow), a near-2-D integrand."""
    h = base_header(PLANE_SIZE, PLANE_SIZE, spp, sampler=sampler, max_bounces=0, direct="LIGHT",
                    camera={"type": "ORTHO", "matrix_world": translation(0, 0, 3), "ortho_scale": 0.05,
                            "clip_start": 0.01, "clip_end": 100})
    a = {}
    white = add_material(h, "white", [{"type": "DIFFUSE", "color": [1, 1, 1]}])
    black = add_material(h, "black", [{"type": "DIFFUSE", "color": [0, 0, 0]}])
    add_mesh(h, a, "plane", *quad((0, 0, 0), (5, 0, 0), (0, 5, 0)), material=white)
    add_mesh(h, a, "blocker", *quad((0.6, 0, 0.5), (0.6, 0, 0), (0, 2, 0)), material=black)
    h["lights"].append({"type": "AREA", "matrix_world": translation(0, 0, 1.5), "power": 50.0,
                        "shape": "RECTANGLE", "size": 1.0, "size_y": 0.6})
    return scene_from_dict(h, a)


def rmse_curve(sampler, spps, reference):
    out = []
    for n in spps:
        img = render(soft_shadow_scene(sampler, n), threads=2, seed=11, parallel="threads").combined[..., 0]
        out.append(math.sqrt(np.mean((img - reference) ** 2)))
    return np.array(out)


@pytest.fixture(scope="module")
def reference():
    return render(soft_shadow_scene("SOBOL", 4096), threads=2, seed=99, parallel="threads").combined[..., 0]


def slope(spps, err):
    return np.polyfit(np.log(spps), np.log(err), 1)[0]


def test_random_sampling_error_falls_as_inverse_square_root(reference):
    spps = np.array([4, 16, 64])
    s = slope(spps, rmse_curve("RANDOM", spps, reference))
    assert -0.65 < s < -0.35, s


def test_low_discrepancy_sampling_converges_faster(reference):
    spps = np.array([4, 16, 64])
    s_sobol = slope(spps, rmse_curve("SOBOL", spps, reference))
    s_random = slope(spps, rmse_curve("RANDOM", spps, reference))
    assert s_sobol < -0.6 and s_sobol < s_random - 0.1, (s_sobol, s_random)


def test_no_bias_trend_between_few_and_many_samples():
    """The mean of many independent 4-spp renders equals a 1024-spp render within noise: a
    biased estimator (wrong weights, clamping, roulette mistakes) would show a trend."""
    scene = soft_shadow_scene("RANDOM", 4)
    ctx = prepare(scene)
    few = np.stack([render(scene, spp=4, seed=s, threads=2, context=prepare(scene, seed=s), parallel="threads").combined[..., 0]
                    for s in range(16)])
    many = render(scene, spp=1024, seed=1000, threads=2, context=ctx, parallel="threads").combined[..., 0]
    diff = few.mean(axis=0) - many
    # per-pixel noise of the 64-sample mean dominates the 1024-sample one
    se = few.std(axis=0, ddof=1) / math.sqrt(16)
    mean_diff = diff.mean()
    se_mean = math.sqrt(np.mean(se**2) / diff.size)
    assert abs(mean_diff) < 4 * se_mean + 1e-4, (mean_diff, se_mean)
