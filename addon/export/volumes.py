"""Volume shaders → the core's homogeneous media (drt.volumes.media, docs/volumes.md).

The Volume input of a Material Output (or World Output) is followed through Add and Mix
Shaders to Principled Volume, Volume Absorption, Volume Scatter and Emission nodes; their
inputs must be constant (a textured input warns and uses the socket's value: heterogeneous media
are not supported yet). Coefficients follow Cycles 5.0 (drt.volumes.media.principled_volume…).
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


def volume_medium(exporter, out_node, problems: list) -> dict | None:
    """The medium of ``out_node``'s Volume input (None: unlinked or black). ``exporter``: a
    ``MaterialExporter`` (its constant-input readers)."""
    sock = out_node.inputs.get("Volume") if out_node is not None else None
    if sock is None:
        return None
    src, ctx = resolve(sock, ())
    if src is None:
        return None
    return _medium(exporter, src, ctx, 1.0, problems, 0)


def _medium(ex, sock, ctx, weight, problems, depth):
    if depth > 32 or weight <= 0.0:
        return None
    node = sock.node
    kind = node.bl_idname
    if kind == "ShaderNodeAddShader":
        parts = []
        for inp in node.inputs[:2]:
            s, c = resolve(inp, ctx)
            parts.append(_medium(ex, s, c, weight, problems, depth + 1) if s is not None else None)
        return add_media(*parts)
    if kind == "ShaderNodeMixShader":
        fac = min(max(ex._const_value(node, ("Fac", "Factor"), problems, 0.5, ctx), 0.0), 1.0)
        parts = []
        for inp, f in ((node.inputs[1], 1.0 - fac), (node.inputs[2], fac)):
            s, c = resolve(inp, ctx)
            parts.append(_medium(ex, s, c, weight * f, problems, depth + 1) if s is not None and f > 0 else None)
        return add_media(*parts)
    if kind == "ShaderNodeVolumePrincipled":
        for name in ("Density Attribute", "Color Attribute", "Temperature Attribute"):
            s = node.inputs.get(name)
            if s is not None and s.is_linked:
                problems.append(f"'{node.name}' {name} unsupported")
        return principled_volume(
            color=ex._const_color(node, "Color", problems, (0.5, 0.5, 0.5), ctx),
            density=ex._const_value(node, "Density", problems, 1.0, ctx),
            anisotropy=ex._const_value(node, "Anisotropy", problems, 0.0, ctx),
            absorption_color=ex._const_color(node, "Absorption Color", problems, (0.0, 0.0, 0.0), ctx),
            emission_strength=ex._const_value(node, "Emission Strength", problems, 0.0, ctx),
            emission_color=ex._const_color(node, "Emission Color", problems, (1.0, 1.0, 1.0), ctx),
            blackbody_intensity=ex._const_value(node, "Blackbody Intensity", problems, 0.0, ctx),
            blackbody_tint=ex._const_color(node, "Blackbody Tint", problems, (1.0, 1.0, 1.0), ctx),
            temperature=ex._const_value(node, "Temperature", problems, 1000.0, ctx),
            weight=weight)
    if kind == "ShaderNodeVolumeAbsorption":
        return volume_absorption(ex._const_color(node, "Color", problems, (0.8, 0.8, 0.8), ctx),
                                 ex._const_value(node, "Density", problems, 1.0, ctx), weight)
    if kind == "ShaderNodeVolumeScatter":
        phase = getattr(node, "phase", "HENYEY_GREENSTEIN")
        if phase != "HENYEY_GREENSTEIN":
            problems.append(f"'{node.name}' phase {phase} rendered as Henyey-Greenstein")
        return volume_scatter(ex._const_color(node, "Color", problems, (0.8, 0.8, 0.8), ctx),
                              ex._const_value(node, "Density", problems, 1.0, ctx),
                              ex._const_value(node, "Anisotropy", problems, 0.0, ctx), weight)
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
