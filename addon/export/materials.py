"""Blender materials (shader node trees) → the core's lobe lists.

A core material is a SUM of lobes (DIFFUSE, GLOSSY, GLASS, ... see docs/scene-format.md) plus
an emitted radiance. Node trees
are evaluated symbolically from the active Material Output's Surface input, carrying a scalar
weight down Mix/Add shaders. Only constant inputs are read; a linked input that is not an RGB or
Value node falls back to the socket's own value with a warning.

Mapping (see docs/addon.md, "Materials"):

- Diffuse BSDF → DIFFUSE(color) (roughness > 0, Oren-Nayar in Cycles, is rendered as Lambert).
- Glossy BSDF → GLOSSY(color, roughness; Multiscatter GGX, the node's default:
  multiscatter_tint = color, Cycles's energy compensation with constant Fresnel).
- Glass BSDF → GLASS(color, roughness, ior; Multiscatter GGX: multiscatter_tint = color, Cycles's
  energy compensation). Transparent BSDF → GLASS(color, 0, ior 1), a dielectric with no Fresnel
  and no bending, i.e. straight transmission.
- Translucent BSDF → TRANSLUCENT(color), Lambert transmission.
- Refraction BSDF → REFRACTION(color, roughness, ior): GGX refraction only, no Fresnel factor
  (Beckmann is rendered as GGX, with a warning).
- Holdout → HOLDOUT(weight): cuts camera-visible hits out of the film alpha (docs/materials.md,
  "More shader nodes").
- Emission → emission += color × strength.
- Mix Shader → (1 − fac)·A + fac·B; Add Shader → A + B.
- Principled BSDF, with alpha a, metallic m, transmission t, specular level s:
    a·m          · METALLIC(clamped base, roughness, F82 tint = min(specular tint, 1),
                            multiscatter; weight a·m)                metal (a textured a·m:
                                                                     weight_reg, per hit)
    a·(1−m)·t    · GLASS(sqrt(clamped base), roughness, ior,         glass (Cycles's
                         reflection_weight a·(1−m)·t,                generalized-Schlick
                         multiscatter_tint sqrt(base))               glass: untinted reflection)
    a·(1−m)(1−t) · [DIELECTRIC_SPECULAR(white, roughness, eta, tint, multiscatter)
                    + DIFFUSE(base, layer → the specular lobe)]      dielectric (Principled v2)
    (1−a)        · GLASS(white, 0, ior 1)                            transparency
    emission     = a · emission color × emission strength
  where eta is the IOR after Specular IOR Level (F0 × 2s, back to an IOR; no specular lobe when
  eta = 1) and multiscatter = distribution "Multiscatter GGX". The core scales the layered
  lobes per hit by 1 − the specular layer's albedo E(wo) (docs/materials.md, "Principled
  dielectric layering").
  Sheen and coat lie on top of all of the above (Cycles's order, top first; docs/materials.md
  "Principled coat and sheen"), with sheen weight w_sh, tint t_sh, coat weight w_c, tint t_c:
    a·w_sh·t_sh  · SHEEN(sheen roughness; layer_weight w_sh·max(t_sh))
    a·w_c        · DIELECTRIC_SPECULAR(white, coat roughness, coat IOR, multiscatter;
                                       layer → sheen, layer_weight w_c, coat_tint t_c)
  and metal, glass and the specular layer carry "layer" → the coat (or the sheen): the core
  scales them per hit by each layer's 1 − k·albedo(wo) and the coat tint's absorption. Weights
  and tints may be textured (k and the tint then come from registers), so may the coat IOR
  ("ior_reg"); a Coat Normal that differs from Normal warns (Normal's shading normal used);
  the Principled's emission lies under its coat/sheen ("emission_layer": camera and BSDF rays
  see it attenuated per view angle, as Cycles 5.0; light samples do not).
  Subsurface weight w_s splits the DIFFUSE lobe (Cycles's "Diffuse/Subsurface component"):
    DIFFUSE(base·(1−w_s)) + SUBSURFACE(clamp(base)·w_s, radius × scale, method,
    ior: IOR (Random Walk) or Subsurface IOR (Skin), roughness, anisotropy, weight = the scalar
    factor of the colour; both layered under the specular lobe) — docs/subsurface.md. Radius, scale, IORs and anisotropy are
    constant-only.
- Sheen BSDF → SHEEN(color, roughness) (Microfiber) or VELVET(color, sigma = roughness)
  (Ashikhmin; the legacy Velvet node too).
- Subsurface Scattering node → SUBSURFACE(color, radius × scale, falloff, IOR, roughness:
  sqrt(Roughness) (Cycles uses the node's roughness as the GGX alpha), anisotropy).
- Anything else (Toon, Hair, Principled Hair, Specular BSDF (EEVEE), Ray Portal, ...): one
  warning per material naming the node, and a DIFFUSE lobe of the node's color/base color (or
  the material's viewport color); docs/materials.md lists the fallbacks.

Textures (docs/materials.md): a linked input is compiled by ``node_programs`` into the
material's *program*; the arithmetic above is written on ``Value``s, so a textured base colour,
roughness, metallic, mix factor or emission gives lobes whose colour / roughness come from
program registers (``color_reg`` / ``roughness_reg`` / ``emission_reg``), and constant inputs
fold to today's constant lobes. Node groups, reroutes and muted nodes are followed at the
shader level too. Alpha, metallic and transmission may be textured (alpha cut-outs), and the
coat and sheen weights, tints and roughnesses, and IOR, Coat IOR, Specular IOR Level and
Specular Tint (the lobes' "ior_reg" / "ior_level_reg" / "tint_reg": eta, f0·tint and the F82
tint per hit; docs/materials.md "Textured IOR and tint"). Thin Film warns (not rendered).
"""

import numpy as np

from .. import compat
from .volumes import volume_medium
from .node_programs import (VMATH_OPS, ImageTable, OP_VMATH, ProgramBuilder, Unsupported, Value, clamp01,
                            constant, maybe_positive, resolve)

#: a constant Normal input (rare) still goes through a register: normalised once per hit
OP_VMATH_NORMALIZE = (OP_VMATH, VMATH_OPS.index("NORMALIZE"))

DEFAULT_MATERIAL = {"name": "__drt_default__",
                    "lobes": [{"type": "DIFFUSE", "color": [0.8, 0.8, 0.8]}],
                    "emission": [0.0, 0.0, 0.0],
                    "cryptomatte": "default_surface"}  # (Cycles's default shader's name)

_GLOSSY_IDS = {"ShaderNodeBsdfGlossy", "ShaderNodeBsdfAnisotropic"}
_SHARP = {"SHARP"}
#: smallest representative colour of a program-driven lobe: the table drops lobes below
#: CLOSURE_WEIGHT_CUTOFF (1e-5), which would detach the lobe from its register
MIN_PLACEHOLDER = 1e-4
#: smallest stand-in IOR of a lobe whose IOR comes per hit from a register: an IOR of 1 would
#: make the stand-in lobe unselectable (zero average albedo) or a straight transmission
TEXTURED_IOR_FLOOR = 1.01
#: lobe keys of the per-hit Fresnel registers (drt.materials.program_format.IOR_REG_KEYS)
IOR_REG_KEYS = ("ior_reg", "ior_level_reg", "tint_reg")


def _rgb(value) -> np.ndarray:
    v = np.array(value[:3] if hasattr(value, "__len__") else [value] * 3, dtype=np.float64)
    return v


def _from_socket(link_sock):
    """The socket a link comes from, skipping reroutes, muted links and nodes, node groups;
    None if unlinked."""
    return resolve(link_sock, ())[0]


def _normal_key(node, name, ctx):
    """Identity of what drives a normal input (None: unlinked), to compare two of them."""
    sock = node.inputs.get(name)
    src, sctx = resolve(sock, ctx) if sock is not None else (None, ())
    return None if src is None else (src.node.as_pointer(), src.identifier, tuple(n.as_pointer() for n in sctx))


def _above_cutoff(x) -> bool:
    """A layer weight that may exceed Cycles's CLOSURE_WEIGHT_CUTOFF (1e-5) somewhere."""
    return isinstance(x, Value) and maybe_positive(x) or not isinstance(x, Value) and x > 1e-5


def _representative(v: Value, floor: float) -> list:
    """The constant standing for a program-driven value: its fallback (0.5 if unknown), each
    component at least ``floor``."""
    fb = v.fallback if v.fallback is not None else np.full(3, 0.5)
    return [float(max(x, floor)) for x in np.broadcast_to(fb, 3)]


def _stand_in(v, lo: float) -> float:
    """A float input's constant (its representative if it is a Value), at least ``lo``."""
    return max(_representative(v, lo)[0] if isinstance(v, Value) else float(v), lo)


def conductor_fresnel(cos_i, n, k):
    """Unpolarised Fresnel reflectance of a conductor of complex IOR n + ik (per channel) at
    incidence cosine ``cos_i`` (the exact formula Cycles's Physical Conductor evaluates)."""
    c2 = cos_i * cos_i
    s2 = 1.0 - c2
    t0 = n * n - k * k - s2
    a2b2 = np.sqrt(t0 * t0 + 4.0 * n * n * k * k)
    a = np.sqrt(0.5 * (a2b2 + t0))
    t1, t2 = a2b2 + c2, 2.0 * cos_i * a
    rs = (t1 - t2) / (t1 + t2)
    t3, t4 = c2 * a2b2 + s2 * s2, t2 * s2
    return 0.5 * (rs + rs * (t3 - t4) / (t3 + t4))


def conductor_f82(n, k):
    """(F0, F82 tint) of the F82-tint model that meets the conductor's Fresnel at normal
    incidence and at cos θ = 1/7, where the model's tint is defined (Cycles's
    ``bsdf_microfacet_setup_fresnel_f82_tint``: F(1/7) = Schlick(F0, 1/7) × tint). Within
    ~2 % of the exact Fresnel at every angle on metals' measured n, k (5 % at grazing angles
    in gold's blue; docs/decisions.md); the tint is clamped to [0, 1] as the lobe's is."""
    f0 = conductor_fresnel(1.0, n, k)
    schlick_82 = f0 + (1.0 - f0) * (6.0 / 7.0) ** 5
    return f0, np.clip(conductor_fresnel(1.0 / 7.0, n, k) / schlick_82, 0.0, 1.0)


def _multiscatter_tint(color) -> list:
    """Fss of Cycles's Multiscatter GGX compensation (glass, glossy), in [0, 1]: the colour, or for a
    program-driven one its constant stand-in (the compensation is per material, not per hit)."""
    c = _representative(color, 0.0) if isinstance(color, Value) else np.broadcast_to(color, 3)
    return [float(min(max(x, 0.0), 1.0)) for x in c]


class MaterialExporter:
    """Converts Blender materials to core material dicts, once each; collects warnings."""

    def __init__(self):
        self.materials: list[dict] = []
        self._index: dict = {}  # material pointer (or None) -> index
        self.warnings: list[str] = []
        self.images = ImageTable()
        self.attributes: list[str] = []  # named per-corner attributes programs read
        self._b = None

    def index_of(self, material) -> int:
        """Global index of a Blender material (None: the default gray diffuse)."""
        key = None if material is None else material.original.as_pointer()
        idx = self._index.get(key)
        if idx is None:
            idx = len(self.materials)
            self._index[key] = idx
            self.materials.append(DEFAULT_MATERIAL if material is None else self.convert(material))
        return idx

    def reads_object_info(self) -> bool:
        """Whether any material program reads Object Info (objects then carry it)."""
        from .node_programs import OP_OBJECT_INFO, reads_object_transform

        # object-space inputs read the object's transform from the same per-object table
        return any(op[0] == OP_OBJECT_INFO or reads_object_transform(op) for m in self.materials
                   for op in (m.get("program") or {}).get("ops", []))

    def reads(self, indices) -> dict:
        """Geometry inputs the programs of the materials with these global indices read:
        {"uv" / "generated" / "object_coords": None, named attribute ("uv:Name"): its index in
        ``attributes``}."""
        from .node_programs import OP_ATTRIBUTE, OP_GENERATED, OP_OBJECT, OP_UV

        names = {OP_UV: "uv", OP_GENERATED: "generated", OP_OBJECT: "object_coords"}
        out = {}
        for i in indices:
            prog = self.materials[int(i)].get("program")
            for op in (prog or {}).get("ops", []):
                if op[0] in names:
                    out[names[op[0]]] = None
                elif op[0] == OP_ATTRIBUTE:
                    out[self.attributes[op[10]]] = op[10]
        return out

    # --- conversion ---------------------------------------------------------------------------

    def convert(self, material) -> dict:
        problems: list[str] = []
        tree = compat.material_node_tree(material)
        lobes: list[dict] = []
        emission = np.zeros(3)
        self._b = ProgramBuilder(self.images, self.attributes)
        self._normal = None  # (source key, Value) of the first BSDF Normal input that is linked
        self._coat_normal = None  # (source key, Value or "SMOOTH") of the first coat with its own normal
        self._disp_normal = None  # the Displacement's bumped normal (Value), if any
        self._emitters = 0  # shaders that may emit (Emission, Principled with emission)
        self._emission_layer = None  # the lowest coat / sheen lobe over a Principled's emission
        self._b.material_pass_index = int(getattr(material, "pass_index", 0))
        if tree is None:
            lobes = [{"type": "DIFFUSE", "color": list(map(float, material.diffuse_color[:3]))}]
        else:
            out = self._output_node(tree)
            surface = out.inputs.get("Surface") if out is not None else None
            src, ctx = resolve(surface, ()) if surface is not None else (None, ())
            if src is None:
                # Cycles renders an unconnected surface black.
                lobes = []
            else:
                # first: the displacement's bump sets the N every later input reads
                disp_normal = self._displacement(material, out, problems)
                self._disp_normal = disp_normal
                lobes, emission = self._shader(src, ctx, 1.0, problems, material, depth=0)
                if disp_normal is not None and self._normal is None:
                    self._normal = (None, disp_normal)
        medium = volume_medium(self, out, problems, textured=True) if tree is not None else None
        result = {"name": material.name, "lobes": [], "emission": [0.0, 0.0, 0.0]}
        if getattr(material, "pass_index", 0):  # (the Material Index pass)
            result["pass_index"] = int(material.pass_index)
        if medium is not None:  # a Volume output: the mesh bounds a medium (drt.volumes)
            result["volume"] = medium
            if src is None:
                result["surface"] = False  # no Surface shader: rays pass its faces (Cycles)
        index_of = {}  # id of an exported lobe dict -> its index in result["lobes"]
        for lb in lobes:
            entry = self._lobe(lb)
            if entry is not None:
                index_of[id(lb)] = len(result["lobes"])
                result["lobes"].append(entry)
        for lb, entry in zip([lb for lb in lobes if id(lb) in index_of], result["lobes"]):
            top = lb.get("layer")
            while top is not None and id(top) not in index_of:  # a black layer: the one above it
                top = top.get("layer")
            if top is not None:
                entry["layer"] = index_of[id(top)]
        emission = constant(emission)
        if isinstance(emission, Value):
            result["emission_reg"] = self._b.reg_of(emission)
            result["emission"] = _representative(emission, 0.0)
        else:
            result["emission"] = [float(x) for x in np.broadcast_to(emission, 3)]
        if self._emission_layer is not None:
            top = self._emission_layer
            while top is not None and id(top) not in index_of:  # a black layer: the one above it
                top = top.get("layer")
            if self._emitters > 1:
                problems.append("emission of several shaders, one under a coat / sheen: not attenuated by it")
            elif top is not None and np.any(np.asarray(result["emission"]) > 0):
                result["emission_layer"] = index_of[id(top)]
        if self._normal is not None and result["lobes"]:
            result["normal_reg"] = self._b.reg_of(self._normal[1])
        if self._coat_normal is not None and any(lb.get("frame") for lb in result["lobes"]):
            cn = self._coat_normal[1]
            if isinstance(cn, Value):
                result["coat_normal_reg"] = self._b.reg_of(cn)
            else:
                result["coat_normal"] = cn
        if getattr(getattr(material, "cycles", None), "emission_sampling", "AUTO") == "NONE":
            result["light"] = False  # Cycles: emission found by BSDF rays only, never sampled
        if "emission_reg" in result or "normal_reg" in result or "density_reg" in result.get("volume", {}) \
                or "coat_normal_reg" in result or "coat_normal" in result \
                or "color_reg" in result.get("volume", {}) or any(
                "color_reg" in lb or "roughness_reg" in lb or "layer_weight_reg" in lb or "coat_tint_reg" in lb
                or "ior_reg" in lb or "tint_reg" in lb
                for lb in result["lobes"]):
            result["program"] = self._b.to_dict()
        problems += self._b.problems
        if problems:
            uniq = list(dict.fromkeys(problems))
            self.warnings.append(f"Material '{material.name}': " + "; ".join(uniq))
        return result

    def _displacement(self, material, out, problems):
        """The Material Output's Displacement rendered as bump, as Cycles's displacement method
        Bump Only (docs/materials.md, "Displacement"): the bumped normal Value, or None."""
        sock = out.inputs.get("Displacement") if out is not None else None
        if sock is None or resolve(sock, ())[0] is None:
            return None
        method = getattr(material, "displacement_method", None)
        if method is None:  # Blender < 4.1 kept it in the Cycles settings
            method = getattr(getattr(material, "cycles", None), "displacement_method", "BUMP")
        if method == "DISPLACEMENT":
            problems.append("displacement method 'Displacement Only' needs true displacement, which DRT "
                            "does not do: displacement ignored")
            return None
        if method == "BOTH":
            problems.append("displacement method 'Displacement and Bump': true displacement is not done, "
                            "rendered as bump only")
        try:
            return self._b.displacement_bump(out, sock)
        except Unsupported as e:
            problems.append(f"Displacement is driven by {e} (unsupported), ignored")
            return None

    def _lobe(self, lb: dict) -> dict | None:
        """A lobe with Value entries → the header's lobe dict (None if constant black)."""
        out = {"type": lb["type"]}
        color = constant(lb["color"])
        if isinstance(color, Value):
            out["color"] = _representative(color, MIN_PLACEHOLDER)
            out["color_reg"] = self._b.reg_of(color)
        else:
            color = np.broadcast_to(np.asarray(color, dtype=np.float64), 3)
            if not max(color) > 0.0:
                return None
            out["color"] = [float(x) for x in color]
        if "roughness" in lb:
            r = constant(lb["roughness"])
            if isinstance(r, Value):
                out["roughness"] = min(max(_representative(r, 0.0)[0], 0.0), 1.0)
                out["roughness_reg"] = self._b.reg_of(r)
            else:
                out["roughness"] = min(max(float(np.ravel(r)[0]), 0.0), 1.0)
        if "ior" in lb:
            out["ior"] = lb["ior"]
        for key in ("radius", "method", "anisotropy", "tint", "multiscatter", "multiscatter_tint",
                    "frame"):  # SSS, specular, coat / sheen normal
            if key in lb:
                out[key] = lb[key]
        for key in ("layer_weight", "coat_tint"):  # coat and sheen layers: constants or registers
            if key in lb:
                v = constant(lb[key])
                if isinstance(v, Value):
                    rep = _representative(v, 0.0)
                    out[key] = max(rep) if key == "layer_weight" else rep
                    out[key + "_reg"] = self._b.reg_of(v)
                else:
                    v = np.maximum(np.broadcast_to(np.asarray(v, np.float64), 3), 0.0)
                    out[key] = float(v.max()) if key == "layer_weight" else [float(x) for x in v]
        if any(isinstance(lb.get(key), Value) for key in IOR_REG_KEYS):
            # a textured IOR / level / tint (docs/materials.md "Textured IOR and tint"): a
            # DIELECTRIC_SPECULAR lobe names all three registers (constants get one too)
            for key in IOR_REG_KEYS:
                if key in lb:
                    v = lb[key]
                    out[key] = self._b.reg_of(v if isinstance(v, Value) else Value(self._b, const=v))
        for key in ("weight", "reflection_weight"):  # METALLIC, SUBSURFACE / Principled glass
            if key not in lb:
                continue
            k = constant(lb[key])
            if isinstance(k, Value):  # per hit from a register (METALLIC, glass); SSS: constant
                out[key] = max(_representative(k, 1e-3)[0], 1e-3)
                if lb["type"] in ("METALLIC", "GLASS"):
                    out["weight_reg"] = self._b.reg_of(k)
            else:
                out[key] = float(np.ravel(k)[0])
                if key == "weight" and not out[key] > 0.0:
                    return None
        return out

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

    def _compiled(self, node, sock, ctx, problems, kind):
        """The compiled value of an input (a constant or a program register); an input driven by
        a node the compiler does not know falls back to the socket's own value, with a warning."""
        try:
            v = constant(self._b.input(node, sock, ctx, kind))
            if isinstance(v, Value):  # the socket's own value is the fallback (viewport, hints)
                d = sock.default_value
                fb = float(d if not hasattr(d, "__len__") else d[0]) if kind == "float" else _rgb(d)
                v = Value(self._b, reg=v.reg, fallback=fb)
            return v
        except Unsupported as e:
            problems.append(f"'{node.name}' input '{sock.name}' is driven by {e} (unsupported), "
                            f"using its constant value")
            return _rgb(sock.default_value) if kind is None else None

    def _value(self, node, name, problems, default=0.0, ctx=()):
        """Float input: a float, or a Value when it varies over the surface."""
        sock = compat.find_input(node, name)
        if sock is None:
            return default
        v = self._compiled(node, sock, ctx, problems, "float")
        if v is None:
            d = sock.default_value
            return float(d if not hasattr(d, "__len__") else d[0])
        return v if isinstance(v, Value) else float(np.ravel(v)[0])

    def _const_value(self, node, name, problems, default=0.0, ctx=()):
        """Float input that must be constant (a textured one warns and uses the socket value)."""
        v = self._value(node, name, problems, default, ctx)
        if isinstance(v, Value):
            sock = compat.find_input(node, name)
            problems.append(f"'{node.name}' textured '{sock.name}' not supported yet, using its value")
            d = sock.default_value
            return float(d if not hasattr(d, "__len__") else d[0])
        return v

    def _color(self, node, name, problems, default=(0.8, 0.8, 0.8), ctx=()):
        """Colour input: an RGB array, or a Value when it varies over the surface."""
        sock = compat.find_input(node, name)
        if sock is None:
            return _rgb(default)
        v = self._compiled(node, sock, ctx, problems, None)
        return v if isinstance(v, Value) else _rgb(v)

    def _const_color(self, node, name, problems, default=(0.8, 0.8, 0.8), ctx=()):
        v = self._color(node, name, problems, default, ctx)
        if isinstance(v, Value):
            sock = compat.find_input(node, name)
            problems.append(f"'{node.name}' textured '{sock.name}' not supported yet, using its value")
            return _rgb(sock.default_value)
        return v

    def _roughness(self, node, problems, ctx):
        dist = getattr(node, "distribution", "GGX")
        if dist in _SHARP:
            return 0.0
        if dist not in ("GGX", "MULTI_GGX"):
            problems.append(f"'{node.name}' distribution {dist} rendered as GGX")
        r = self._value(node, "Roughness", problems, 0.5, ctx)
        return r if isinstance(r, Value) else min(max(r, 0.0), 1.0)

    def _shader(self, sock, ctx, weight, problems, material, depth):
        """Lobes and emission of the shader output ``sock`` scaled by ``weight``."""
        node = sock.node
        kind = node.bl_idname
        if depth > 32:
            problems.append("shader graph too deep")
            return [], np.zeros(3)
        w = weight
        if node.inputs.get("Normal") is not None and kind != "ShaderNodeBump":
            self._bsdf_normal(node, ctx, problems)

        if kind == "ShaderNodeBsdfDiffuse":
            r = self._value(node, "Roughness", problems, 0.0, ctx)
            if isinstance(r, Value) or r > 0.0:
                problems.append(f"'{node.name}' roughness ignored (rendered as Lambert)")
            return [{"type": "DIFFUSE", "color": w * self._color(node, "Color", problems, ctx=ctx)}], \
                np.zeros(3)
        if kind in _GLOSSY_IDS:
            if kind == "ShaderNodeBsdfAnisotropic" and abs(self._const_value(node, "Anisotropy", problems, 0.0, ctx)) > 0:
                problems.append(f"'{node.name}' anisotropy ignored")
            col = self._color(node, "Color", problems, ctx=ctx)
            lobe = {"type": "GLOSSY", "color": w * col, "roughness": self._roughness(node, problems, ctx)}
            if getattr(node, "distribution", "") == "MULTI_GGX":  # Cycles's compensation, Fss = colour
                lobe["multiscatter_tint"] = _multiscatter_tint(col)
            return [lobe], np.zeros(3)
        if kind == "ShaderNodeBsdfGlass":
            col = self._color(node, "Color", problems, ctx=ctx)
            ior = self._value(node, "IOR", problems, 1.45, ctx)
            lobe = {"type": "GLASS", "color": w * col, "roughness": self._roughness(node, problems, ctx),
                    "ior": _stand_in(ior, TEXTURED_IOR_FLOOR if isinstance(ior, Value) else 1.0)}
            if isinstance(ior, Value):  # per hit from a register
                lobe["ior_reg"] = ior
            if getattr(node, "distribution", "") == "MULTI_GGX":  # Cycles's compensation, Fss = colour
                lobe["multiscatter_tint"] = _multiscatter_tint(col)
            return [lobe], np.zeros(3)
        if kind == "ShaderNodeBsdfTranslucent":
            return [{"type": "TRANSLUCENT", "color": w * self._color(node, "Color", problems, ctx=ctx)}], np.zeros(3)
        if kind == "ShaderNodeBsdfRefraction":
            ior = self._value(node, "IOR", problems, 1.45, ctx)
            lobe = {"type": "REFRACTION", "color": w * self._color(node, "Color", problems, ctx=ctx),
                    "roughness": self._roughness(node, problems, ctx), "ior": _stand_in(ior, 1e-5)}
            if isinstance(ior, Value):  # per hit from a register (a stand-in of 1 is no delta: the
                lobe.update(ior=max(lobe["ior"], TEXTURED_IOR_FLOOR), ior_reg=ior)  # straight case)
            return [lobe], np.zeros(3)
        if kind == "ShaderNodeHoldout":
            return [{"type": "HOLDOUT", "color": w * np.ones(3)}], np.zeros(3)
        if kind in ("ShaderNodeBsdfSheen", "ShaderNodeBsdfVelvet"):  # drt.materials.sheen
            # Microfiber: the LTC sheen; Ashikhmin (and the legacy Velvet node): velvet, whose
            # sigma is the Roughness (Sigma) input
            velvet = kind == "ShaderNodeBsdfVelvet" or getattr(node, "distribution", "MICROFIBER") == "ASHIKHMIN"
            r = self._value(node, ("Roughness", "Sigma"), problems, 0.5, ctx)
            return [{"type": "VELVET" if velvet else "SHEEN", "color": w * self._color(node, "Color", problems, ctx=ctx),
                     "roughness": r if isinstance(r, Value) else min(max(r, 0.0), 1.0)}], np.zeros(3)
        if kind == "ShaderNodeBsdfTransparent":
            return [{"type": "GLASS", "color": w * self._color(node, "Color", problems, ctx=ctx),
                     "roughness": 0.0, "ior": 1.0}], np.zeros(3)
        if kind == "ShaderNodeEmission":
            col = self._color(node, "Color", problems, (1, 1, 1), ctx)
            em = w * col * self._value(node, "Strength", problems, 1.0, ctx)
            self._emitters += 1 if maybe_positive(em) else 0
            return [], em
        if kind == "ShaderNodeMixShader":
            fac = clamp01(self._value(node, ("Fac", "Factor"), problems, 0.5, ctx))
            lobes, em = [], np.zeros(3)
            for inp, f in ((node.inputs[1], 1.0 - fac), (node.inputs[2], fac)):
                src, sctx = resolve(inp, ctx)
                if src is not None and maybe_positive(f):
                    lb, e = self._shader(src, sctx, w * f, problems, material, depth + 1)
                    lobes += lb
                    em = em + e
            return lobes, em
        if kind == "ShaderNodeAddShader":
            lobes, em = [], np.zeros(3)
            for inp in node.inputs[:2]:
                src, sctx = resolve(inp, ctx)
                if src is not None:
                    lb, e = self._shader(src, sctx, w, problems, material, depth + 1)
                    lobes += lb
                    em = em + e
            return lobes, em
        if kind == "ShaderNodeBsdfPrincipled":
            return self._principled(node, w, problems, ctx)
        if kind == "ShaderNodeBsdfMetallic":
            return [self._metallic(node, w, problems, ctx)], np.zeros(3)
        if kind == "ShaderNodeSubsurfaceScattering":
            col = self._color(node, "Color", problems, ctx=ctx)
            r = min(max(self._const_value(node, "Roughness", problems, 1.0, ctx), 0.0), 1.0)
            return [{"type": "SUBSURFACE", "color": w * col, "weight": w,
                     "radius": self._sss_radius(node, "Radius", "Scale", problems, ctx),
                     "method": self._sss_method(node, "falloff", problems),
                     "ior": self._const_value(node, "IOR", problems, 1.4, ctx),
                     "roughness": float(np.sqrt(r)),
                     "anisotropy": self._const_value(node, "Anisotropy", problems, 0.0, ctx)}], np.zeros(3)

        # Unsupported (Toon, Hair, Principled Hair, Specular BSDF (EEVEE), Ray Portal...): its
        # (base) color as diffuse (docs/materials.md, "Unsupported shader nodes")
        problems.append(f"unsupported shader '{node.name}' ({kind}), rendered as diffuse")
        for name in ("Base Color", "Color"):
            if node.inputs.get(name) is not None:
                col = self._color(node, name, problems, ctx=ctx)
                break
        else:
            col = _rgb(material.diffuse_color)
        return [{"type": "DIFFUSE", "color": w * col}], np.zeros(3)

    def _metallic(self, node, w, problems, ctx) -> dict:
        """The Metallic BSDF as the Principled BSDF's METALLIC lobe (Cycles's F82 conductor:
        F0 = the clamped Base Color, F82 tint = the clamped Edge Tint). Physical Conductor takes
        the F82 model through the conductor's own Fresnel at normal incidence and at
        cos θ = 1/7 (`conductor_f82`); its IOR and Extinction must be constant."""
        rough = self._roughness(node, problems, ctx)
        if getattr(node, "fresnel_type", "F82") == "PHYSICAL_CONDUCTOR":
            n = _rgb(self._const_color(node, "IOR", problems, (2.757, 2.513, 2.231), ctx))
            k = _rgb(self._const_color(node, "Extinction", problems, (3.867, 3.404, 3.009), ctx))
            f0, tint = conductor_f82(np.maximum(n, 0.0), np.maximum(k, 0.0))
        else:
            base = self._color(node, "Base Color", problems, ctx=ctx)
            f0 = clamp01(base) if isinstance(base, Value) else np.clip(base, 0.0, 1.0)
            tint = self._color(node, "Edge Tint", problems, (1, 1, 1), ctx)
            tint = clamp01(tint) if isinstance(tint, Value) else np.clip(tint, 0.0, 1.0)
        if abs(self._const_value(node, "Anisotropy", problems, 0.0, ctx)) > 0:
            problems.append(f"'{node.name}' anisotropy ignored")
        film = node.inputs.get("Thin Film Thickness")
        if film is not None and (resolve(film, ctx)[0] is not None or film.default_value > 0.1):
            problems.append(f"'{node.name}' thin film (iridescence) not supported, rendered without it")
        tint_c = np.asarray(_representative(tint, 0.0)) if isinstance(tint, Value) else tint
        return {"type": "METALLIC", "color": w * f0, "weight": w, "roughness": rough,
                "tint": [float(x) for x in np.broadcast_to(tint_c, 3)],
                "multiscatter": getattr(node, "distribution", "MULTI_GGX") == "MULTI_GGX",
                **({"tint_reg": tint} if isinstance(tint, Value) else {})}

    def _bsdf_normal(self, node, ctx, problems):
        """Record a BSDF's linked Normal input (a Normal Map...) as the material's shading normal.
        DRT has one shading normal per material: a second, different linked normal warns."""
        key = _normal_key(node, "Normal", ctx)
        if key is None:
            return
        if self._normal is not None:
            if self._normal[0] != key:
                problems.append(f"'{node.name}' has its own Normal input; DRT uses one shading normal "
                                f"per material (the first BSDF's)")
            return
        v = self._normal_value(node, "Normal", ctx, problems, "using the mesh normal")
        if v is not None:
            self._normal = (key, v)

    def _normal_value(self, node, name, ctx, problems, fallback):
        """The program value of a BSDF's linked normal input ``name`` (a constant one
        normalised, as Cycles does), or None after a warning ending in ``fallback`` when an
        unsupported node drives it."""
        try:
            v = self._b.input(node, node.inputs[name], ctx)
        except Unsupported as e:
            problems.append(f"'{node.name}' {name} is driven by {e} (unsupported), {fallback}")
            return None
        if v.is_const:
            v = self._b.emit(OP_VMATH_NORMALIZE[0], OP_VMATH_NORMALIZE[1], [v, v])
        return v

    def _sss_radius(self, node, radius_name, scale_name, problems, ctx):
        """Radius × scale (metres per channel, ≥ 0), constant-only."""
        rad = self._const_color(node, radius_name, problems, (1.0, 0.2, 0.1), ctx)
        scale = self._const_value(node, scale_name, problems, 1.0, ctx)
        return [float(max(x * scale, 0.0)) for x in np.broadcast_to(rad, 3)]

    @staticmethod
    def _sss_method(node, prop, problems):
        method = getattr(node, prop, "RANDOM_WALK")
        if method == "BURLEY":
            problems.append(f"'{node.name}' Christensen-Burley subsurface rendered as Random Walk")
        return method if method in ("RANDOM_WALK", "RANDOM_WALK_SKIN", "BURLEY") else "RANDOM_WALK"

    def _principled_glass(self, node, k, base, tint, rough, ior, problems):
        """The Principled transmission as Cycles 5.0 builds it: a GGX glass of weight k whose
        generalized-Schlick Fresnel (exponent −IOR, i.e. the real dielectric curve) reflects
        untinted and refracts tinted by sqrt(clamped base colour). A GLASS lobe with colour
        k·sqrt(base) and reflection_weight k (a textured k — alpha, transmission, metallic —
        comes per hit from a register: ``weight_reg``)."""
        clamped = clamp01(base) if isinstance(base, Value) else np.clip(base, 0.0, 1.0)
        if isinstance(clamped, Value):
            root = self._b.emit(OP_VMATH, VMATH_OPS.index("POWER"), [clamped, Value(self._b, const=0.5)])
            if clamped.fallback is not None:
                root.fallback = np.sqrt(np.clip(clamped.fallback, 0.0, 1.0))
        else:  # (a black base still reflects: keep the lobe with a negligible transmission)
            root = np.maximum(np.sqrt(clamped), MIN_PLACEHOLDER)
        if isinstance(tint, Value) or np.any(np.abs(np.broadcast_to(tint, 3) - 1.0) > 1e-6):
            problems.append(f"'{node.name}' specular tint on the transmission ignored (reflection untinted)")
        lobe = {"type": "GLASS", "color": k * root, "roughness": rough, "ior": ior, "reflection_weight": k}
        if getattr(node, "distribution", "") == "MULTI_GGX":  # Fss = the transmission tint
            lobe["multiscatter_tint"] = _multiscatter_tint(root)
        return lobe

    def _principled(self, node, w, problems, ctx):
        base = self._color(node, "Base Color", problems, ctx=ctx)
        metallic = clamp01(self._value(node, "Metallic", problems, 0.0, ctx))
        rough = self._value(node, "Roughness", problems, 0.5, ctx)
        rough = rough if isinstance(rough, Value) else min(max(rough, 0.0), 1.0)
        ior_in = self._value(node, "IOR", problems, 1.5, ctx)
        alpha = clamp01(self._value(node, "Alpha", problems, 1.0, ctx))
        trans = clamp01(self._value(node, "transmission", problems, 0.0, ctx))
        spec_in = self._value(node, "specular", problems, 0.5, ctx)
        tint_sock = compat.find_input(node, "specular_tint")
        if tint_sock is not None and tint_sock.type == "RGBA":
            tint = self._color(node, "specular_tint", problems, (1, 1, 1), ctx)
        else:  # 3.x: a float blending white toward the base color
            t = self._const_value(node, "specular_tint", problems, 0.0, ctx) if tint_sock is not None else 0.0
            tint = (1.0 - t) * np.ones(3) + t * base
        em_col = self._color(node, "emission_color", problems, (0, 0, 0), ctx)
        em_strength = self._value(node, "Emission Strength", problems, 1.0, ctx) \
            if node.inputs.get("Emission Strength") is not None else 1.0
        layers = self._coat_and_sheen(node, w * alpha, problems, ctx)
        film = node.inputs.get("Thin Film Thickness")  # Blender 4.2+
        if film is not None and (resolve(film, ctx)[0] is not None or film.default_value > 0.1):
            # Cycles's iridescence (THINFILM_THICKNESS_CUTOFF 0.1 nm) needs its spectral
            # sensitivity table; not done (docs/materials.md "Thin film")
            problems.append(f"'{node.name}' thin film (iridescence) not supported, rendered without it")
        for key in ("Tangent",):
            sock = node.inputs.get(key)
            if sock is not None and resolve(sock, ctx)[0] is not None:
                problems.append(f"'{node.name}' linked {key} ignored")
        sss = min(max(self._const_value(node, "subsurface", problems, 0.0, ctx), 0.0), 1.0)

        # A textured IOR / Specular IOR Level / Specular Tint: the lobes take them per hit from
        # registers ("ior_reg", "ior_level_reg", "tint_reg"; the core recomputes eta, f0 and
        # the layer albedo per hit); the constants below are their stand-ins (selection, hints)
        fresnel_textured = isinstance(ior_in, Value) or isinstance(spec_in, Value)
        ior = _stand_in(ior_in, 1.0)
        spec = max(_representative(spec_in, 0.0)[0], 0.0) if isinstance(spec_in, Value) else max(spec_in, 0.0)
        tint_c = np.asarray(_representative(tint, 0.0)) if isinstance(tint, Value) else tint
        # Cycles's "Apply IOR adjustment": Specular IOR Level rescales F0, then back to an IOR
        f0 = ((ior - 1.0) / (ior + 1.0)) ** 2
        eta = ior
        if spec != 0.5:
            f0s = min(max(f0 * 2.0 * spec, 0.0), 0.99)
            eta = (1.0 + np.sqrt(f0s)) / (1.0 - np.sqrt(f0s))
        if fresnel_textured:  # a stand-in that keeps the specular lobe selectable
            eta = max(eta, TEXTURED_IOR_FLOOR)
        multiscatter = getattr(node, "distribution", "MULTI_GGX") == "MULTI_GGX"
        lobes = list(layers)
        # everything below the sheen / coat lies under the lowest of them ("layer": scaled per
        # hit by 1 − its albedo(wo), and a coat tint's absorption; docs/materials.md)
        below = {"layer": layers[-1]} if layers else {}
        wa = w * alpha
        if maybe_positive(metallic):
            k = wa * metallic
            # Cycles's F82-tint metal: F0 = the clamped base colour, F82 tint = min(tint, 1); a
            # textured metallic / alpha gives the weight per hit from a register (weight_reg)
            clamped = clamp01(base) if isinstance(base, Value) else np.clip(base, 0.0, 1.0)
            lobes.append({"type": "METALLIC", "color": k * clamped, "weight": k, "roughness": rough,
                          "tint": [float(min(x, 1.0)) for x in np.broadcast_to(tint_c, 3)],
                          "multiscatter": multiscatter, **below,
                          **({"tint_reg": tint} if isinstance(tint, Value) else {})})
        dielectric = 1.0 - metallic
        if maybe_positive(trans) and maybe_positive(dielectric):
            glass = self._principled_glass(node, wa * dielectric * trans, base, tint, rough, ior, problems)
            if isinstance(ior_in, Value):
                glass.update(ior=max(ior, TEXTURED_IOR_FLOOR), ior_reg=ior_in)
            lobes.append({**glass, **below})
        opaque = wa * dielectric * (1 - trans)
        if maybe_positive(opaque):
            # The specular layer (GGX × dielectric Fresnel) over the diffuse/subsurface base,
            # which the core scales per hit by 1 − the layer's albedo E(wo) ("layer": the index
            # of the specular lobe in this list; docs/materials.md)
            layer = below
            if eta != 1.0:
                top = {"type": "DIELECTRIC_SPECULAR", "color": opaque * np.ones(3),
                       "roughness": rough, "ior": float(eta),
                       "tint": [float(x) for x in np.broadcast_to(tint_c, 3)],
                       "multiscatter": multiscatter, **below}
                if fresnel_textured or isinstance(tint, Value):
                    top.update(ior_reg=ior_in, ior_level_reg=spec_in, tint_reg=tint)
                layer = {"layer": top}  # the lobe dict itself: indices shift when lists merge
                lobes.append(top)
            if sss < 1.0:
                lobes.append({"type": "DIFFUSE", "color": opaque * (1 - sss) * base, **layer})
            if sss > 1e-5:  # Cycles's CLOSURE_WEIGHT_CUTOFF
                k = opaque * sss
                clamped = clamp01(base) if isinstance(base, Value) else np.clip(base, 0.0, 1.0)
                method = self._sss_method(node, "subsurface_method", problems)
                # Cycles's Random Walk enters through the specular layer's IOR (eta above)
                ior_sss = self._const_value(node, "Subsurface IOR", problems, 1.4, ctx) \
                    if method == "RANDOM_WALK_SKIN" else eta
                if fresnel_textured and method != "RANDOM_WALK_SKIN":
                    problems.append(f"'{node.name}' textured IOR / Specular IOR Level: the subsurface "
                                    f"entry uses its constant IOR {eta:.3g}")
                r_entry = rough if not isinstance(rough, Value) else rough
                lobes.append({"type": "SUBSURFACE", "color": k * clamped, "weight": k,
                              "radius": self._sss_radius(node, "Subsurface Radius", "Subsurface Scale",
                                                         problems, ctx),
                              "method": method, "ior": float(ior_sss), "roughness": r_entry,
                              "anisotropy": self._const_value(node, "Subsurface Anisotropy", problems, 0.0, ctx),
                              **layer})
        if maybe_positive(1 - alpha):  # transparency: straight through (a textured alpha: cut-outs)
            lobes.append({"type": "GLASS", "color": w * (1 - alpha), "roughness": 0.0, "ior": 1.0})
        emission = wa * em_col * em_strength
        if maybe_positive(emission):
            self._emitters += 1
            if layers:  # attenuated per view angle by the coat / sheen (core: emission_layer)
                self._emission_layer = layers[-1]
        return lobes, emission

    def _coat_and_sheen(self, node, wa, problems, ctx):
        """The Principled BSDF's top layers, top first (Cycles 5.0's order: sheen over coat over
        the rest), as lobe dicts whose "layer" chains them: [SHEEN?, DIELECTRIC_SPECULAR coat?].

        Sheen: SHEEN(wa·Sheen Weight·Sheen Tint, Sheen Roughness), layer_weight = weight ×
        max(tint) (Cycles's closure_layering_weight of its albedo). Coat: a dielectric GGX layer
        with the real Fresnel of Coat IOR and Multiscatter GGX energy compensation (Cycles's
        bsdf_microfacet_setup_fresnel_dielectric always preserves energy): DIELECTRIC_SPECULAR
        (wa·Coat Weight, Coat Roughness, Coat IOR, white tint), layer_weight = Coat Weight,
        coat_tint = Coat Tint (absorption of the layers below). Weights, tints and roughnesses may
        be textured (registers; k is the largest component of the weight register), and the coat
        IOR (``ior_reg``, per hit). A Coat Normal driven apart from Normal (e.g. a normal map on
        the base only, Coat Normal unlinked: the smooth normal) gives the coat lobe frame COAT
        and the sheen frame SHEEN (Cycles: normalize(mix(Normal, Coat Normal, Coat Weight)));
        the material's ``coat_normal_reg`` / ``coat_normal`` names that normal
        (``_own_coat_normal``)."""
        layers = []
        sheen_w = self._value(node, "sheen", problems, 0.0, ctx)
        coat_w = self._value(node, "coat", problems, 0.0, ctx)
        sheen_w = sheen_w if isinstance(sheen_w, Value) else max(sheen_w, 0.0)
        coat_w = coat_w if isinstance(coat_w, Value) else max(coat_w, 0.0)
        if _above_cutoff(sheen_w):  # Cycles's CLOSURE_WEIGHT_CUTOFF
            sheen_tint = self._color(node, "Sheen Tint", problems, (1, 1, 1), ctx)
            sheen_tint = sheen_tint if isinstance(sheen_tint, Value) else np.maximum(sheen_tint, 0.0)
            r = self._value(node, "Sheen Roughness", problems, 0.5, ctx)
            r = r if isinstance(r, Value) else min(max(r, 0.0), 1.0)
            k = sheen_w * sheen_tint  # the layer weight: its largest component (core)
            if maybe_positive(k):
                layers.append({"type": "SHEEN", "color": wa * k, "roughness": r, "layer_weight": k})
        if _above_cutoff(coat_w):
            coat_ior_in = self._value(node, "Coat IOR", problems, 1.5, ctx)
            coat_ior = _stand_in(coat_ior_in, 1.0)
            if isinstance(coat_ior_in, Value):  # per hit from a register; a selectable stand-in
                coat_ior = max(coat_ior, TEXTURED_IOR_FLOOR)
            coat_tint = self._color(node, "Coat Tint", problems, (1, 1, 1), ctx)
            coat_tint = coat_tint if isinstance(coat_tint, Value) else np.maximum(coat_tint, 0.0)
            r = self._value(node, "Coat Roughness", problems, 0.03, ctx)
            r = r if isinstance(r, Value) else min(max(r, 0.0), 1.0)
            if coat_ior == 1.0 and (isinstance(coat_tint, Value) or not np.all(coat_tint == 1.0)):
                problems.append(f"'{node.name}' Coat IOR 1: the coat tint is ignored")
            if coat_ior > 1.0:
                layers.append({"type": "DIELECTRIC_SPECULAR", "color": wa * coat_w * np.ones(3),
                               "roughness": r, "ior": float(coat_ior), "tint": [1.0, 1.0, 1.0],
                               "multiscatter": True, "layer_weight": coat_w, "coat_tint": coat_tint,
                               **({"layer": layers[-1]} if layers else {}),
                               **({"ior_reg": coat_ior_in, "ior_level_reg": 0.5, "tint_reg": np.ones(3)}
                                  if isinstance(coat_ior_in, Value) else {})})
        coat = [lb for lb in layers if lb["type"] == "DIELECTRIC_SPECULAR"]
        if coat and self._own_coat_normal(node, ctx, problems):
            coat[0]["frame"] = "COAT"
            for lb in layers:
                if lb["type"] == "SHEEN":
                    lb["frame"] = "SHEEN"
        return layers

    def _own_coat_normal(self, node, ctx, problems) -> bool:
        """Does this Principled's coat have a normal of its own (Coat Normal driven apart from
        Normal)? Records it as the material's coat normal: the Coat Normal input's Value, or for
        an unlinked Coat Normal the normal Cycles links it to — the Displacement's bumped normal
        if there is one, else "SMOOTH" (the unmapped shading normal). DRT has one coat normal
        per material: a second, different one warns and shades that coat about the first."""
        key = _normal_key(node, "Coat Normal", ctx)
        main = _normal_key(node, "Normal", ctx)
        if key == main or (key is None and self._disp_normal is None and main is None):
            return False
        if key is None:
            value = self._disp_normal if self._disp_normal is not None else "SMOOTH"
        else:
            value = self._normal_value(node, "Coat Normal", ctx, problems,
                                       "the coat uses the material's shading normal")
            if value is None:
                return False
        if self._coat_normal is not None:
            if self._coat_normal[0] != key:
                problems.append(f"'{node.name}' has its own Coat Normal; DRT uses one coat normal per "
                                f"material (the first coat's)")
            return True
        self._coat_normal = (key, value)
        return True
