"""Holdout objects (Cycles's Object > Visibility > Mask > Holdout, and holdout collections;
scene format: an object's "holdout"): where a camera ray hits one, the film's alpha loses the
hit's opaque part and no light is added, with or without a transparent film; through the
object's transparency the camera ray goes on. Every other ray sees the object as usual: it
casts shadows and is seen in bounces. Parity with Cycles: test_shading_inputs.py
(test_holdout_object_matches_cycles)."""

import math

import numpy as np
import pytest

from drt.render import render
from drt.scene import SceneError, scene_from_dict
from scene_builders import add_material, add_mesh, base_header, look_at, quad, translation

SUN_E = 3.0  # the sun's irradiance across its beam (W/m²)
COS_SUN = math.cos(math.radians(45.0))  # the sun comes from 45° toward +x: the floor gets E·cos
ALBEDO = 0.6
LIT = ALBEDO * SUN_E * COS_SUN / math.pi  # the open floor's radiance


def _scene(card="diffuse", holdout=True, film_transparent=False, spp=16, wall=False, max_bounces=0):
    """An orthographic camera over a white floor (z = 0, 2 × 2 m seen, 16 × 16 pixels) lit by a
    sun at 45° from +x, no world light; a 0.8 m card at z = 0.5 over the floor's centre, whose
    shadow falls 0.5 m toward −x. ``card``: "diffuse" (red), or "half" (50 % Transparent, the
    rest a black diffuse: it reflects nothing). ``wall``: a white wall beside the view, hidden
    from the camera, that lights the floor by interreflection. Direct light only by default
    (``max_bounces`` 0), so that every figure is exact."""
    cam = {"type": "ORTHO", "matrix_world": translation(0, 0, 3.0), "ortho_scale": 2.0,
           "clip_start": 0.01, "clip_end": 100.0}
    h = base_header(16, 16, spp, camera=cam, film_transparent=film_transparent, max_bounces=max_bounces)
    a = {}
    white = add_material(h, "white", [{"type": "DIFFUSE", "color": [ALBEDO] * 3}])
    if card == "diffuse":
        lobes = [{"type": "DIFFUSE", "color": [0.8, 0.1, 0.1]}]
    else:
        lobes = [{"type": "GLASS", "color": [0.5] * 3, "ior": 1.0, "roughness": 0.0},
                 {"type": "DIFFUSE", "color": [0.0] * 3}]
    m_card = add_material(h, "card", lobes)
    add_mesh(h, a, "floor", *quad((0, 0, 0), (3, 0, 0), (0, 3, 0)), material=white)
    add_mesh(h, a, "card", *quad((0, 0, 0.5), (0.4, 0, 0), (0, 0.4, 0)), material=m_card)
    if holdout is not None:
        h["objects"][-1]["holdout"] = holdout
    if wall:
        add_mesh(h, a, "wall", *quad((-1.2, 0, 1.0), (0, 0, 1.0), (0, 3, 0)), material=white)
        h["objects"][-1]["visibility"] = {"camera": False}
    h["lights"].append({"type": "SUN", "name": "sun", "matrix_world": look_at((1, 0, 1), (0, 0, 0)),
                        "color": [1, 1, 1], "strength": SUN_E, "angle": 0.0})
    return scene_from_dict(h, a)


def _img(scene):
    return np.asarray(render(scene, threads=1).combined, np.float64)


# pixel blocks (rows, columns; row 0 is +y, column 0 is −x; 0.125 m pixels, a pixel's filter
# reaching 0.75 pixel): under the card (x, y in ±0.4: pixels 4.8 … 11.2), in the part of its
# shadow (x in [−0.9, −0.1]) the card does not hide, and on the open, lit floor
CARD = (slice(6, 10), slice(6, 10))
SHADOW = (slice(6, 10), slice(2, 4))
CARD_LIT = (slice(6, 10), slice(8, 10))  # the floor behind the card but out of its shadow
OPEN = (slice(0, 3), slice(12, 16))


@pytest.mark.parametrize("film_transparent", [False, True])
def test_a_holdout_card_is_a_hole_that_still_casts_its_shadow(film_transparent):
    """The camera sees no light and alpha 0 where the card is (transparent film or not: the
    holdout cuts alpha either way, as Cycles); the floor keeps the card's shadow."""
    img = _img(_scene(film_transparent=film_transparent))
    np.testing.assert_array_equal(img[CARD], 0.0)
    np.testing.assert_allclose(img[SHADOW][..., :3], 0.0, atol=1e-7)
    np.testing.assert_allclose(img[SHADOW][..., 3], 1.0)
    np.testing.assert_allclose(img[OPEN][..., :3], LIT, rtol=1e-5)
    np.testing.assert_allclose(img[OPEN][..., 3], 1.0)


def test_a_holdout_is_a_plain_object_to_every_other_ray():
    """Outside the card's pixels the image is that of the scene with a plain card: its shadow
    and its light bounced to the floor (via the wall hidden from the camera) are the same."""
    hold = _img(_scene(wall=True, spp=32, max_bounces=4))
    plain = _img(_scene(wall=True, holdout=False, spp=32, max_bounces=4))
    outside = np.ones((16, 16), bool)
    outside[3:13, 3:13] = False  # the card covers pixels 4.8 … 11.2 (the filter's tail: ±1.5)
    np.testing.assert_allclose(hold[outside], plain[outside], rtol=1e-6, atol=1e-9)
    assert plain[CARD][..., 0].min() > 0.01  # the plain card is seen (lit by the wall)
    np.testing.assert_array_equal(hold[CARD], 0.0)


def test_a_half_transparent_holdout_cuts_half_and_shows_what_is_behind_at_half():
    """Cycles's holdout weight is 1 − transparency: a 50 % Transparent card leaves alpha
    1 − 0.5 over the floor, and the camera ray passing it sees the floor at half strength (the
    card's own lobes add nothing); its shadow is a half shadow (transparent shadow rays)."""
    for film_transparent in (False, True):
        img = _img(_scene(card="half", film_transparent=film_transparent))
        np.testing.assert_allclose(img[CARD][..., 3], 0.5, rtol=1e-6)
        np.testing.assert_allclose(img[CARD_LIT][..., :3], 0.5 * LIT, rtol=1e-5)
        np.testing.assert_allclose(img[SHADOW][..., :3], 0.5 * LIT, rtol=1e-5)
        np.testing.assert_allclose(img[SHADOW][..., 3], 1.0)


def test_a_half_transparent_holdout_over_the_world_with_a_transparent_film():
    """Over the world (the floor removed from the camera's view): alpha is 0 with a transparent
    film (0.5 cut by the holdout, the rest by the world behind it)."""
    sc = _scene(card="half", film_transparent=True)
    sc.objects[0].visibility &= ~1  # the floor hidden from the camera
    from drt.scene import VIS_ALL
    assert sc.objects[0].visibility == VIS_ALL & ~1
    img = _img(sc)
    np.testing.assert_allclose(img[CARD], 0.0, atol=1e-7)


def test_holdout_is_read_and_checked():
    assert _scene().objects[1].holdout and not _scene(holdout=None).objects[1].holdout
    with pytest.raises(SceneError) as e:
        _scene(holdout=1)
    assert e.value.field == "objects[1].holdout"
