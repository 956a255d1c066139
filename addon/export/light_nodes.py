"""A light's node tree (Light > Nodes in Cycles) as a constant colour factor.

Cycles shades a light with "Use Nodes" on by its tree: the emission the Light Output receives
multiplies the light's own colour and power (measured in Cycles 5.0: a point light's Emission
Strength 2 doubles its light, an Emission Color (1, 0.5, 0.25) tints it, a Blackbody at 3000 K
feeding the colour multiplies by that blackbody colour, unnormalised). DRT's lights carry one
colour, so the tree is folded at export: an Emission (or a Mix/Add of emissions) whose Color
and Strength are constants — unlinked sockets, RGB / Value nodes, a Blackbody of constant
temperature, through groups and reroutes — becomes an RGB factor. Anything else (textures, IES,
Light Falloff, and Math nodes, which the program compiler does not fold) the export warns
about and uses the driven sockets' own values.
"""

from __future__ import annotations

import numpy as np

from .node_programs import ImageTable, ProgramBuilder, Unsupported, resolve


def _light_output(tree):
    """The Light Output node Cycles uses (active, targeting Cycles or all engines)."""
    outputs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputLight"]
    for n in outputs:
        if n.is_active_output and getattr(n, "target", "ALL") in ("CYCLES", "ALL"):
            return n
    for n in outputs:
        if getattr(n, "target", "ALL") in ("CYCLES", "ALL"):
            return n
    return outputs[0] if outputs else None


def _constant(builder, node, name, ctx, problems, kind=None):
    """The constant value of input ``name`` (a 3-vector), or its socket value with a problem
    noted when nodes that do not fold drive it."""
    sock = node.inputs[name]
    try:
        v = builder.input(node, sock, ctx, kind)
    except Unsupported as e:
        problems.append(f"{e} drives '{node.name}' {name}")
        v = None
    if v is not None and not v.is_const:
        problems.append(f"'{node.name}' {name} varies (textures, Light Falloff...)")
        v = None
    if v is None:
        d = sock.default_value
        return np.array(list(d)[:3] if hasattr(d, "__len__") else [d] * 3, dtype=np.float64)
    return np.asarray(v.const, dtype=np.float64)


def _emission(builder, sock, ctx, problems, depth=0):
    """The constant RGB emission of the shader output ``sock`` (in group context ``ctx``)."""
    node = sock.node
    kind = node.bl_idname
    if depth > 32:
        problems.append("light node tree too deep")
        return np.ones(3)
    if kind == "ShaderNodeEmission":
        return _constant(builder, node, "Color", ctx, problems) \
            * _constant(builder, node, "Strength", ctx, problems, "float")[0]
    if kind in ("ShaderNodeMixShader", "ShaderNodeAddShader"):
        parts = []
        fac = None if kind == "ShaderNodeAddShader" else \
            float(np.clip(_constant(builder, node, node.inputs[0].name, ctx, problems, "float")[0], 0.0, 1.0))
        for i, w in ((0, 1.0), (1, 1.0)) if fac is None else ((1, 1.0 - fac), (2, fac)):
            src, sctx = resolve(node.inputs[i], ctx)
            parts.append(w * _emission(builder, src, sctx, problems, depth + 1) if src is not None else np.zeros(3))
        return parts[0] + parts[1]
    problems.append(f"'{node.name}' ({kind}) is not an emission")
    return np.ones(3)


def light_node_factor(light, warnings: list, name: str) -> np.ndarray:
    """RGB factor by which ``light``'s node tree scales its colour × power: ones without
    nodes (Use Nodes off, no tree, no linked Light Output), black for an unlinked Light Output
    (Cycles emits nothing then). Problems are reported in ``warnings`` under the light's
    ``name``."""
    tree = getattr(light, "node_tree", None)
    if tree is None or not getattr(light, "use_nodes", False):
        return np.ones(3)
    out = _light_output(tree)
    if out is None:
        return np.ones(3)
    src, ctx = resolve(out.inputs["Surface"], ())
    if src is None:
        return np.zeros(3)
    problems: list[str] = []
    factor = _emission(ProgramBuilder(ImageTable()), src, ctx, problems)
    if problems:
        warnings.append(f"Light '{name}' nodes: " + "; ".join(problems) + " (rendered with constant values)")
    return np.maximum(factor, 0.0)
