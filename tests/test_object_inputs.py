"""Object-space shading inputs and displacement (docs/materials.md, "Object spaces and
displacement"): Texture Coordinate Normal, Normal Map in Object / Blender Object space, the
Displacement and Vector Displacement nodes and the Material Output's Displacement rendered as
bump (Cycles's "Bump Only"), and the Environment Texture inside a surface material; DRT
against Cycles pixel by pixel on emission-only tiles of rotated (some also non-uniformly
scaled) smooth spheres (tests/node_parity.py)."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from node_parity import node, render_tiles, tile  # noqa: E402
from test_shading_inputs import _compare, _height, _normal_color  # noqa: E402


def _scaled(case, scale=(1.3, 0.8, 1.0)):
    """The case on a non-uniformly scaled sphere (object and world normals then differ by
    more than a rotation)."""
    def setup(mesh):
        bpy.context.object.scale = scale
    case.setup = setup
    return case


def _output(nt):
    return next(n for n in nt.nodes if n.bl_idname == "ShaderNodeOutputMaterial")


def _displaced(disp, show="Normal"):
    """Geometry ``show`` (Normal, or Fresnel on the default normal) of a material whose output's
    Displacement is ``disp(nt, uv)``: the bump from displacement changes the N it reads."""
    def case(nt, uv):
        nt.links.new(disp(nt, uv), _output(nt).inputs["Displacement"])
        if show == "Fresnel":
            return node(nt, "ShaderNodeFresnel", {"IOR": 1.5}).outputs[0]
        return node(nt, "ShaderNodeNewGeometry").outputs["Normal"]
    return case


def _displacement(space="WORLD", scale=0.05, midlevel=0.0):
    def disp(nt, uv):
        return node(nt, "ShaderNodeDisplacement", {"Height": _height(nt, uv), "Midlevel": midlevel,
                                                   "Scale": scale}, space=space).outputs[0]
    return disp


def _vector_displacement(space="WORLD"):
    def disp(nt, uv):
        h = _height(nt, uv)
        vec = node(nt, "ShaderNodeCombineXYZ", {0: h, 1: 0.3, 2: h}).outputs[0]
        return node(nt, "ShaderNodeVectorDisplacement", {"Vector": vec, "Midlevel": 0.1, "Scale": 0.04},
                    space=space).outputs[0]
    return disp


def _normal_map(space, strength=1.0):
    def case(nt, uv):
        return node(nt, "ShaderNodeNormalMap", {"Color": _normal_color(nt, uv), "Strength": strength},
                    space=space).outputs[0]
    return case


def _texco_normal(nt, uv):
    return nt.nodes.new("ShaderNodeTexCoord").outputs["Normal"]


def _sky():
    """A smooth float environment image (linear): colours varying slowly over the sphere."""
    img = bpy.data.images.get("sky")
    if img is None:
        w, h = 64, 32
        u = (np.arange(w) + 0.5) / w
        v = (np.arange(h) + 0.5) / h
        px = np.ones((h, w, 4), np.float32)
        px[..., 0] = 0.5 + 0.4 * np.sin(2 * np.pi * u)[None, :]
        px[..., 1] = 0.2 + 0.7 * v[:, None]
        px[..., 2] = 0.5 + 0.3 * np.cos(2 * np.pi * u)[None, :] * np.sin(np.pi * v)[:, None]
        img = bpy.data.images.new("sky", w, h, alpha=False, float_buffer=True)
        img.pixels.foreach_set(px.reshape(-1))
        img.colorspace_settings.name = "Linear Rec.709"
    return img


def _environment(vector=None):
    def case(nt, uv):
        inputs = {} if vector is None else {"Vector": nt.nodes.new("ShaderNodeTexCoord").outputs[vector]}
        return node(nt, "ShaderNodeTexEnvironment", inputs, image=_sky(), interpolation="Linear").outputs[0]
    return case


CASES = [
    _texco_normal,
    _scaled(_texco_normal),
    _normal_map("OBJECT"),
    _scaled(_normal_map("OBJECT", 0.6)),
    _normal_map("BLENDER_OBJECT"),
    _scaled(_normal_map("BLENDER_OBJECT")),
    _environment(),
    _environment("Reflection"),
    _displaced(_displacement()),
    _scaled(_displaced(_displacement("OBJECT", 0.04, 0.3))),
    _displaced(_displacement(), "Fresnel"),
    _displaced(_vector_displacement()),
    _scaled(_displaced(_vector_displacement("OBJECT"))),
    lambda nt, uv: node(nt, "ShaderNodeDisplacement", {"Height": _height(nt, uv), "Scale": 0.5},
                        space="WORLD").outputs[0],
    _scaled(lambda nt, uv: node(nt, "ShaderNodeDisplacement", {"Height": _height(nt, uv), "Scale": 0.5},
                                space="OBJECT").outputs[0]),
    lambda nt, uv: node(nt, "ShaderNodeNewGeometry").outputs["Normal"],  # undisplaced, for reference
]


def test_object_space_inputs_match_cycles(tmp_path):
    cycles, drt, res = render_tiles(CASES, 4, tmp_path, shape="sphere")
    assert not res.warnings, res.warnings
    for k in (0, 2, 8):  # the inputs vary over the tile (not a constant by mistake)
        assert np.ptp(tile(drt, k, 4)) > 0.05, k
    # the scale changes object-space normals; the displacement bends the normal
    for a, b in ((0, 1), (2, 3), (4, 5), (15, 8), (15, 11)):
        assert np.abs(tile(cycles, a, 4) - tile(cycles, b, 4)).max() > 0.02, (a, b)
    _compare(cycles, drt, len(CASES))


def test_displaced_bsdfs_under_a_sun_match_cycles(tmp_path):
    """Bump from displacement on lit surfaces (a delta sun, no bounces: exact at one sample):
    a Diffuse, a Principled, and a Diffuse whose Normal is a Bump node on top of the
    displacement (Cycles's Bump takes the displaced N as its default normal)."""
    from test_shading_inputs import _bump

    def lit(kind, bump=False, **inputs):
        def case(nt, uv):
            nt.links.new(_displacement(scale=0.08)(nt, uv), _output(nt).inputs["Displacement"])
            if bump:
                inputs["Normal"] = _bump(distance=0.02)(nt, uv)
            return node(nt, kind, inputs).outputs[0]
        return case
    cases = [lit("ShaderNodeBsdfDiffuse", Color=(0.8, 0.6, 0.4, 1)),
             lit("ShaderNodeBsdfPrincipled", **{"Base Color": (0.5, 0.7, 0.3, 1), "Roughness": 0.6}),
             lit("ShaderNodeBsdfDiffuse", bump=True, Color=(0.8, 0.6, 0.4, 1)),
             lambda nt, uv: node(nt, "ShaderNodeBsdfDiffuse", {"Color": (0.8, 0.6, 0.4, 1)}).outputs[0]]
    cycles, drt, res = render_tiles(cases, 2, tmp_path, shader=True, sun=(3.0, (0.5, 0.3, 0.0)))
    assert not res.warnings, res.warnings
    assert np.abs(tile(cycles, 0, 2) - tile(cycles, 3, 2)).max() > 0.05  # displacement shows
    for k in range(len(cases)):
        a, b = tile(cycles, k, 2), tile(drt, k, 2)
        assert a.mean() > 0.05
        assert abs(b.mean() / a.mean() - 1) < 0.01, (k, a.mean(), b.mean())
        rel = np.abs(a - b).max(axis=-1) / a.max()
        assert np.quantile(rel, 0.95) < 0.02, (k, np.quantile(rel, 0.95), rel.max())


def test_displacement_methods_warn():
    """True displacement is not done: 'Displacement Only' warns and keeps the undisplaced
    normal; 'Displacement and Bump' warns and renders the bump."""
    from addon.export import export_depsgraph
    from node_parity import setup_scene
    from test_shading_inputs import _height

    setup_scene(1)
    for name, method in (("true", "DISPLACEMENT"), ("both", "BOTH")):
        bpy.ops.mesh.primitive_plane_add(size=1.0)
        mat = bpy.data.materials.new(name)
        nt = mat.node_tree
        mat.displacement_method = method
        uv = nt.nodes.new("ShaderNodeTexCoord").outputs["UV"]
        disp = node(nt, "ShaderNodeDisplacement", {"Height": _height(nt, uv)}, space="WORLD")
        nt.links.new(disp.outputs[0], nt.nodes["Material Output"].inputs["Displacement"])
        bpy.context.object.data.materials.append(mat)
    res = export_depsgraph(bpy.context.evaluated_depsgraph_get())
    text = " ".join(res.warnings)
    assert "Material 'true'" in text and "true displacement" in text, res.warnings
    assert "Material 'both'" in text and "bump only" in text, res.warnings
    mats = {m["name"]: m for m in res.header["materials"]}
    assert "normal_reg" not in mats["true"] and "normal_reg" in mats["both"]


TANGENT_CASES = [_displaced(_vector_displacement("TANGENT")),
                 _scaled(_displaced(_vector_displacement("TANGENT"))),
                 _vector_displacement("TANGENT"),
                 _scaled(_vector_displacement("TANGENT"))]


def test_tangent_space_vector_displacement_matches_cycles(tmp_path):
    """Vector Displacement in tangent space (the active UV map's MikkTSpace tangents, in object
    space): its vector, and the normal its bump gives, on rotated and scaled spheres."""
    cycles, drt, res = render_tiles(TANGENT_CASES, 2, tmp_path, shape="sphere")
    assert not res.warnings, res.warnings
    assert np.abs(tile(cycles, 0, 2) - tile(cycles, 1, 2)).max() > 0.02
    _compare(cycles, drt, len(TANGENT_CASES), n=2)
