"""Material programs (docs/materials.md): node graphs compiled at export and evaluated by DRT,
against Cycles pixel by pixel (tests/node_parity.py: an emission tile per case seen by an
orthographic camera), plus unit tests of the compiler (no rendering).

Tolerance: 2e-3 absolute on atan-squashed values in (0, 1) (node_parity.squash). Cycles
evaluates in float32 and jitters its sample inside a 0.01-pixel filter; DRT in float64 with its
own jitter; 8-bit images are compared after Cycles's own sRGB decoding.
"""

from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

import node_parity as P  # noqa: E402
from node_parity import centred, make_image, mapping, node  # noqa: E402

pytestmark = pytest.mark.blender

TOL = 2e-3


def _check(cases, n, tmp_path, tag, names):
    """Render and compare; a case whose name ends in '*' is discontinuous (checker edges,
    Closest texels, floor/step maths): one pixel whose centre lies within the 0.01-pixel sample
    jitter of an edge may differ."""
    cycles, drt, res = P.render_tiles(cases, n, tmp_path, tag)
    bad = {}
    for k in range(len(cases)):
        err = np.abs(P.tile(cycles, k, n) - P.tile(drt, k, n)).max(axis=2)
        allowed = 1 if names[k].endswith("*") else 0
        if np.count_nonzero(err > TOL) > allowed:
            bad[names[k]] = round(float(np.sort(err.ravel())[-1 - allowed]), 5)
    assert not bad, f"cases differing from Cycles (max abs error): {bad}"
    # every case really varies over its tile or is a deliberate constant, and is not black
    assert np.all(cycles[..., :3].mean(axis=(0, 1)) > 0.05)
    return res


# --- textures ------------------------------------------------------------------------------


def _image_case(path, space, interp, ext, scale=1.5, loc=-0.25):
    def case(nt, uv):
        img = bpy.data.images.load(path, check_existing=True)
        img.colorspace_settings.name = space
        vec = mapping(nt, uv, loc=(loc, loc, 0), scale=(scale, scale, 1))
        t = node(nt, "ShaderNodeTexImage", {"Vector": vec}, image=img, interpolation=interp, extension=ext)
        return t.outputs["Color"]
    return case


def _checker(use_uv, scale=5.0, rot=0.0):
    def case(nt, uv):
        ins = {"Scale": scale, "Color1": (0.9, 0.2, 0.1, 1), "Color2": (0.1, 0.3, 0.8, 1)}
        if use_uv:
            ins["Vector"] = mapping(nt, uv, rot=(0, 0, rot), kind="TEXTURE")
        return node(nt, "ShaderNodeTexChecker", ins).outputs["Color"]
    return case


def _gradient(kind, use_uv=True):
    def case(nt, uv):
        ins = {"Vector": centred(nt, uv)} if use_uv else {}
        return node(nt, "ShaderNodeTexGradient", ins, gradient_type=kind).outputs["Fac"]
    return case


def test_textures_match_cycles(tmp_path):
    srgb, data = str(tmp_path / "srgb.png"), str(tmp_path / "data.png")
    make_image("srgb", path=srgb)
    make_image("data", seed=2, path=data)
    cases, names = [], []
    for interp in ("Closest", "Linear", "Cubic"):
        for ext in ("REPEAT", "EXTEND", "CLIP", "MIRROR"):
            cases.append(_image_case(srgb, "sRGB", interp, ext))
            names.append(f"image {interp} {ext}" + ("*" if interp == "Closest" else ""))
    cases.append(_image_case(data, "Non-Color", "Linear", "REPEAT", 2.0, 0.1))
    names.append("image Non-Color")
    cases += [_checker(False), _checker(True, 3.0, 0.4)]
    names += ["checker generated*", "checker uv+mapping*"]
    for kind in ("LINEAR", "QUADRATIC", "EASING", "DIAGONAL", "SPHERICAL", "QUADRATIC_SPHERE", "RADIAL"):
        cases.append(_gradient(kind))
        names.append(f"gradient {kind}")
    cases.append(_image_case(srgb, "sRGB", "Smart", "REPEAT", 0.8, 0.1))
    names.append("image Smart")
    res = _check(cases, 5, tmp_path, "textures", names)
    assert [im["srgb"] for im in res.header["images"]] == [True, False]
    assert res.arrays["image0.pixels"].dtype == np.uint8


def _projected_image(path, projection, blend=0.0, coords="Object"):
    def case(nt, uv):
        img = bpy.data.images.load(path, check_existing=True)
        vec = nt.nodes.new("ShaderNodeTexCoord").outputs[coords]
        t = node(nt, "ShaderNodeTexImage", {"Vector": vec}, image=img, interpolation="Linear",
                 projection=projection, projection_blend=blend)
        return t.outputs["Color"]
    return case


def test_image_projections_match_cycles(tmp_path):
    """The Image Texture's Sphere, Tube and Box projections (Box at several blends), on turned
    spheres (every normal direction, and the object-space normal the Box blends by), against
    Cycles. Box without blend and the tube's seam switch faces abruptly: a few pixels there may
    differ through each engine's sample jitter."""
    path = str(tmp_path / "proj.png")
    make_image("proj", w=16, h=12, path=path)
    cases = [_projected_image(path, "SPHERE"), _projected_image(path, "TUBE"),
             _projected_image(path, "SPHERE", coords="Generated"),
             _projected_image(path, "BOX"), _projected_image(path, "BOX", 0.2),
             _projected_image(path, "BOX", 0.6), _projected_image(path, "BOX", 1.0),
             _projected_image(path, "BOX", 0.3, coords="Generated")]
    cycles, drt, res = P.render_tiles(cases, 3, tmp_path, "projections", shape="sphere")
    assert not res.warnings, res.warnings
    lit = cycles[..., 0] + cycles[..., 1] + cycles[..., 2] > 0.0
    bad = {}
    for k in range(len(cases)):
        err = np.abs(P.tile(cycles, k, 3) - P.tile(drt, k, 3)).max(axis=2)[P.tile(lit[..., None], k, 3)[..., 0]]
        if np.count_nonzero(err > TOL) > 8:  # (seams and face switches: a line of pixels)
            bad[k] = (np.count_nonzero(err > TOL), round(float(np.sort(err)[-9]), 4))
    assert not bad, bad
    assert np.abs(P.tile(cycles, 3, 3) - P.tile(cycles, 6, 3)).max() > 0.05  # the blend matters


# --- converters ----------------------------------------------------------------------------

MATH_OPS = ["ADD", "SUBTRACT", "MULTIPLY", "DIVIDE", "MULTIPLY_ADD", "POWER", "LOGARITHM", "SQRT",
            "INVERSE_SQRT", "ABSOLUTE", "EXPONENT", "MINIMUM", "MAXIMUM", "LESS_THAN",
            "GREATER_THAN", "SIGN", "COMPARE", "SMOOTH_MIN", "SMOOTH_MAX", "ROUND", "FLOOR", "CEIL",
            "TRUNC", "FRACT", "MODULO", "FLOORED_MODULO", "WRAP", "SNAP", "PINGPONG", "SINE",
            "COSINE", "TANGENT", "ARCSINE", "ARCCOSINE", "ARCTANGENT", "ARCTAN2", "SINH", "COSH",
            "TANH", "RADIANS", "DEGREES"]
STEPPY = {"LESS_THAN", "GREATER_THAN", "SIGN", "COMPARE", "ROUND", "FLOOR", "CEIL", "TRUNC", "FRACT",
          "MODULO", "FLOORED_MODULO", "WRAP", "SNAP", "PINGPONG"}


def _ab(nt, uv):
    """Two floats varying over the tile: a = 4u − 2 ∈ (−2, 2), b = 1.5v + 1.2 ∈ (1.2, 2.7) (b
    away from 0 and 1, where modulo/snap/log are ill-conditioned against the sample jitter)."""
    sep = node(nt, "ShaderNodeSeparateXYZ", {0: uv})
    a = node(nt, "ShaderNodeMath", {0: sep.outputs[0], 1: 4.0, 2: -2.0}, operation="MULTIPLY_ADD")
    b = node(nt, "ShaderNodeMath", {0: sep.outputs[1], 1: 1.5, 2: 1.2}, operation="MULTIPLY_ADD")
    return a.outputs[0], b.outputs[0]


def _math(op, clamp=False):
    def case(nt, uv):
        a, b = _ab(nt, uv)
        return node(nt, "ShaderNodeMath", {0: a, 1: b, 2: 0.3}, operation=op, use_clamp=clamp).outputs[0]
    return case


@pytest.mark.slow
def test_math_matches_cycles(tmp_path):
    cases = [_math(op) for op in MATH_OPS] + [_math("MULTIPLY", True), _math("SUBTRACT", True)]
    names = [op + ("*" if op in STEPPY else "") for op in MATH_OPS] + ["MULTIPLY clamp", "SUBTRACT clamp"]
    _check(cases, 7, tmp_path, "math", names)


VMATH_OPS = ["ADD", "SUBTRACT", "MULTIPLY", "DIVIDE", "MULTIPLY_ADD", "CROSS_PRODUCT", "PROJECT",
             "REFLECT", "DOT_PRODUCT", "DISTANCE", "LENGTH", "SCALE", "NORMALIZE", "ABSOLUTE",
             "MINIMUM", "MAXIMUM", "FLOOR", "CEIL", "FRACTION", "MODULO", "WRAP", "SNAP", "SINE",
             "COSINE", "TANGENT", "POWER", "SIGN"]
VSTEPPY = {"FLOOR", "CEIL", "FRACTION", "MODULO", "WRAP", "SNAP", "SIGN"}
BLENDS = ["MIX", "DARKEN", "MULTIPLY", "BURN", "LIGHTEN", "SCREEN", "DODGE", "ADD", "OVERLAY",
          "SOFT_LIGHT", "LINEAR_LIGHT", "DIFFERENCE", "EXCLUSION", "SUBTRACT", "DIVIDE", "HUE",
          "SATURATION", "VALUE", "COLOR"]


def _vectors(nt, uv):
    a = mapping(nt, uv, loc=(-2, -1, -0.5), scale=(4, 3, 2))
    b = mapping(nt, uv, loc=(1, -2, 0.7), scale=(-2, 3, 1), rot=(0.2, 0.5, -0.3))
    return a, b


def _vmath(op):
    def case(nt, uv):
        a, b = _vectors(nt, uv)
        if op in ("MODULO", "WRAP", "SNAP"):  # divisors well away from 0 (see _ab)
            b = mapping(nt, uv, loc=(1.3, 1.7, 2.1), scale=(0.5, 0.4, 1))
        n = node(nt, "ShaderNodeVectorMath", {0: a, 1: b, 2: (0.3, -0.2, 0.5), 3: 1.7}, operation=op)
        return n.outputs["Value" if op in ("DOT_PRODUCT", "DISTANCE", "LENGTH") else "Vector"]
    return case


def _colors(nt, uv):
    sep = node(nt, "ShaderNodeSeparateXYZ", {0: uv})
    c1 = node(nt, "ShaderNodeCombineColor", {0: sep.outputs[0], 1: sep.outputs[1], 2: 0.3}).outputs[0]
    inv = node(nt, "ShaderNodeMath", {0: 1.0, 1: sep.outputs[0]}, operation="SUBTRACT").outputs[0]
    c2 = node(nt, "ShaderNodeCombineColor", {0: 0.8, 1: inv, 2: sep.outputs[1]}).outputs[0]
    return c1, c2, sep


def _mix(blend, data_type="RGBA", fac=0.7, legacy=False, clamp=False):
    def case(nt, uv):
        c1, c2, sep = _colors(nt, uv)
        if legacy:
            n = node(nt, "ShaderNodeMixRGB", {0: fac, 1: c1, 2: c2}, blend_type=blend, use_clamp=clamp)
            return n.outputs[0]
        n = node(nt, "ShaderNodeMix", data_type=data_type, blend_type=blend, clamp_result=clamp)
        socks = [s for s in n.inputs if s.enabled]
        if data_type == "FLOAT":
            nt.links.new(sep.outputs[0], socks[1])
            nt.links.new(sep.outputs[1], socks[2])
        else:
            nt.links.new(c1, socks[1])
            nt.links.new(c2, socks[2])
        if fac is None:
            nt.links.new(sep.outputs[1], socks[0])
        else:
            socks[0].default_value = fac
        return [o for o in n.outputs if o.enabled][0]
    return case


@pytest.mark.slow
def test_vector_math_and_mix_match_cycles(tmp_path):
    cases, names = [], []
    for op in VMATH_OPS:
        cases.append(_vmath(op))
        names.append("vmath " + op + ("*" if op in VSTEPPY else ""))
    for blend in BLENDS:
        cases.append(_mix(blend))
        names.append("mix " + blend)
    cases += [_mix("MIX", "FLOAT", None), _mix("MIX", "VECTOR", None), _mix("MULTIPLY", fac=None),
              _mix("ADD", fac=1.5, clamp=True), _mix("OVERLAY", legacy=True),
              _mix("LINEAR_LIGHT", fac=0.6, legacy=True, clamp=True)]
    names += ["mix float", "mix vector", "mix fac linked", "mix clamp", "mixrgb overlay", "mixrgb clamp"]
    _check(cases, 8, tmp_path, "vmath_mix", names)


def _ramp(interp, color_mode="RGB"):
    def case(nt, uv):
        sep = node(nt, "ShaderNodeSeparateXYZ", {0: uv})
        n = node(nt, "ShaderNodeValToRGB", {0: sep.outputs[0]})
        r = n.color_ramp
        r.interpolation = interp
        r.elements[0].position, r.elements[0].color = 0.15, (0.9, 0.1, 0.2, 1.0)
        r.elements[1].position, r.elements[1].color = 0.8, (0.1, 0.7, 0.9, 0.5)
        e = r.elements.new(0.45)
        e.color = (1.0, 0.9, 0.1, 0.8)
        return n.outputs["Color"]
    return case


def _map_range(kind, clamp):
    def case(nt, uv):
        a, _ = _ab(nt, uv)
        return node(nt, "ShaderNodeMapRange", {"Value": a, "From Min": -1.0, "From Max": 1.5,
                                               "To Min": 0.2, "To Max": -0.7, "Steps": 4.0},
                    interpolation_type=kind, clamp=clamp).outputs[0]
    return case


def _color_node(kind, **inputs):
    def case(nt, uv):
        c1, _, sep = _colors(nt, uv)
        ins = {"Color": c1}
        for k, v in inputs.items():
            ins[k.replace("_", " ")] = sep.outputs[0] if v == "u" else v
        return node(nt, kind, ins).outputs[0]
    return case


def _clamp(kind):
    def case(nt, uv):
        a, b = _ab(nt, uv)
        lo, hi = (0.5, -0.3) if kind == "RANGE" else (-0.3, 0.5)
        return node(nt, "ShaderNodeClamp", {"Value": a, "Min": lo, "Max": hi}, clamp_type=kind).outputs[0]
    return case


def _hsv_roundtrip(nt, uv):
    c1, _, _ = _colors(nt, uv)
    sep = node(nt, "ShaderNodeSeparateColor", {0: c1}, mode="HSV")
    h = node(nt, "ShaderNodeMath", {0: sep.outputs[0], 1: 0.3}, operation="ADD")
    return node(nt, "ShaderNodeCombineColor", {0: h.outputs[0], 1: sep.outputs[1], 2: sep.outputs[2]},
                mode="HSV").outputs[0]


def _coords(kind):
    def case(nt, uv):
        tc = nt.nodes.new("ShaderNodeTexCoord")
        return mapping(nt, tc.outputs[kind], scale=(3, 3, 3), rot=(0, 0, 0.3))
    return case


def _uv_map_node(nt, uv):
    return node(nt, "ShaderNodeUVMap").outputs[0]


def _group(nt, uv):
    """A group (with a nested group) that scales its vector input by an unlinked factor 2.5 and
    adds a default offset; a reroute and a muted node on the way."""
    inner = bpy.data.node_groups.get("inner") or _make_inner()
    outer = bpy.data.node_groups.new("outer", "ShaderNodeTree")
    outer.interface.new_socket("Vec", in_out="INPUT", socket_type="NodeSocketVector")
    f = outer.interface.new_socket("Fac", in_out="INPUT", socket_type="NodeSocketFloat")
    f.default_value = 2.5
    outer.interface.new_socket("Out", in_out="OUTPUT", socket_type="NodeSocketVector")
    gi = outer.nodes.new("NodeGroupInput")
    go = outer.nodes.new("NodeGroupOutput")
    scale = outer.nodes.new("ShaderNodeVectorMath")
    scale.operation = "SCALE"
    outer.links.new(gi.outputs[0], scale.inputs[0])
    outer.links.new(gi.outputs[1], scale.inputs[3])
    g = outer.nodes.new("ShaderNodeGroup")
    g.node_tree = inner
    outer.links.new(scale.outputs[0], g.inputs[0])
    outer.links.new(g.outputs[0], go.inputs[0])
    n = nt.nodes.new("ShaderNodeGroup")
    n.node_tree = outer
    reroute = nt.nodes.new("NodeReroute")
    nt.links.new(uv, reroute.inputs[0])
    muted = node(nt, "ShaderNodeVectorMath", {0: reroute.outputs[0], 1: (5, 5, 5)}, operation="ADD")
    muted.mute = True
    nt.links.new(muted.outputs[0], n.inputs[0])
    return n.outputs[0]


def _make_inner():
    inner = bpy.data.node_groups.new("inner", "ShaderNodeTree")
    inner.interface.new_socket("V", in_out="INPUT", socket_type="NodeSocketVector")
    off = inner.interface.new_socket("Offset", in_out="INPUT", socket_type="NodeSocketVector")
    off.default_value = (-0.5, 0.25, 0.1)
    inner.interface.new_socket("R", in_out="OUTPUT", socket_type="NodeSocketVector")
    gi = inner.nodes.new("NodeGroupInput")
    go = inner.nodes.new("NodeGroupOutput")
    add = inner.nodes.new("ShaderNodeVectorMath")
    add.operation = "ADD"
    inner.links.new(gi.outputs[0], add.inputs[0])
    inner.links.new(gi.outputs[1], add.inputs[1])
    inner.links.new(add.outputs[0], go.inputs[0])
    return inner


def test_converters_match_cycles(tmp_path):
    cases, names = [], []
    for interp in ("LINEAR", "CONSTANT", "EASE", "B_SPLINE", "CARDINAL"):
        cases.append(_ramp(interp))
        names.append("ramp " + interp + ("*" if interp == "CONSTANT" else ""))
    for kind in ("LINEAR", "STEPPED", "SMOOTHSTEP", "SMOOTHERSTEP"):
        for clamp in (False, True):
            cases.append(_map_range(kind, clamp))
            names.append(f"map range {kind} {clamp}" + ("*" if kind == "STEPPED" else ""))
    cases += [_clamp("MINMAX"), _clamp("RANGE"),
              _color_node("ShaderNodeInvert", Fac=0.7),
              _color_node("ShaderNodeGamma", Gamma=2.2),
              _color_node("ShaderNodeBrightContrast", Bright=0.1, Contrast=0.4),
              _color_node("ShaderNodeHueSaturation", Hue=0.3, Saturation=1.4, Value=0.8, Fac="u"),
              _hsv_roundtrip, _coords("Generated"), _coords("Object"), _uv_map_node, _group]
    names += ["clamp minmax", "clamp range", "invert", "gamma", "bright contrast", "hue sat",
              "separate/combine hsv", "generated", "object", "uv map", "group+reroute+muted"]
    res = _check(cases, 5, tmp_path, "converters", names)
    assert not res.warnings


def _vec3(nt, uv):
    """A 3-D vector varying over the tile (UV centred to [−1, 1]² and turned out of its plane)."""
    return mapping(nt, centred(nt, uv), rot=(0.4, 0.2, 0.1))


def _rgb_to_bw(nt, uv):
    c1, _, _ = _colors(nt, uv)
    return node(nt, "ShaderNodeRGBToBW", {"Color": c1}).outputs[0]


def _normal_node(output):
    def case(nt, uv):
        n = node(nt, "ShaderNodeNormal", {"Normal": _vec3(nt, uv)})
        n.outputs["Normal"].default_value = (0.3, -0.5, 0.8)  # normalised by the node
        return n.outputs[output]
    return case


def _vector_rotate(kind, invert=False, linked_axis=False, linked_angle=True):
    def case(nt, uv):
        sep = node(nt, "ShaderNodeSeparateXYZ", {0: uv})
        ins = {"Vector": _vec3(nt, uv), "Center": (0.2, -0.1, 0.3)}
        if kind == "EULER_XYZ":
            ins["Rotation"] = mapping(nt, uv, scale=(2.0, 1.0, 1.5), loc=(0.3, -0.4, 0.2))
        else:
            ins["Angle"] = node(nt, "ShaderNodeMath", {0: sep.outputs[0], 1: 5.0}, operation="MULTIPLY").outputs[0] \
                if linked_angle else 1.1
            ins["Axis"] = mapping(nt, uv, loc=(0.5, 0.2, 0.7)) if linked_axis else (0.3, 0.9, -0.4)
        return node(nt, "ShaderNodeVectorRotate", ins, rotation_type=kind, invert=invert).outputs[0]
    return case


def _camera_data(output):
    def case(nt, uv):
        return node(nt, "ShaderNodeCameraData").outputs[output]
    return case


def _blackbody_emission(kelvin):
    def case(nt, uv):
        bb = node(nt, "ShaderNodeBlackbody", {"Temperature": kelvin})
        return node(nt, "ShaderNodeEmission", {"Color": bb.outputs[0]}).outputs[0]
    return case


def test_converter_nodes_built_from_operations_match_cycles(tmp_path):
    """RGB to BW, Normal, Vector Rotate (every type, inverted, linked and constant axis and
    angle) and Camera Data against Cycles."""
    cases = [_rgb_to_bw, _normal_node("Dot"), _normal_node("Normal"),
             _vector_rotate("AXIS_ANGLE"), _vector_rotate("AXIS_ANGLE", invert=True),
             _vector_rotate("AXIS_ANGLE", linked_axis=True), _vector_rotate("AXIS_ANGLE", linked_angle=False),
             _vector_rotate("X_AXIS"), _vector_rotate("Y_AXIS", invert=True), _vector_rotate("Z_AXIS"),
             _vector_rotate("EULER_XYZ"), _vector_rotate("EULER_XYZ", invert=True),
             _camera_data("View Vector"), _camera_data("View Z Depth"), _camera_data("View Distance")]
    names = ["rgb to bw", "normal dot", "normal normal", "rotate axis angle", "rotate axis angle inv",
             "rotate linked axis", "rotate const angle", "rotate x", "rotate y inv", "rotate z",
             "rotate euler", "rotate euler inv", "camera view vector", "camera z depth",
             "camera distance"]
    res = _check(cases, 4, tmp_path, "converters2", names)
    assert not res.warnings


def _vector_map_range(kind, clamp, steps=(3.0, 4.0, 2.0)):
    def case(nt, uv):
        n = node(nt, "ShaderNodeMapRange", data_type="FLOAT_VECTOR", interpolation_type=kind, clamp=clamp)
        sock = {s.identifier: s for s in n.inputs}
        nt.links.new(_vec3(nt, uv), sock["Vector"])
        sock["From_Min_FLOAT3"].default_value = (-0.8, -0.5, 0.2)
        sock["From_Max_FLOAT3"].default_value = (0.7, 0.9, 0.2)  # z: an empty range (factor 0)
        sock["To_Min_FLOAT3"].default_value = (0.1, 0.9, -0.4)
        sock["To_Max_FLOAT3"].default_value = (0.8, 0.2, 1.3)  # y reversed: clamps either way
        sock["Steps_FLOAT3"].default_value = steps
        return n.outputs["Vector"]
    return case


def test_vector_map_range_matches_cycles(tmp_path):
    """Map Range on vectors: every interpolation, with and without clamping, an empty source
    range and a reversed target one, against Cycles."""
    cases = [_vector_map_range(k, c) for k in ("LINEAR", "STEPPED", "SMOOTHSTEP", "SMOOTHERSTEP")
             for c in (False, True)]
    names = [f"{k} {c}" + ("*" if k == "STEPPED" else "") for k in ("LINEAR", "STEPPED", "SMOOTHSTEP", "SMOOTHERSTEP")
             for c in (False, True)]
    cases.append(_vector_map_range("STEPPED", False, steps=(0.0, 2.0, 5.0)))
    names.append("stepped zero steps*")
    res = _check(cases, 3, tmp_path, "vector_map_range", names)
    assert not res.warnings


def test_camera_data_under_a_perspective_camera_matches_cycles(tmp_path, monkeypatch):
    """Camera Data's outputs where the view vector varies most: a moved, turned perspective
    camera (the grid's own camera is orthographic)."""
    setup = P.setup_scene

    def perspective(n):
        sc = setup(n)
        sc.camera.data.type = "PERSP"
        sc.camera.location, sc.camera.rotation_euler = (0.2, -0.3, 2.5), (0.1, 0.05, 0.2)
        return sc

    monkeypatch.setattr(P, "setup_scene", perspective)
    _check([_camera_data(o) for o in ("View Vector", "View Z Depth", "View Distance")], 2, tmp_path,
           "camera_data", ["view vector", "z depth", "distance"])


def _light_falloff(output, smooth=0.0, linked_smooth=False):
    def case(nt, uv):
        sep = node(nt, "ShaderNodeSeparateXYZ", {0: uv})
        lf = node(nt, "ShaderNodeLightFalloff", {"Strength": 2.0, "Smooth": smooth})
        if linked_smooth:  # −0.5 … 1.5 over the tile: Cycles smooths only where it is > 0
            sm = node(nt, "ShaderNodeMath", {0: sep.outputs[0], 1: 2.0, 2: -0.5}, operation="MULTIPLY_ADD")
            nt.links.new(sm.outputs[0], lf.inputs["Smooth"])
        return lf.outputs[output]
    return case


def test_light_falloff_matches_cycles(tmp_path, monkeypatch):
    """Light Falloff's three outputs, with and without Smooth (constant and driven), on spheres
    seen by a perspective camera (the ray length varies over each tile)."""
    setup = P.setup_scene

    def perspective(n):
        sc = setup(n)
        sc.camera.data.type = "PERSP"
        sc.camera.location = (0.0, 0.0, 1.6)
        return sc

    monkeypatch.setattr(P, "setup_scene", perspective)
    cases = [_light_falloff(o) for o in ("Quadratic", "Linear", "Constant")]
    cases += [_light_falloff(o, smooth=0.7) for o in ("Quadratic", "Linear", "Constant")]
    cases += [_light_falloff("Linear", linked_smooth=True)]
    cycles, drt, res = P.render_tiles(cases, 3, tmp_path, "falloff", shape="sphere")
    assert not res.warnings, res.warnings
    lit = cycles[..., 0] > 0.0  # the spheres (the world is black)
    for k in range(len(cases)):
        err = np.abs(P.tile(cycles, k, 3) - P.tile(drt, k, 3)).max(axis=2)[P.tile(lit[..., None], k, 3)[..., 0]]
        assert np.count_nonzero(err > TOL) <= 2, (k, float(err.max()))  # (sphere rims: filter jitter)
    assert np.abs(P.tile(cycles, 1, 3) - P.tile(cycles, 2, 3)).max() > 0.05  # the outputs differ


def test_blackbody_matches_cycles(tmp_path):
    """The Blackbody colour across its fit's temperature ranges and both ends, as emitted
    radiance (not squashed: compared to 1e-4 relative, Cycles's float32)."""
    kelvins = (500.0, 900.0, 1000.0, 1300.0, 1600.0, 2500.0, 4500.0, 6500.0, 9000.0)
    cycles, drt, res = P.render_tiles([_blackbody_emission(k) for k in kelvins], 3, tmp_path, "blackbody",
                                      shader=True)
    assert not res.warnings
    for k, kelvin in enumerate(kelvins):
        c, d = P.tile(cycles, k, 3)[8, 8], P.tile(drt, k, 3)[8, 8]
        np.testing.assert_allclose(d, c, rtol=1e-4, atol=1e-6, err_msg=f"{kelvin} K")
    assert cycles[..., 0].min() > 0.3  # warm to white: every tile lit


# --- textured BSDFs under a sun (direct light only: exact, no noise) ---------------------------


def _diffuse_image(path):
    def case(nt, uv):
        img = bpy.data.images.load(path, check_existing=True)
        # Closest: magnified Linear texels change by ~1 % over the 0.01-pixel sample jitter
        # (Linear is compared, squashed, in test_textures_match_cycles)
        t = node(nt, "ShaderNodeTexImage", {"Vector": mapping(nt, uv, scale=(2, 2, 1))}, image=img,
                 interpolation="Closest")
        return node(nt, "ShaderNodeBsdfDiffuse", {"Color": t.outputs["Color"]}).outputs[0]
    return case


def _principled_checker(nt, uv):
    ck = node(nt, "ShaderNodeTexChecker", {"Scale": 4.0, "Color1": (0.9, 0.5, 0.1, 1),
                                           "Color2": (0.1, 0.4, 0.9, 1)})
    p = node(nt, "ShaderNodeBsdfPrincipled", {"Base Color": ck.outputs["Color"],
                                              "Specular IOR Level": 0.0})
    return p.outputs[0]


def _not_a_light(nt):
    """Emission Sampling None on the tile's material: its coplanar neighbours cannot see it
    (Cycles's light tree gives it no probability there), but DRT's light selection has no
    orientation bounds and would spend sun samples on it: noise at the one sample compared."""
    next(m for m in bpy.data.materials if m.node_tree == nt).cycles.emission_sampling = "NONE"


def _principled_emission(nt, uv):
    _not_a_light(nt)
    g = node(nt, "ShaderNodeTexGradient", {"Vector": uv})
    ramp = node(nt, "ShaderNodeValToRGB", {0: g.outputs["Fac"]})
    p = node(nt, "ShaderNodeBsdfPrincipled", {"Base Color": (0, 0, 0, 1), "Specular IOR Level": 0.0,
                                              "Emission Color": ramp.outputs["Color"],
                                              "Emission Strength": 2.0})
    return p.outputs[0]


def _mix_shader_fac(nt, uv):
    _not_a_light(nt)
    ck = node(nt, "ShaderNodeTexChecker", {"Scale": 3.0})
    a = node(nt, "ShaderNodeBsdfDiffuse", {"Color": (0.8, 0.2, 0.2, 1)})
    b = node(nt, "ShaderNodeEmission", {"Color": (0.2, 0.3, 0.9, 1), "Strength": 1.5})
    sep = node(nt, "ShaderNodeSeparateXYZ", {0: uv})
    fac = node(nt, "ShaderNodeMath", {0: ck.outputs["Fac"], 1: sep.outputs[0]}, operation="MULTIPLY")
    return node(nt, "ShaderNodeMixShader", {0: fac.outputs[0], 1: a.outputs[0], 2: b.outputs[0]}).outputs[0]


def test_textured_bsdfs_under_a_sun_match_cycles(tmp_path):
    img = str(tmp_path / "img.png")
    make_image("img", path=img)
    cases = [_diffuse_image(img), _principled_checker, _principled_emission, _mix_shader_fac]
    names = ["diffuse image*", "principled checker base*", "principled ramp emission", "mix shader fac*"]
    cycles, drt, res = P.render_tiles(cases, 2, tmp_path, "sun", shader=True, sun=(3.0, (0.4, 0.3, 0)))
    bad = {}
    for k in range(len(cases)):
        err = np.abs(P.tile(cycles, k, 2) - P.tile(drt, k, 2)).max(axis=2)
        # 2e-3 of the tile's brightest value: the 0.01-pixel sample jitter moves steep
        # gradients (magnified texels, ramps) by ~1e-3 of their range
        rel = err / P.tile(cycles, k, 2).max()
        allowed = 1 if names[k].endswith("*") else 0
        if np.count_nonzero(rel > 2e-3) > allowed:
            bad[names[k]] = float(np.sort(rel.ravel())[-1 - allowed])
    assert not bad, f"error vs Cycles (fraction of the tile's peak): {bad}"
    assert cycles.mean() > 0.1
    assert not res.warnings


# --- the compiler, without rendering ---------------------------------------------------------

@pytest.fixture
def fresh():
    import _common as C
    from test_addon import ensure_registered

    ensure_registered()
    scene = C.reset()
    C.camera((0, -5, 1), (0, 0, 0))
    return scene


def _export():
    from addon.export.blend import export_current

    return export_current()


def _mat(name):
    import _common as C

    return C._new_material(name)


def _plane(mat, name="Q", z=0.0):
    bpy.ops.mesh.primitive_plane_add(size=1, location=(0, 0, z))
    obj = bpy.context.object
    obj.name = name
    obj.data.materials.append(mat)
    return obj


def _material_dict(res, name):
    return next(m for m in res.header["materials"] if m["name"] == name)


def _ops(m):
    return [op[0] for op in m["program"]["ops"]]


def test_constants_fold_to_todays_lobes(fresh):
    mat, nodes, out = _mat("Const")
    rgb = node(mat.node_tree, "ShaderNodeRGB")
    rgb.outputs[0].default_value = (0.2, 0.4, 0.6, 1)
    p = node(mat.node_tree, "ShaderNodeBsdfPrincipled", {"Base Color": rgb.outputs[0], "Metallic": 0.0})
    mat.node_tree.links.new(p.outputs[0], out.inputs[0])
    _plane(mat)
    res = _export()
    m = _material_dict(res, "Const")
    assert "program" not in m and "images" not in res.header
    assert not any(k.endswith(("generated", "object_coords")) for k in res.arrays)
    diffuse = next(lb for lb in m["lobes"] if lb["type"] == "DIFFUSE")
    assert diffuse["color"][2] > diffuse["color"][0] > 0


def test_textured_principled_compiles_to_register_lobes(fresh):
    from addon.export.node_programs import OP_CHECKER, OP_GENERATED, OP_VMATH

    mat, nodes, out = _mat("Tex")
    nt = mat.node_tree
    ck = node(nt, "ShaderNodeTexChecker")
    p = node(nt, "ShaderNodeBsdfPrincipled", {"Base Color": ck.outputs["Color"], "Roughness": ck.outputs["Fac"],
                                              "Metallic": 0.0})
    nt.links.new(p.outputs[0], out.inputs[0])
    _plane(mat)
    res = _export()
    m = _material_dict(res, "Tex")
    ops = _ops(m)
    # one checker (shared by both outputs) fed by Generated: the colour of the diffuse lobe
    # under the (textured-roughness) specular layer, its roughness
    assert ops.count(OP_CHECKER) == 1 and ops.count(OP_GENERATED) == 1
    assert set(ops) <= {OP_CHECKER, OP_GENERATED, OP_VMATH}
    kinds = [(lb["type"], "color_reg" in lb, "roughness_reg" in lb) for lb in m["lobes"]]
    assert kinds == [("DIELECTRIC_SPECULAR", False, True), ("DIFFUSE", True, False)]
    assert m["lobes"][1]["layer"] == 0
    assert "mesh0.generated" in res.arrays and "mesh0.object_coords" not in res.arrays
    assert res.arrays["mesh0.generated"].shape == (2, 3, 3)
    assert not res.warnings


def test_principled_in_a_group_exports_like_unwrapped(fresh):
    """glTF-style: the whole PBR material inside a node group (shader output through the group)."""
    for wrapped in (False, True):
        mat, nodes, out = _mat(f"G{wrapped}")
        nt = mat.node_tree
        tree = nt
        if wrapped:
            tree = bpy.data.node_groups.new("pbr", "ShaderNodeTree")
            tree.interface.new_socket("Shader", in_out="OUTPUT", socket_type="NodeSocketShader")
            s = tree.interface.new_socket("Scale", in_out="INPUT", socket_type="NodeSocketFloat")
            s.default_value = 7.0
        ck = node(tree, "ShaderNodeTexChecker", {"Scale": 7.0})
        p = node(tree, "ShaderNodeBsdfPrincipled", {"Base Color": ck.outputs["Color"]})
        if wrapped:
            gi, go = tree.nodes.new("NodeGroupInput"), tree.nodes.new("NodeGroupOutput")
            tree.links.new(gi.outputs[0], ck.inputs["Scale"])
            tree.links.new(p.outputs[0], go.inputs[0])
            g = nt.nodes.new("ShaderNodeGroup")
            g.node_tree = tree
            nt.links.new(g.outputs[0], out.inputs[0])
        else:
            nt.links.new(p.outputs[0], out.inputs[0])
        _plane(mat, f"P{wrapped}", z=float(wrapped))
    res = _export()
    a, b = _material_dict(res, "GFalse"), _material_dict(res, "GTrue")
    assert a["program"] == b["program"] and a["lobes"] == b["lobes"]
    assert not res.warnings


def test_muted_node_passes_through_and_reroutes_vanish(fresh):
    from addon.export.node_programs import OP_MATH

    mat, nodes, out = _mat("Muted")
    nt = mat.node_tree
    ck = node(nt, "ShaderNodeTexChecker")
    r = nt.nodes.new("NodeReroute")
    nt.links.new(ck.outputs["Fac"], r.inputs[0])
    m = node(nt, "ShaderNodeMath", {0: r.outputs[0], 1: 10.0}, operation="ADD")
    m.mute = True
    em = node(nt, "ShaderNodeEmission", {"Color": m.outputs[0]})
    nt.links.new(em.outputs[0], out.inputs[0])
    _plane(mat)
    d = _material_dict(_export(), "Muted")
    assert OP_MATH not in _ops(d) and "emission_reg" in d


def test_unsupported_texture_warns_and_falls_back(fresh):
    mat, nodes, out = _mat("Noisy")
    nt = mat.node_tree
    noise = nt.nodes.new("ShaderNodeTexGabor")  # not compiled (yet)
    p = node(nt, "ShaderNodeBsdfDiffuse", {"Color": (0.3, 0.2, 0.1, 1)})
    nt.links.new(noise.outputs["Value"], p.inputs["Color"])
    nt.links.new(p.outputs[0], out.inputs[0])
    _plane(mat)
    res = _export()
    d = _material_dict(res, "Noisy")
    assert "program" not in d and d["lobes"][0]["color"] == pytest.approx([0.3, 0.2, 0.1])
    assert len(res.warnings) == 1 and "'Noisy'" in res.warnings[0] and "ShaderNodeTexGabor" in res.warnings[0]


def test_blackbody_with_a_driven_temperature_warns_and_falls_back(fresh):
    """A Blackbody whose temperature other nodes drive is not compiled: the export warns and
    the driven socket keeps its own value, as for any node it cannot compile."""
    from addon.export.converter_nodes import blackbody_rgb

    mat, nodes, out = _mat("Fire")
    nt = mat.node_tree
    bb = node(nt, "ShaderNodeBlackbody", {"Temperature": 1800.0})
    nt.links.new(nt.nodes.new("ShaderNodeObjectInfo").outputs["Random"], bb.inputs["Temperature"])
    em = node(nt, "ShaderNodeEmission", {"Color": bb.outputs[0]})
    em.inputs["Color"].default_value = (0.5, 0.25, 0.125, 1.0)
    nt.links.new(em.outputs[0], out.inputs[0])
    _plane(mat)
    res = _export()
    assert len(res.warnings) == 1 and "Blackbody" in res.warnings[0]
    assert _material_dict(res, "Fire")["emission"] == pytest.approx([0.5, 0.25, 0.125])
    assert blackbody_rgb(1800.0)[0] > blackbody_rgb(1800.0)[2] >= 0.0  # warm, clamped at 0


def test_images_stored_once_as_bytes(fresh, tmp_path):
    path = str(tmp_path / "i.png")
    make_image("i", w=5, h=3, path=path)
    for name in ("A", "B"):
        mat, nodes, out = _mat(name)
        nt = mat.node_tree
        t = node(nt, "ShaderNodeTexImage", image=bpy.data.images.load(path, check_existing=True))
        e = node(nt, "ShaderNodeEmission", {"Color": t.outputs["Color"]})
        nt.links.new(e.outputs[0], out.inputs[0])
        _plane(mat, name, z=float(name == "B"))
    res = _export()
    assert len(res.header["images"]) == 1
    px = res.arrays["image0.pixels"]
    assert px.dtype == np.uint8 and px.shape == (3, 5, 4)
    from drt.scene import scene_from_dict

    scene = scene_from_dict(res.header, res.arrays)
    assert len(scene.images) == 1


def _second_uv(render_active=False):
    """Adds a UV map 'Second' (the first one rotated and scaled) to the plane being built."""
    mesh = bpy.context.object.data
    uv = np.empty(2 * len(mesh.loops), np.float32)
    mesh.uv_layers[0].uv.foreach_get("vector", uv)
    u, v = uv[0::2].copy(), uv[1::2].copy()
    uv[0::2], uv[1::2] = 1.7 * v - 0.3, 0.6 * u + 0.2
    second = mesh.uv_layers.new(name="Second")
    second.uv.foreach_set("vector", uv)
    if render_active:
        second.active_render = True


def _uv_case(kind):
    def case(nt, uv):
        _second_uv(render_active=kind == "active_render")
        if kind == "named":
            return node(nt, "ShaderNodeUVMap", uv_map="Second").outputs[0]
        if kind == "missing":
            return node(nt, "ShaderNodeUVMap", uv_map="Nope").outputs[0]
        return uv  # Texture Coordinate UV: the active render map
    return case


def test_named_uv_maps_match_cycles(tmp_path):
    names = ["named", "active_render", "default", "missing"]
    res = _check([_uv_case(k) for k in names], 2, tmp_path, "uvmaps", names)
    assert res.header["attributes"] == ["uv:Second", "uv:Nope"]
    assert "mesh0.attr0" in res.arrays and not any(k.endswith("attr1") for k in res.arrays)


def _float_image_case(path, interp, space=None):
    def case(nt, uv):
        img = bpy.data.images.load(path, check_existing=space is None)
        if space is not None:
            img.colorspace_settings.name = space
        t = node(nt, "ShaderNodeTexImage", {"Vector": mapping(nt, uv, scale=(1.3, 1.3, 1))}, image=img,
                 interpolation=interp)
        return t.outputs["Color"]
    return case


def test_float_image_matches_cycles(tmp_path):
    """A float (EXR, values above 1) image: stored as float16; tagged sRGB (what bpy assigns to
    this saved file) Cycles interpolates it sRGB-encoded, tagged Linear it reads it as is."""
    path = str(tmp_path / "hdr.exr")
    rng = np.random.default_rng(3)
    px = np.ones((5, 7, 4), np.float32)
    px[..., :3] = rng.uniform(0.0, 4.0, (5, 7, 3)).astype(np.float16)  # float16-exact values
    img = bpy.data.images.new("hdr", 7, 5, alpha=False, float_buffer=True)
    img.pixels.foreach_set(px.reshape(-1))
    img.filepath_raw = path
    img.file_format = "OPEN_EXR"
    img.save()
    names = ["float Closest*", "float Linear", "float Cubic", "float Linear Rec.709"]
    cases = [_float_image_case(path, i) for i in ("Closest", "Linear", "Cubic")]
    cases.append(_float_image_case(path, "Linear", "Linear Rec.709"))
    res = _check(cases, 2, tmp_path, "float", names)
    assert [im["srgb"] for im in res.header["images"]] == [True, False]
    assert all(res.arrays[f"image{i}.pixels"].dtype == np.float16 for i in range(2))


def test_unknown_colour_space_warns_and_falls_back(fresh, tmp_path):
    path = str(tmp_path / "acescg.png")
    make_image("a", path=path)
    mat, nodes, out = _mat("Aces")
    nt = mat.node_tree
    img = bpy.data.images.load(path)
    img.colorspace_settings.name = "ACEScg"
    t = node(nt, "ShaderNodeTexImage", image=img)
    d = node(nt, "ShaderNodeBsdfDiffuse", {"Color": (0.2, 0.3, 0.4, 1)})
    nt.links.new(t.outputs["Color"], d.inputs["Color"])
    nt.links.new(d.outputs[0], out.inputs[0])
    _plane(mat)
    res = _export()
    m = _material_dict(res, "Aces")
    assert "program" not in m and m["lobes"][0]["color"] == pytest.approx([0.2, 0.3, 0.4])
    assert len(res.warnings) == 1 and "ACEScg" in res.warnings[0] and "'Aces'" in res.warnings[0]


def test_viewport_renders_textured_materials_like_the_final_render():
    """The Rendered viewport runs the material programs: the textured scene's camera view
    matches DRT's final render of the same view; a node edit that makes a program read a new
    geometry input (UV → Generated) re-exports the meshes."""
    import os

    from addon import viewport
    from addon.export import export_depsgraph
    from drt.render import render
    from drt.scene import scene_from_dict
    from test_addon import ensure_registered
    from test_viewport import camera_view_spec

    ensure_registered()
    bpy.ops.wm.open_mainfile(filepath=os.path.join(P.REPO, "blend_scenes", "textured.blend"))
    sc = bpy.context.scene
    vp = viewport.ViewportSync(threads=1)
    try:
        dg = bpy.context.evaluated_depsgraph_get()
        vp.sync(dg)
        w, h, spp = 48, 27, 32
        vp.set_view(camera_view_spec(viewport, dg, w, h), w, h, spp)
        frame = vp.session.wait(lambda f: f.divider == 1 and f.samples >= spp, 300)
        assert frame is not None, vp.session.error
        floor = next(m for m in vp.session.live.materials if m["name"] == "Floor")
        assert "program" in floor and vp.session.live.images
        # the kernels its gate waits for and its header names: the textured variant
        assert vp.kernel_variant() == "programs"
        live = np.asarray(frame.rgba, np.float64)[::-1, :, :3]  # bottom row first → top first

        sc.render.resolution_x, sc.render.resolution_y, sc.render.resolution_percentage = w, h, 100
        sc.drt.samples = spp
        res = export_depsgraph(bpy.context.evaluated_depsgraph_get())
        final = np.asarray(render(scene_from_dict(res.header, res.arrays), threads=1).combined,
                           np.float64)[..., :3]
        # 3×3 regions: means agree within Monte Carlo noise (32 spp)
        for rows in np.array_split(np.arange(h), 3):
            for cols in np.array_split(np.arange(w), 3):
                a, b = live[np.ix_(rows, cols)].mean(), final[np.ix_(rows, cols)].mean()
                assert abs(a - b) <= 0.1 * max(b, 0.02), (rows[0], cols[0], a, b)

        def handler(scene, depsgraph):  # hands the sync depsgraph.updates, as view_update does
            vp.sync(depsgraph)
        bpy.app.handlers.depsgraph_update_post.append(handler)
        try:
            meshes_before = vp.exports["meshes"]
            mat = bpy.data.materials["Floor"]
            tex = next(n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeTexImage")
            coord = mat.node_tree.nodes.new("ShaderNodeTexCoord")
            mat.node_tree.links.new(coord.outputs["Generated"], tex.inputs["Vector"])
            bpy.context.evaluated_depsgraph_get()
            assert vp.exports["meshes"] > meshes_before
            assert vp.session.wait(lambda f: f.divider == 1, 120) is not None, vp.session.error
        finally:
            bpy.app.handlers.depsgraph_update_post.remove(handler)
    finally:
        assert vp.stop()
