"""Cycles's Ambient Occlusion pass (``render.light_passes`` "ao", ``render.ao_distance``): at each
surface a camera ray meets, throughput × alpha where a cosine-distributed ray about the shading
normal finds nothing within the AO distance (Cycles's integrate_surface_ao with
PATH_RAY_SHADOW_FOR_AO). The analytic answer under an infinite ceiling, transparency and
parity with Cycles through F12."""

import numpy as np
import pytest

from drt.exr import film_from_exr, write_exr
from drt.render import merge_films, render
from drt.scene import SceneError, scene_from_dict
from scene_builders import add_material, add_mesh, base_header, quad, translation


def _scene(height=1.0, distance=2.0, spp=64, ceiling="opaque", passes=("ao",)):
    """An orthographic view down on a floor (z = 0) under a ceiling plane at z = ``height``
    that camera rays do not see (``ceiling``: "opaque", "clear" — a Transparent BSDF — or None)."""
    cam = {"type": "ORTHO", "matrix_world": translation(0, 0, 3.0), "ortho_scale": 2.0,
           "clip_start": 0.01, "clip_end": 100.0}
    h = base_header(8, 8, spp, camera=cam, max_bounces=0, light_passes=list(passes), ao_distance=distance)
    a = {}
    floor = add_material(h, "floor", [{"type": "DIFFUSE", "color": [0.6] * 3}])
    add_mesh(h, a, "floor", *quad((0, 0, 0), (5, 0, 0), (0, 5, 0)), material=floor)
    if ceiling is not None:
        lobes = ([{"type": "DIFFUSE", "color": [0.6] * 3}] if ceiling == "opaque"
                 else [{"type": "GLASS", "color": [1.0] * 3, "ior": 1.0, "roughness": 0.0}])
        add_mesh(h, a, "ceiling", *quad((0, 0, height), (50, 0, 0), (0, 50, 0)), material=add_material(h, "c", lobes))
        h["objects"][-1]["visibility"] = {"camera": False}
    h["lights"].append({"type": "SUN", "name": "sun", "matrix_world": translation(0, 0, 5), "color": [1, 1, 1],
                        "strength": 3.0, "angle": 0.0})
    return scene_from_dict(h, a)


@pytest.mark.parametrize("height, distance", [(1.0, 2.0), (0.5, 2.0), (1.0, 1.25)])
def test_ao_under_an_infinite_ceiling_is_the_share_of_cosine_directions_that_escape(height, distance):
    # a cosine-distributed direction at angle θ meets the ceiling at h / cos θ; it escapes when
    # that is beyond the distance D, i.e. cos θ < h / D, which cosine sampling picks with
    # probability (h / D)² (cos² θ is uniform)
    f = render(_scene(height, distance, spp=256), threads=2)
    expected = (height / distance) ** 2
    ao = f.ao[..., 0]
    assert np.allclose(f.ao[..., 0], f.ao[..., 2])  # a grey visibility
    # 64 pixels × 256 stratified samples: the binomial bound on the mean is 0.0034 at p = 0.25
    assert abs(ao.mean() - expected) < 4 * np.sqrt(expected * (1 - expected) / ao.size / 256)
    assert np.all(np.abs(ao - expected) < 0.1)


def test_no_occluder_or_a_far_one_leaves_ao_one_and_the_world_zero():
    f = render(_scene(ceiling=None, spp=4), threads=1)
    assert np.allclose(f.ao, 1.0)
    far = render(_scene(height=3.0, distance=2.0, spp=4), threads=1)  # beyond the distance
    assert np.allclose(far.ao, 1.0)
    cam = {"type": "ORTHO", "matrix_world": translation(0, 0, 3.0), "ortho_scale": 2.0}
    h = base_header(4, 4, 2, camera=cam, light_passes=["ao"])
    empty = render(scene_from_dict(h, {}), threads=1)
    assert np.all(empty.ao == 0.0)


def test_a_transparent_occluder_lets_ao_through():
    clear = render(_scene(ceiling="clear", spp=16), threads=1)
    assert np.allclose(clear.ao, 1.0)  # (transparent shadows: Cycles's shadow path for AO)


def test_ao_merges_survives_the_exr_and_is_absent_unless_asked(tmp_path):
    sc = _scene(spp=16)
    whole = render(sc, threads=1)
    merged = merge_films([render(sc, threads=1, sample_offset=o, sample_count=8) for o in (0, 8)])
    assert np.allclose(merged.ao, whole.ao, atol=1e-6)
    write_exr(tmp_path / "ao.exr", whole)
    assert np.allclose(film_from_exr(tmp_path / "ao.exr").ao, whole.ao, atol=1e-6)
    other = render(_scene(spp=2, passes=("emission",)), threads=1)
    assert np.all(other.ao == 0.0)  # the light passes without AO leave its columns empty


def test_a_bad_ao_distance_is_named():
    h = base_header(4, 4, 1, light_passes=["ao"], ao_distance=0.0)
    with pytest.raises(SceneError) as e:
        scene_from_dict(h, {})
    assert "render.ao_distance" in str(e.value)


def _blender_ao_scene():
    """node_parity's orthographic view down on a floor with a cube standing on it, an
    overhanging card and a half-transparent card, World > Ambient Occlusion > Distance 0.6."""
    import bpy

    from node_parity import grey_principled, setup_scene

    sc = setup_scene(2)
    sc.cycles.samples = sc.drt.samples = 256
    sc.view_layers[0].use_pass_ambient_occlusion = True
    sc.world.light_settings.distance = 0.6

    material = grey_principled
    grey = material("grey")
    bpy.ops.mesh.primitive_plane_add(size=1.8, location=(0, 0, -1))
    bpy.context.object.data.materials.append(grey)
    bpy.ops.mesh.primitive_cube_add(size=0.5, location=(-0.35, 0.35, -0.75))
    bpy.context.object.data.materials.append(grey)
    bpy.ops.mesh.primitive_plane_add(size=0.5, location=(0.4, 0.4, -0.7))
    bpy.context.object.data.materials.append(grey)
    bpy.ops.mesh.primitive_plane_add(size=0.6, location=(0.1, -0.4, -0.8))
    bpy.context.object.data.materials.append(material("veil", alpha=0.5))
    return sc


def test_ao_pass_matches_cycles(tmp_path):
    """F12 in both engines, same scene: the AO pass pixel by pixel. Measured (256 samples
    each): means 0.6636 and 0.6632, mean absolute difference 0.004, 99th percentile 0.02."""
    pytest.importorskip("bpy")
    from addon import compat
    from node_parity import f12_in_both

    sc = _blender_ao_scene()
    w, h = sc.render.resolution_x, sc.render.resolution_y
    got = {}
    for engine, chans, _ in f12_in_both(sc, tmp_path):
        key = f"ViewLayer.{compat.pass_name('AO')}"
        got[engine] = np.asarray(chans[key], np.float64).reshape(h, w, 3)
    c, d = got["CYCLES"], got["DRT"]
    diff = np.abs(c - d)
    print("AO means", c.mean(), d.mean(), "mean |diff|", diff.mean(), "p99", np.quantile(diff, 0.99))
    assert 0.2 < c.mean() < 0.9  # (the scene has occlusion and open floor)
    assert abs(c.mean() - d.mean()) < 0.01
    assert diff.mean() < 0.03 and np.quantile(diff, 0.99) < 0.2
