"""Volume shaders → the core's homogeneous media (drt.volumes.media, docs/volumes.md).

The Volume input of a Material Output (or World Output) is followed through Add and Mix
Shaders to Principled Volume, Volume Absorption, Volume Scatter and Emission nodes. A textured
Density (a material's, not the world's) makes a heterogeneous medium: its coefficients are
exported per unit density and ``density_reg`` names the program register holding the density
(drt.volumes.hetero); other inputs must be constant (a textured one warns and uses the socket's
value), as must a density textured inside an Add/Mix of two media or next to volume emission.
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
    Density may become a program register (``density_reg``), else it warns."""
    sock = out_node.inputs.get("Volume") if out_node is not None else None
    if sock is None:
        return None
    src, ctx = resolve(sock, ())
    if src is None:
        return None
    m = _medium(exporter, src, ctx, 1.0, problems, 0, textured)
    if m is not None:
        m.pop("_fallback", None)
    return m


def _density(ex, node, problems, ctx, textured):
    """(density, Value or None): a textured Density gives (1, its Value) when ``textured``."""
    if textured:
        v = ex._value(node, "Density", problems, 1.0, ctx)
        if not isinstance(v, float):
            return 1.0, v
        return v, None
    return ex._const_value(node, "Density", problems, 1.0, ctx), None


def _with_density(ex, medium, value, problems, node):
    """Attach a textured density's register to a per-unit-density medium (or fall back)."""
    if medium is None or value is None:
        return medium
    fb = float(np.ravel(value.fallback)[0]) if getattr(value, "fallback", None) is not None else 1.0
    if max(medium["emission"]) > 0.0:
        problems.append(f"'{node.name}' textured Density with emission not supported, using its value")
        return _scaled(medium, fb)
    return dict(medium, density_reg=ex._b.reg_of(value), _fallback=fb)


def _scaled(m, k):
    """A per-unit-density medium at constant density k (emission not scaled: Cycles)."""
    return {"scatter": (np.asarray(m["scatter"]) * k).tolist(),
            "absorption": (np.asarray(m["absorption"]) * k).tolist(),
            "emission": m["emission"], "anisotropy": m["anisotropy"]}


def _constant(m, problems):
    """A part of an Add/Mix: a textured density there falls back to its constant value."""
    if m is None or "density_reg" not in m:
        return m
    problems.append("a textured volume Density inside an Add/Mix Shader of two media is not "
                    "supported, using its value")
    return _scaled(m, m["_fallback"])


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
        dens, tex = _density(ex, node, problems, ctx, textured)
        return _with_density(ex, principled_volume(
            color=ex._const_color(node, "Color", problems, (0.5, 0.5, 0.5), ctx),
            density=dens,
            anisotropy=ex._const_value(node, "Anisotropy", problems, 0.0, ctx),
            absorption_color=ex._const_color(node, "Absorption Color", problems, (0.0, 0.0, 0.0), ctx),
            emission_strength=ex._const_value(node, "Emission Strength", problems, 0.0, ctx),
            emission_color=ex._const_color(node, "Emission Color", problems, (1.0, 1.0, 1.0), ctx),
            blackbody_intensity=ex._const_value(node, "Blackbody Intensity", problems, 0.0, ctx),
            blackbody_tint=ex._const_color(node, "Blackbody Tint", problems, (1.0, 1.0, 1.0), ctx),
            temperature=ex._const_value(node, "Temperature", problems, 1000.0, ctx),
            weight=weight), tex, problems, node)
    if kind == "ShaderNodeVolumeAbsorption":
        dens, tex = _density(ex, node, problems, ctx, textured)
        return _with_density(ex, volume_absorption(
            ex._const_color(node, "Color", problems, (0.8, 0.8, 0.8), ctx), dens, weight), tex, problems, node)
    if kind == "ShaderNodeVolumeScatter":
        phase = getattr(node, "phase", "HENYEY_GREENSTEIN")
        if phase != "HENYEY_GREENSTEIN":
            problems.append(f"'{node.name}' phase {phase} rendered as Henyey-Greenstein")
        dens, tex = _density(ex, node, problems, ctx, textured)
        return _with_density(ex, volume_scatter(
            ex._const_color(node, "Color", problems, (0.8, 0.8, 0.8), ctx), dens,
            ex._const_value(node, "Anisotropy", problems, 0.0, ctx), weight), tex, problems, node)
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
