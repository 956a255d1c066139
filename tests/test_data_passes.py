"""Cycles's data passes (scene format ``render.data_passes``): Object Index, Material Index and
Position from each pixel's sample 0, the UV averaged over samples, each at the first surface a
camera ray meets whose alpha reaches the view layer's Alpha Threshold (Cycles's
film_write_data_passes); and its Emission and Environment passes (``render.light_passes``): what
camera rays bring from emitters and from the world before their first scattering. Exact values
on orthographic views of known geometry; parity with Cycles through F12 in both engines at the
end."""

import numpy as np
import pytest

from drt.exr import film_from_exr, write_exr
from drt.render import merge_films, render
from drt.scene import scene_from_dict
from scene_builders import add_material, add_mesh, base_header, quad, scene_error_of, translation

ALL = ["object_index", "material_index", "position", "uv"]
PIXEL = 2.0 / 16  # metres a pixel spans on the floor (ortho scale 2, 16 pixels)
FLOOR_OBJECT, FLOOR_MATERIAL, CARD_OBJECT, CARD_MATERIAL = 3, 7, 5, 2


def _scene(passes=ALL, card="opaque", threshold=None, offset=(0.0, 0.0, 0.0), spp=16):
    """An orthographic camera 3 m over a floor quad (z = 0, ±0.8 m, UV = xy/2 + ½ there) with
    a card at z = 0.5 over the floor's +x+y quarter (x, y in [0, 0.8]; no UV map). ``card``: "opaque"
    (diffuse) or "clear" (a Transparent BSDF of colour 1: alpha 0). Everything, camera
    included, moved by ``offset`` (metres)."""
    ox, oy, oz = offset
    cam = {"type": "ORTHO", "matrix_world": translation(ox, oy, oz + 3.0), "ortho_scale": 2.0,
           "clip_start": 0.01, "clip_end": 100.0}
    render_opts = {"max_bounces": 0, "data_passes": list(passes)}
    if threshold is not None:
        render_opts["pass_alpha_threshold"] = threshold
    h = base_header(16, 16, spp, camera=cam, **render_opts)
    a = {}
    floor_mat = add_material(h, "floor", [{"type": "DIFFUSE", "color": [0.6] * 3}])
    h["materials"][-1]["pass_index"] = FLOOR_MATERIAL
    lobes = ([{"type": "DIFFUSE", "color": [0.6] * 3}] if card == "opaque"
             else [{"type": "GLASS", "color": [1.0] * 3, "ior": 1.0, "roughness": 0.0}])
    card_mat = add_material(h, "card", lobes)
    h["materials"][-1]["pass_index"] = CARD_MATERIAL
    k = add_mesh(h, a, "floor", *quad((ox, oy, oz), (0.8, 0, 0), (0, 0.8, 0)), material=floor_mat)
    h["objects"][-1]["pass_index"] = FLOOR_OBJECT
    corners = a[f"mesh{k}.positions"][a[f"mesh{k}.triangles"]]
    a[f"mesh{k}.uvs"] = ((corners[..., :2] - (ox, oy)) * 0.5 + 0.5).astype(np.float32)
    add_mesh(h, a, "card", *quad((ox + 0.4, oy + 0.4, oz + 0.5), (0.4, 0, 0), (0, 0.4, 0)), material=card_mat)
    h["objects"][-1]["pass_index"] = CARD_OBJECT
    h["lights"].append({"type": "SUN", "name": "sun", "matrix_world": translation(0, 0, 5), "color": [1, 1, 1],
                        "strength": 3.0, "angle": 0.0})
    return scene_from_dict(h, a)


def _centres():
    """(x, y) of each pixel's centre on the floor, rows from the top (+y)."""
    c = -1.0 + PIXEL * (np.arange(16) + 0.5)
    return np.meshgrid(c, c[::-1])


#: how far from its pixel's centre a sample may land: Cycles's Blackman-Harris of width 1.5
#: reaches 1.5 pixels (its table spans twice the width)
REACH = 1.5 * PIXEL
# pixels whose every sample lands inside one region: the card's x in [0, 0.8] is columns
# 8 … 14.4 (rows 1.6 … 8 for y), the floor's −x half below the card columns 1.6 … 8
CARD = (slice(3, 6), slice(9, 12))
FLOOR = (slice(8, 13), slice(3, 7))
BACKGROUND = (slice(0, 1), slice(None))


@pytest.fixture(scope="module")
def film():
    return render(_scene(), threads=2)


def test_index_passes_hold_the_pass_indices_of_sample_zeros_surface(film):
    assert np.all(film.object_index[CARD] == CARD_OBJECT)
    assert np.all(film.material_index[CARD] == CARD_MATERIAL)
    assert np.all(film.object_index[FLOOR] == FLOOR_OBJECT)
    assert np.all(film.material_index[FLOOR] == FLOOR_MATERIAL)
    assert np.all(film.object_index[BACKGROUND] == 0) and np.all(film.material_index[BACKGROUND] == 0)
    # one sample decides a pixel: every pixel holds one of the three values, never a blend
    assert set(np.unique(film.object_index)) <= {0.0, FLOOR_OBJECT, CARD_OBJECT}


def test_position_is_sample_zeros_hit_point(film):
    x, y = _centres()
    pos = film.position
    for region, z in ((FLOOR, 0.0), (CARD, 0.5)):
        assert np.all(pos[region][..., 2] == pytest.approx(z, abs=1e-5))
        assert np.all(np.abs(pos[region][..., 0] - x[region]) <= REACH + 1e-6)
        assert np.all(np.abs(pos[region][..., 1] - y[region]) <= REACH + 1e-6)
    # sample 0 is not the pixel's centre: the positions are scattered within the filter's reach
    assert np.std(pos[FLOOR][..., 0] - x[FLOOR]) > 0.05 * PIXEL
    assert np.all(pos[BACKGROUND] == 0.0)


def test_position_is_in_blender_world_space_far_from_the_origin():
    offset = (1.0e5, -2.0e5, 3.0e4)
    pos = render(_scene(passes=["position"], offset=offset), threads=1).position
    x, y = _centres()
    assert np.all(np.abs(pos[FLOOR][..., 0] - (x[FLOOR] + offset[0])) <= REACH + 0.02)
    assert np.all(np.abs(pos[FLOOR][..., 1] - (y[FLOOR] + offset[1])) <= REACH + 0.02)
    assert np.all(np.abs(pos[CARD][..., 2] - (offset[2] + 0.5)) <= 0.01)
    assert np.all(pos[BACKGROUND] == 0.0)


def test_uv_pass_is_the_mean_uv_with_coverage(film):
    x, y = _centres()
    uv = film.uv
    # UV is linear over the floor and the filter symmetric: the mean is the centre's UV, up to
    # the 16 samples' scatter (a pixel is 0.0625 in u; stratified samples average closely)
    assert np.abs(uv[FLOOR][..., 0] - (x[FLOOR] * 0.5 + 0.5)).max() < 0.02
    assert np.abs(uv[FLOOR][..., 1] - (y[FLOOR] * 0.5 + 0.5)).max() < 0.02
    assert np.all(uv[FLOOR][..., 2] == 1.0)
    assert np.all(uv[CARD] == 0.0)  # a mesh without a UV map: (0, 0, 0), as Cycles
    assert np.all(uv[BACKGROUND] == 0.0)


def test_a_surface_below_the_alpha_threshold_is_seen_through():
    x, y = _centres()
    through = render(_scene(card="clear"), threads=1)  # alpha 0 < Blender's default 0.5
    assert np.all(through.object_index[CARD] == FLOOR_OBJECT)
    assert np.all(through.material_index[CARD] == FLOOR_MATERIAL)
    assert np.all(through.position[CARD][..., 2] == pytest.approx(0.0, abs=1e-5))
    assert np.abs(through.uv[CARD][..., 0] - (x[CARD] * 0.5 + 0.5)).max() < 0.02
    stopped = render(_scene(card="clear", threshold=0.0), threads=1)  # 0: every surface counts
    assert np.all(stopped.object_index[CARD] == CARD_OBJECT)
    assert np.all(stopped.position[CARD][..., 2] == pytest.approx(0.5, abs=1e-5))
    assert np.all(stopped.uv[CARD] == 0.0)


def test_sample_ranges_merge_and_the_exr_keeps_the_passes(film, tmp_path):
    sc = _scene()
    parts = [render(sc, threads=1, sample_offset=o, sample_count=8) for o in (0, 8)]
    merged = merge_films(parts)
    assert np.array_equal(merged.object_index, film.object_index)
    assert np.array_equal(merged.material_index, film.material_index)
    assert np.array_equal(merged.position, film.position)
    assert np.allclose(merged.uv, film.uv, atol=1e-6)
    assert np.all(parts[1].object_index == 0)  # only the range with sample 0 writes it
    write_exr(tmp_path / "a.exr", film)
    back = film_from_exr(tmp_path / "a.exr")
    for name in ("object_index", "material_index", "position"):
        assert np.array_equal(getattr(back, name), getattr(film, name)), name
    assert np.allclose(back.uv, film.uv, atol=1e-6)


def test_a_render_without_data_passes_keeps_none():
    f = render(_scene(passes=[], spp=2), threads=1)
    assert f.sum_data is None and f.object_index is None and f.uv is None


@pytest.mark.parametrize("change, where", [
    (lambda h: h["render"].__setitem__("data_passes", ["object_index", "cryptomatte"]), "render.data_passes"),
    (lambda h: h["render"].__setitem__("data_passes", "uv"), "render.data_passes"),
    (lambda h: h["render"].__setitem__("light_passes", ["emission", "shadow"]), "render.light_passes"),
    (lambda h: h["render"].__setitem__("pass_alpha_threshold", 1.5), "render.pass_alpha_threshold"),
    (lambda h: h["objects"][0].__setitem__("pass_index", -1), "objects[0].pass_index"),
    (lambda h: h["materials"][0].__setitem__("pass_index", 2.5), "materials[0].pass_index"),
])
def test_bad_data_pass_settings_are_named(change, where):
    message = scene_error_of(change)
    assert message is not None and where in message


# ------------------------------------------------------------------------- light passes
WORLD = (0.2, 0.3, 0.4)
GLOW = (2.0, 1.0, 0.5)


def _glow_scene(spp=16, card=False, **render_opts):
    """An orthographic view down on a grey floor (x < 0.6) and, over its −x half, a glowing
    plate (emission GLOW) at z = 0.3; the world (WORLD) seen beyond the floor (x > 0.6).
    ``card``: a 50 % transparent card at z = 0.6 over the plate's −y half."""
    cam = {"type": "ORTHO", "matrix_world": translation(0, 0, 3.0), "ortho_scale": 2.0,
           "clip_start": 0.01, "clip_end": 100.0}
    h = base_header(16, 16, spp, camera=cam, world=WORLD, light_passes=["emission", "environment"],
                    **render_opts)
    a = {}
    grey = add_material(h, "grey", [{"type": "DIFFUSE", "color": [0.5] * 3}])
    glow = add_material(h, "glow", [{"type": "DIFFUSE", "color": [0.0] * 3}], emission=GLOW)
    add_mesh(h, a, "floor", *quad((-0.2, 0, 0), (0.8, 0, 0), (0, 1.2, 0)), material=grey)
    add_mesh(h, a, "plate", *quad((-0.5, 0, 0.3), (0.45, 0, 0), (0, 0.9, 0)), material=glow)
    if card:
        half = add_material(h, "half", [{"type": "GLASS", "color": [0.5] * 3, "ior": 1.0, "roughness": 0.0},
                                        {"type": "DIFFUSE", "color": [0.0] * 3}])
        add_mesh(h, a, "card", *quad((-0.5, -0.45, 0.6), (0.45, 0, 0), (0, 0.45, 0)), material=half)
    return scene_from_dict(h, a)


# pixels every sample of which sees the plate (x in [−0.95, −0.05], y in ±0.9), the floor
# beside it (x in [0, 0.6]) and the world (x > 0.6); the card's half of the plate (y < −0.05)
PLATE = (slice(3, 13), slice(2, 5))
FLOOR_LIT = (slice(4, 12), slice(10, 11))
WORLD_SEEN = (slice(2, 14), slice(15, 16))
PLATE_UNDER_CARD = (slice(10, 13), slice(2, 5))


def test_emission_and_environment_passes_hold_what_camera_rays_see():
    film = render(_glow_scene(), threads=2)
    emit, env = film.emission, film.environment
    np.testing.assert_allclose(emit[PLATE], np.broadcast_to(GLOW, emit[PLATE].shape), rtol=1e-6)
    np.testing.assert_allclose(env[WORLD_SEEN], np.broadcast_to(WORLD, env[WORLD_SEEN].shape), rtol=1e-6)
    assert np.all(env[PLATE] == 0.0) and np.all(emit[WORLD_SEEN] == 0.0)
    # the floor reflects the plate and the world: light the two passes do not hold
    assert np.all(emit[FLOOR_LIT] == 0.0) and np.all(env[FLOOR_LIT] == 0.0)
    assert np.all(film.combined[FLOOR_LIT][..., :3] > 0.05)
    # where nothing but emitters and the world is seen, the combined pass is their sum
    np.testing.assert_allclose(film.combined[PLATE][..., :3], emit[PLATE], rtol=1e-6)


def test_the_environment_pass_sees_the_world_behind_a_transparent_film_and_exposure_scales():
    film = render(_glow_scene(film_transparent=True, exposure=2.0), threads=1)
    env, emit = film.environment[WORLD_SEEN], film.emission[PLATE]
    np.testing.assert_allclose(env, np.broadcast_to(np.multiply(WORLD, 2.0), env.shape), rtol=1e-6)
    assert np.all(film.combined[WORLD_SEEN][..., 3] == 0.0) and np.all(film.combined[WORLD_SEEN][..., :3] == 0.0)
    np.testing.assert_allclose(emit, np.broadcast_to(np.multiply(GLOW, 2.0), emit.shape), rtol=1e-6)


def test_emission_seen_through_a_transparent_card_is_weighted_by_it():
    """A camera ray stays one through transparency (Cycles: no PATH_RAY_ANY_PASS): behind the
    50 % card the pass is half the plate's glow, in the mean of 64 stochastic pass-throughs."""
    film = render(_glow_scene(spp=64, card=True), threads=2)
    under = film.emission[PLATE_UNDER_CARD].reshape(-1, 3).mean(axis=0)
    # 9 pixels × 64 samples of a Bernoulli(½) × 2·GLOW: σ of the mean ≈ GLOW / 24
    np.testing.assert_allclose(under, np.multiply(GLOW, 0.5), rtol=0.15)


def test_light_passes_merge_across_ranges_and_survive_the_exr(tmp_path):
    sc = _glow_scene()
    full = render(sc, threads=1)
    merged = merge_films([render(sc, threads=1, sample_offset=o, sample_count=8) for o in (0, 8)])
    np.testing.assert_allclose(merged.emission, full.emission, atol=1e-6)
    np.testing.assert_allclose(merged.environment, full.environment, atol=1e-6)
    write_exr(tmp_path / "l.exr", full)
    back = film_from_exr(tmp_path / "l.exr")
    np.testing.assert_allclose(back.emission, full.emission, atol=1e-6)
    np.testing.assert_allclose(back.environment, full.environment, atol=1e-6)
    assert render(_scene(passes=[], spp=1), threads=1).sum_light is None


def test_the_diffuse_color_pass_holds_diffuse_lobes_only_and_is_not_exposed():
    """Cycles's Diffuse Color: the diffuse-class closures' weights (× throughput), not the
    albedo the denoiser reads: a Lambert plate gives its colour, a glossy one 0 (its albedo is
    not 0); exposure scales light, not this colour."""
    cam = {"type": "ORTHO", "matrix_world": translation(0, 0, 3.0), "ortho_scale": 2.0,
           "clip_start": 0.01, "clip_end": 100.0}
    h = base_header(16, 16, 4, camera=cam, world=WORLD, light_passes=["diffuse_color"], exposure=2.0)
    a = {}
    colour = [0.8, 0.5, 0.2]
    add_mesh(h, a, "matte", *quad((-0.5, 0, 0), (0.45, 0, 0), (0, 0.9, 0)),
             material=add_material(h, "matte", [{"type": "DIFFUSE", "color": colour}]))
    add_mesh(h, a, "shiny", *quad((0.5, 0, 0), (0.45, 0, 0), (0, 0.9, 0)),
             material=add_material(h, "shiny", [{"type": "GLOSSY", "color": colour, "roughness": 0.3}]))
    film = render(scene_from_dict(h, a), threads=1)
    matte, shiny = (slice(3, 13), slice(2, 5)), (slice(3, 13), slice(11, 14))
    np.testing.assert_allclose(film.diffuse_color[matte], np.broadcast_to(colour, film.diffuse_color[matte].shape),
                               rtol=1e-6)
    assert np.all(film.diffuse_color[shiny] == 0.0) and np.all(film.albedo[shiny] > 0.1)
    assert np.all(film.diffuse_color[WORLD_SEEN] == 0.0)
    assert film.emission is not None  # (the light passes come together)


# ------------------------------------------------------------------------------ Blender
def _blender_data_scene():
    """node_parity's orthographic view down on a floor (object pass 3, material pass 7) with a
    sphere (4, 9), an opaque card (6, 2) and a card of Principled Alpha 0 (5, 8): every pass on
    (Object and Material Index, Position, UV), the view layer's Alpha Threshold at its default."""
    import bpy

    from node_parity import grey_principled, setup_scene

    sc = setup_scene(2)
    sc.cycles.samples = sc.drt.samples = 16
    vl = sc.view_layers[0]
    vl.use_pass_object_index = vl.use_pass_material_index = vl.use_pass_position = vl.use_pass_uv = True

    def material(name, pass_index, alpha=1.0):
        return grey_principled(name, alpha, pass_index)

    def place(obj_pass, mat):
        bpy.context.object.pass_index = obj_pass
        bpy.context.object.data.materials.append(mat)

    bpy.ops.mesh.primitive_plane_add(size=1.6, location=(0, 0, -1))
    place(3, material("floor", 7))
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.4, location=(-0.4, 0.4, -0.5), segments=48, ring_count=24)
    place(4, material("ball", 9))
    bpy.ops.mesh.primitive_plane_add(size=0.5, location=(0.45, 0.45, 0.0))
    place(6, material("card", 2))
    bpy.ops.mesh.primitive_plane_add(size=0.6, location=(0.3, -0.4, 0.0))
    place(5, material("clear", 8, alpha=0.0))
    return sc


def test_data_passes_match_cycles(tmp_path):
    """The four passes DRT writes into Blender's render result (F12) against Cycles's, same
    scene, pixel by pixel (both engines read the scene's pixel filter, 0.01 pixel wide here, so
    sample 0 is at the pixel's centre in both): the indexes equal but for pixels a silhouette
    crosses, positions within a hundredth of a pixel there, UVs within noise. Measured: the
    indexes agree on all but 1 of 1024 pixels, positions within 0.002, mean UV difference
    0.0001."""
    pytest.importorskip("bpy")
    from addon import compat
    from node_parity import f12_in_both

    sc = _blender_data_scene()
    w, h = sc.render.resolution_x, sc.render.resolution_y
    got = {}
    for engine, chans, _ in f12_in_both(sc, tmp_path):

        def pass_of(name, comps):
            keys = [next(k for k in chans if k.endswith(f"{name}.{c}")) for c in comps]
            return np.stack([np.asarray(chans[k], np.float64).reshape(h, w) for k in keys], axis=-1)

        got[engine] = {"ob": pass_of(compat.pass_name("IndexOB"), "X")[..., 0],
                       "ma": pass_of(compat.pass_name("IndexMA"), "X")[..., 0],
                       "pos": pass_of("Position", "XYZ"), "uv": pass_of("UV", "UVA")}
    c, d = got["CYCLES"], got["DRT"]
    same = c["ob"] == d["ob"]
    print("object index agrees on", same.mean(), "material index", (c["ma"] == d["ma"]).mean(),
          "position max |diff| where they agree", np.abs(c["pos"] - d["pos"])[same].max(),
          "uv mean |diff|", np.abs(c["uv"] - d["uv"]).mean())
    assert set(np.unique(c["ob"])) == {0.0, 3.0, 4.0, 6.0}  # the clear card is seen through
    assert same.mean() > 0.98 and (c["ma"] == d["ma"]).mean() > 0.98
    assert np.abs(c["pos"] - d["pos"])[same].max() < 0.01
    coverage = np.abs(c["uv"][..., 2] - d["uv"][..., 2])  # (differs where a sample hits an edge)
    assert (coverage == 0).mean() > 0.99 and coverage.max() <= 2 / 16
    uv_diff = np.abs(c["uv"] - d["uv"])[same]
    assert uv_diff.mean() < 0.002 and np.quantile(uv_diff, 0.99) < 0.01


def _blender_glow_scene():
    """node_parity's orthographic view down on a grey floor lit by a glowing plate (Emission
    strength 3) beside a half-transparent card over part of it, a world of colour WORLD:
    the Emission and Environment passes on, 256 samples, 2 bounces."""
    import bpy

    from node_parity import setup_scene, shader_material

    sc = setup_scene(2)
    sc.cycles.samples = sc.drt.samples = 256
    sc.cycles.max_bounces = sc.drt.max_bounces = 2
    sc.world.node_tree.nodes["Background"].inputs[0].default_value = (*WORLD, 1.0)
    sc.world.node_tree.nodes["Background"].inputs[1].default_value = 1.0
    vl = sc.view_layers[0]
    vl.use_pass_emit = vl.use_pass_environment = True

    material = shader_material

    bpy.ops.mesh.primitive_plane_add(size=1.2, location=(-0.2, 0, -1))
    grey = material("grey", "ShaderNodeBsdfDiffuse", {"Color": (0.5, 0.5, 0.5, 1)})
    bpy.context.object.data.materials.append(grey)
    bpy.ops.mesh.primitive_plane_add(size=0.5, location=(-0.45, 0.2, -0.7))
    bpy.context.object.data.materials.append(material("glow", "ShaderNodeEmission",
                                                      {"Color": (1.0, 0.5, 0.25, 1), "Strength": 3.0}))
    bpy.ops.mesh.primitive_plane_add(size=0.3, location=(-0.45, 0.2, -0.4))  # (over the plate)
    bpy.context.object.data.materials.append(material("card", "ShaderNodeBsdfPrincipled",
                                                      {"Base Color": (0.8, 0.2, 0.2, 1), "Alpha": 0.5}))
    return sc


def test_light_passes_match_cycles(tmp_path):
    """The Emission and Environment passes through F12 in both engines, pixel by pixel: the
    plate's glow, the world beyond the floor, zero on the floor; mean absolute difference of
    each pass well under a percent of its scale (measured: see the print)."""
    pytest.importorskip("bpy")
    from addon import compat
    from node_parity import f12_in_both

    sc = _blender_glow_scene()
    w, h = sc.render.resolution_x, sc.render.resolution_y
    got = {}
    for engine, chans, _ in f12_in_both(sc, tmp_path):
        got[engine] = {}
        for name in ("Emit", "Env"):
            key = compat.pass_name(name)
            keys = [k for k in chans if k.split(".")[-2:-1] == [key] or k.endswith(f".{key}")]
            assert len(keys) == 1, keys  # (a colour pass reads back as one (h, w, 3) group)
            got[engine][name] = np.asarray(chans[keys[0]], np.float64).reshape(h, w, -1)[..., :3]
    for name, scale in (("Emit", 3.0), ("Env", max(WORLD))):
        c, d = got["CYCLES"][name], got["DRT"][name]
        diff = np.abs(c - d)
        print(name, "mean |DRT − Cycles|", diff.mean(), "means", c.mean(), d.mean())
        assert c.max() > 0.5 * scale  # the pass shows its subject
        assert diff.mean() < 0.01 * scale and abs(c.mean() - d.mean()) < 0.01 * scale


def test_the_passes_panel_shows_the_data_and_light_passes():
    """DRT's Data passes panel edits the view layer's Position, UV, index and light passes and
    the Alpha Threshold: every property it draws exists on the view layer."""
    pytest.importorskip("bpy")
    import bpy

    from addon import ui
    from test_addon import FakeLayout, ensure_registered

    ensure_registered()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    panel = type("FakePanel", (), {"layout": FakeLayout()})()
    ui.DRT_VIEWLAYER_PT_passes_data.draw(panel, bpy.context)
    drawn = set(panel.layout.props)
    assert {"use_pass_position", "use_pass_uv", "use_pass_object_index", "use_pass_material_index",
            "pass_alpha_threshold", "use_pass_emit", "use_pass_environment", "use_pass_ambient_occlusion"} <= drawn
    vl = bpy.context.view_layer
    assert all(hasattr(vl, p) or hasattr(getattr(vl, "cycles", None), p) for p in drawn), drawn


def _blender_diffuse_color_scene():
    """node_parity's view down on a grey floor and eight smooth spheres of base colour C, one
    shader each: a coated Principled, Principled subsurface, Translucent, Principled sheen, a
    Principled of Alpha 0.5, a rough Principled of IOR 2, the Sheen BSDF, a half-transmissive
    Principled; the Diffuse Color pass on."""
    import bpy

    from node_parity import setup_scene, shader_material

    sc = setup_scene(4)
    sc.cycles.samples = sc.drt.samples = 64
    sc.view_layers[0].use_pass_diffuse_color = True

    material = shader_material

    c = (0.8, 0.5, 0.2, 1)
    principled = "ShaderNodeBsdfPrincipled"
    mats = [material("coat", principled, {"Base Color": c, "Coat Weight": 1.0}),
            material("sss", principled, {"Base Color": c, "Subsurface Weight": 1.0}),
            material("translucent", "ShaderNodeBsdfTranslucent", {"Color": c}),
            material("sheen", principled, {"Base Color": c, "Sheen Weight": 1.0}),
            material("alpha", principled, {"Base Color": c, "Alpha": 0.5}),
            material("rough", principled, {"Base Color": c, "Roughness": 1.0, "IOR": 2.0}),
            material("sheen_bsdf", "ShaderNodeBsdfSheen", {"Color": c}),
            material("transmission", principled, {"Base Color": c, "Transmission Weight": 0.5})]
    bpy.ops.mesh.primitive_plane_add(size=2, location=(0, 0, -2))
    bpy.context.object.data.materials.append(material("floor", "ShaderNodeBsdfDiffuse", {"Color": (0.3, 0.3, 0.3, 1)}))
    for k, m in enumerate(mats):
        loc = (-0.75 + 0.5 * (k % 4), 0.75 - 0.5 * (k // 4), -1)
        bpy.ops.mesh.primitive_uv_sphere_add(radius=0.22, location=loc, segments=32, ring_count=16)
        bpy.ops.object.shade_smooth()
        bpy.context.object.data.materials.append(m)
    return sc, [m.name for m in mats]


def test_diffuse_color_matches_cycles(tmp_path):
    """Cycles's Diffuse Color pass against DRT's through F12: every sphere's centre within
    0.002 per channel (measured: equal to 3 decimals, the Sheen BSDF's 0.02 included), the
    image's mean difference under 0.002 (the Alpha sphere's stochastic pass-through)."""
    pytest.importorskip("bpy")
    from addon import compat
    from node_parity import f12_in_both

    sc, names = _blender_diffuse_color_scene()
    w, h = sc.render.resolution_x, sc.render.resolution_y
    got = {}
    for engine, chans, _ in f12_in_both(sc, tmp_path):
        key = f"ViewLayer.{compat.pass_name('DiffCol')}"
        got[engine] = np.asarray(chans[key], np.float64).reshape(h, w, -1)[..., :3]
    for k, name in enumerate(names):
        cx, cy = int((k % 4 + 0.5) * w / 4), int((k // 4 + 0.5) * h / 4)
        region = (slice(cy - 3, cy + 3), slice(cx - 3, cx + 3))
        c, d = got["CYCLES"][region].reshape(-1, 3).mean(0), got["DRT"][region].reshape(-1, 3).mean(0)
        print(name, c.round(4), d.round(4))
        tol = 0.03 if name == "alpha" else 0.002  # (stochastic transparency: 36 pixels × 64 samples)
        np.testing.assert_allclose(d, c, atol=tol, err_msg=name)
    diff = np.abs(got["CYCLES"] - got["DRT"]).max(-1)
    print("mean |DRT − Cycles|", diff.mean())
    assert diff.mean() < 0.002
