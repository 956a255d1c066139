"""Volume shaders → the core's homogeneous media (drt.volumes.media, docs/volumes.md).

The Volume input of a Material Output (or World Output) is followed through Add and Mix
Shaders to Principled Volume, Volume Absorption, Volume Scatter and Emission nodes. A textured
Density or Color (a material's, not the world's) makes a heterogeneous medium: coefficients per
unit density (and colour) with ``density_reg`` / ``color_reg`` naming the program registers
(drt.volumes.hetero); other inputs must be constant (a textured one warns and uses the socket's
value), as must a textured Density/Color inside an Add/Mix of two media or next to emission.
Coefficients follow Cycles 5.0 (drt.volumes.media.principled_volume…).
"""

from __future__ import annotations

import numpy as np

from .. import compat
from .node_programs import resolve



def _m():
    """The core's media conversions (bundled or installed), imported at first use: importing
    the add-on must not need the core (a Blender without it still loads and reports)."""
    return compat.core_module("volumes.media")


def add_media(*parts):
    return _m().add_media(*parts)


def principled_volume(**kw):
    return _m().principled_volume(**kw)


def scale_medium(*a, **kw):
    return _m().scale_medium(*a, **kw)


def volume_absorption(*a):
    return _m().volume_absorption(*a)


def volume_scatter(*a):
    return _m().volume_scatter(*a)


def volume_medium(exporter, out_node, problems: list, textured: bool = False) -> dict | None:
    """The medium of ``out_node``'s Volume input (None: unlinked or black). ``exporter``: a
    ``MaterialExporter`` (its input readers and program builder); ``textured``: a textured
    Density / Color may become a program register (``density_reg`` / ``color_reg``), else it
    warns."""
    sock = out_node.inputs.get("Volume") if out_node is not None else None
    if sock is None:
        return None
    src, ctx = resolve(sock, ())
    if src is None:
        return None
    m = _medium(exporter, src, ctx, 1.0, problems, 0, textured)
    if m is not None:
        m.pop("_const", None)
    return m


def _fallback(v, n):
    fb = np.ravel(np.asarray(getattr(v, "fallback", None) if getattr(v, "fallback", None) is not None
                             else [1.0] * 3, float))
    return float(fb[0]) if n == 1 else [float(x) for x in np.broadcast_to(fb[:3] if fb.size >= 3 else fb[0], 3)]


def _hetero(ex, node, problems, ctx, textured, color_name, color_default, build):
    """The medium of a volume node whose Density (and Color) may be textured. ``build(color,
    density)`` gives its coefficients (Cycles's formulas, linear in density; σs linear in the
    colour and σa in 1 − colour). A textured Density exports per unit density with
    ``density_reg``, a textured Color exports S = σs at colour 1 and A = σa at colour 0 with
    ``color_reg`` (drt.volumes.hetero); ``_const`` keeps the all-constant medium for an Add/Mix
    (where textures fall back) and for volume emission (not heterogeneous)."""
    if textured:
        dv = ex._value(node, "Density", problems, 1.0, ctx)
        cv = ex._color(node, color_name, problems, color_default, ctx) if color_name else None
    else:
        dv = ex._const_value(node, "Density", problems, 1.0, ctx)
        cv = ex._const_color(node, color_name, problems, color_default, ctx) if color_name else None
    d_tex = not isinstance(dv, (float, int))
    c_tex = cv is not None and not isinstance(cv, np.ndarray)
    d_fb = _fallback(dv, 1) if d_tex else float(dv)
    c_fb = (_fallback(cv, 3) if c_tex else cv)
    const = build(c_fb, d_fb)
    if not (d_tex or c_tex):
        return const
    if max(const["emission"]) > 0.0:
        problems.append(f"'{node.name}' textured Density/Color with emission not supported, using their values")
        return const
    dens = 1.0 if d_tex else d_fb
    if c_tex:
        m = dict(build(np.ones(3), dens))
        m["absorption"] = build(np.zeros(3), dens)["absorption"]
        m["color_reg"] = ex._b.reg_of(cv)
    else:
        m = dict(build(c_fb, dens))
    if d_tex:
        m["density_reg"] = ex._b.reg_of(dv)
    m["_const"] = const
    return m


def _constant(m, problems):
    """A part of an Add/Mix: a textured density or colour there falls back to its constant value."""
    if m is None or "_const" not in m:
        return m
    problems.append("a textured volume Density/Color inside an Add/Mix Shader of two media is not "
                    "supported, using its value")
    return m["_const"]


def _combine(parts, problems):
    live = [p for p in parts if p is not None]
    if len(live) == 1:
        return live[0]
    return add_media(*(_constant(p, problems) for p in parts))


def _medium(ex, sock, ctx, weight, problems, depth, textured=False):
    if depth > 32 or weight <= 0.0:
        return None
    node = sock.node
    kind = node.bl_idname
    if kind == "ShaderNodeAddShader":
        parts = []
        for inp in node.inputs[:2]:
            s, c = resolve(inp, ctx)
            parts.append(_medium(ex, s, c, weight, problems, depth + 1, textured) if s is not None else None)
        return _combine(parts, problems)
    if kind == "ShaderNodeMixShader":
        fac = min(max(ex._const_value(node, ("Fac", "Factor"), problems, 0.5, ctx), 0.0), 1.0)
        parts = []
        for inp, f in ((node.inputs[1], 1.0 - fac), (node.inputs[2], fac)):
            s, c = resolve(inp, ctx)
            parts.append(_medium(ex, s, c, weight * f, problems, depth + 1, textured)
                         if s is not None and f > 0 else None)
        return _combine(parts, problems)
    if kind == "ShaderNodeVolumePrincipled":
        for name in ("Density Attribute", "Color Attribute", "Temperature Attribute"):
            s = node.inputs.get(name)
            if s is not None and s.is_linked:
                problems.append(f"'{node.name}' {name} unsupported")
        anisotropy = ex._const_value(node, "Anisotropy", problems, 0.0, ctx)
        absorption_color = ex._const_color(node, "Absorption Color", problems, (0.0, 0.0, 0.0), ctx)
        emission = dict(
            emission_strength=ex._const_value(node, "Emission Strength", problems, 0.0, ctx),
            emission_color=ex._const_color(node, "Emission Color", problems, (1.0, 1.0, 1.0), ctx),
            blackbody_intensity=ex._const_value(node, "Blackbody Intensity", problems, 0.0, ctx),
            blackbody_tint=ex._const_color(node, "Blackbody Tint", problems, (1.0, 1.0, 1.0), ctx),
            temperature=ex._const_value(node, "Temperature", problems, 1000.0, ctx))
        return _hetero(ex, node, problems, ctx, textured, "Color", (0.5, 0.5, 0.5),
                       lambda c, d: principled_volume(color=c, density=d, anisotropy=anisotropy,
                                                      absorption_color=absorption_color, weight=weight,
                                                      **emission))
    if kind == "ShaderNodeVolumeAbsorption":
        return _hetero(ex, node, problems, ctx, textured, "Color", (0.8, 0.8, 0.8),
                       lambda c, d: volume_absorption(c, d, weight))
    if kind == "ShaderNodeVolumeScatter":
        phase = getattr(node, "phase", "HENYEY_GREENSTEIN")
        if phase != "HENYEY_GREENSTEIN":
            problems.append(f"'{node.name}' phase {phase} rendered as Henyey-Greenstein")
        anisotropy = ex._const_value(node, "Anisotropy", problems, 0.0, ctx)
        return _hetero(ex, node, problems, ctx, textured, "Color", (0.8, 0.8, 0.8),
                       lambda c, d: volume_scatter(c, d, anisotropy, weight))
    if kind == "ShaderNodeEmission":
        col = np.asarray(ex._const_color(node, "Color", problems, (1.0, 1.0, 1.0), ctx), float)
        strength = ex._const_value(node, "Strength", problems, 1.0, ctx)
        return scale_medium({"scatter": [0.0] * 3, "absorption": [0.0] * 3,
                             "emission": (col * max(strength, 0.0)).tolist(), "anisotropy": 0.0}, weight)
    problems.append(f"'{node.name}' ({kind}) unsupported on a Volume output")
    return None


def world_volume(world, warnings: list) -> dict | None:
    """The world's medium (its World Output's Volume input), or None."""
    from .materials import MaterialExporter

    tree = compat.world_node_tree(world) if world is not None else None
    if tree is None:
        return None
    outs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputWorld"]
    out = next((n for n in outs if n.is_active_output), outs[0] if outs else None)
    from .node_programs import ProgramBuilder

    problems: list[str] = []
    ex = MaterialExporter()
    ex._b = ProgramBuilder(ex.images, ex.attributes)  # constant inputs only: nothing is kept
    medium = volume_medium(ex, out, problems)
    if problems:
        warnings.append(f"World '{world.name}' volume: " + "; ".join(dict.fromkeys(problems)))
    return medium
