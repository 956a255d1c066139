"""Procedural texture, curve and attribute nodes → program operations (the compiler half; the
kernels are ``drt.materials.procedural``; see docs/materials.md, "Procedural textures").

Each function compiles one Blender node into one operation and returns its outputs by socket
identifier. Scalar inputs travel packed three to a register (``ProgramBuilder.pack``): the
operations have six input slots, the Noise node has nine inputs. Modes encode the node's enums
in ``drt.materials.procedural``'s numbering.
"""

from __future__ import annotations

from .node_programs import (DIMENSIONS, NOISE_TYPES, OP_BRICK, OP_COMPONENT, OP_CURVES,
                            OP_GENERATED, OP_MAGIC, OP_NOISE, OP_VORONOI, OP_WAVE, OP_WHITE_NOISE,
                            RAMP_TABLE_SIZE, VORONOI_FEATURES, VORONOI_METRICS, WAVE_BANDS,
                            WAVE_PROFILES, WAVE_RINGS, Unsupported, Value, socket)


def _linked(node, name) -> bool:
    """Whether output ``name`` of ``node`` feeds anything (it is then computed)."""
    try:
        return bool(socket(node.outputs, name).is_linked)
    except KeyError:
        return False


#: inputs older Blenders lack, with the value those versions used (Noise and Voronoi before 4.0
#: had no Lacunarity/Roughness/Detail controls of these kinds; 4.1 added Offset/Gain to Noise)
_OLD_DEFAULTS = {"Lacunarity": 2.0, "Roughness": 0.5, "Detail": 0.0, "Offset": 0.0, "Gain": 1.0,
                 "Distortion": 0.0, "W": 0.0, "Smoothness": 1.0, "Exponent": 0.5, "Randomness": 1.0}


def _floats(b, node, names, ctx):
    """Float inputs by name; an input this Blender's node lacks takes the value older versions
    used (so files from 3.x/4.0 export instead of failing)."""
    out = []
    for n in names:
        try:
            out.append(b.inp(node, n, ctx, "float"))
        except KeyError:
            out.append(Value(b, const=_OLD_DEFAULTS.get(n, 0.0)))
    return out


def _vector(b, node, ctx):
    """The node's Vector input; unlinked: Generated coordinates (Cycles's texture default)."""
    from .node_programs import resolve

    src, sctx = resolve(socket(node.inputs, "Vector"), ctx)
    if src is None:
        return b.geometry(OP_GENERATED)
    return b.output(src, sctx)


def noise(b, node, out, ctx):
    dim = DIMENSIONS.index(node.noise_dimensions) + 1
    w, scale, detail, rough, lac, offs, gain, dist = _floats(
        b, node, ["W", "Scale", "Detail", "Roughness", "Lacunarity", "Offset", "Gain", "Distortion"], ctx)
    want_color = _linked(node, "Color")
    # before 4.1 the Noise node was fBM only, normalized
    kind = NOISE_TYPES[getattr(node, "noise_type", "FBM")]
    mode = (dim - 1) | kind << 2 | int(getattr(node, "normalize", True)) << 5 | int(want_color) << 6
    vec = _vector(b, node, ctx) if dim > 1 else Value(b, const=0.0)
    fac, col = b.emit(OP_NOISE, mode, [vec, b.pack(w, scale, detail), b.pack(rough, lac, offs),
                                       b.pack(gain, dist)], outputs=2)
    return {"Fac": fac, "Color": col}


def white_noise(b, node, out, ctx):
    dim = DIMENSIONS.index(node.noise_dimensions) + 1
    vec = b.inp(node, "Vector", ctx)  # no texture-coordinate default: the socket's value
    value, col = b.emit(OP_WHITE_NOISE, dim, [vec, b.inp(node, "W", ctx, "float")], outputs=2)
    return {"Value": value, "Color": col}


def voronoi(b, node, out, ctx):
    dim = DIMENSIONS.index(node.voronoi_dimensions) + 1
    feature = VORONOI_FEATURES.index(node.feature)
    mode = ((dim - 1) | feature << 2 | VORONOI_METRICS.index(node.distance) << 5
            | int(getattr(node, "normalize", False)) << 7)
    w, scale, detail, rough, lac, smooth, expo, rnd = _floats(
        b, node, ["W", "Scale", "Detail", "Roughness", "Lacunarity", "Smoothness", "Exponent",
               "Randomness"], ctx)
    vec = _vector(b, node, ctx) if dim > 1 else Value(b, const=0.0)
    pos_reg = b.new_reg() if _linked(node, "Position") else -1
    col, scalars = b.emit(OP_VORONOI, mode, [vec, b.pack(w, scale, detail), b.pack(rough, lac, smooth),
                                             b.pack(expo, rnd)], param=pos_reg, outputs=2)
    zero = Value(b, const=0.0)
    radius_mode = node.feature == "N_SPHERE_RADIUS"
    used = _linked(node, "Radius" if radius_mode else "Distance") or out.identifier in ("Distance", "Radius")
    dist = b.emit(OP_COMPONENT, 0, [scalars]) if used else zero
    w_out = b.emit(OP_COMPONENT, 1, [scalars]) if feature <= 2 and (_linked(node, "W") or out.identifier == "W") else zero
    return {"Distance": zero if radius_mode else dist,
            "Radius": dist if radius_mode else zero,
            "Color": col if feature <= 2 else zero,
            "Position": Value(b, reg=pos_reg) if pos_reg >= 0 and feature <= 2 else zero,
            "W": w_out}


def wave(b, node, out, ctx):
    mode = (int(node.wave_type == "RINGS") | WAVE_BANDS.index(node.bands_direction) << 1
            | WAVE_RINGS.index(node.rings_direction) << 3 | WAVE_PROFILES.index(node.wave_profile) << 5)
    scale, dist, detail, dscale, drough, phase = _floats(
        b, node, ["Scale", "Distortion", "Detail", "Detail Scale", "Detail Roughness", "Phase Offset"], ctx)
    col, fac = b.emit(OP_WAVE, mode, [_vector(b, node, ctx), b.pack(scale, dist, detail),
                                      b.pack(dscale, drough, phase)], outputs=2)
    return {"Color": col, "Fac": fac}


def magic(b, node, out, ctx):
    scale, dist = _floats(b, node, ["Scale", "Distortion"], ctx)
    col, fac = b.emit(OP_MAGIC, int(node.turbulence_depth), [_vector(b, node, ctx), b.pack(scale, dist)],
                      outputs=2)
    return {"Color": col, "Fac": fac}


def brick(b, node, out, ctx):
    c1, c2, mortar = (b.inp(node, n, ctx) for n in ("Color1", "Color2", "Mortar"))
    scale, msize, msmooth, bias, bw, rh = _floats(
        b, node, ["Scale", "Mortar Size", "Mortar Smooth", "Bias", "Brick Width", "Row Height"], ctx)
    off = len(b.data)
    b.data += [float(node.offset), float(node.offset_frequency), float(node.squash),
               float(node.squash_frequency)]
    col, fac = b.emit(OP_BRICK, 0, [_vector(b, node, ctx), c1, c2, mortar, b.pack(scale, msize, msmooth),
                                    b.pack(bias, bw, rh)], param=off, outputs=2)
    return {"Color": col, "Fac": fac}


def _curve_table(mapping, kind) -> list[float]:
    """[min_x, max_x, extrapolate, 0] + RAMP_TABLE_SIZE RGBA entries: Blender's own
    ``CurveMapping.evaluate`` sampled over the x range of the curves' points, as Cycles's sync
    bakes curves (RGB: each channel's curve of the combined curve, R(C(t)))."""
    mapping.initialize()
    curves = list(mapping.curves)
    n = {"RGB": 4, "VECTOR": 3, "FLOAT": 1}[kind]
    xs = [p.location[0] for c in curves[:n] for p in c.points]
    lo, hi = min(xs), max(xs)
    out = [lo, hi, float(mapping.extend == "EXTRAPOLATED"), 0.0]
    for i in range(RAMP_TABLE_SIZE):
        t = lo + i / (RAMP_TABLE_SIZE - 1) * (hi - lo)
        if kind == "RGB":
            c = mapping.evaluate(curves[3], t)
            out += [mapping.evaluate(curves[k], c) for k in range(3)] + [0.0]
        elif kind == "VECTOR":
            out += [mapping.evaluate(curves[k], t) for k in range(3)] + [0.0]
        else:
            v = mapping.evaluate(curves[0], t)
            out += [v, v, v, 0.0]
    return out


def curves(b, node, out, ctx):
    k = node.bl_idname
    kind = {"ShaderNodeRGBCurve": "RGB", "ShaderNodeVectorCurve": "VECTOR", "ShaderNodeFloatCurve": "FLOAT"}[k]
    off = len(b.data)
    b.data += _curve_table(node.mapping, kind)
    fac = b.input(node, node.inputs[0], ctx, "float")  # "Fac" ("Factor" on the Float Curve)
    val = b.input(node, node.inputs[1], ctx, "float" if kind == "FLOAT" else None)
    return b.emit(OP_CURVES, int(kind == "FLOAT"), [fac, val], param=off)


def color_attribute(b, node, out, ctx):
    """Color Attribute node: the named colour attribute (empty: the render colour attribute);
    each output is its own attribute array, stored only if used."""
    kind = "alpha:" if out.identifier == "Alpha" else "attr:"
    return b.attribute(kind + node.layer_name)


def attribute(b, node, out, ctx):
    if node.attribute_type != "GEOMETRY" or not node.attribute_name:
        raise Unsupported(node)  # object / instancer / view-layer attributes: later
    name = node.attribute_name
    if out.identifier == "Fac":
        return b.attribute("fac:" + name)
    if out.identifier == "Alpha":
        return b.attribute("alpha:" + name)
    return b.attribute("attr:" + name)


PROCEDURAL_COMPILERS = {
    "ShaderNodeTexNoise": noise, "ShaderNodeTexWhiteNoise": white_noise,
    "ShaderNodeTexVoronoi": voronoi, "ShaderNodeTexWave": wave, "ShaderNodeTexMagic": magic,
    "ShaderNodeTexBrick": brick, "ShaderNodeRGBCurve": curves, "ShaderNodeVectorCurve": curves,
    "ShaderNodeFloatCurve": curves, "ShaderNodeVertexColor": color_attribute,
    "ShaderNodeAttribute": attribute,
}
