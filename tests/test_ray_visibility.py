"""Cycles's per-object ray visibility (scene format: an object's "visibility"): a ray of a kind
the object is not visible to passes it as if it were not there; shadow rays the same for
"shadow". Parity with Cycles: test_shading_inputs.py (test_ray_visibility_matches_cycles)."""

import math

import numpy as np
import pytest

from drt.render import render
from drt.scene import VIS_ALL, SceneError, scene_from_dict
from scene_builders import add_material, add_mesh, base_header, look_at, quad, translation

SUN_E = 3.0  # irradiance of the sun on the floor (W/m², straight down)
ALBEDO = 0.6


def _scene(card_visibility=None, wall_visibility=None, spp=16, film_transparent=False):
    """An orthographic camera over a white floor (z = 0, 2 × 2 m seen) lit by a sun straight
    down; optionally a red card at z = 0.5 over the floor's centre (its shadow: the centre) and
    a tall white wall beside the view (it only adds light by diffuse interreflection)."""
    cam = {"type": "ORTHO", "matrix_world": translation(0, 0, 3.0), "ortho_scale": 2.0,
           "clip_start": 0.01, "clip_end": 100.0}
    h = base_header(16, 16, spp, camera=cam, film_transparent=film_transparent)
    a = {}
    white = add_material(h, "white", [{"type": "DIFFUSE", "color": [ALBEDO] * 3}])
    red = add_material(h, "red", [{"type": "DIFFUSE", "color": [0.8, 0.1, 0.1]}])
    add_mesh(h, a, "floor", *quad((0, 0, 0), (3, 0, 0), (0, 3, 0)), material=white)
    if card_visibility is not False:
        add_mesh(h, a, "card", *quad((0, 0, 0.5), (0.4, 0, 0), (0, 0.4, 0)), material=red)
        if card_visibility is not None:
            h["objects"][-1]["visibility"] = card_visibility
    if wall_visibility is not False:
        add_mesh(h, a, "wall", *quad((1.2, 0, 1.0), (0, 0, 1.0), (0, 3, 0)), material=white)
        if wall_visibility is not None:
            h["objects"][-1]["visibility"] = wall_visibility
    h["lights"].append({"type": "SUN", "name": "sun", "matrix_world": look_at((0, 0, 1), (0, 0, 0)),
                        "color": [1, 1, 1], "strength": SUN_E, "angle": 0.0})
    return scene_from_dict(h, a)


def _img(scene):
    return render(scene, threads=1).combined


def test_unset_visibility_is_every_ray():
    assert all(o.visibility == VIS_ALL for o in _scene().objects)
    assert _scene(card_visibility={"camera": False}).objects[1].visibility == VIS_ALL & ~1


def test_a_card_hidden_from_the_camera_still_casts_its_shadow():
    """Camera (and diffuse) off: the camera sees the floor through the card, and the card's
    shadow on it (0 under it: no world light, neither the card's underside nor the wall seen by
    diffuse rays); the lit floor is ALBEDO·E/π as without the card. With shadows off too, no
    shadow either."""
    no_wall = {"camera": False, "diffuse": False, "shadow": False}
    img = _img(_scene({"camera": False, "diffuse": False}, wall_visibility=no_wall))
    lit = ALBEDO * SUN_E / math.pi
    np.testing.assert_allclose(img[0, 0, :3], lit, rtol=1e-5)  # a corner: the open floor
    np.testing.assert_allclose(img[7:9, 7:9, :3], 0.0, atol=1e-7)  # the centre: in the shadow, not red
    shown = _img(_scene(None, wall_visibility=no_wall))
    assert shown[7:9, 7:9, 0].min() > 2 * shown[7:9, 7:9, 1].max() > 0  # the red card, when seen
    free = _img(_scene({"camera": False, "diffuse": False, "shadow": False}, wall_visibility=no_wall))
    np.testing.assert_allclose(free[..., :3], lit, rtol=1e-5)  # neither card nor shadow


def test_hidden_from_every_ray_is_the_scene_without_it():
    """An object no ray sees changes nothing (to float rounding of the rays that pass it)."""
    hidden = {k: False for k in ("camera", "diffuse", "glossy", "transmission", "volume_scatter", "shadow")}
    with_card = _img(_scene(hidden))
    without = _img(_scene(False))
    np.testing.assert_allclose(with_card, without, rtol=1e-4, atol=1e-6)


def test_the_wall_lights_the_floor_only_for_diffuse_rays_that_see_it():
    """A wall beside the view, hidden from the camera: diffuse rays that see it bring light
    back onto the floor; hidden from diffuse rays, the floor is as without the wall."""
    shown = _img(_scene(False, {"camera": False}, spp=64))
    hidden = _img(_scene(False, {"camera": False, "diffuse": False}, spp=64))
    without = _img(_scene(False, False, spp=64))
    np.testing.assert_allclose(hidden, without, rtol=1e-4, atol=1e-6)
    gain = shown[..., :3].mean() / without[..., :3].mean() - 1
    assert gain > 0.02, gain  # interreflection from the wall: several per cent


def test_a_transparent_film_sees_the_world_through_a_hidden_card():
    """Alpha: a camera ray passing a card it does not see and then the world leaves alpha 0."""
    h_cam = {"camera": False, "shadow": False}
    img = _img(_scene(h_cam, wall_visibility=False, film_transparent=True))
    assert np.all(img[..., 3] == 1.0)  # the floor fills the view, card or not


@pytest.mark.parametrize("bad, field", [
    ({"camera": 0}, "objects[1].visibility.camera"),
    ({"sky": False}, "objects[1].visibility.sky"),
    ([False], "objects[1].visibility"),
])
def test_bad_visibility_is_refused_by_name(bad, field):
    with pytest.raises(SceneError) as e:
        _scene(bad)
    assert e.value.field == field


def test_an_emitter_no_bounce_ray_sees_is_no_light():
    """As Cycles: an emissive card hidden from diffuse, glossy, transmission and volume-scatter
    rays lights nothing (nor is it sampled); hidden from the camera only, it lights the floor."""
    from scene_builders import add_material as add_mat

    def scene(visibility):
        cam = {"type": "ORTHO", "matrix_world": translation(0, 0, 3.0), "ortho_scale": 2.0,
               "clip_start": 0.01, "clip_end": 100.0}
        h = base_header(8, 8, 16, camera=cam)
        a = {}
        white = add_mat(h, "white", [{"type": "DIFFUSE", "color": [ALBEDO] * 3}])
        glow = add_mat(h, "glow", [], emission=[5.0, 5.0, 5.0])
        add_mesh(h, a, "floor", *quad((0, 0, 0), (3, 0, 0), (0, 3, 0)), material=white)
        # facing down onto the floor, above the camera's view of it
        add_mesh(h, a, "glow", *quad((0, 0, 1.0), (0, 0.5, 0), (0.5, 0, 0)), material=glow)
        h["objects"][-1]["visibility"] = visibility
        return scene_from_dict(h, a)

    lit = _img(scene({"camera": False}))
    dark = _img(scene({"camera": False, "diffuse": False, "glossy": False, "transmission": False,
                       "volume_scatter": False}))
    assert lit[..., :3].mean() > 0.05
    assert dark[..., :3].max() == 0.0
