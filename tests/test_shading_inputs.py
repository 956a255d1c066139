"""Shading-point inputs of the material programs (docs/materials.md, "Shading-point inputs"):
Fresnel, Layer Weight, Geometry, Light Path and Normal Map, DRT against Cycles pixel by pixel on
emission-only tiles (tests/node_parity.py): smooth UV spheres under an orthographic camera, so
the normal and the angle to the viewer vary over every tile."""

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from node_parity import add_sun, node, render_rgba_both, render_tiles, tile  # noqa: E402

N = 4


def _compare(cycles, drt, count, tol=2e-3, outliers=6, n=N):
    """Per tile of an n×n grid, all but a few silhouette pixels (a pixel centre within the
    sample jitter of the sphere's edge) agree within tol."""
    bad = []
    for k in range(count):
        a, b = tile(cycles, k, n), tile(drt, k, n)
        assert a.shape == (16, 16, 3) and b.shape == a.shape
        diff = np.abs(a - b).max(axis=-1)
        if int((diff > tol).sum()) > outliers:
            bad.append((k, int((diff > tol).sum()), float(diff.max())))
    assert not bad, f"tiles differing from Cycles (case, pixels, max diff): {bad}"


def _normal_color(nt, uv):
    """A normal-map colour varying over the UVs (tilts of up to ~35° in every direction)."""
    sep = node(nt, "ShaderNodeSeparateXYZ", {0: uv})
    x = node(nt, "ShaderNodeMath", {0: sep.outputs[0], 1: 0.7, 2: 0.15}, operation="MULTIPLY_ADD")
    y = node(nt, "ShaderNodeMath", {0: sep.outputs[1], 1: 0.7, 2: 0.15}, operation="MULTIPLY_ADD")
    return node(nt, "ShaderNodeCombineXYZ", {0: x.outputs[0], 1: y.outputs[0], 2: 0.85}).outputs[0]


def _normal_map(space="TANGENT", strength=1.0):
    def case(nt, uv):
        return node(nt, "ShaderNodeNormalMap", {"Color": _normal_color(nt, uv), "Strength": strength},
                    space=space).outputs[0]
    return case


CASES = [
    lambda nt, uv: node(nt, "ShaderNodeFresnel", {"IOR": 1.45}).outputs[0],
    lambda nt, uv: node(nt, "ShaderNodeFresnel", {"IOR": 3.0}).outputs[0],
    lambda nt, uv: node(nt, "ShaderNodeLayerWeight", {"Blend": 0.3}).outputs["Fresnel"],
    lambda nt, uv: node(nt, "ShaderNodeLayerWeight", {"Blend": 0.3}).outputs["Facing"],
    lambda nt, uv: node(nt, "ShaderNodeLayerWeight", {"Blend": 0.8}).outputs["Facing"],
    lambda nt, uv: node(nt, "ShaderNodeLayerWeight", {"Blend": 0.5}).outputs["Facing"],
    lambda nt, uv: node(nt, "ShaderNodeNewGeometry").outputs["Normal"],
    lambda nt, uv: node(nt, "ShaderNodeNewGeometry").outputs["Position"],
    lambda nt, uv: node(nt, "ShaderNodeNewGeometry").outputs["True Normal"],
    lambda nt, uv: node(nt, "ShaderNodeNewGeometry").outputs["Incoming"],
    lambda nt, uv: node(nt, "ShaderNodeLightPath").outputs["Ray Length"],
    lambda nt, uv: node(nt, "ShaderNodeLightPath").outputs["Is Camera Ray"],
    _normal_map(),
    _normal_map(strength=0.5),
    _normal_map("WORLD"),
    lambda nt, uv: node(nt, "ShaderNodeFresnel", {"IOR": 1.5, "Normal": _normal_map()(nt, uv)}).outputs[0],
]


def test_shading_inputs_match_cycles(tmp_path):
    cycles, drt, res = render_tiles(CASES, N, tmp_path, shape="sphere")
    assert not res.warnings, res.warnings
    _compare(cycles, drt, len(CASES))


def test_backfacing_inputs_match_cycles(tmp_path):
    cases = [lambda nt, uv: node(nt, "ShaderNodeNewGeometry").outputs["Backfacing"],
             lambda nt, uv: node(nt, "ShaderNodeNewGeometry").outputs["Normal"],
             lambda nt, uv: node(nt, "ShaderNodeFresnel", {"IOR": 1.45}).outputs[0],
             _normal_map()]
    cycles, drt, res = render_tiles(cases, N, tmp_path, shape="back_plane")
    assert not res.warnings, res.warnings
    assert np.all(tile(drt, 0, N) > 0.7)  # backfacing = 1 → atan(1)·0.3 + 0.5
    _compare(cycles, drt, len(cases))


def test_normal_mapped_bsdfs_under_a_sun_match_cycles(tmp_path):
    """Direct light from a delta sun on normal-mapped Diffuse, Glossy and Principled surfaces:
    exact in both engines at one sample (no bounces), so pixels compare directly."""
    def bsdf(kind, **inputs):
        def case(nt, uv):
            nm = _normal_map()(nt, uv)
            n = node(nt, kind, dict(inputs, Normal=nm))
            if hasattr(n, "distribution"):
                n.distribution = "GGX"  # DRT's GGX is single-scatter
            return n.outputs[0]
        return case
    cases = [bsdf("ShaderNodeBsdfDiffuse", Color=(0.8, 0.6, 0.4, 1)),
             bsdf("ShaderNodeBsdfGlossy", Color=(0.8, 0.8, 0.8, 1), Roughness=0.4),
             bsdf("ShaderNodeBsdfPrincipled", **{"Base Color": (0.5, 0.7, 0.3, 1), "Roughness": 0.5}),
             lambda nt, uv: node(nt, "ShaderNodeBsdfDiffuse", {"Color": (0.8, 0.6, 0.4, 1)}).outputs[0],
             lambda nt, uv: node(nt, "ShaderNodeBsdfDiffuse", {"Color": (0.8, 0.6, 0.4, 1),
                                                               "Normal": _bump()(nt, uv)}).outputs[0],
             lambda nt, uv: node(nt, "ShaderNodeBsdfGlossy", {"Roughness": 0.3, "Normal": _bump()(nt, uv)},
                                 distribution="GGX").outputs[0]]
    cycles, drt, res = render_tiles(cases, 3, tmp_path, shader=True, sun=(3.0, (0.5, 0.3, 0.0)))
    assert not res.warnings, res.warnings
    for k in range(len(cases)):
        a, b = tile(cycles, k, 3), tile(drt, k, 3)
        assert a.mean() > 0.05
        # (the bumped highlight, 5: its edge pixels below move its mean by ~1 %)
        assert abs(b.mean() / a.mean() - 1) < (0.02 if k == 5 else 0.01), (k, a.mean(), b.mean())
        rel = np.abs(a - b).max(axis=-1) / a.max()
        if k == 2:
            # Principled: Cycles tilts the specular layer's normal back above the horizon where
            # the map tilts it too far (bump map correction) but not the diffuse one's; DRT has
            # one shading normal per material and keeps the diffuse one's (docs/materials.md),
            # which moves the specular layer's highlights where the map tilts the normal far
            assert np.quantile(rel, 0.95) < 0.08, (k, np.quantile(rel, 0.95))
        elif k == 5:
            # a glossy highlight on a bumped surface: Cycles's finite difference (float32, its own
            # step) and DRT's agree to ~0.3 % in the normal, which moves a highlight's edge pixels
            assert np.quantile(rel, 0.95) < 0.02 and rel.max() < 0.1, (k, np.quantile(rel, 0.95), rel.max())
        else:
            assert rel.max() < 0.02, (k, rel.max(), a.mean(), b.mean())


def test_light_path_ray_types_match_cycles(tmp_path):
    """Light Path flags and depths of rays after a mirror, a rough glossy reflection and a glass
    slab: an emitter whose strength encodes them in binary (camera 1, diffuse 2, glossy 4,
    singular 8, reflection 16, transmission 32, + 64·ray depth + 256·transmission depth) is seen
    directly, in a mirror, in a rough mirror and through glass; tile means against Cycles."""
    from addon.export import export_depsgraph
    from drt.render import render
    from drt.scene import scene_from_dict
    from node_parity import setup_scene

    sc = setup_scene(2)
    sc.cycles.max_bounces = 4
    sc.cycles.samples = 64
    sc.cycles.sample_clamp_indirect = 0.0  # Cycles's default 10 would clamp the encoded values
    sc.drt.max_bounces = 4
    sc.drt.samples = 64
    sc.cycles.filter_width = 1.5
    emit = bpy.data.materials.new("encoded")
    nt = emit.node_tree
    nt.nodes.clear()
    lp = nt.nodes.new("ShaderNodeLightPath")
    total = None
    for name, w in (("Is Camera Ray", 1), ("Is Diffuse Ray", 2), ("Is Glossy Ray", 4), ("Is Singular Ray", 8),
                    ("Is Reflection Ray", 16), ("Is Transmission Ray", 32), ("Ray Depth", 64),
                    ("Transmission Depth", 256)):
        term = node(nt, "ShaderNodeMath", {0: lp.outputs[name], 1: float(w)}, operation="MULTIPLY").outputs[0]
        total = term if total is None else node(nt, "ShaderNodeMath", {0: total, 1: term}).outputs[0]
    em = node(nt, "ShaderNodeEmission", {"Color": (1, 1, 1, 1), "Strength": total})
    nt.links.new(em.outputs[0], nt.nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])

    def plane(size, loc, mat, rotation=(0, 0, 0)):
        bpy.ops.mesh.primitive_plane_add(size=size, location=loc, rotation=rotation)
        bpy.context.object.data.materials.append(mat)

    def bsdf(kind, **inputs):
        m = bpy.data.materials.new(kind)
        m.node_tree.nodes.clear()
        b = node(m.node_tree, kind, inputs)
        if hasattr(b, "distribution"):
            b.distribution = "GGX"
        m.node_tree.links.new(b.outputs[0], m.node_tree.nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
        return m
    plane(12.0, (0, 0, 2), emit, rotation=(math.pi, 0, 0))   # above the camera, facing down
    plane(12.0, (0, 0, -1), emit)                             # below everything, facing up
    plane(1.0, (-0.5, 0.5, 0), bsdf("ShaderNodeBsdfGlossy", Roughness=0.0))    # top left: mirror
    plane(1.0, (0.5, 0.5, 0), bsdf("ShaderNodeBsdfGlossy", Roughness=0.15))    # top right: rough
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(-0.5, -0.5, 0), scale=(1, 1, 0.2))
    bpy.context.object.data.materials.append(bsdf("ShaderNodeBsdfGlass", IOR=1.5, Roughness=0.0))
    # bottom right: the lower emitter seen directly
    path = str(tmp_path / "lp.exr")
    sc.render.filepath = path
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(path)
    h = w = 2 * 16
    cycles = np.array(img.pixels[:], dtype=np.float64).reshape(h, w, 4)[::-1, :, :3]
    bpy.data.images.remove(img)
    res = export_depsgraph(bpy.context.evaluated_depsgraph_get())
    assert not res.warnings, res.warnings
    drt = np.asarray(render(scene_from_dict(res.header, res.arrays), threads=1).combined, np.float64)[..., :3]
    inner = (slice(3, 13), slice(3, 13))  # away from tile edges (filter footprint)
    for k, expected in enumerate([0.8 * 92.0, None, None, 1.0]):  # the mirror reflects 0.8
        a, b = tile(cycles, k, 2)[inner].mean(), tile(drt, k, 2)[inner].mean()
        if expected is not None:
            assert abs(a - expected) < 0.01 * expected and abs(b - expected) < 0.01 * expected, (k, a, b)
        assert abs(b / a - 1) < 0.02, (k, a, b)


def test_object_info_matches_cycles(tmp_path):
    """Object Info's Random (Cycles's name hash; instances: Blender's random id), Location,
    Color, Alpha, Object Index and Material Index on several objects and linked duplicates."""
    def case(output, scale=1.0):
        def build(nt, uv):
            v = node(nt, "ShaderNodeObjectInfo").outputs[output]
            return node(nt, "ShaderNodeVectorMath", {0: v, 3: scale}, operation="SCALE").outputs[0] \
                if output in ("Location", "Color") else \
                node(nt, "ShaderNodeMath", {0: v, 1: scale}, operation="MULTIPLY").outputs[0]
        return build
    cases = [case("Random"), case("Location", 0.5), case("Color"), case("Alpha"), case("Object Index", 0.1),
             case("Material Index", 0.1), case("Random"), case("Random", 3.0)]
    import bpy as _bpy

    orig_add = _bpy.ops.mesh.primitive_plane_add
    count = {"n": 0}

    def add_with_props(**kw):  # give every tile object its own colour / pass index
        orig_add(**kw)
        ob = _bpy.context.object
        k = count["n"]
        count["n"] += 1
        ob.name = f"Tile object {k} ünïcode"
        ob.color = (0.1 * k, 0.5, 1.0 - 0.1 * k, 0.25 + 0.05 * k)
        ob.pass_index = k + 1
    _bpy.ops.mesh.primitive_plane_add = add_with_props
    try:
        cycles, drt, res = render_tiles(cases, 3, tmp_path)
    finally:
        _bpy.ops.mesh.primitive_plane_add = orig_add
    assert not res.warnings, res.warnings
    for k in range(len(cases)):
        assert np.abs(tile(cycles, k, 3) - tile(drt, k, 3)).max() < 2e-3, k


def test_object_info_random_of_instances_matches_cycles(tmp_path):
    """Collection instances take Blender's per-instance random id (not the name hash)."""
    from addon.export import export_depsgraph
    from drt.render import render
    from drt.scene import scene_from_dict
    from node_parity import _material, setup_scene

    sc = setup_scene(2)
    mat = _material("rnd", lambda nt, uv: node(nt, "ShaderNodeObjectInfo").outputs["Random"])
    coll = bpy.data.collections.new("src")
    bpy.ops.mesh.primitive_plane_add(size=1.0)
    ob = bpy.context.object
    ob.data.materials.append(mat)
    for c in ob.users_collection:
        c.objects.unlink(ob)
    coll.objects.link(ob)
    for k, loc in enumerate([(-0.5, 0.5, 0), (0.5, 0.5, 0), (-0.5, -0.5, 0), (0.5, -0.5, 0)]):
        e = bpy.data.objects.new(f"inst{k}", None)
        e.instance_type = "COLLECTION"
        e.instance_collection = coll
        e.location = loc
        sc.collection.objects.link(e)
    path = str(tmp_path / "inst.exr")
    sc.render.filepath = path
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(path)
    cycles = np.array(img.pixels[:], dtype=np.float64).reshape(32, 32, 4)[::-1, :, :3]
    bpy.data.images.remove(img)
    res = export_depsgraph(bpy.context.evaluated_depsgraph_get())
    drt = np.asarray(render(scene_from_dict(res.header, res.arrays), threads=1).combined, np.float64)[..., :3]
    values = [tile(cycles, k, 2).mean() for k in range(4)]
    assert len(set(np.round(values, 4))) == 4  # four different randoms
    for k in range(4):
        assert np.abs(tile(cycles, k, 2) - tile(drt, k, 2)).max() < 2e-3, k


def _height(nt, uv):
    """A smooth height field over the UVs: sin(12u)·cos(9v)."""
    sep = node(nt, "ShaderNodeSeparateXYZ", {0: uv})
    a = node(nt, "ShaderNodeMath", {0: sep.outputs[0], 1: 12.0}, operation="MULTIPLY")
    b = node(nt, "ShaderNodeMath", {0: sep.outputs[1], 1: 9.0}, operation="MULTIPLY")
    sa = node(nt, "ShaderNodeMath", {0: a.outputs[0]}, operation="SINE")
    cb = node(nt, "ShaderNodeMath", {0: b.outputs[0]}, operation="COSINE")
    return node(nt, "ShaderNodeMath", {0: sa.outputs[0], 1: cb.outputs[0]}, operation="MULTIPLY").outputs[0]


def _bump(strength=1.0, distance=0.05, invert=False, normal=None):
    def case(nt, uv):
        inputs = {"Height": _height(nt, uv), "Strength": strength, "Distance": distance}
        if normal is not None:
            inputs["Normal"] = normal(nt, uv)
        return node(nt, "ShaderNodeBump", inputs, invert=invert).outputs[0]
    return case


BUMP_CASES = [_bump(), _bump(0.5), _bump(distance=0.2, invert=True), _bump(normal=_normal_map()),
              lambda nt, uv: node(nt, "ShaderNodeFresnel", {"IOR": 1.5, "Normal": _bump()(nt, uv)}).outputs[0]]


@pytest.mark.parametrize("shape", ["plane", "sphere"])
def test_bump_matches_cycles(tmp_path, shape):
    """The Bump node's normal (Cycles differentiates the height over ray differentials, DRT over
    a small step along the triangle's edges: the same derivative of a smooth height field)."""
    cycles, drt, res = render_tiles(BUMP_CASES, 3, tmp_path, shape=shape)
    assert not res.warnings, res.warnings
    for k in range(len(BUMP_CASES)):
        diff = np.abs(tile(cycles, k, 3) - tile(drt, k, 3)).max(axis=-1)
        assert int((diff > 3e-3).sum()) <= 6, (k, int((diff > 3e-3).sum()), float(diff.max()))


def _interior(img, tol=1e-6):
    """Pixels away from the image border and from any step of ``img`` (a noise-free render):
    Cycles's samples spread over about a pixel even with a 0.01-pixel filter (measured: edge
    pixels blend ~10 % of the neighbour), so only these compare pixel by pixel."""
    flat = np.zeros(img.shape[:2], bool)
    flat[1:-1, 1:-1] = True
    for axis in (0, 1):
        step = np.abs(np.diff(img, axis=axis)).max(axis=-1) > tol
        if axis == 0:
            flat[1:] &= ~step
            flat[:-1] &= ~step
        else:
            flat[:, 1:] &= ~step
            flat[:, :-1] &= ~step
    return flat


def test_textured_alpha_cuts_out_like_cycles(tmp_path):
    """A Principled BSDF whose Alpha is a checker (a cut-out card) in front of an emitter: the
    camera sees the card's emission where alpha is 1 and the emitter where it is 0."""
    from addon.export import export_depsgraph
    from drt.render import render
    from drt.scene import scene_from_dict
    from node_parity import setup_scene

    sc = setup_scene(2)
    sc.cycles.samples = sc.drt.samples = 4
    mat = bpy.data.materials.new("card")
    nt = mat.node_tree
    nt.nodes.clear()
    uv = nt.nodes.new("ShaderNodeTexCoord").outputs["UV"]
    chk = node(nt, "ShaderNodeTexChecker", {"Vector": uv, "Scale": 4.0, "Color1": (1, 1, 1, 1),
                                            "Color2": (0, 0, 0, 1)})
    bsdf = node(nt, "ShaderNodeBsdfPrincipled", {"Base Color": (0, 0, 0, 1), "Specular IOR Level": 0.0,
                                                 "Emission Color": (1.0, 0.5, 0.2, 1), "Emission Strength": 1.0,
                                                 "Alpha": chk.outputs["Fac"]})
    nt.links.new(bsdf.outputs[0], nt.nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
    back = bpy.data.materials.new("back")
    back.node_tree.nodes.clear()
    em = node(back.node_tree, "ShaderNodeEmission", {"Color": (0.2, 0.4, 1.0, 1), "Strength": 0.5})
    back.node_tree.links.new(em.outputs[0], back.node_tree.nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
    bpy.ops.mesh.primitive_plane_add(size=2.0, location=(0, 0, 0))
    bpy.context.object.data.materials.append(mat)
    bpy.ops.mesh.primitive_plane_add(size=4.0, location=(0, 0, -0.5))
    bpy.context.object.data.materials.append(back)
    path = str(tmp_path / "alpha.exr")
    sc.render.filepath = path
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(path)
    cycles = np.array(img.pixels[:], dtype=np.float64).reshape(32, 32, 4)[::-1, :, :3]
    bpy.data.images.remove(img)
    res = export_depsgraph(bpy.context.evaluated_depsgraph_get())
    assert not res.warnings, res.warnings
    drt = np.asarray(render(scene_from_dict(res.header, res.arrays), threads=1).combined, np.float64)[..., :3]
    card = np.abs(cycles - [1.0, 0.5, 0.2]).max(axis=-1) < 1e-3
    through = np.abs(cycles - [0.1, 0.2, 0.5]).max(axis=-1) < 1e-3
    assert card.sum() > 300 and through.sum() > 300  # both kinds of pixel are there
    flat = _interior(drt)
    assert flat.sum() > 400
    diff = np.abs(cycles - drt).max(axis=-1)
    assert diff[flat].max() < 1e-3, diff[flat].max()


def test_texture_coordinate_outputs_match_cycles(tmp_path):
    """Texture Coordinate's Reflection, Camera, Window and Object-of-another-object outputs
    (an empty, rotated and scaled), on spheres under the orthographic camera."""
    empty = {}

    def other_object(nt, uv):
        if "ob" not in empty:
            e = bpy.data.objects.new("controller", None)
            e.location = (0.3, -0.2, 0.1)
            e.rotation_euler = (0.3, 0.5, 0.7)
            e.scale = (2.0, 0.5, 1.5)
            bpy.context.scene.collection.objects.link(e)
            bpy.context.view_layer.update()
            empty["ob"] = e
        tc = nt.nodes.new("ShaderNodeTexCoord")
        tc.object = empty["ob"]
        return tc.outputs["Object"]
    cases = [(lambda name: lambda nt, uv: nt.nodes.new("ShaderNodeTexCoord").outputs[name])(n)
             for n in ("Reflection", "Camera", "Window")] + [other_object]
    cycles, drt, res = render_tiles(cases, 2, tmp_path, shape="sphere")
    assert not res.warnings, res.warnings
    _compare(cycles, drt, len(cases), n=2)


def test_normal_map_on_ngons_matches_cycles(tmp_path):
    """Blender computes tangents only for triangles and quads: an n-gon mesh gets them from its
    loop triangles (Cycles's tangents on the same faces)."""
    cases = [_normal_map(), _normal_map(strength=0.5)]
    cycles, drt, res = render_tiles(cases, 2, tmp_path, shape="ngon")
    assert not res.warnings, res.warnings
    assert np.abs(tile(drt, 0, 2) - tile(drt, 3, 2)).max() > 0.05  # the map bends the normal
    _compare(cycles, drt, len(cases), n=2, outliers=10)


def _diffuse_material(name, color):
    mat = bpy.data.materials.new(name)
    mat.node_tree.nodes.clear()
    d = node(mat.node_tree, "ShaderNodeBsdfDiffuse", {"Color": color})
    mat.node_tree.links.new(d.outputs[0], mat.node_tree.nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
    return mat


def _shadow_scene(make_card_material):
    """A white ground lit by a delta sun at 30°, a card above it with the material
    ``make_card_material()`` builds, seen from above (orthographic, no indirect light): the
    ground shows the card's shadow."""
    from node_parity import setup_scene

    sc = setup_scene(2)
    card_material = make_card_material()
    sc.cycles.samples = sc.drt.samples = 16
    ground = _diffuse_material("ground", (0.8, 0.8, 0.8, 1))
    bpy.ops.mesh.primitive_plane_add(size=4.0, location=(0, 0, -0.5))
    bpy.context.object.data.materials.append(ground)
    bpy.ops.mesh.primitive_plane_add(size=1.2, location=(-0.2, 0.1, 0.2))
    bpy.context.object.data.materials.append(card_material)
    add_sun(sc, 3.0, (0.0, 0.5, 0.0))
    return sc


def _render_both(sc, tmp_path, tag):
    from addon.export import export_depsgraph
    from drt.render import render
    from drt.scene import scene_from_dict

    path = str(tmp_path / f"{tag}.exr")
    sc.render.filepath = path
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(path)
    cycles = np.array(img.pixels[:], dtype=np.float64).reshape(32, 32, 4)[::-1, :, :3]
    bpy.data.images.remove(img)
    res = export_depsgraph(bpy.context.evaluated_depsgraph_get())
    assert not res.warnings, res.warnings
    drt = np.asarray(render(scene_from_dict(res.header, res.arrays), threads=1).combined, np.float64)[..., :3]
    return cycles, drt


def test_alpha_cut_out_casts_a_cut_out_shadow_like_cycles(tmp_path):
    """Transparent shadows: a checker-alpha card's shadow on the ground is a checker too (the
    shadow rays pass the transparent squares), and the camera sees the ground through them."""
    def card():
        mat = bpy.data.materials.new("card")
        nt = mat.node_tree
        nt.nodes.clear()
        uv = nt.nodes.new("ShaderNodeTexCoord").outputs["UV"]
        chk = node(nt, "ShaderNodeTexChecker", {"Vector": uv, "Scale": 3.0, "Color1": (1, 1, 1, 1),
                                                "Color2": (0, 0, 0, 1)})
        # (a Diffuse BSDF: DRT's Principled specular layer is still the simplified one)
        dif = node(nt, "ShaderNodeBsdfDiffuse", {"Color": (0.2, 0.5, 0.9, 1)})
        tr = node(nt, "ShaderNodeBsdfTransparent")
        mix = node(nt, "ShaderNodeMixShader", {0: chk.outputs["Fac"], 1: tr.outputs[0], 2: dif.outputs[0]})
        nt.links.new(mix.outputs[0], nt.nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
        return mat
    cycles, drt = _render_both(_shadow_scene(card), tmp_path, "cutout")
    lit = cycles[..., 0] > 0.5
    assert 50 < (~lit).sum() < 900  # a partial shadow: some ground is lit through the squares
    assert abs(drt.mean() / cycles.mean() - 1) < 0.01, (drt.mean(), cycles.mean())
    flat = _interior(drt, 1e-3)
    assert flat.sum() > 300
    # (a few samples of Cycles's land farther than a pixel: one of 16 shows as 0.04)
    assert (np.abs(drt - cycles).max(axis=-1)[flat] > 2e-3).mean() < 0.02


def test_film_exposure_scales_like_cycles(tmp_path):
    """Cycles's Film > Exposure 2.5 (transparent film): both engines scale the radiance, not
    the alpha; DRT's image against Cycles's pixel by pixel."""
    from addon.export import export_depsgraph
    from drt.render import render
    from drt.scene import scene_from_dict

    sc = _shadow_scene(lambda: _diffuse_material("card", (0.2, 0.5, 0.9, 1)))
    sc.cycles.film_exposure = 2.5
    sc.render.film_transparent = True
    path = str(tmp_path / "exposure.exr")
    sc.render.filepath = path
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(path)
    cycles = np.array(img.pixels[:], dtype=np.float64).reshape(32, 32, 4)[::-1]
    bpy.data.images.remove(img)
    res = export_depsgraph(bpy.context.evaluated_depsgraph_get())
    assert res.header["render"]["exposure"] == 2.5
    drt = np.asarray(render(scene_from_dict(res.header, res.arrays), threads=1).combined, np.float64)
    assert cycles[..., :3].max() > 1.5  # the lit ground: 2.5 × 0.67
    np.testing.assert_array_equal(drt[..., 3], cycles[..., 3])
    assert abs(drt[..., :3].mean() / cycles[..., :3].mean() - 1) < 0.01
    flat = _interior(drt[..., :3], 1e-3)
    assert (np.abs(drt - cycles)[..., :3].max(axis=-1)[flat] > 5e-3).mean() < 0.02


@pytest.mark.parametrize("hidden", [("visible_camera",), ("visible_shadow",),
                                    ("visible_camera", "visible_diffuse")])
def test_ray_visibility_matches_cycles(tmp_path, hidden):
    """Object > Visibility: a card hidden from camera rays still casts its shadow; one hidden
    from shadow rays is seen and casts none; pixel by pixel against Cycles."""
    def card():
        return _diffuse_material("card", (0.2, 0.5, 0.9, 1))
    sc = _shadow_scene(card)
    ob = next(o for o in sc.objects if o.type == "MESH" and o.active_material
              and o.active_material.name.startswith("card"))
    for attr in hidden:
        setattr(ob, attr, False)
    cycles, drt = _render_both(sc, tmp_path, "visibility_" + "_".join(hidden))
    assert abs(drt.mean() / cycles.mean() - 1) < 0.01, (drt.mean(), cycles.mean())
    flat = _interior(drt, 1e-3)
    assert flat.sum() > 300
    assert (np.abs(drt - cycles).max(axis=-1)[flat] > 2e-3).mean() < 0.02
    blue = (cycles[..., 2] > 2 * cycles[..., 0] + 0.02).sum()  # the card's blue pixels
    assert (blue == 0) == ("visible_camera" in hidden), blue


@pytest.mark.parametrize("mask, half, film_transparent", [
    ("object", False, False), ("object", True, True), ("collection", False, True), ("indirect_only", False, True)])
def test_holdout_object_matches_cycles(tmp_path, mask, half, film_transparent):
    """Object > Visibility > Mask > Holdout (or the card's collection set to Holdout): the card
    is a hole in the image (alpha 0, no light; a 50 % Transparent card: alpha 0.5 and the ground
    behind at half) yet casts its shadow; an Indirect Only collection hides it from the camera
    only. RGBA pixel by pixel against Cycles."""
    def card():
        if not half:
            return _diffuse_material("card", (0.2, 0.5, 0.9, 1))
        mat = bpy.data.materials.new("card")
        nt = mat.node_tree
        nt.nodes.clear()
        t = node(nt, "ShaderNodeBsdfTransparent")
        d = node(nt, "ShaderNodeBsdfDiffuse", {"Color": (0.2, 0.5, 0.9, 1)})
        mix = node(nt, "ShaderNodeMixShader", {0: 0.5, 1: t.outputs[0], 2: d.outputs[0]})
        nt.links.new(mix.outputs[0], nt.nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
        return mat
    sc = _shadow_scene(card)
    sc.render.film_transparent = film_transparent
    ob = next(o for o in sc.objects if o.active_material and o.active_material.name.startswith("card"))
    if mask == "object":
        ob.is_holdout = True
    else:
        col = bpy.data.collections.new("cards")
        sc.collection.children.link(col)
        for c in list(ob.users_collection):
            c.objects.unlink(ob)
        col.objects.link(ob)
        layer = bpy.context.view_layer.layer_collection.children["cards"]
        setattr(layer, "holdout" if mask == "collection" else "indirect_only", True)
    cycles, drt = render_rgba_both(sc, tmp_path / f"holdout_{mask}.exr")
    hole = np.abs(cycles[..., 3] - (0.5 if half else 0.0)) < 1e-3  # the card, as Cycles cuts it
    assert (hole.sum() > 200) == (mask != "indirect_only"), hole.sum()
    flat = _interior(cycles, 1e-3)
    assert flat.sum() > 300
    assert (np.abs(drt - cycles).max(axis=-1)[flat] > 2e-3).mean() < 0.02
    assert abs(drt[..., 3].mean() - cycles[..., 3].mean()) < 0.01, (drt[..., 3].mean(), cycles[..., 3].mean())
    assert abs(drt[..., :3].mean() / cycles[..., :3].mean() - 1) < 0.01


def test_is_shadow_ray_trick_removes_a_shadow_like_cycles(tmp_path):
    """Mix(Diffuse, Transparent, Is Shadow Ray): the card is seen but casts no shadow."""
    def card():
        mat = bpy.data.materials.new("card")
        nt = mat.node_tree
        nt.nodes.clear()
        lp = nt.nodes.new("ShaderNodeLightPath")
        dif = node(nt, "ShaderNodeBsdfDiffuse", {"Color": (0.9, 0.3, 0.1, 1)})
        tr = node(nt, "ShaderNodeBsdfTransparent")
        mix = node(nt, "ShaderNodeMixShader", {0: lp.outputs["Is Shadow Ray"], 1: dif.outputs[0], 2: tr.outputs[0]})
        nt.links.new(mix.outputs[0], nt.nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
        return mat
    cycles, drt = _render_both(_shadow_scene(card), tmp_path, "noshadow")
    ground = np.abs(cycles - cycles[0, -1]).max(axis=-1) < 1e-3  # pixels like a lit ground corner
    assert ground.mean() > 0.5  # no shadow anywhere: the ground is uniformly lit
    assert abs(drt.mean() / cycles.mean() - 1) < 0.01, (drt.mean(), cycles.mean())
    flat = _interior(drt, 1e-3)
    assert (np.abs(drt - cycles).max(axis=-1)[flat] > 2e-3).mean() < 0.02


def test_half_transparent_card_under_an_area_light_matches_cycles(tmp_path):
    """A 50 % transparent card between an area light and the ground: light reaches the ground
    both by next-event estimation (shadow rays pass the card at half strength) and by BSDF rays
    passing it; the MIS state of the ground vertex is kept across the pass, so neither is
    counted twice. Image means against Cycles."""
    from node_parity import setup_scene

    sc = setup_scene(2)
    sc.cycles.samples = sc.drt.samples = 64
    sc.cycles.max_bounces = sc.drt.max_bounces = 2
    ground = _diffuse_material("ground", (0.8, 0.8, 0.8, 1))
    card = bpy.data.materials.new("card")
    card.node_tree.nodes.clear()
    dif = node(card.node_tree, "ShaderNodeBsdfDiffuse", {"Color": (0.9, 0.2, 0.1, 1)})
    tr = node(card.node_tree, "ShaderNodeBsdfTransparent", {"Color": (0.6, 0.9, 1.0, 1)})
    mix = node(card.node_tree, "ShaderNodeMixShader", {0: 0.5, 1: dif.outputs[0], 2: tr.outputs[0]})
    card.node_tree.links.new(mix.outputs[0], card.node_tree.nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
    bpy.ops.mesh.primitive_plane_add(size=4.0, location=(0, 0, -0.5))
    bpy.context.object.data.materials.append(ground)
    bpy.ops.mesh.primitive_plane_add(size=1.0, location=(0.3, 0.0, 0.0))
    bpy.context.object.data.materials.append(card)
    light = bpy.data.lights.new("area", "AREA")
    light.energy, light.size = 30.0, 0.8
    ob = bpy.data.objects.new("area", light)
    ob.location = (0.5, 0.0, 0.6)
    sc.collection.objects.link(ob)
    cycles, drt = _render_both(sc, tmp_path, "halfcard")
    under = np.zeros((32, 32), bool)
    under[8:24, 16:28] = True  # the ground under the card (and the card itself)
    for mask in (under, ~under):
        a, b = cycles[mask].mean(), drt[mask].mean()
        assert abs(b / a - 1) < 0.02, (a, b)


@pytest.mark.slow
def test_cutout_scene_matches_cycles(tmp_path):
    """blend_scenes/cutout (alpha-cut leaves with their shadows, a Brick-cut fence, a normal
    mapped sphere, a Voronoi-bumped box) at 64 spp: channel means within 1 % of Cycles's and
    ≥ 95 % of 16×16 blocks within 3 % (measured: 0.1 %, 100 %)."""
    import os
    import sys

    from test_addon import ensure_registered

    repo = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    sys.path.insert(0, os.path.join(repo, "scripts"))
    from compare_cycles import compare, render

    ensure_registered()
    bpy.ops.wm.open_mainfile(filepath=os.path.join(repo, "blend_scenes", "cutout.blend"))
    scene = bpy.context.scene
    cyc = render(scene, "CYCLES", 64, str(tmp_path / "cycles.exr"))
    drt = render(scene, "DRT", 64, str(tmp_path / "drt.exr"))
    ratio, blocks = compare(drt, cyc)
    assert np.all(np.abs(ratio - 1.0) < 0.01), ratio
    assert blocks >= 0.95, blocks


def _pointiness_material():
    from node_parity import squash

    mat = bpy.data.materials.new("pointiness")
    nt = mat.node_tree
    nt.nodes.clear()
    g = nt.nodes.new("ShaderNodeNewGeometry").outputs["Pointiness"]
    # spread the values (~0.3–0.7) over the squash's range so that errors show
    spread = node(nt, "ShaderNodeMath", {0: g, 1: 6.0, 2: -3.0}, operation="MULTIPLY_ADD")
    em = node(nt, "ShaderNodeEmission", {"Color": squash(nt, spread.outputs[0])})
    nt.links.new(em.outputs[0], nt.nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
    return mat


def test_pointiness_matches_cycles(tmp_path):
    """The Geometry node's Pointiness on meshes with convex and concave vertices, a loose part
    and duplicated vertices along split edges (welded as Cycles welds them), subdivided and
    smooth-shaded: pixel by pixel against Cycles."""
    from node_parity import render_rgba_both, setup_scene

    sc = setup_scene(4)
    mat = _pointiness_material()
    bpy.ops.mesh.primitive_monkey_add(size=1.1, location=(-0.45, 0.0, -1.0), rotation=(0.6, 0.2, 0.3))
    subd = bpy.context.object.modifiers.new("subd", "SUBSURF")
    subd.levels = subd.render_levels = 1  # (the harness exports the viewport's levels)
    bpy.ops.object.shade_smooth()
    bpy.ops.mesh.primitive_cube_add(size=0.7, location=(0.55, 0.2, -1.0), rotation=(0.5, 0.4, 0.1))
    bpy.context.object.modifiers.new("split", "EDGE_SPLIT")  # duplicated vertices on every edge
    bpy.ops.mesh.primitive_torus_add(major_radius=0.3, minor_radius=0.1, location=(0.5, -0.6, -1.0),
                                     rotation=(0.9, 0.0, 0.0))
    for o in bpy.context.scene.objects:
        if o.type == "MESH":
            o.data.materials.append(mat)
    cycles, drt = render_rgba_both(sc, tmp_path / "pointiness.exr")
    covered = cycles[..., 0] > 0.01  # (the world is black)
    assert covered.mean() > 0.15
    err = np.abs(cycles[..., :3] - drt[..., :3]).max(axis=-1)
    assert np.percentile(err, 99) < 2e-3, np.percentile(err, 99)
    assert np.ptp(cycles[covered][:, 0]) > 0.2  # the values vary


def _geometry_output_material(name, output):
    from node_parity import squash

    mat = bpy.data.materials.new(name)
    nt = mat.node_tree
    nt.nodes.clear()
    g = nt.nodes.new("ShaderNodeNewGeometry").outputs[output]
    em = node(nt, "ShaderNodeEmission", {"Color": squash(nt, g)})
    nt.links.new(em.outputs[0], nt.nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
    return mat


def test_random_per_island_and_parametric_match_cycles(tmp_path):
    """Random Per Island on meshes of many islands (Suzanne's head and eyes, an array of
    unmerged cubes in one object, joined in Cycles's order) and Parametric on n-gon caps (whose
    pixel centres stay off the triangles' shared edges, where the two engines may pick either
    triangle), pixel by pixel against Cycles."""
    from node_parity import render_rgba_both, render_tiles, setup_scene

    sc = setup_scene(4)
    islands = _geometry_output_material("islands", "Random Per Island")
    bpy.ops.mesh.primitive_monkey_add(size=0.9, location=(-0.5, 0.3, -1.0), rotation=(0.3, 0.0, 0.2))
    bpy.context.object.data.materials.append(islands)
    bpy.ops.mesh.primitive_cube_add(size=0.2, location=(-0.1, -0.6, -1.0), rotation=(0.4, 0.3, 0.0))
    array = bpy.context.object.modifiers.new("row", "ARRAY")
    array.count, array.relative_offset_displace = 5, (1.4, 0.3, 0.0)
    bpy.context.object.data.materials.append(islands)
    cycles, drt = render_rgba_both(sc, tmp_path / "islands.exr")
    err = np.abs(cycles[..., :3] - drt[..., :3]).max(axis=-1)
    lit = cycles[..., 0] > 0.01
    assert np.percentile(err[lit], 97) < 1e-4, np.percentile(err[lit], 97)  # (silhouettes: jitter)
    assert len(np.unique(np.round(cycles[lit][:, 0], 3))) >= 6  # islands differ

    cycles, drt, res = render_tiles([lambda nt, uv: nt.nodes.new("ShaderNodeNewGeometry").outputs["Parametric"]],
                                    1, tmp_path, "parametric", shape="ngon")
    assert not res.warnings
    cap = cycles[..., 0] > 0.01
    assert np.percentile(np.abs(cycles - drt).max(axis=-1)[cap], 99) < 2e-3
    assert cycles[cap][:, 0].std() > 0.05


def _mirrored_spheres(mat):
    """Four turned smooth spheres with ``mat``, scaled (−1, 1, 1), (1, 1, 1), (1, −1, −1) (a
    rotation) and (−1, −1, −1): two mirror, two do not."""
    for loc, scale in (((-0.5, 0.5, -1), (-1, 1, 1)), ((0.5, 0.5, -1), (1, 1, 1)),
                       ((-0.5, -0.5, -1), (1, -1, -1)), ((0.5, -0.5, -1), (-1, -1, -1))):
        bpy.ops.mesh.primitive_uv_sphere_add(radius=0.4, location=loc, segments=32, ring_count=16)
        bpy.ops.object.shade_smooth()
        obj = bpy.context.object
        obj.scale, obj.rotation_euler = scale, (0.4, 0.3, 0.2)
        obj.data.materials.append(mat)


def _quadrant_means(img):
    return [img[r * 32:(r + 1) * 32, c * 32:(c + 1) * 32, :3].mean() for r in (0, 1) for c in (0, 1)]


@pytest.mark.parametrize("case", ["normal map", "backfacing", "glass"])
def test_mirrored_objects_match_cycles(tmp_path, case):
    """Objects whose matrix mirrors (negative determinant) turn their triangles inside out in
    world space; DRT swaps two corners of each so that their true normal faces out as Cycles's
    does, and flips the tangent sign the Normal Map's world-space bitangent needs. Before, such
    objects were backfacing everywhere: a normal-mapped sphere rendered black, and glass
    refracted as if every ray were leaving it. Per quadrant (one sphere each) against Cycles."""
    from node_parity import add_sun, render_rgba_both, setup_scene

    sc = setup_scene(4)
    sc.cycles.samples = sc.drt.samples = 64
    mat = bpy.data.materials.new(case)
    nt = mat.node_tree
    bsdf = nt.nodes["Principled BSDF"]
    if case == "normal map":
        bsdf.inputs["Roughness"].default_value = 0.4
        nm = node(nt, "ShaderNodeNormalMap", {"Color": (0.7, 0.4, 0.9, 1.0)})
        nt.links.new(nm.outputs[0], bsdf.inputs["Normal"])
        add_sun(sc, 3.0, (0.5, 0.3, 0.2))
    elif case == "backfacing":
        em = node(nt, "ShaderNodeEmission", {"Strength": 1.0})
        mix = node(nt, "ShaderNodeMix", {"Factor": nt.nodes.new("ShaderNodeNewGeometry").outputs["Backfacing"],
                                        "A": (0.2, 0.8, 0.3, 1), "B": (0.9, 0.1, 0.1, 1)}, data_type="RGBA")
        nt.links.new(mix.outputs["Result"], em.inputs["Color"])
        nt.links.new(em.outputs[0], nt.nodes["Material Output"].inputs["Surface"])
    else:  # glass over a lit checker floor: the refraction shows which way the ray goes
        bsdf.inputs["Transmission Weight"].default_value = 1.0
        bsdf.inputs["Roughness"].default_value = 0.0
        sc.cycles.max_bounces = sc.drt.max_bounces = 8
        sc.cycles.transmission_bounces = sc.drt.transmission_bounces = 8
        floor = bpy.data.materials.new("floor")
        floor.node_tree.nodes.clear()
        ck = node(floor.node_tree, "ShaderNodeTexChecker", {"Scale": 8.0})
        fem = node(floor.node_tree, "ShaderNodeEmission", {"Color": ck.outputs["Color"]})
        floor.node_tree.links.new(fem.outputs[0], floor.node_tree.nodes.new("ShaderNodeOutputMaterial").inputs[0])
        bpy.ops.mesh.primitive_plane_add(size=2.0, location=(0, 0, -2.0))
        bpy.context.object.data.materials.append(floor)
    sc.world.node_tree.nodes["Background"].inputs[1].default_value = 0.3
    _mirrored_spheres(mat)
    cycles, drt = render_rgba_both(sc, tmp_path / "mirrored.exr")
    c, d = _quadrant_means(cycles), _quadrant_means(drt)
    print(case, np.round(c, 4), np.round(d, 4))
    np.testing.assert_allclose(d, c, rtol=0.03)
    if case == "glass":
        err = np.abs(cycles[..., :3] - drt[..., :3]).max(axis=-1)
        assert np.percentile(err, 90) < 0.05  # the refracted checker, pixel by pixel


def test_tangents_go_to_world_space_by_the_normal_transform_keeping_their_length():
    """`geometry._transform_tangents` (a row kernel over threads) against the formula in numpy
    (inverse transpose, then each vector rescaled to its object-space length), for a sheared,
    mirrored, non-uniformly scaled matrix; zero tangents stay zero; any split of the rows over
    threads gives the same bytes."""
    from drt.geometry import _transform_tangents
    from drt.kernels.row_chunks import preparation_threads

    rng = np.random.default_rng(11)
    t = rng.normal(size=(150_000, 3, 3)).astype(np.float32)
    t[:5] = 0.0
    m = np.eye(4)
    m[:3, :3] = np.array([[2.0, 0.3, 0.0], [0.0, -0.5, 0.2], [0.1, 0.0, 4.0]])
    m[:3, 3] = (1.0, -2.0, 3.0)
    n_t = np.linalg.inv(m[:3, :3]).T
    w = t.astype(np.float64) @ n_t.T
    want = w * (np.linalg.norm(t.astype(np.float64), axis=-1, keepdims=True)
                / np.maximum(np.linalg.norm(w, axis=-1, keepdims=True), 1e-300))
    with preparation_threads(1):
        one = _transform_tangents(t, m)
    with preparation_threads(2):
        two = _transform_tangents(t, m)
    assert one.dtype == np.float32 and one.shape == t.shape
    np.testing.assert_allclose(one, want, rtol=2e-6, atol=1e-7)
    assert not one[:5].any()
    assert one.tobytes() == two.tobytes()
