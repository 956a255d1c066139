"""Cycles's Film > Exposure (render.exposure): the film's radiance is scaled, after clamping;
alpha and the data passes are not. Parity with Cycles: test_shading_inputs.py
(test_film_exposure_scales_like_cycles)."""

import numpy as np
import pytest

from drt.render import render
from drt.scene import SceneError, scene_from_dict
from scene_builders import add_material, add_mesh, base_header, quad, uv_sphere


def _scene(exposure, **render_settings):
    h = base_header(24, 24, 8, world=(0.3, 0.3, 0.3), film_transparent=True, exposure=exposure,
                    **render_settings)
    a = {}
    m = add_material(h, "m", [{"type": "DIFFUSE", "color": [0.8, 0.6, 0.4]}])
    pos, tri, nrm = uv_sphere(1.0, rings=12, segments=24)
    add_mesh(h, a, "s", pos, tri, material=m, normals=nrm)
    add_mesh(h, a, "floor", *quad((0, 0, -1), (3, 0, 0), (0, 3, 0)), material=m)  # indirect light
    h["lights"].append({"type": "POINT", "name": "p", "matrix_world": np.eye(4).tolist(),
                        "color": [1, 1, 1], "power": 200.0, "radius": 0.1})
    h["lights"][-1]["matrix_world"][0][3] = 2.0
    h["lights"][-1]["matrix_world"][1][3] = -3.0
    return scene_from_dict(h, a)


def test_exposure_scales_radiance_after_clamping_and_nothing_else():
    """Same seed, exposure 1 and 2.5, an indirect clamp that cuts some samples: the RGB is 2.5×
    pixel for pixel (the clamp sees the unexposed radiance, as in Cycles), the variance 6.25×;
    alpha, depth, normal and albedo are the same."""
    unclamped = render(_scene(1.0), threads=1)
    one = render(_scene(1.0, clamp_indirect=0.02, clamp_direct=0.3), threads=1)
    assert np.abs(unclamped.combined - one.combined).max() > 0.01  # the clamps cut
    two = render(_scene(2.5, clamp_indirect=0.02, clamp_direct=0.3), threads=1)
    rgb1, rgb2 = one.combined[..., :3], two.combined[..., :3]
    assert rgb1.max() > 0.1 and (one.combined[..., 3] < 1).any()
    np.testing.assert_allclose(rgb2, 2.5 * rgb1, rtol=1e-6, atol=1e-7)
    np.testing.assert_array_equal(two.combined[..., 3], one.combined[..., 3])
    for name in ("depth", "normal", "albedo", "sample_count"):
        np.testing.assert_array_equal(getattr(two, name), getattr(one, name))
    np.testing.assert_allclose(two.variance, 6.25 * one.variance, rtol=1e-5, atol=1e-12)


def test_exposure_defaults_to_one_and_is_validated():
    assert _scene(1.0).render.exposure == 1.0
    h = base_header(4, 4, 1)
    assert scene_from_dict(h, {}).render.exposure == 1.0
    for bad in (-1.0, float("nan"), float("inf"), "2", True):
        h = base_header(4, 4, 1, exposure=bad)
        with pytest.raises(SceneError) as e:
            scene_from_dict(h, {})
        assert e.value.field == "render.exposure"
