"""The world's surface shader → a constant colour or a world program (docs/materials.md, World).

The World Output's Surface is a Background (Emission is the same in a world, as Cycles), or
Add/Mix Shaders of them; its radiance is Color × Strength, summed and mixed as Cycles sums the
background closures. Color and Strength compile through the material compiler
(``node_programs.ProgramBuilder`` with ``world=True``): Environment Texture, Mapping (the usual
rotation in front of it), Texture Coordinate Generated/Object (= the ray direction), math and
colour nodes. A world whose radiance folds to a constant exports exactly the old
``{"color": …}``; otherwise ``{"color": stand-in, "program": …, "radiance_reg": r,
"map_size": [W, H]}`` with Cycles's importance-map size (`map_size`; the core builds the map at
load). The stand-in colour (viewport, light-selection
fallbacks) is the radiance with each image replaced by its mean colour.
"""

from __future__ import annotations

import numpy as np

from .node_programs import (OP_ENVIRONMENT, ImageTable, ProgramBuilder, Unsupported, Value, clamp01, constant,
                            resolve)

#: Cycles's default importance-map resolution (World > Settings > Map Resolution)
DEFAULT_MAP_RESOLUTION = 1024
_BACKGROUNDS = ("ShaderNodeBackground", "ShaderNodeEmission")


def world_surface(world, surface_sock, images: ImageTable | None, warnings: list) -> dict:
    """The ``world`` header entry for the World Output's linked Surface input."""
    images = images if images is not None else ImageTable()
    b = ProgramBuilder(images, [])
    b.world = True
    problems: list[str] = []
    src, ctx = resolve(surface_sock, ())
    radiance = np.zeros(3) if src is None else _shader(b, src, ctx, problems, 0)
    radiance = constant(radiance)
    problems += b.problems
    if problems:
        warnings.append(f"World '{world.name}': " + "; ".join(dict.fromkeys(problems)))
    if not isinstance(radiance, Value):
        return {"color": [float(max(x, 0.0)) for x in np.broadcast_to(radiance, 3)]}
    fb = radiance.fallback if radiance.fallback is not None else np.asarray(world.color[:3])
    return {"color": [float(max(x, 0.0)) for x in np.broadcast_to(fb, 3)], "program": b.to_dict(),
            "radiance_reg": b.reg_of(radiance), "map_size": map_size(world, b)}


def map_size(world, b: ProgramBuilder) -> list[int]:
    """The importance map's [width, height] as Cycles chooses it (World > Settings > Sampling):
    None → [0, 0] (not sampled: BSDF rays only); Manual → Map Resolution R × R/2; Automatic
    (the default) → the largest Environment Texture image the program reads (each side's
    maximum), else 1024 × 512."""
    cycles = getattr(world, "cycles", None)
    method = getattr(cycles, "sampling_method", "AUTOMATIC")
    if method == "NONE":
        return [0, 0]
    if method == "MANUAL":
        r = max(int(getattr(cycles, "sample_map_resolution", DEFAULT_MAP_RESOLUTION)), 2)
        return [r, r // 2]
    w = h = 0
    for op in b.ops:
        if op[0] == OP_ENVIRONMENT:
            img = b.images.images[op[10]]
            w, h = max(w, int(img["width"])), max(h, int(img["height"]))
    return [w, h] if w > 0 and h > 0 else [DEFAULT_MAP_RESOLUTION, DEFAULT_MAP_RESOLUTION // 2]


def _input(b, node, name, ctx, problems, kind):
    """A compiled input of ``node`` (constant or register); an unsupported driver falls back to
    the socket's own value, with a warning naming it."""
    sock = next((s for s in node.inputs if s.name == name and s.enabled), None)
    if sock is None:
        return Value(b, const=1.0)
    try:
        v = b.input(node, sock, ctx, kind)
    except Unsupported as e:
        problems.append(f"'{node.name}' input '{name}' is driven by {e} (unsupported), using its "
                        f"constant value")
        d = sock.default_value
        return Value(b, const=float(d) if kind == "float" else list(d)[:3])
    if not v.is_const and v.fallback is None:  # a stand-in for the viewport: the socket's value
        d = sock.default_value
        v = Value(b, reg=v.reg, fallback=float(d) if kind == "float" else list(d)[:3])
    return v


def _shader(b, out_sock, ctx, problems, depth):
    """Radiance (Value or 3-vector) of the shader output ``out_sock``."""
    node = out_sock.node
    kind = node.bl_idname
    if depth > 32:
        problems.append("shader graph too deep")
        return np.zeros(3)
    if kind in _BACKGROUNDS:
        return _input(b, node, "Color", ctx, problems, None) * _input(b, node, "Strength", ctx, problems, "float")
    if kind == "ShaderNodeAddShader":
        total = np.zeros(3)
        for inp in node.inputs[:2]:
            src, sctx = resolve(inp, ctx)
            if src is not None:
                total = _shader(b, src, sctx, problems, depth + 1) + total
        return total
    if kind == "ShaderNodeMixShader":
        fac = clamp01(_input(b, node, node.inputs[0].name, ctx, problems, "float"))
        total = np.zeros(3)
        for inp, f in ((node.inputs[1], 1.0 - fac), (node.inputs[2], fac)):
            src, sctx = resolve(inp, ctx)
            if src is not None:
                total = _shader(b, src, sctx, problems, depth + 1) * f + total
        return total
    problems.append(f"'{node.name}' ({kind}) is not a background shader, rendered black")
    return np.zeros(3)
