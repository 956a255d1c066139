"""Cryptomatte (scene format ``render.cryptomatte``; drt.cryptomatte): per pixel, the ids of the
objects, materials and assets camera rays saw, each with the share of the samples that saw it
(weighted by the surface's opacity), as Cycles's film_write_data_passes accumulates them. Exact
ids and coverages on an orthographic view of known geometry, the hash and metadata conventions
against Blender's own test vectors, and parity with Cycles through F12 at the end."""

import json

import numpy as np
import pytest

from drt import cryptomatte
from drt.exr import film_from_exr, read_exr, write_exr
from drt.render import merge_films, render
from drt.scene import scene_from_dict
from scene_builders import add_material, add_mesh, base_header, quad, scene_error_of, translation

ALL = ["object", "material", "asset"]
# pixels whose every sample lands on the card / on the floor beside it / on nothing (the 16 × 16
# view of test_data_passes: card over x, y in [0, 0.8], floor ±0.8, ortho scale 2)
CARD = (slice(3, 6), slice(9, 12))
FLOOR = (slice(8, 13), slice(3, 7))
BACKGROUND = (slice(0, 1), slice(None))


def _scene(layers=ALL, card="opaque", levels=None, spp=16, card_names=None):
    """An orthographic camera 3 m over a floor quad with a card over its +x+y quarter. ``card``:
    "opaque" (diffuse), "half" (half of it lets light straight through) or "clear"."""
    cam = {"type": "ORTHO", "matrix_world": translation(0, 0, 3.0), "ortho_scale": 2.0,
           "clip_start": 0.01, "clip_end": 100.0}
    opts = {"max_bounces": 0, "cryptomatte": list(layers)}
    if levels is not None:
        opts["cryptomatte_levels"] = levels
    h = base_header(16, 16, spp, camera=cam, **opts)
    a = {}
    floor_mat = add_material(h, "Floor Paint", [{"type": "DIFFUSE", "color": [0.6] * 3}])
    lobes = {"opaque": [{"type": "DIFFUSE", "color": [0.6] * 3}],
             "half": [{"type": "DIFFUSE", "color": [0.3] * 3},
                      {"type": "GLASS", "color": [0.5] * 3, "ior": 1.0, "roughness": 0.0}],
             "clear": [{"type": "GLASS", "color": [1.0] * 3, "ior": 1.0, "roughness": 0.0}]}[card]
    card_mat = add_material(h, "Card Stock", lobes)
    add_mesh(h, a, "Floor", *quad((0, 0, 0), (0.8, 0, 0), (0, 0.8, 0)), material=floor_mat)
    add_mesh(h, a, "Card", *quad((0.4, 0.4, 0.5), (0.4, 0, 0), (0, 0.4, 0)), material=card_mat)
    if card_names is not None:
        h["objects"][-1]["cryptomatte"] = card_names
    h["lights"].append({"type": "SUN", "name": "sun", "matrix_world": translation(0, 0, 5), "color": [1, 1, 1],
                        "strength": 3.0, "angle": 0.0})
    return scene_from_dict(h, a)


@pytest.fixture(scope="module")
def film():
    return render(_scene(), threads=2)


def _id(name):
    return np.float32(cryptomatte.name_id(name))


def test_the_hash_and_the_metadata_keys_are_blenders():
    # MurmurHash3 x86 32 reference values, and BKE_cryptomatte_meta_data_key's test vectors
    assert cryptomatte.murmur3_32(b"") == 0
    assert cryptomatte.murmur3_32(b"hello") == 0x248BFA47
    assert cryptomatte.murmur3_32(b"The quick brown fox jumps over the lazy dog") == 0x2E4FF723
    assert cryptomatte.layer_key("ViewLayer.CryptoMaterial") == "cryptomatte/c7dbf5e/"
    assert cryptomatte.layer_key("𝖚𝖓𝖎𝖈𝖔𝖉𝖊.CryptoMaterial") == "cryptomatte/b990b65/"
    # the float keeps the hash's bits except an exponent of 0 or 255 (never 0, inf or NaN)
    for h in (0x00000000, 0x7F800000, 0xFFFFFFFF, 0x3F800000, 0x12345678):
        f = cryptomatte.hash_to_float(h)
        bits = int(np.array(f, np.float32).view(np.uint32))
        assert np.isfinite(f) and f != 0.0
        assert bits & 0x807FFFFF == h & 0x807FFFFF
        assert 1 <= (bits >> 23) & 0xFF <= 254
    assert cryptomatte.slot_count(6) == 6 and cryptomatte.slot_count(3) == 4


def test_each_region_holds_its_objects_material_and_asset(film):
    for layer, card, floor in (("object", "Card", "Floor"), ("material", "Card Stock", "Floor Paint"),
                               ("asset", "Card", "Floor")):
        slots = film.cryptomatte(layer)
        assert slots.shape == (16, 16, 6, 2)
        assert np.all(slots[CARD][..., 0, 0] == _id(card)) and np.all(slots[CARD][..., 0, 1] == 1.0)
        assert np.all(slots[FLOOR][..., 0, 0] == _id(floor)) and np.all(slots[FLOOR][..., 0, 1] == 1.0)
        assert np.all(slots[CARD][..., 1:, :] == 0.0) and np.all(slots[FLOOR][..., 1:, :] == 0.0)
        assert np.all(slots[BACKGROUND] == 0.0)  # the world adds nothing


def test_edge_pixels_share_their_coverage_heaviest_first(film):
    slots = film.cryptomatte("object")
    total = slots[..., 1].sum(axis=-1)
    assert np.all(total <= 1.0 + 1e-6)
    assert np.all(np.diff(slots[..., 1], axis=-1) <= 0.0)  # sorted by coverage
    # the card's left edge (x = 0: between columns 7 and 8) splits pixels between card and floor
    shared = (slots[..., 0, 1] < 1.0) & (slots[..., 1, 1] > 0.0)
    assert shared[2:8, 7:9].any()
    # the floor's edge (x = -0.8: column 1.6) splits pixels between floor and background
    edge = total[10, 1]
    assert 0.0 < edge < 1.0


def test_a_half_transparent_card_shares_its_pixels_with_the_floor_behind():
    f = render(_scene(layers=["object"], card="half", spp=64), threads=1)
    slots = f.cryptomatte("object")[CARD]
    weight = {name: np.where(slots[..., 0] == _id(name), slots[..., 1], 0.0).sum(axis=-1) for name in ("Card", "Floor")}
    # the card takes its opacity (0.5) of every sample, the floor the half that passes
    assert np.allclose(weight["Card"], 0.5, atol=1e-6)
    assert abs(weight["Floor"].mean() - 0.5) < 0.05
    clear = render(_scene(layers=["object"], card="clear", spp=4), threads=1).cryptomatte("object")[CARD]
    assert np.all(clear[..., 0, 0] == _id("Floor")) and np.allclose(clear[..., 0, 1], 1.0)


def test_object_and_asset_names_come_from_the_scene():
    f = render(_scene(card_names={"object": "Card.001", "asset": "Desk"}, spp=4), threads=1)
    assert np.all(f.cryptomatte("object")[CARD][..., 0, 0] == _id("Card.001"))
    assert np.all(f.cryptomatte("asset")[CARD][..., 0, 0] == _id("Desk"))
    assert f.crypto_names["asset"] == ("Desk", "Floor")


def test_levels_bound_the_slots_and_a_render_without_cryptomatte_keeps_none():
    f = render(_scene(layers=["material"], levels=2, spp=4), threads=1)
    assert f.cryptomatte("material").shape == (16, 16, 2, 2) and f.cryptomatte("object") is None
    none = render(_scene(layers=[], spp=2), threads=1)
    assert none.sum_crypto is None and none.cryptomatte("object") is None


def test_threads_sample_ranges_and_the_exr_keep_the_mattes(film, tmp_path):
    sc = _scene()
    one = render(sc, threads=1)
    assert np.array_equal(one.cryptomatte("object"), film.cryptomatte("object"))
    merged = merge_films([render(sc, threads=1, sample_offset=o, sample_count=8) for o in (0, 8)])
    for layer in ALL:
        a, b = merged.cryptomatte(layer), film.cryptomatte(layer)
        assert np.array_equal(a[..., 0], b[..., 0]) and np.allclose(a[..., 1], b[..., 1], atol=1e-6)
    write_exr(tmp_path / "c.exr", film)
    ch, _, header = read_exr(tmp_path / "c.exr", with_header=True)
    assert {"CryptoObject00.R", "CryptoObject02.A", "CryptoMaterial00.G", "CryptoAsset01.B"} <= set(ch)
    key = cryptomatte.layer_key("CryptoMaterial")
    assert header[key + "name"] == "CryptoMaterial" and header[key + "hash"] == "MurmurHash3_32"
    manifest = json.loads(header[key + "manifest"])
    assert manifest == {"Card Stock": f"{cryptomatte.name_hash('Card Stock'):08x}",
                        "Floor Paint": f"{cryptomatte.name_hash('Floor Paint'):08x}"}
    back = film_from_exr(tmp_path / "c.exr")
    for layer in ALL:
        assert np.array_equal(back.cryptomatte(layer)[..., 0], film.cryptomatte(layer)[..., 0])
        assert np.allclose(back.cryptomatte(layer)[..., 1], film.cryptomatte(layer)[..., 1], atol=1e-6)
    assert back.crypto_names == film.crypto_names


@pytest.mark.parametrize("change, where", [
    (lambda h: h["render"].__setitem__("cryptomatte", ["object", "shadow"]), "render.cryptomatte"),
    (lambda h: h["render"].__setitem__("cryptomatte_levels", 17), "render.cryptomatte_levels"),
    (lambda h: h["objects"][0].__setitem__("cryptomatte", {"object": ""}), "objects[0].cryptomatte.object"),
    (lambda h: h["objects"][0].__setitem__("cryptomatte", "Card"), "objects[0].cryptomatte"),
])
def test_bad_cryptomatte_settings_are_named(change, where):
    message = scene_error_of(change)
    assert message is not None and where in message


def test_the_add_on_names_the_passes_as_the_core():
    pytest.importorskip("bpy")
    from addon import engine

    assert engine.CRYPTO_PASS_PREFIX == cryptomatte.PASS_PREFIX


def _blender_crypto_scene():
    """node_parity's orthographic view down on a floor, a sphere parented to an empty "Rig"
    (its asset), an opaque card, a card of Principled Alpha 0.5, a plane without a material and
    a collection instance, with every Cryptomatte layer on at the default Levels (6) and
    Cycles's default pixel filter (edges share pixels)."""
    import bpy

    from node_parity import grey_principled, setup_scene

    sc = setup_scene(2)
    sc.cycles.samples = sc.drt.samples = 64
    sc.cycles.filter_width = 1.5
    vl = sc.view_layers[0]
    vl.use_pass_cryptomatte_object = vl.use_pass_cryptomatte_material = vl.use_pass_cryptomatte_asset = True

    material = grey_principled
    def place(name, mat):
        bpy.context.object.name = name
        bpy.context.object.data.materials.append(mat)
        return bpy.context.object

    bpy.ops.mesh.primitive_plane_add(size=1.6, location=(0, 0, -1))
    place("Floor", material("Floor Paint"))
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.4, location=(-0.4, 0.4, -0.5), segments=48, ring_count=24)
    ball = place("Ball", material("Rubber"))
    rig = bpy.data.objects.new("Rig", None)
    sc.collection.objects.link(rig)
    ball.parent = rig
    bpy.ops.mesh.primitive_plane_add(size=0.5, location=(0.45, 0.45, 0.0))
    place("Card", material("Card Stock"))
    bpy.ops.mesh.primitive_plane_add(size=0.6, location=(0.3, -0.4, 0.0))
    place("Veil", material("Gauze", alpha=0.5))
    bpy.ops.mesh.primitive_plane_add(size=0.2, location=(0.75, -0.75, -0.3))
    bpy.context.object.name = "Bare"  # no material: Cycles's default surface
    bpy.ops.mesh.primitive_plane_add(size=0.3, location=(0.0, 0.0, 0.0))
    prop = bpy.context.object
    prop.name = "Prop"
    prop.data.materials.append(material("Plastic"))
    props = bpy.data.collections.new("Props")
    for c in prop.users_collection:
        c.objects.unlink(prop)
    props.objects.link(prop)
    instancer = bpy.data.objects.new("PropInstance", None)  # a collection instance
    instancer.instance_type, instancer.instance_collection = "COLLECTION", props
    instancer.location = (-0.5, -0.5, -0.2)
    sc.collection.objects.link(instancer)
    return sc


def test_cryptomatte_matches_cycles(tmp_path):
    """The Cryptomatte passes DRT writes into Blender's render result (F12) against Cycles's,
    same scene, pixel by pixel: each pixel's (id → coverage) map, compared as the L1 distance
    between the two maps (0: the same ids with the same coverage; 2: nothing in common), and
    the manifests in the multilayer EXR's header. Measured: mean distance 0.007, at most 0.16
    (edge pixels, 64 samples in each engine)."""
    pytest.importorskip("bpy")
    from node_parity import f12_in_both

    sc = _blender_crypto_scene()
    w, h = sc.render.resolution_x, sc.render.resolution_y
    maps, manifests = {}, {}
    for engine, chans, header in f12_in_both(sc, tmp_path):
        for layer in ("Object", "Material", "Asset"):
            passes = [np.stack([np.asarray(chans[f"ViewLayer.Crypto{layer}{j:02d}.{c}"], np.float32).reshape(h, w)
                                for c in "rgba"], axis=-1).reshape(h, w, 2, 2) for j in range(3)]
            maps[engine, layer] = np.concatenate(passes, axis=2)  # (h, w, 6, [id, coverage])
            key = cryptomatte.layer_key(f"ViewLayer.Crypto{layer}")
            manifests[engine, layer] = json.loads(header.get(key + "manifest", "{}"))
    for layer, names in (("Object", {"Floor", "Ball", "Card", "Veil", "Bare", "Prop"}),
                         ("Material", {"Floor Paint", "Rubber", "Card Stock", "Gauze", "Plastic", "default_surface"}),
                         ("Asset", {"Floor", "Rig", "Card", "Veil", "Bare", "Prop"})):
        c, d = maps["CYCLES", layer], maps["DRT", layer]
        dist = np.zeros((h, w))
        for y in range(h):
            for x in range(w):
                mc = {float(i): float(v) for i, v in c[y, x] if v > 0.0}
                md = {float(i): float(v) for i, v in d[y, x] if v > 0.0}
                dist[y, x] = sum(abs(mc.get(k, 0.0) - md.get(k, 0.0)) for k in set(mc) | set(md))
        ids = {float(np.float32(cryptomatte.name_id(n))) for n in names}
        print(layer, "L1 mean", dist.mean(), "p99", np.quantile(dist, 0.99), "max", dist.max(),
              "manifest", sorted(manifests["DRT", layer]), "cycles", sorted(manifests["CYCLES", layer]))
        assert {float(i) for i in np.unique(d[..., 0])} - {0.0} == ids  # the names hash alike
        assert dist.mean() < 0.03 and np.quantile(dist, 0.99) < 0.4
        assert names <= set(manifests["DRT", layer])
        for n in names:
            assert manifests["DRT", layer][n] == manifests["CYCLES", layer].get(n, manifests["DRT", layer][n])
