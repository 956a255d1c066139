"""Blender materials (shader node trees) → the core's lobe lists.

A core material is a SUM of lobes (DIFFUSE, GLOSSY, GLASS) plus an emitted radiance. Node trees
are evaluated symbolically from the active Material Output's Surface input, carrying a scalar
weight down Mix/Add shaders. Only constant inputs are read; a linked input that is not an RGB or
Value node falls back to the socket's own value with a warning.

Mapping (see docs/addon.md, "Materials"):

- Diffuse BSDF → DIFFUSE(color) (roughness > 0, Oren-Nayar in Cycles, is rendered as Lambert).
- Glossy BSDF → GLOSSY(color, roughness) (GGX; Cycles's Multiscatter GGX keeps slightly more
  energy at high roughness).
- Glass BSDF → GLASS(color, roughness, ior). Transparent BSDF → GLASS(color, 0, ior 1), a
  dielectric with no Fresnel and no bending, i.e. straight transmission.
- Emission → emission += color × strength.
- Mix Shader → (1 − fac)·A + fac·B; Add Shader → A + B.
- Principled BSDF, with alpha a, metallic m, transmission t, specular level s:
    a·m          · GLOSSY(base color, roughness)                     metal
    a·(1−m)·t    · GLASS(base color, roughness, ior)                 glass
    a·(1−m)(1−t) · [DIFFUSE(base·(1−F)) + GLOSSY(F·tint, roughness)] dielectric
    (1−a)        · GLASS(white, 0, ior 1)                            transparency
    emission     = a · emission color × emission strength
  where F = 2s·(F0 + (1 − F0)/21), F0 = ((ior − 1)/(ior + 1))², the cosine-weighted average of
  Schlick's Fresnel: the core's GLOSSY lobe has no Fresnel term, so the average reflectance
  stands in for it. Coat, sheen and subsurface are ignored with a warning.
- Anything else: one warning per material, and a DIFFUSE lobe of the node's color/base color
  (or the material's viewport color).
"""

import numpy as np

from .. import compat

DEFAULT_MATERIAL = {"name": "__drt_default__",
                    "lobes": [{"type": "DIFFUSE", "color": [0.8, 0.8, 0.8]}],
                    "emission": [0.0, 0.0, 0.0]}

_GLOSSY_IDS = {"ShaderNodeBsdfGlossy", "ShaderNodeBsdfAnisotropic"}
_SHARP = {"SHARP"}


def _rgb(value) -> np.ndarray:
    v = np.array(value[:3] if hasattr(value, "__len__") else [value] * 3, dtype=np.float64)
    return v


def _from_socket(link_sock):
    """The socket a link comes from, skipping reroutes and muted links; None if unlinked."""
    sock = link_sock
    seen = 0
    while sock.is_linked and seen < 64:
        link = sock.links[0]
        if getattr(link, "is_muted", False) or not getattr(link, "is_valid", True):
            return None
        node = link.from_node
        if node.bl_idname == "NodeReroute":
            sock = node.inputs[0]
            seen += 1
            continue
        return link.from_socket
    return None


class MaterialExporter:
    """Converts Blender materials to core material dicts, once each; collects warnings."""

    def __init__(self):
        self.materials: list[dict] = []
        self._index: dict = {}  # material pointer (or None) -> index
        self.warnings: list[str] = []

    def index_of(self, material) -> int:
        """Global index of a Blender material (None: the default gray diffuse)."""
        key = None if material is None else material.original.as_pointer()
        idx = self._index.get(key)
        if idx is None:
            idx = len(self.materials)
            self._index[key] = idx
            self.materials.append(DEFAULT_MATERIAL if material is None else self.convert(material))
        return idx

    # --- conversion ---------------------------------------------------------------------------

    def convert(self, material) -> dict:
        problems: list[str] = []
        tree = compat.material_node_tree(material)
        lobes: list[dict] = []
        emission = np.zeros(3)
        if tree is None:
            lobes = [{"type": "DIFFUSE", "color": list(map(float, material.diffuse_color[:3]))}]
        else:
            out = self._output_node(tree)
            surface = out.inputs.get("Surface") if out is not None else None
            src = _from_socket(surface) if surface is not None else None
            if src is None:
                # Cycles renders an unconnected surface black.
                lobes = []
            else:
                lobes, emission = self._shader(src, 1.0, problems, material, depth=0)
        lobes = [lb for lb in lobes if max(lb["color"]) > 0.0]
        if problems:
            uniq = list(dict.fromkeys(problems))
            self.warnings.append(f"Material '{material.name}': " + "; ".join(uniq))
        return {"name": material.name, "lobes": lobes,
                "emission": [float(x) for x in emission]}

    @staticmethod
    def _output_node(tree):
        outputs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial"]
        for wanted in ("CYCLES", "ALL"):
            for n in outputs:
                if n.is_active_output and n.target in (wanted, "ALL"):
                    return n
        for n in outputs:
            if n.target in ("CYCLES", "ALL"):
                return n
        return outputs[0] if outputs else None

    def _value(self, node, name, problems, default=0.0):
        """Constant float input, following links to Value nodes."""
        sock = compat.find_input(node, name)
        if sock is None:
            return default
        src = _from_socket(sock)
        if src is not None:
            if src.node.bl_idname == "ShaderNodeValue":
                return float(src.node.outputs[0].default_value)
            problems.append(f"'{node.name}' input '{sock.name}' is driven by "
                            f"'{src.node.name}' (unsupported), using its constant value")
        v = sock.default_value
        return float(v if not hasattr(v, "__len__") else v[0])

    def _color(self, node, name, problems, default=(0.8, 0.8, 0.8)):
        """Constant color input, following links to RGB / Value nodes."""
        sock = compat.find_input(node, name)
        if sock is None:
            return _rgb(default)
        src = _from_socket(sock)
        if src is not None:
            if src.node.bl_idname == "ShaderNodeRGB":
                return _rgb(src.node.outputs[0].default_value)
            if src.node.bl_idname == "ShaderNodeValue":
                return _rgb(src.node.outputs[0].default_value)
            problems.append(f"'{node.name}' input '{sock.name}' is driven by "
                            f"'{src.node.name}' (unsupported), using its constant value")
        return _rgb(sock.default_value)

    def _roughness(self, node, problems):
        dist = getattr(node, "distribution", "GGX")
        if dist in _SHARP:
            return 0.0
        if dist not in ("GGX", "MULTI_GGX"):
            problems.append(f"'{node.name}' distribution {dist} rendered as GGX")
        return min(max(self._value(node, "Roughness", problems), 0.0), 1.0)

    def _shader(self, sock, weight, problems, material, depth):
        """Lobes and emission of the shader output ``sock`` scaled by ``weight``."""
        node = sock.node
        kind = node.bl_idname
        if depth > 32:
            problems.append("shader graph too deep")
            return [], np.zeros(3)
        if getattr(node, "mute", False):
            problems.append(f"'{node.name}' is muted")
            return [], np.zeros(3)
        w = float(weight)

        if kind == "ShaderNodeBsdfDiffuse":
            if self._value(node, "Roughness", problems) > 0.0:
                problems.append(f"'{node.name}' roughness ignored (rendered as Lambert)")
            return [{"type": "DIFFUSE", "color": (w * self._color(node, "Color", problems)).tolist()}], \
                np.zeros(3)
        if kind in _GLOSSY_IDS:
            if kind == "ShaderNodeBsdfAnisotropic" and abs(self._value(node, "Anisotropy", problems)) > 0:
                problems.append(f"'{node.name}' anisotropy ignored")
            return [{"type": "GLOSSY", "color": (w * self._color(node, "Color", problems)).tolist(),
                     "roughness": self._roughness(node, problems)}], np.zeros(3)
        if kind == "ShaderNodeBsdfGlass":
            return [{"type": "GLASS", "color": (w * self._color(node, "Color", problems)).tolist(),
                     "roughness": self._roughness(node, problems),
                     "ior": max(self._value(node, "IOR", problems, 1.45), 1.0)}], np.zeros(3)
        if kind == "ShaderNodeBsdfTransparent":
            return [{"type": "GLASS", "color": (w * self._color(node, "Color", problems)).tolist(),
                     "roughness": 0.0, "ior": 1.0}], np.zeros(3)
        if kind == "ShaderNodeEmission":
            col = self._color(node, "Color", problems, (1, 1, 1))
            return [], w * col * self._value(node, "Strength", problems, 1.0)
        if kind == "ShaderNodeMixShader":
            fac = min(max(self._value(node, ("Fac", "Factor"), problems, 0.5), 0.0), 1.0)
            lobes, em = [], np.zeros(3)
            for inp, f in ((node.inputs[1], 1.0 - fac), (node.inputs[2], fac)):
                src = _from_socket(inp)
                if src is not None and f > 0.0:
                    lb, e = self._shader(src, w * f, problems, material, depth + 1)
                    lobes += lb
                    em = em + e
            return lobes, em
        if kind == "ShaderNodeAddShader":
            lobes, em = [], np.zeros(3)
            for inp in node.inputs[:2]:
                src = _from_socket(inp)
                if src is not None:
                    lb, e = self._shader(src, w, problems, material, depth + 1)
                    lobes += lb
                    em = em + e
            return lobes, em
        if kind == "ShaderNodeBsdfPrincipled":
            return self._principled(node, w, problems)

        # Unsupported: its (base) color as diffuse.
        problems.append(f"unsupported shader '{node.name}' ({kind}), rendered as diffuse")
        for name in ("Base Color", "Color"):
            if node.inputs.get(name) is not None:
                col = self._color(node, name, problems)
                break
        else:
            col = _rgb(material.diffuse_color)
        return [{"type": "DIFFUSE", "color": (w * col).tolist()}], np.zeros(3)

    def _principled(self, node, w, problems):
        base = self._color(node, "Base Color", problems)
        metallic = min(max(self._value(node, "Metallic", problems), 0.0), 1.0)
        rough = min(max(self._value(node, "Roughness", problems, 0.5), 0.0), 1.0)
        ior = max(self._value(node, "IOR", problems, 1.5), 1.0)
        alpha = min(max(self._value(node, "Alpha", problems, 1.0), 0.0), 1.0)
        trans = min(max(self._value(node, "transmission", problems), 0.0), 1.0)
        spec = max(self._value(node, "specular", problems, 0.5), 0.0)
        tint_sock = compat.find_input(node, "specular_tint")
        if tint_sock is not None and tint_sock.type == "RGBA":
            tint = self._color(node, "specular_tint", problems, (1, 1, 1))
        else:  # 3.x: a float blending white toward the base color
            t = self._value(node, "specular_tint", problems, 0.0) if tint_sock is not None else 0.0
            tint = (1.0 - t) * np.ones(3) + t * base
        em_col = self._color(node, "emission_color", problems, (0, 0, 0))
        em_strength = self._value(node, "Emission Strength", problems, 1.0) \
            if node.inputs.get("Emission Strength") is not None else 1.0
        for key in ("coat", "sheen", "subsurface"):
            if self._value(node, key, problems, 0.0) > 0.0:
                problems.append(f"'{node.name}' {key} ignored")

        f0 = ((ior - 1.0) / (ior + 1.0)) ** 2
        f_avg = min(2.0 * spec * (f0 + (1.0 - f0) / 21.0), 1.0) if ior > 1.0 else 0.0
        lobes = []
        wa = w * alpha
        if metallic > 0:
            lobes.append({"type": "GLOSSY", "color": (wa * metallic * base).tolist(), "roughness": rough})
        if trans > 0 and metallic < 1:
            lobes.append({"type": "GLASS", "color": (wa * (1 - metallic) * trans * base).tolist(),
                          "roughness": rough, "ior": ior})
        opaque = wa * (1 - metallic) * (1 - trans)
        if opaque > 0:
            lobes.append({"type": "DIFFUSE", "color": (opaque * (1 - f_avg) * base).tolist()})
            if f_avg > 0:
                lobes.append({"type": "GLOSSY", "color": (opaque * f_avg * tint).tolist(),
                              "roughness": rough})
        if alpha < 1:
            lobes.append({"type": "GLASS", "color": [w * (1 - alpha)] * 3, "roughness": 0.0,
                          "ior": 1.0})
        return lobes, wa * em_col * em_strength
