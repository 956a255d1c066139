"""Cycles's Mist pass (View Layer > Passes > Mist, World > Mist Pass settings).

Each sample adds, at every surface its camera ray meets while the world still shows through
(past transparency), (1 − mist) × average(throughput × alpha), with mist = clamp((distance −
start) / depth, 0, 1) ^ falloff; the pass is 1 − the pixel's mean (drt.path_stages.mist_weight).
Headless: exact values where every hit is at one distance (an orthographic view of a plane, a
camera inside a sphere), the mix through a half-transparent card, the world's 1, the EXR
round trip. (bpy) The add-on writes the pass where Cycles does, with Cycles's values.
"""

import math

import numpy as np
import pytest

from drt.exr import film_from_exr, write_exr
from drt.render import render
from drt.scene import SceneError, scene_from_dict
from scene_builders import add_material, add_mesh, base_header, quad, uv_sphere, with_render

FALLOFFS = {"QUADRATIC": 2.0, "LINEAR": 1.0, "INVERSE_QUADRATIC": 0.5}


def _ortho_header(n=8, spp=4, height=5.0):
    return base_header(n, n, spp, camera={"type": "ORTHO", "ortho_scale": 2.0,
                                          "matrix_world": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, height], [0, 0, 0, 1]]})


def _film(h, arrays, mist, **kw):
    return render(scene_from_dict(with_render(h, mist=mist, **kw), arrays), threads=1)


def _expected(dist, start, depth, falloff):
    return min(max((dist - start) / depth, 0.0), 1.0) ** FALLOFFS[falloff]


@pytest.mark.parametrize("falloff", list(FALLOFFS))
def test_a_plane_seen_orthographically_has_the_mist_of_its_distance(falloff):
    """An opaque plane filling an orthographic view 5 units below the camera: every pixel's
    pass is the mist at distance 5 (start 1, depth 8: 0.5 ^ falloff); a start beyond it gives
    0, a depth ending before it 1."""
    h = _ortho_header()
    add_mesh(h, arrays := {}, "plane", *quad((0, 0, 0), (4, 0, 0), (0, 4, 0)),
             add_material(h, "grey", [{"type": "DIFFUSE", "color": [0.5, 0.5, 0.5]}]))
    for start, depth in ((1.0, 8.0), (6.0, 8.0), (0.0, 2.0)):
        film = _film(h, arrays, {"start": start, "depth": depth, "falloff": falloff})
        np.testing.assert_allclose(film.mist, _expected(5.0, start, depth, falloff), rtol=0, atol=1e-6)


def test_inside_a_sphere_every_pixel_sees_its_radius():
    """A perspective camera at the centre of a sphere of radius 3 (seen from inside): the
    distance is the Euclidean one from the eye, 3 in every pixel, though the depth pass (along
    the view axis) varies across the image."""
    h = base_header(12, 8, 4, camera={"type": "PERSP", "lens": 20.0,
                                      "matrix_world": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]})
    pos, tri = uv_sphere(3.0, (0, 0, 0), 96, 192)[:2]
    add_mesh(h, arrays := {}, "sphere", pos, tri, add_material(h, "grey", [{"type": "DIFFUSE", "color": [0.5] * 3}]))
    film = _film(h, arrays, {"start": 1.0, "depth": 4.0, "falloff": "LINEAR"})
    # (the sphere's facets lie up to ~0.001 inside its radius)
    np.testing.assert_allclose(film.mist, 0.5, rtol=0, atol=1e-3)
    assert np.ptp(film.depth) > 0.3


def test_the_world_is_full_mist_and_a_card_mixes_by_its_alpha():
    """Pixels that see only the world have mist 1. A card of Principled alpha 0.5 (a 50 %
    transparent lobe) 2 units down over an opaque floor 6 units down: 1 − (0.5·(1 − m(2)) +
    0.5·(1 − m(6))), within its Monte Carlo error (the card's pass-through is sampled)."""
    h = _ortho_header(n=8, spp=256, height=5.0)
    card = add_material(h, "card", [{"type": "DIFFUSE", "color": [0.4, 0.4, 0.4]},
                                    {"type": "GLASS", "color": [0.5, 0.5, 0.5], "roughness": 0.0, "ior": 1.0}])
    floor = add_material(h, "floor", [{"type": "DIFFUSE", "color": [0.8, 0.8, 0.8]}])
    arrays = {}
    add_mesh(h, arrays, "card", *quad((-1, 0, 3), (1, 0, 0), (0, 2, 0)), card)  # the left half
    add_mesh(h, arrays, "floor", *quad((1, 0, -1), (1, 0, 0), (0, 2, 0)), floor)  # the right half
    mist = {"start": 0.0, "depth": 10.0, "falloff": "LINEAR"}
    film = _film(h, arrays, mist)
    left, right = film.mist[:, :3], film.mist[:, 5:]
    # the left half sees the card, and through it the world (no floor there): 1 − 0.5·(1 − 0.2)
    np.testing.assert_allclose(left, 1 - 0.5 * (1 - 0.2), rtol=0, atol=0.05)
    assert abs(left.mean() - 0.6) < 0.01
    np.testing.assert_allclose(right, 0.6, rtol=0, atol=1e-6)  # the floor alone, 6 units down
    h2 = _ortho_header(n=8, spp=256, height=5.0)
    arrays2 = {}
    card2 = add_material(h2, "card", h["materials"][card]["lobes"])
    floor2 = add_material(h2, "floor", h["materials"][floor]["lobes"])
    add_mesh(h2, arrays2, "card", *quad((0, 0, 3), (2, 0, 0), (0, 2, 0)), card2)
    add_mesh(h2, arrays2, "floor", *quad((0, 0, -1), (2, 0, 0), (0, 2, 0)), floor2)
    stacked = _film(h2, arrays2, mist).mist
    expected = 1 - (0.5 * (1 - 0.2) + 0.5 * (1 - 0.6))
    assert abs(stacked.mean() - expected) < 0.01, stacked.mean()
    empty = _ortho_header()
    add_material(empty, "unused", [{"type": "DIFFUSE", "color": [0.5] * 3}])
    arrays3 = {}
    add_mesh(empty, arrays3, "far", *quad((5, 5, 0), (1, 0, 0), (0, 1, 0)), 0)  # out of view
    np.testing.assert_array_equal(_film(empty, arrays3, mist).mist, 1.0)


def test_no_mist_pass_unless_asked_and_the_exr_round_trip(tmp_path):
    h = _ortho_header()
    add_mesh(h, arrays := {}, "plane", *quad((0, 0, 0), (4, 0, 0), (0, 4, 0)),
             add_material(h, "grey", [{"type": "DIFFUSE", "color": [0.5, 0.5, 0.5]}]))
    film = render(scene_from_dict(h, arrays), threads=1)
    assert film.mist is None and film.sum_mist is None
    film = _film(h, arrays, {"start": 1.0, "depth": 8.0, "falloff": "QUADRATIC"})
    write_exr(tmp_path / "m.exr", film)
    back = film_from_exr(tmp_path / "m.exr")
    np.testing.assert_allclose(back.mist, film.mist, rtol=0, atol=1e-6)
    assert scene_from_dict(with_render(h, mist={}), arrays).render.mist == (5.0, 25.0, 2.0)
    for bad in ({"depth": -1.0}, {"falloff": "CUBIC"}, {"start": "near"}):
        with pytest.raises(SceneError, match="mist"):
            scene_from_dict(with_render(h, mist=bad), arrays)


# ------------------------------------------------------------------------------ Blender
def _blender_mist_scene(camera_type, falloff):
    """node_parity's view down on a floor with a sphere and a raised half-transparent card, the
    Mist pass on with start 0.5, depth 2.5 and the given falloff."""
    import bpy

    from node_parity import node, setup_scene

    sc = setup_scene(2)
    sc.cycles.samples = sc.drt.samples = 64
    vl = sc.view_layers[0]
    vl.use_pass_mist = True
    sc.world.mist_settings.start, sc.world.mist_settings.depth = 0.5, 2.5
    sc.world.mist_settings.falloff = falloff
    cam = sc.camera
    if camera_type == "PERSP":
        cam.data.type = "PERSP"
        cam.data.lens = 35.0
        cam.location = (0, 0, 1.5)
    grey = bpy.data.materials.new("grey")
    nt = grey.node_tree
    nt.nodes.clear()
    nt.links.new(node(nt, "ShaderNodeBsdfDiffuse", {"Color": (0.5, 0.5, 0.5, 1)}).outputs[0],
                 nt.nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
    bpy.ops.mesh.primitive_plane_add(size=2.0, location=(0, 0, -1))
    bpy.context.object.data.materials.append(grey)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.4, location=(-0.3, 0.3, -0.5), segments=48, ring_count=24)
    bpy.context.object.data.materials.append(grey)
    card = bpy.data.materials.new("card")
    card.node_tree.nodes["Principled BSDF"].inputs["Alpha"].default_value = 0.5
    bpy.ops.mesh.primitive_plane_add(size=0.6, location=(0.4, -0.4, 0.0))
    bpy.context.object.data.materials.append(card)
    return sc


@pytest.mark.parametrize("camera_type, falloff", [("ORTHO", "LINEAR"), ("PERSP", "QUADRATIC"),
                                                  ("PERSP", "INVERSE_QUADRATIC")])
def test_mist_pass_matches_cycles(tmp_path, camera_type, falloff):
    """The Mist pass DRT writes into Blender's render result (F12) against Cycles's, same scene,
    pixel by pixel: mean absolute difference below 0.01 (measured: see the print), and the
    floor, the sphere top and the card at their own values."""
    pytest.importorskip("bpy")
    from test_addon import render_to

    sc = _blender_mist_scene(camera_type, falloff)
    mists = {}
    for engine in ("CYCLES", "DRT"):
        sc.render.engine = engine
        chans, _ = render_to(sc, tmp_path / f"{engine}.exr", multilayer=True)
        key = next(k for k in chans if k.endswith("Mist.Z") or k.endswith("Mist.V") or k.endswith("Mist.Y")
                   or k.split(".")[-2:-1] == ["Mist"])
        mists[engine] = np.asarray(chans[key], np.float64).reshape(sc.render.resolution_y, sc.render.resolution_x)
    diff = np.abs(mists["DRT"] - mists["CYCLES"])
    print(camera_type, falloff, "mean |DRT − Cycles|", diff.mean(), "max", diff.max(),
          "means", mists["CYCLES"].mean(), mists["DRT"].mean())
    assert diff.mean() < 0.01 and np.median(diff) < 0.005
    assert 0.2 < mists["CYCLES"].mean() < 0.95
