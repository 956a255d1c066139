"""Converter and input nodes built from existing program operations (no kernel of their own):
RGB to BW, Normal, Vector Rotate, Blackbody, Camera Data and Light Falloff (see docs/materials.md,
"Converter nodes").

Each function compiles one Blender node and returns its outputs by socket identifier, as
``procedural_nodes`` does. They follow Cycles's SVM nodes (``svm_node_normal``,
``svm_node_vector_rotate``, ``svm_node_blackbody``) and are composed of the vector-math, math
and mapping operations the program interpreter already runs, so a material that uses them
compiles no new kernel code. Where Cycles's own arithmetic differs from the composition only
for degenerate input (a zero axis or normal), the constant case follows Cycles exactly and the
linked case takes the composed operation's safe value (noted per node).
"""

from __future__ import annotations

import numpy as np

from .. import compat
from .node_programs import (MAPPING_TYPES, MATH_OPS, OP_COMPONENT, OP_MAPPING, OP_MATH, OP_VMATH,
                            POINT_MISC, VMATH_OPS, Unsupported, Value, socket)


def _vmath(b, op, a, bb=None, scale=None):
    """One vector-math operation (Cycles's ``svm_vector_math``) on Values: inputs A, B and the
    Scale (unused ones zero / one, as the node's own sockets would give)."""
    zero = Value(b, const=0.0)
    return b.emit(OP_VMATH, VMATH_OPS.index(op), [a, zero if bb is None else bb, zero,
                                                  Value(b, const=1.0) if scale is None else scale])


def _math(b, op, x, y=None):
    """One math operation on float Values (component 0 of each register)."""
    zero = Value(b, const=0.0)
    return b.emit(OP_MATH, MATH_OPS.index(op), [x, zero if y is None else y, zero])


def rgb_to_bw(b, node, out, ctx):
    """RGB to BW: the colour's luminance, the same conversion as a colour plugged into a float
    socket (Cycles's ``svm_node_convert`` / ``linear_rgb_to_gray``)."""
    return {out.identifier: b.inp(node, "Color", ctx, "float")}


def _normal_direction(node) -> np.ndarray:
    """The Normal node's direction (its Normal output's value), normalised as Cycles does."""
    d = np.array(socket(node.outputs, "Normal").default_value[:3], dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        return d / np.linalg.norm(d)


def normal(b, node, out, ctx):
    """Normal: outputs the node's (normalised) direction and its dot product with the
    normalised input vector. A zero input gives 0 where Cycles's plain ``normalize`` would give
    NaN (the vector-math NORMALIZE is Cycles's safe one)."""
    direction = _normal_direction(node)
    v = b.inp(node, "Normal", ctx)
    if v.is_const:
        n = np.linalg.norm(v.const)
        dot = float(np.dot(direction, v.const / n)) if n > 0 else 0.0
        dot_v = Value(b, const=dot)
    else:
        dot_v = _vmath(b, "DOT_PRODUCT", Value(b, const=direction), _vmath(b, "NORMALIZE", v))
    return {socket(node.outputs, "Normal").identifier: Value(b, const=direction),
            socket(node.outputs, "Dot").identifier: dot_v}


_AXES = {"X_AXIS": (1.0, 0.0, 0.0), "Y_AXIS": (0.0, 1.0, 0.0), "Z_AXIS": (0.0, 0.0, 1.0)}


def vector_rotate(b, node, out, ctx):
    """Vector Rotate (Cycles's ``svm_node_vector_rotate``). Euler XYZ is the Mapping node's
    rotation about the centre (its VECTOR type; inverted, its TEXTURE type, which applies the
    transposed rotation); the axis types are Rodrigues's formula,
    p cos θ + (a × p) sin θ + a (a · p)(1 − cos θ) with p = vector − centre, a the unit axis,
    which expands to the same matrix Cycles's ``rotate_around_axis`` builds. A constant zero
    axis leaves the vector unrotated, as in Cycles; a linked one that is zero gives
    p cos θ + centre (the safe normalisation's zero axis)."""
    kind = node.rotation_type
    vec = b.inp(node, "Vector", ctx)
    centre = b.inp(node, "Center", ctx)
    p = vec - centre
    if kind == "EULER_XYZ":
        rot = b.inp(node, "Rotation", ctx)
        mode = MAPPING_TYPES.index("TEXTURE" if node.invert else "VECTOR")
        rotated = b.emit(OP_MAPPING, mode, [p, Value(b, const=0.0), rot, Value(b, const=1.0)])
        return {out.identifier: rotated + centre}
    if kind in _AXES:
        axis = Value(b, const=_AXES[kind])
    elif kind == "AXIS_ANGLE":
        axis = b.inp(node, "Axis", ctx)
        if axis.is_const:
            length = float(np.linalg.norm(axis.const))
            if length == 0.0:
                return {out.identifier: vec}
            axis = Value(b, const=axis.const / length)
        else:
            axis = _vmath(b, "NORMALIZE", axis)
    else:
        raise Unsupported(node)
    angle = b.inp(node, "Angle", ctx, "float")
    if node.invert:
        angle = _math(b, "MULTIPLY", angle, Value(b, const=-1.0)) if not angle.is_const \
            else Value(b, const=-float(angle.const[0]))
    if angle.is_const:
        c, s = np.cos(angle.const[0]), np.sin(angle.const[0])
        cos_t, sin_t, one_minus = Value(b, const=c), Value(b, const=s), Value(b, const=1.0 - c)
    else:
        cos_t = _math(b, "COSINE", angle)
        sin_t = _math(b, "SINE", angle)
        one_minus = _math(b, "SUBTRACT", Value(b, const=1.0), cos_t)
    along = _vmath(b, "DOT_PRODUCT", axis, p)
    term_cos = _vmath(b, "SCALE", p, scale=cos_t)
    term_sin = _vmath(b, "SCALE", _vmath(b, "CROSS_PRODUCT", axis, p), scale=sin_t)
    term_axis = _vmath(b, "SCALE", axis, scale=_math(b, "MULTIPLY", along, one_minus))
    return {out.identifier: term_cos + term_sin + term_axis + centre}


def blackbody_rgb(t: float) -> np.ndarray:
    """The Blackbody node's colour at temperature ``t`` (kelvin): Cycles's fit in Rec.709
    (Blender's default scene-linear space; the core's ``drt.volumes.media.blackbody_rgb_of``,
    which the Principled Volume's blackbody uses too), negative components clamped to 0 as
    ``svm_node_blackbody`` does. Not normalised: the fit's own scale (≈ 1 at 6500 K)."""
    return np.maximum(compat.core_module("volumes.media").blackbody_rgb_of(float(t)), 0.0)


def blackbody(b, node, out, ctx):
    """Blackbody with a constant temperature (the usual use: a light's or an emitter's colour),
    folded to its colour here. A temperature driven by other nodes is not supported: the
    export warns and the driven socket keeps its own value, as for any node it cannot compile."""
    t = b.inp(node, "Temperature", ctx, "float")
    if not t.is_const:
        raise Unsupported(node)
    return {out.identifier: Value(b, const=blackbody_rgb(float(t.const[0])))}


def camera_data(b, node, out, ctx):
    """Camera Data (``svm_node_camera``): the shading point in camera space (Cycles's
    worldtocamera, +z in front of the camera: the Texture Coordinate node's Camera output)
    gives View Vector = its direction, View Z Depth = its z, View Distance = its length."""
    p = b._tex_coord(node, "Camera")
    outs = {o.name: o.identifier for o in node.outputs}
    return {outs["View Vector"]: _vmath(b, "NORMALIZE", p),
            outs["View Z Depth"]: b.emit(OP_COMPONENT, 2, [p]),
            outs["View Distance"]: _vmath(b, "LENGTH", p)}


def light_falloff(b, node, out, ctx):
    """Light Falloff (``svm_node_light_falloff``), with L the ray's length (Light Path's Ray
    Length): Quadratic = Strength, Linear = Strength·L, Constant = Strength·L², each × L²/(Smooth
    + L²) when Smooth > 0. Quadratic with a zero Smooth is the Strength itself: a constant one
    folds (so a light's tree with it still folds, `light_nodes`)."""
    strength = b.inp(node, "Strength", ctx, "float")
    smooth = b.inp(node, "Smooth", ctx, "float")
    no_smooth = smooth.is_const and not smooth.const[0] > 0.0
    kind = next(o.name for o in node.outputs if o.identifier == out.identifier)
    if kind == "Quadratic" and no_smooth:
        return {out.identifier: strength}
    length = b.point(POINT_MISC, 1)
    squared = _math(b, "MULTIPLY", length, length)
    value = {"Quadratic": strength, "Linear": _math(b, "MULTIPLY", strength, length),
             "Constant": _math(b, "MULTIPLY", strength, squared)}[kind]
    if no_smooth:
        return {out.identifier: value}
    smoothed = _math(b, "MULTIPLY", value, _math(b, "DIVIDE", squared, _math(b, "ADD", smooth, squared)))
    if smooth.is_const:
        return {out.identifier: smoothed}
    # Cycles smooths only where Smooth > 0: value + (Smooth > 0)·(smoothed − value)
    on = _math(b, "GREATER_THAN", smooth, Value(b, const=0.0))
    return {out.identifier: _math(b, "ADD", value, _math(b, "MULTIPLY", on, _math(b, "SUBTRACT", smoothed, value)))}


def vector_map_range(b, node, out, ctx):
    """Map Range on vectors (``svm_node_vector_map_range``), per component: factor =
    (v − from min) / (from max − from min) (0 where the range is empty), Stepped
    ⌊factor·(steps + 1)⌋ / steps (0 for no steps), Smooth Step 3f² − 2f³ and Smoother Step
    6f⁵ − 15f⁴ + 10f³ of the factor clamped to [0, 1]; result = to min + factor·(to max − to min),
    clamped between the two when the node clamps."""
    from .node_programs import _first

    def vec(name):
        return b.input(node, _first(node.inputs, name, "VECTOR"), ctx)

    v, f_min, f_max, t_min, t_max = (vec(n) for n in ("Vector", "From Min", "From Max", "To Min", "To Max"))
    factor = _vmath(b, "DIVIDE", v - f_min, f_max - f_min)  # (VMATH DIVIDE is Cycles's safe one)
    kind = node.interpolation_type
    if kind == "STEPPED":
        steps = vec("Steps")
        factor = _vmath(b, "DIVIDE", _vmath(b, "FLOOR", factor * (steps + 1.0)), steps)
    elif kind in ("SMOOTHSTEP", "SMOOTHERSTEP"):
        f = _vmath(b, "MINIMUM", _vmath(b, "MAXIMUM", factor, Value(b, const=0.0)), Value(b, const=1.0))
        if kind == "SMOOTHSTEP":
            factor = (3.0 - f * 2.0) * (f * f)
        else:
            factor = f * f * f * (f * (f * 6.0 - 15.0) + 10.0)
    result = t_min + factor * (t_max - t_min)
    if node.clamp:
        result = _vmath(b, "MINIMUM", _vmath(b, "MAXIMUM", result, _vmath(b, "MINIMUM", t_min, t_max)),
                        _vmath(b, "MAXIMUM", t_min, t_max))
    return {out.identifier: result}


CONVERTER_COMPILERS = {
    "ShaderNodeRGBToBW": rgb_to_bw, "ShaderNodeNormal": normal,
    "ShaderNodeVectorRotate": vector_rotate, "ShaderNodeBlackbody": blackbody,
    "ShaderNodeCameraData": camera_data, "ShaderNodeLightFalloff": light_falloff,
}
