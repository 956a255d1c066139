"""Shader node trees → flat material programs (the compiler half of docs/materials.md).

Cycles's SVM is the model: at export every texture/converter node that feeds a BSDF parameter
becomes one operation over a register file; the core's interpreter
(``drt.materials.programs``) runs the operations in order at each shading point. Every register
holds three float64; a float value is stored replicated in all three (so float × colour is a
component-wise product and float→colour conversion is free).

``Value`` is what a compiled socket is at export: either a constant (a numpy 3-vector, folded)
or a register. Arithmetic between Values emits component-wise operations and folds constants,
so the exporter's Principled/Mix decomposition (materials.py) is written once, as ordinary
arithmetic, and works for textured and constant inputs alike.

Graph structure follows Blender: reroutes are skipped, muted nodes pass their internal links
through (an output without one gives its socket's default value), node groups are compiled
inline with their Group Input sockets bound to the group node's inputs (linked or default).
Opcodes and modes are listed once, in ``drt.materials.programs`` (mirrored here by name).
"""

from __future__ import annotations

import numpy as np

from .. import compat

# --- opcodes: keep in sync with core/drt/materials/programs.py ----------------------------------
OP_UV, OP_GENERATED, OP_OBJECT, OP_ATTRIBUTE = 1, 2, 3, 4
OP_VMATH, OP_MATH, OP_MIX, OP_MAPPING = 10, 11, 12, 13
OP_IMAGE, OP_CHECKER, OP_GRADIENT, OP_RAMP = 20, 21, 22, 23
OP_IMAGE_BOX = 24  # Box projection (drt.materials.program_format)
IMAGE_PROJECTION_STRIDE = 32  # OP_IMAGE's mode = projection·32 + interpolation·8 + extension
IMAGE_PROJECTIONS = ["FLAT", "SPHERE", "TUBE", "BOX"]  # (BOX: OP_IMAGE_BOX)
OP_MAP_RANGE, OP_CLAMP, OP_INVERT, OP_GAMMA, OP_BRIGHT_CONTRAST, OP_HSV = 30, 31, 32, 33, 34, 35
OP_COMPONENT, OP_COMBINE, OP_TO_GRAY, OP_AVERAGE, OP_RGB_TO_HSV, OP_HSV_TO_RGB = 40, 41, 42, 43, 44, 45
OP_POINT, OP_FRESNEL, OP_LAYER_WEIGHT, OP_NORMAL_MAP, OP_OBJECT_INFO = 90, 91, 92, 93, 94
#: Object Info outputs → OP_OBJECT_INFO mode (Material Index is the material's constant)
OP_BUMP_OFFSET, OP_BUMP, OP_CAMERA_COORDS = 95, 96, 97
OP_TEXCO_NORMAL, OP_DISPLACEMENT, OP_VECTOR_DISPLACEMENT, OP_SET_NORMAL = 98, 99, 100, 101


def reads_object_transform(op) -> bool:
    """Whether operation row ``op`` needs the hit object's transform (objects then carry their
    per-object data): Texture Coordinate Normal, the Image Texture's Box projection, and the
    object spaces of Normal Map
    (Object, Blender Object), Displacement and Vector Displacement."""
    return (op[0] in (OP_TEXCO_NORMAL, OP_IMAGE_BOX) or (op[0] == OP_NORMAL_MAP and op[1] in (1, 3))
            or (op[0] == OP_DISPLACEMENT and op[1] == 1)
            or (op[0] == OP_VECTOR_DISPLACEMENT and op[1] in (0, 1)))
OBJECT_INFO_OUTPUTS = {"Location": 0, "Color": 1, "Alpha": 2, "Object Index": 3, "Random": 4}
# shading-point rows (drt.materials.program_format.POINT_*)
POINT_P, POINT_N, POINT_NG, POINT_I = 3, 4, 5, 6
POINT_PATH, POINT_PATH2, POINT_DEPTH, POINT_MISC, POINT_SHADOW = 8, 9, 10, 11, 15
NORMAL_MAP_SPACES = ["TANGENT", "OBJECT", "WORLD", "BLENDER_OBJECT", "BLENDER_WORLD"]
#: Geometry node outputs → (row, component or −1 for the vector)
GEOMETRY_OUTPUTS = {"Position": (POINT_P, -1), "Normal": (POINT_N, -1), "True Normal": (POINT_NG, -1),
                    "Incoming": (POINT_I, -1), "Backfacing": (POINT_MISC, 2)}
#: Geometry node outputs the export computes per mesh (addon/export/mesh.py) → attribute name
MESH_ATTRIBUTE_OUTPUTS = {"Pointiness": "pointiness:", "Random Per Island": "random_island:",
                          "Parametric": "parametric:"}
#: Light Path node outputs → (row, component); None: always 0 for the rays DRT shades
LIGHT_PATH_OUTPUTS = {
    "Is Camera Ray": (POINT_PATH, 0), "Is Diffuse Ray": (POINT_PATH, 1), "Is Glossy Ray": (POINT_PATH, 2),
    "Is Singular Ray": (POINT_PATH2, 0), "Is Reflection Ray": (POINT_PATH2, 1),
    "Is Transmission Ray": (POINT_PATH2, 2), "Ray Depth": (POINT_DEPTH, 0), "Diffuse Depth": (POINT_DEPTH, 1),
    "Glossy Depth": (POINT_DEPTH, 2), "Transmission Depth": (POINT_MISC, 0), "Ray Length": (POINT_MISC, 1),
    "Is Shadow Ray": (POINT_SHADOW, 0), "Is Volume Scatter Ray": None, "Transparent Depth": None,
    "Portal Depth": None,
}
OP_NOISE, OP_WHITE_NOISE, OP_VORONOI, OP_WAVE, OP_MAGIC, OP_BRICK, OP_CURVES = 50, 51, 52, 53, 54, 55, 56
OP_ENVIRONMENT = 70  # mode = projection·ENV_PROJECTION_STRIDE + interpolation·8 (+ REPEAT)
ENV_PROJECTION_STRIDE = 32
ENV_PROJECTIONS = ["EQUIRECTANGULAR", "MIRROR_BALL"]

MATH_OPS = ["ADD", "SUBTRACT", "MULTIPLY", "DIVIDE", "MULTIPLY_ADD", "POWER", "LOGARITHM", "SQRT",
            "INVERSE_SQRT", "ABSOLUTE", "EXPONENT", "MINIMUM", "MAXIMUM", "LESS_THAN",
            "GREATER_THAN", "SIGN", "COMPARE", "SMOOTH_MIN", "SMOOTH_MAX", "ROUND", "FLOOR", "CEIL",
            "TRUNC", "FRACT", "MODULO", "FLOORED_MODULO", "WRAP", "SNAP", "PINGPONG", "SINE",
            "COSINE", "TANGENT", "ARCSINE", "ARCCOSINE", "ARCTANGENT", "ARCTAN2", "SINH", "COSH",
            "TANH", "RADIANS", "DEGREES"]
VMATH_OPS = ["ADD", "SUBTRACT", "MULTIPLY", "DIVIDE", "MULTIPLY_ADD", "CROSS_PRODUCT", "PROJECT",
             "REFLECT", "DOT_PRODUCT", "DISTANCE", "LENGTH", "SCALE", "NORMALIZE", "ABSOLUTE",
             "MINIMUM", "MAXIMUM", "FLOOR", "CEIL", "FRACTION", "MODULO", "WRAP", "SNAP", "SINE",
             "COSINE", "TANGENT", "POWER", "SIGN"]
BLEND_TYPES = ["MIX", "DARKEN", "MULTIPLY", "BURN", "LIGHTEN", "SCREEN", "DODGE", "ADD", "OVERLAY",
               "SOFT_LIGHT", "LINEAR_LIGHT", "DIFFERENCE", "EXCLUSION", "SUBTRACT", "DIVIDE", "HUE",
               "SATURATION", "VALUE", "COLOR"]
MAPPING_TYPES = ["POINT", "TEXTURE", "VECTOR", "NORMAL"]
GRADIENT_TYPES = ["LINEAR", "QUADRATIC", "EASING", "DIAGONAL", "SPHERICAL", "QUADRATIC_SPHERE",
                  "RADIAL"]
MAP_RANGE_TYPES = ["LINEAR", "STEPPED", "SMOOTHSTEP", "SMOOTHERSTEP"]
INTERPOLATIONS = ["Closest", "Linear", "Cubic", "Smart"]
EXTENSIONS = ["REPEAT", "EXTEND", "CLIP", "MIRROR"]
DIMENSIONS = ["1D", "2D", "3D", "4D"]
# procedural modes: drt.materials.procedural's numbering of Blender's enums
NOISE_TYPES = {"MULTIFRACTAL": 0, "FBM": 1, "HYBRID_MULTIFRACTAL": 2, "RIDGED_MULTIFRACTAL": 3,
               "HETERO_TERRAIN": 4}
VORONOI_FEATURES = ["F1", "F2", "SMOOTH_F1", "DISTANCE_TO_EDGE", "N_SPHERE_RADIUS"]
VORONOI_METRICS = ["EUCLIDEAN", "MANHATTAN", "CHEBYCHEV", "MINKOWSKI"]
WAVE_BANDS = ["X", "Y", "Z", "DIAGONAL"]
WAVE_RINGS = ["X", "Y", "Z", "SPHERICAL"]
WAVE_PROFILES = ["SIN", "SAW", "TRI"]
VMATH_VALUE_OUT = {"DOT_PRODUCT", "DISTANCE", "LENGTH"}
RAMP_TABLE_SIZE = 256  # Cycles bakes colour ramps into this many entries (RAMP_TABLE_SIZE)
#: Rec.709 luminance (Blender 5's default working space): Cycles's colour → float conversion
LUMINANCE = (0.2126729, 0.7151522, 0.0721750)

SUPPORTED_NODES = {
    "ShaderNodeTexCoord", "ShaderNodeUVMap", "ShaderNodeMapping", "ShaderNodeTexImage",
    "ShaderNodeTexChecker", "ShaderNodeTexGradient", "ShaderNodeValue", "ShaderNodeRGB",
    "ShaderNodeMath", "ShaderNodeVectorMath", "ShaderNodeMix", "ShaderNodeMixRGB",
    "ShaderNodeValToRGB", "ShaderNodeMapRange", "ShaderNodeClamp", "ShaderNodeInvert",
    "ShaderNodeGamma", "ShaderNodeBrightContrast", "ShaderNodeHueSaturation",
    "ShaderNodeSeparateXYZ", "ShaderNodeCombineXYZ", "ShaderNodeSeparateRGB",
    "ShaderNodeCombineRGB", "ShaderNodeSeparateColor", "ShaderNodeCombineColor",
    "ShaderNodeFresnel", "ShaderNodeLayerWeight", "ShaderNodeNewGeometry", "ShaderNodeLightPath",
    "ShaderNodeNormalMap", "ShaderNodeObjectInfo", "ShaderNodeBump",
    "ShaderNodeTexNoise", "ShaderNodeTexWhiteNoise", "ShaderNodeTexVoronoi", "ShaderNodeTexWave",
    "ShaderNodeTexMagic", "ShaderNodeTexBrick", "ShaderNodeRGBCurve", "ShaderNodeVectorCurve",
    "ShaderNodeFloatCurve", "ShaderNodeVertexColor", "ShaderNodeAttribute",
    "ShaderNodeTexEnvironment", "ShaderNodeDisplacement", "ShaderNodeVectorDisplacement",
    "ShaderNodeRGBToBW", "ShaderNodeNormal", "ShaderNodeVectorRotate", "ShaderNodeBlackbody",
    "ShaderNodeCameraData", "ShaderNodeLightFalloff",
}


class Unsupported(Exception):
    """A node the compiler cannot evaluate; the caller falls back and warns."""

    def __init__(self, node):
        super().__init__(f"'{node.name}' ({node.bl_idname})")
        self.node = node


def _vec3(v) -> np.ndarray:
    if hasattr(v, "__len__"):
        v = list(v)[:3]
        if len(v) == 1:
            v = v * 3
        return np.array(v + [0.0] * (3 - len(v)), dtype=np.float64)
    return np.full(3, float(v))


class Value:
    """A compiled socket value: constant (``const``, a 3-vector) or register (``reg``).

    ``fallback`` (3-vector) is what the value is without programs: the driven socket's own
    value, carried through the exporter's arithmetic. It is the lobe's representative constant
    in the scene file and what a renderer without program support (the viewport) shows — the
    same as before programs existed."""

    __array_ufunc__ = None  # numpy arrays defer arithmetic to us

    def __init__(self, builder, reg=None, const=None, fallback=None):
        self.b = builder
        self.reg = reg
        self.const = None if const is None else _vec3(const)
        self.fallback = self.const if fallback is None else _vec3(fallback)

    @property
    def is_const(self) -> bool:
        return self.const is not None

    def _bin(self, other, mode, swap=False):
        o = other if isinstance(other, Value) else Value(self.b, const=other)
        a, b = (o, self) if swap else (self, o)
        if a.is_const and b.is_const:
            return Value(self.b, const=_FOLD[mode](a.const, b.const))
        out = self.b.emit(OP_VMATH, VMATH_OPS.index(mode), [a, b])
        if a.fallback is not None and b.fallback is not None:
            out.fallback = _FOLD[mode](a.fallback, b.fallback)
        return out

    def __add__(self, o): return self._bin(o, "ADD")
    def __radd__(self, o): return self._bin(o, "ADD", True)
    def __sub__(self, o): return self._bin(o, "SUBTRACT")
    def __rsub__(self, o): return self._bin(o, "SUBTRACT", True)
    def __mul__(self, o): return self._bin(o, "MULTIPLY")
    def __rmul__(self, o): return self._bin(o, "MULTIPLY", True)


_FOLD = {"ADD": np.add, "SUBTRACT": np.subtract, "MULTIPLY": np.multiply,
         "MINIMUM": np.minimum, "MAXIMUM": np.maximum}


def clamp01(x):
    """min(max(x, 0), 1) of a float, array or Value."""
    if isinstance(x, Value):
        if x.is_const:
            return Value(x.b, const=np.clip(x.const, 0.0, 1.0))
        lo = x.b.emit(OP_VMATH, VMATH_OPS.index("MAXIMUM"), [x, Value(x.b, const=0.0)])
        out = x.b.emit(OP_VMATH, VMATH_OPS.index("MINIMUM"), [lo, Value(x.b, const=1.0)])
        if x.fallback is not None:
            out.fallback = np.clip(x.fallback, 0.0, 1.0)
        return out
    return np.clip(x, 0.0, 1.0) if isinstance(x, np.ndarray) else min(max(float(x), 0.0), 1.0)


def maybe_positive(x) -> bool:
    """False only for a constant ≤ 0 everywhere (a lobe weighted by it can be dropped)."""
    if isinstance(x, Value):
        return not x.is_const or bool(np.max(x.const) > 0.0)
    return bool(np.max(x) > 0.0)


def constant(x):
    """x as a plain float/array if it is constant, else the Value itself."""
    if isinstance(x, Value) and x.is_const:
        return x.const
    return x


def _socket_default(sock):
    v = getattr(sock, "default_value", 0.0)
    return _vec3(v) if v is not None else np.zeros(3)


def resolve(sock, ctx):
    """The (output socket, group context) that drives input ``sock`` in context ``ctx`` (a tuple
    of enclosing group nodes), skipping reroutes and muted links, entering node groups and
    leaving them through their Group Input; (None, ctx) if the input is unlinked (use its
    default value; for a Group Input socket, the group node's own input default)."""
    for _ in range(256):
        if not sock.is_linked:
            return None, ctx
        link = sock.links[0]
        if getattr(link, "is_muted", False) or not getattr(link, "is_valid", True):
            return None, ctx
        node, out = link.from_node, link.from_socket
        kind = node.bl_idname
        if kind == "NodeReroute":
            sock = node.inputs[0]
            continue
        if getattr(node, "mute", False):
            through = [lk.from_socket for lk in node.internal_links if lk.to_socket == out]
            if not through:
                return out, ctx  # a muted node without a pass-through: its default value
            sock = through[0]
            continue
        if kind == "ShaderNodeGroup" and node.node_tree is not None:
            group_out = _group_output(node.node_tree)
            if group_out is None:
                return None, ctx
            idx = list(node.outputs).index(out)
            if idx >= len(group_out.inputs):
                return None, ctx
            sock = group_out.inputs[idx]
            ctx = ctx + (node,)
            continue
        if kind == "NodeGroupInput":
            if not ctx:
                return None, ctx
            group_node = ctx[-1]
            idx = list(node.outputs).index(out)
            sock = group_node.inputs[idx]
            ctx = ctx[:-1]
            continue
        return out, ctx
    return None, ctx


def _group_output(tree):
    outs = [n for n in tree.nodes if n.bl_idname == "NodeGroupOutput"]
    for n in outs:
        if getattr(n, "is_active_output", False):
            return n
    return outs[0] if outs else None


class ProgramBuilder:
    """Collects the operations of one material's program."""

    def __init__(self, images, attributes=None):
        self.images = images          # ImageTable shared by all materials of the export
        self.attributes = attributes if attributes is not None else []  # names, shared too
        self.ops: list[list[int]] = []
        self.consts: list[tuple[int, list[float]]] = []
        self.data: list[float] = []
        self.n_regs = 0
        self._const_regs: dict = {}
        self._cache: dict = {}
        self._geometry: dict = {}
        self.problems: list[str] = []
        self.material_pass_index = 0  # the Object Info node's Material Index
        self._variant = 0  # 0: at the hit; 1, 2: a Bump node's offset evaluations (own caches)
        #: compiling the world's tree: an unlinked texture vector is the ray direction, which
        #: the core passes as the Generated/Object coordinates (Cycles's background setup)
        self.world = False

    # --- registers ---------------------------------------------------------------------------
    def new_reg(self) -> int:
        self.n_regs += 1
        return self.n_regs - 1

    def reg_of(self, v: Value) -> int:
        if not v.is_const:
            return v.reg
        key = tuple(float(x) for x in v.const)
        r = self._const_regs.get(key)
        if r is None:
            r = self._const_regs[key] = self.new_reg()
            self.consts.append((r, list(key)))
        return r

    def emit(self, opcode, mode, inputs, param=0, outputs=1):
        """Append one operation; returns its output Value (or a tuple for outputs > 1)."""
        ins = [self.reg_of(v) if isinstance(v, Value) else -1 for v in inputs]
        ins += [-1] * (6 - len(ins))
        outs = [self.new_reg() for _ in range(outputs)]
        self.ops.append([opcode, mode, outs[0], outs[1] if outputs > 1 else -1] + ins + [param])
        vals = tuple(Value(self, reg=r) for r in outs)
        return vals if outputs > 1 else vals[0]

    def used(self) -> bool:
        return bool(self.ops)

    def to_dict(self) -> dict:
        return {"registers": self.n_regs, "constants": [[r] + v for r, v in self.consts],
                "ops": self.ops, "data": self.data}

    # --- sockets -----------------------------------------------------------------------------
    def input(self, node, sock, ctx, kind=None) -> Value:
        """The Value of input socket ``sock`` of ``node`` (compiled if linked). kind 'float'
        converts colours/vectors to floats as Cycles does."""
        src, sctx = resolve(sock, ctx)
        if src is None:
            v = Value(self, const=_socket_default(_unlinked_socket(sock, ctx)))
            stype = _unlinked_socket(sock, ctx).type
        else:
            v = self.output(src, sctx)
            stype = src.type
        if kind == "float" and stype in ("RGBA", "VECTOR"):
            v = self._to_float(v, stype)
        elif kind == "float" and not v.is_const:
            pass
        elif kind == "float":
            v = Value(self, const=float(v.const[0]))
        return v

    def _to_float(self, v, stype):
        if v.is_const:
            c = v.const
            return Value(self, const=float(np.dot(c, LUMINANCE)) if stype == "RGBA" else float(c.mean()))
        return self.emit(OP_TO_GRAY if stype == "RGBA" else OP_AVERAGE, 0, [v])

    def inp(self, node, key, ctx, kind=None) -> Value:
        """Input ``key`` (identifier, else name; enabled sockets first) of ``node``."""
        return self.input(node, socket(node.inputs, key), ctx, kind)

    def output(self, out_sock, ctx) -> Value:
        """The Value of a node's output socket; a node is compiled once per group context (a
        node with several outputs — a texture's Color and Fac — emits one operation)."""
        node = out_sock.node
        key = (node.as_pointer(), tuple(n.as_pointer() for n in ctx), self._variant)
        outs = self._cache.setdefault(key, {})
        hit = outs.get(out_sock.identifier)
        if hit is None:
            if getattr(node, "mute", False):
                hit = Value(self, const=_socket_default(out_sock))
            else:
                hit = self._compile(node, out_sock, ctx)
            if isinstance(hit, dict):  # every output of a multi-output operation
                outs.update(hit)
                hit = hit[out_sock.identifier]
            else:
                outs[out_sock.identifier] = hit
        return hit

    def attribute(self, name: str) -> Value:
        """A named per-corner attribute (e.g. "uv:UVMap.001"), read once per program."""
        if name not in self.attributes:
            self.attributes.append(name)
        idx = self.attributes.index(name)
        key = ("attr", idx, self._variant)
        hit = self._geometry.get(key)
        if hit is None:
            hit = self._geometry[key] = self.emit(OP_ATTRIBUTE, 0, [], param=idx)
        return hit

    def geometry(self, opcode) -> Value:
        """A geometry input (UV, Generated, Object), read once per program."""
        key = (opcode, self._variant)
        hit = self._geometry.get(key)
        if hit is None:
            hit = self._geometry[key] = self.emit(opcode, 0, [])
        return hit

    # --- nodes -------------------------------------------------------------------------------
    def _compile(self, node, out, ctx) -> Value:
        k = node.bl_idname
        oname = out.name
        if k == "ShaderNodeValue":
            return Value(self, const=float(out.default_value))
        if k == "ShaderNodeRGB":
            return Value(self, const=_vec3(out.default_value))
        if k == "ShaderNodeTexCoord":
            return self._tex_coord(node, oname)
        if k == "ShaderNodeUVMap":
            if getattr(node, "from_instancer", False):
                raise Unsupported(node)
            name = getattr(node, "uv_map", "")
            # no name: the active render UV map, as Cycles
            return self.attribute("uv:" + name) if name else self.geometry(OP_UV)
        if k == "ShaderNodeObjectInfo":
            if oname == "Material Index":
                return Value(self, const=float(self.material_pass_index))
            if oname not in OBJECT_INFO_OUTPUTS:
                raise Unsupported(node)
            key = ("object_info", oname, self._variant)
            hit = self._geometry.get(key)
            if hit is None:
                hit = self._geometry[key] = self.emit(OP_OBJECT_INFO, OBJECT_INFO_OUTPUTS[oname], [])
            return hit
        if k == "ShaderNodeBump":
            return self._bump(node, ctx)
        if k == "ShaderNodeDisplacement":  # Cycles's svm_node_displacement (object / world space)
            ins = [self.inp(node, n, ctx, "float") for n in ("Height", "Midlevel", "Scale")]
            return self.emit(OP_DISPLACEMENT, int(node.space == "OBJECT"),
                             ins + [self._linked_or_none(node, "Normal", ctx)])
        if k == "ShaderNodeVectorDisplacement":
            spaces = ("TANGENT", "OBJECT", "WORLD")
            if node.space not in spaces:
                raise Unsupported(node)
            ins = [self.inp(node, "Vector", ctx)] + [self.inp(node, n, ctx, "float") for n in ("Midlevel", "Scale")]
            if node.space == "TANGENT":  # the active render UV map's tangents (Cycles's default)
                # read at the hit even in a bump offset evaluation: Cycles's node reads the
                # attribute at the shading point (only coordinate nodes follow the offsets);
                # the hit's evaluation always comes first, so its registers exist
                variant, self._variant = self._variant, 0
                try:
                    ins += [self.attribute("tangent:"), self.attribute("tangent_sign:")]
                finally:
                    self._variant = variant
            return self.emit(OP_VECTOR_DISPLACEMENT, spaces.index(node.space), ins)
        if k in ("ShaderNodeFresnel", "ShaderNodeLayerWeight", "ShaderNodeNewGeometry",
                 "ShaderNodeLightPath", "ShaderNodeNormalMap"):
            return self._shading_point_node(node, out, ctx)
        if k == "ShaderNodeMapping":
            vt = node.vector_type
            ins = [self.inp(node, "Vector", ctx)]
            ins.append(self.inp(node, "Location", ctx) if vt in ("POINT", "TEXTURE") else Value(self, const=0.0))
            ins.append(self.inp(node, "Rotation", ctx))
            ins.append(self.inp(node, "Scale", ctx))
            return self.emit(OP_MAPPING, MAPPING_TYPES.index(vt), ins)
        if k == "ShaderNodeTexImage":
            return self._image(node, ctx)
        if k == "ShaderNodeTexEnvironment":
            return self._environment(node, ctx)
        if k == "ShaderNodeTexChecker":
            vec = self._tex_vector(node, ctx, "generated")
            col, fac = self.emit(OP_CHECKER, 0, [vec, self.inp(node, "Color1", ctx),
                                                 self.inp(node, "Color2", ctx),
                                                 self.inp(node, "Scale", ctx, "float")], outputs=2)
            return {"Color": col, "Fac": fac}
        if k == "ShaderNodeTexGradient":
            vec = self._tex_vector(node, ctx, "generated")
            col, fac = self.emit(OP_GRADIENT, GRADIENT_TYPES.index(node.gradient_type), [vec], outputs=2)
            return {"Color": col, "Fac": fac}
        if k == "ShaderNodeMath":
            op = node.operation
            if op not in MATH_OPS:
                raise Unsupported(node)
            ins = [self.input(node, node.inputs[i], ctx, "float") for i in range(3)]
            return self.emit(OP_MATH, MATH_OPS.index(op), ins, param=int(node.use_clamp))
        if k == "ShaderNodeVectorMath":
            op = node.operation
            if op not in VMATH_OPS:
                raise Unsupported(node)
            ins = [self.input(node, node.inputs[i], ctx) for i in range(3)]
            ins.append(self.input(node, node.inputs[3], ctx, "float"))  # Scale
            res = self.emit(OP_VMATH, VMATH_OPS.index(op), ins)
            if oname == "Value" and op not in VMATH_VALUE_OUT:
                return Value(self, const=0.0)  # Blender: the unused output is 0
            if oname == "Vector" and op in VMATH_VALUE_OUT:
                return Value(self, const=0.0)
            return res
        if k in ("ShaderNodeMix", "ShaderNodeMixRGB"):
            return self._mix(node, oname, ctx)
        if k == "ShaderNodeValToRGB":
            table = _ramp_table(node.color_ramp)
            off = len(self.data)
            self.data += table
            col, alpha = self.emit(OP_RAMP, int(node.color_ramp.interpolation != "CONSTANT"),
                                   [self.inp(node, "Fac", ctx, "float")], param=off, outputs=2)
            return {"Color": col, "Alpha": alpha}
        if k == "ShaderNodeMapRange":
            if node.data_type == "FLOAT_VECTOR":
                return vector_map_range(self, node, out, ctx)
            if node.data_type != "FLOAT":
                raise Unsupported(node)
            names = ["Value", "From Min", "From Max", "To Min", "To Max", "Steps"]
            ins = [self.input(node, _first(node.inputs, n, "VALUE"), ctx, "float") for n in names]
            mode = MAP_RANGE_TYPES.index(node.interpolation_type)
            return self.emit(OP_MAP_RANGE, mode, ins, param=int(node.clamp))
        if k == "ShaderNodeClamp":
            ins = [self.inp(node, n, ctx, "float") for n in ("Value", "Min", "Max")]
            return self.emit(OP_CLAMP, int(node.clamp_type == "RANGE"), ins)
        if k == "ShaderNodeInvert":
            return self.emit(OP_INVERT, 0, [self.inp(node, "Fac", ctx, "float"), self.inp(node, "Color", ctx)])
        if k == "ShaderNodeGamma":
            return self.emit(OP_GAMMA, 0, [self.inp(node, "Color", ctx), self.inp(node, "Gamma", ctx, "float")])
        if k == "ShaderNodeBrightContrast":
            return self.emit(OP_BRIGHT_CONTRAST, 0, [self.inp(node, "Color", ctx),
                                                     self.inp(node, "Bright", ctx, "float"),
                                                     self.inp(node, "Contrast", ctx, "float")])
        if k == "ShaderNodeHueSaturation":
            ins = [self.inp(node, n, ctx, "float") for n in ("Hue", "Saturation", "Value", "Fac")]
            return self.emit(OP_HSV, 0, ins + [self.inp(node, "Color", ctx)])
        if k in ("ShaderNodeSeparateXYZ", "ShaderNodeSeparateRGB", "ShaderNodeSeparateColor"):
            src = self.input(node, node.inputs[0], ctx)
            if k == "ShaderNodeSeparateColor" and node.mode != "RGB":
                if node.mode != "HSV":
                    raise Unsupported(node)
                src = self.emit(OP_RGB_TO_HSV, 0, [src])
            idx = [o.identifier for o in node.outputs].index(out.identifier)
            if src.is_const:
                return Value(self, const=float(src.const[idx]))
            return self.emit(OP_COMPONENT, idx, [src])
        if k in ("ShaderNodeCombineXYZ", "ShaderNodeCombineRGB", "ShaderNodeCombineColor"):
            ins = [self.input(node, node.inputs[i], ctx, "float") for i in range(3)]
            res = self.emit(OP_COMBINE, 0, ins)
            if k == "ShaderNodeCombineColor" and node.mode != "RGB":
                if node.mode != "HSV":
                    raise Unsupported(node)
                res = self.emit(OP_HSV_TO_RGB, 0, [res])
            return res
        if k in PROCEDURAL_COMPILERS:
            return PROCEDURAL_COMPILERS[k](self, node, out, ctx)
        if k in CONVERTER_COMPILERS:
            return CONVERTER_COMPILERS[k](self, node, out, ctx)
        raise Unsupported(node)

    def _linked_or_none(self, node, key, ctx):
        """The Value of a vector input if linked, else None (the node's own default applies)."""
        sock = socket(node.inputs, key)
        return self.input(node, sock, ctx) if resolve(sock, ctx)[0] is not None else None

    def _shading_point_node(self, node, out, ctx):
        """Nodes reading the shading point (normal, incoming direction, ray type): Fresnel, Layer
        Weight, Geometry, Light Path, Normal Map (docs/materials.md, "Shading-point inputs")."""
        k = node.bl_idname
        oname = out.name
        if k == "ShaderNodeFresnel":
            return self.emit(OP_FRESNEL, 0, [self.inp(node, "IOR", ctx, "float"),
                                             self._linked_or_none(node, "Normal", ctx)])
        if k == "ShaderNodeLayerWeight":
            f, facing = self.emit(OP_LAYER_WEIGHT, 0, [self.inp(node, "Blend", ctx, "float"),
                                                       self._linked_or_none(node, "Normal", ctx)], outputs=2)
            return {node.outputs[0].identifier: f, node.outputs[1].identifier: facing}
        if k == "ShaderNodeNewGeometry":
            if oname in MESH_ATTRIBUTE_OUTPUTS:  # attributes the export computes per mesh
                return self.attribute(MESH_ATTRIBUTE_OUTPUTS[oname])
            row = GEOMETRY_OUTPUTS.get(oname)
            if row is None:
                raise Unsupported(node)
            return self.point(*row)
        if k == "ShaderNodeLightPath":
            if oname not in LIGHT_PATH_OUTPUTS:
                raise Unsupported(node)
            row = LIGHT_PATH_OUTPUTS[oname]
            if row is None:
                return Value(self, const=0.0)
            return self.point(*row)
        # Normal Map
        space = node.space
        if space not in NORMAL_MAP_SPACES:
            raise Unsupported(node)
        ins = [self.inp(node, "Strength", ctx, "float"), self.inp(node, "Color", ctx)]
        if space == "TANGENT":
            uv = getattr(node, "uv_map", "")
            ins += [self.attribute("tangent:" + uv), self.attribute("tangent_sign:" + uv)]
        return self.emit(OP_NORMAL_MAP, NORMAL_MAP_SPACES.index(space), ins)

    def _bump(self, node, ctx):
        """The Bump node (Cycles's ``svm_node_set_bump``): its Height sub-graph is compiled
        three times — at the hit and after ``OP_BUMP_OFFSET`` moves the shading point one step
        along each triangle edge (every coordinate input moves with it) — then ``OP_BUMP``
        forms the perturbed normal."""
        normal_in = self._linked_or_none(node, "Normal", ctx)
        hsock = socket(node.inputs, "Height")
        if resolve(hsock, ctx)[0] is None or self._variant:
            if self._variant:  # a Bump inside another Bump's height: not supported
                raise Unsupported(node)
            return normal_in if normal_in is not None else self.point(POINT_N, -1)
        h_c = self.input(node, hsock, ctx, "float")
        if h_c.is_const:  # a constant height does not bend the normal
            return normal_in if normal_in is not None else self.point(POINT_N, -1)
        heights = [h_c]
        fsock = node.inputs.get("Filter Width")
        fw = self.input(node, fsock, ctx, "float") if fsock is not None else Value(self, const=0.1)
        for variant in (1, 2):
            self.emit(OP_BUMP_OFFSET, variant, [fw])
            self._variant = variant
            try:
                heights.append(self.input(node, hsock, ctx, "float"))
            finally:
                self._variant = 0
        self.emit(OP_BUMP_OFFSET, 0, [])
        ins = heights + [self.inp(node, "Strength", ctx, "float"), self.inp(node, "Distance", ctx, "float"),
                         normal_in]
        # param: 2 × the filter width's register + invert (OP_BUMP has no seventh input)
        return self.emit(OP_BUMP, 0, ins, param=2 * self.reg_of(fw) + int(bool(getattr(node, "invert", False))))

    def displacement_bump(self, out_node, sock):
        """The Material Output's Displacement as bump (Cycles's ``bump_from_displacement``,
        displacement method Bump): the displacement vector's sub-graph is compiled at the hit and
        at the two Bump offsets, dotted with N, and fed to a Bump of strength 1, distance 1,
        filter width 0.1 on N; ``OP_SET_NORMAL`` makes the result the shading point's N, which
        everything compiled afterwards reads (the node caches are cleared: nodes shared with
        the surface are evaluated again on the bumped normal, as Cycles's copies are). Returns
        the bumped normal, or None when the displacement is constant (no bump)."""
        src, sctx = resolve(sock, ())
        if src is None:
            return None
        d_c = self.output(src, sctx)
        if d_c.is_const:
            return None
        dot = VMATH_OPS.index("DOT_PRODUCT")
        heights = [self.emit(OP_VMATH, dot, [d_c, self.point(POINT_N, -1)])]
        fw = Value(self, const=0.1)
        for variant in (1, 2):
            self.emit(OP_BUMP_OFFSET, variant, [fw])
            self._variant = variant
            try:
                heights.append(self.emit(OP_VMATH, dot, [self.output(src, sctx), self.point(POINT_N, -1)]))
            finally:
                self._variant = 0
        self.emit(OP_BUMP_OFFSET, 0, [])
        one = Value(self, const=1.0)
        bumped = self.emit(OP_BUMP, 0, heights + [one, one, None], param=2 * self.reg_of(fw))
        normal = self.emit(OP_SET_NORMAL, 0, [bumped])
        self._cache.clear()
        self._geometry = {k: v for k, v in self._geometry.items()
                          if not (isinstance(k, tuple) and k[0] in ("point", "texco_normal"))}
        return normal

    def _tex_coord(self, node, oname):
        """Texture Coordinate outputs (Cycles's ``svm_node_tex_coord``)."""
        other = getattr(node, "object", None)
        if oname == "Object" and other is not None:
            # another object's local space: its inverse world matrix on the world position (not
            # np.linalg.inv: OpenBLAS runs that on threads that spin on beside the render's); an
            # object scaled to zero has no local space: 0 everywhere
            m = compat.core_module("motion").invert_affine(np.array(other.matrix_world, np.float64))
            m = np.zeros((4, 4)) if m is None else m
            p = self.point(POINT_P, -1)
            comps = [self.emit(OP_COMPONENT, j, [p]) for j in range(3)]
            out = Value(self, const=m[:3, 3])
            for j in range(3):
                out = out + comps[j] * Value(self, const=m[:3, j])
            return out
        op = {"UV": OP_UV, "Generated": OP_GENERATED, "Object": OP_OBJECT}.get(oname)
        if op is not None:
            return self.geometry(op)
        if oname == "Reflection":  # the mirror direction of the incoming one about N, world
            n, i = self.point(POINT_N, -1), self.point(POINT_I, -1)
            d = self.emit(OP_VMATH, VMATH_OPS.index("DOT_PRODUCT"), [n, i])
            return n * (d * 2.0) - i
        if oname in ("Camera", "Window"):
            key = ("camera", oname, self._variant)
            hit = self._geometry.get(key)
            if hit is None:
                hit = self._geometry[key] = self.emit(OP_CAMERA_COORDS, int(oname == "Window"), [])
            return hit
        if oname == "Normal":  # the shading normal in object space (svm_node_tex_coord)
            key = ("texco_normal", self._variant)
            hit = self._geometry.get(key)
            if hit is None:
                hit = self._geometry[key] = self.emit(OP_TEXCO_NORMAL, 0, [])
            return hit
        raise Unsupported(node)

    def point(self, row: int, component: int) -> Value:
        """A shading-point input (row of the point array, one component or −1: the vector)."""
        key = ("point", row, component, self._variant)
        hit = self._geometry.get(key)
        if hit is None:
            hit = self._geometry[key] = self.emit(OP_POINT, row, [], param=component)
        return hit

    def pack(self, a, b, c=0.0) -> Value:
        """Three float Values in one register (x, y, z), for the procedural operations' packed
        inputs: a constant when all three are."""
        vals = [v if isinstance(v, Value) else Value(self, const=float(v)) for v in (a, b, c)]
        if all(v.is_const for v in vals):
            return Value(self, const=[float(v.const[0]) for v in vals])
        return self.emit(OP_COMBINE, 0, vals)

    def _tex_vector(self, node, ctx, default):
        sock = socket(node.inputs, "Vector")
        src, sctx = resolve(sock, ctx)
        if src is None:
            return self.geometry(OP_UV if default == "uv" else OP_GENERATED)
        return self.output(src, sctx)

    def _image(self, node, ctx):
        image = node.image
        magenta = {"Color": Value(self, const=(1.0, 0.0, 1.0)), "Alpha": Value(self, const=1.0)}
        if image is None:  # Cycles: a missing image renders magenta (1, 0, 1), alpha 1
            return magenta
        if node.projection not in IMAGE_PROJECTIONS or image.source not in ("FILE", "GENERATED"):
            raise Unsupported(node)
        try:
            idx = self.images.index_of(image)
        except ValueError as e:  # a colour space we cannot convert yet: the input's constant
            self.problems.append(str(e))
            raise Unsupported(node) from None
        if idx is None:
            self.problems.append(f"image '{image.name}' has no pixels (missing file?), rendered "
                                 f"magenta as in Cycles")
            return magenta
        interp = min(INTERPOLATIONS.index(node.interpolation), 2)  # Smart: Cubic, as Cycles's CPU
        mode = interp * 8 + EXTENSIONS.index(node.extension)
        vec = self._tex_vector(node, ctx, "uv")
        if node.projection == "BOX":  # blends up to three planar lookups by the object normal
            blend = Value(self, const=float(min(max(node.projection_blend, 0.0), 1.0)))
            col, alpha = self.emit(OP_IMAGE_BOX, mode, [vec, blend], param=idx, outputs=2)
        else:
            mode += IMAGE_PROJECTIONS.index(node.projection) * IMAGE_PROJECTION_STRIDE
            col, alpha = self.emit(OP_IMAGE, mode, [vec], param=idx, outputs=2)
        return {"Color": col, "Alpha": alpha}

    def _environment(self, node, ctx):
        """Environment Texture (equirectangular, mirror ball; Cycles's extension is always
        REPEAT). Its unlinked Vector is the shading position, which only the world has (the
        ray direction); in a material that is a position we do not carry: unsupported."""
        image = node.image
        magenta = {"Color": Value(self, const=(1.0, 0.0, 1.0)), "Alpha": Value(self, const=1.0)}
        if image is None:
            return magenta
        if node.projection not in ENV_PROJECTIONS or image.source not in ("FILE", "GENERATED"):
            raise Unsupported(node)
        sock = socket(node.inputs, "Vector")
        src, sctx = resolve(sock, ctx)
        try:
            idx = self.images.index_of(image)
        except ValueError as e:
            self.problems.append(str(e))
            raise Unsupported(node) from None
        if idx is None:
            self.problems.append(f"image '{image.name}' has no pixels (missing file?), rendered "
                                 f"magenta as in Cycles")
            return magenta
        if src is not None:
            vec = self.output(src, sctx)
        else:  # the shading position: the ray direction in the world, P (world) on a surface
            vec = self.geometry(OP_GENERATED) if self.world else self.point(POINT_P, -1)
        interp = min(INTERPOLATIONS.index(node.interpolation), 2)  # Smart: Cubic (Cycles's CPU)
        mode = ENV_PROJECTIONS.index(node.projection) * ENV_PROJECTION_STRIDE + interp * 8
        col, alpha = self.emit(OP_ENVIRONMENT, mode, [vec], param=idx, outputs=2)
        col.fallback = self.images.mean_color(idx, node.projection == "EQUIRECTANGULAR")
        return {"Color": col, "Alpha": alpha}

    def _mix(self, node, oname, ctx):
        if node.bl_idname == "ShaderNodeMixRGB":
            data_type, blend = "RGBA", node.blend_type
            fac = clamp01(self.inp(node, "Fac", ctx, "float"))  # legacy MixRGB clamps its factor
            a, b = self.input(node, node.inputs[1], ctx), self.input(node, node.inputs[2], ctx)
            clamp_result = node.use_clamp
        else:
            data_type = node.data_type
            if data_type not in ("FLOAT", "RGBA", "VECTOR"):
                raise Unsupported(node)
            socks = [s for s in node.inputs if s.enabled]
            fac_sock = socks[0]
            a_sock, b_sock = socks[1], socks[2]
            if data_type == "VECTOR" and node.factor_mode == "NON_UNIFORM":
                fac = self.input(node, fac_sock, ctx)
            else:
                fac = self.input(node, fac_sock, ctx, "float")
            if node.clamp_factor:
                fac = clamp01(fac)
            kind = "float" if data_type == "FLOAT" else None
            a, b = self.input(node, a_sock, ctx, kind), self.input(node, b_sock, ctx, kind)
            blend = node.blend_type if data_type == "RGBA" else "MIX"
            clamp_result = data_type == "RGBA" and node.clamp_result
        if blend not in BLEND_TYPES:
            raise Unsupported(node)
        res = self.emit(OP_MIX, BLEND_TYPES.index(blend), [fac, a, b])
        return clamp01(res) if clamp_result else res


def socket(sockets, key):
    """The socket whose identifier (else name) is ``key``, preferring enabled ones: names and
    identifiers differ ('Factor' / 'Fac') and several sockets may share a name."""
    for attr in ("identifier", "name"):
        for want_enabled in (True, False):
            for s in sockets:
                if getattr(s, attr) == key and (s.enabled or not want_enabled):
                    return s
    raise KeyError(key)


def _first(sockets, name, stype):
    for s in sockets:
        if s.name == name and s.enabled:
            return s
    for s in sockets:
        if s.name == name and s.type == stype:
            return s
    return socket(sockets, name)


def _unlinked_socket(sock, ctx):
    """For an input linked through a Group Input to an unlinked group-node socket, that socket
    (its default is the value); otherwise ``sock`` itself."""
    for _ in range(64):
        if not sock.is_linked:
            return sock
        link = sock.links[0]
        node = link.from_node
        if node.bl_idname == "NodeReroute":
            sock = node.inputs[0]
            continue
        if node.bl_idname == "NodeGroupInput" and ctx:
            idx = list(node.outputs).index(link.from_socket)
            sock = ctx[-1].inputs[idx]
            ctx = ctx[:-1]
            continue
        return sock
    return sock


def _ramp_table(ramp) -> list[float]:
    """Blender's own evaluation of the ramp at RAMP_TABLE_SIZE points, RGBA, as Cycles bakes it."""
    out = []
    for i in range(RAMP_TABLE_SIZE):
        out += list(ramp.evaluate(i / (RAMP_TABLE_SIZE - 1)))
    return out


def _linear_to_srgb(px: np.ndarray) -> np.ndarray:
    """Cycles's ``color_linear_to_srgb`` on RGB (alpha unchanged); negatives → 0."""
    out = px.astype(np.float64).copy()
    c = out[..., :3]
    out[..., :3] = np.where(c < 0.0031308, np.maximum(c, 0.0) * 12.92,
                            1.055 * np.power(np.maximum(c, 0.0031308), 1.0 / 2.4) - 0.055)
    return out.astype(np.float32)


class ImageTable:
    """Images referenced by programs: pixels stored once each (uint8 for byte images, float16
    for float images), bottom row first as Blender stores them."""

    def __init__(self):
        self.images: list[dict] = []
        self.arrays: dict = {}
        self._index: dict = {}

    def index_of(self, image):
        key = image.original.as_pointer() if hasattr(image, "original") else image.as_pointer()
        if key in self._index:
            return self._index[key]
        w, h = (int(x) for x in image.size)
        if w == 0 or h == 0:
            self._index[key] = None
            return None
        ch = int(image.channels)
        px = np.empty(w * h * ch, dtype=np.float32)
        image.pixels.foreach_get(px)
        px = px.reshape(h, w, ch)
        if ch < 4:  # grey / RGB → RGBA
            rgba = np.ones((h, w, 4), np.float32)
            rgba[..., :3] = px[..., :1] if ch < 3 else px[..., :3]
            px = rgba
        is_float = bool(image.is_float)
        cs = image.colorspace_settings.name
        if cs not in ("sRGB", "Non-Color", "Linear Rec.709", "Linear", "Raw"):
            raise ValueError(f"image '{image.name}' colour space {cs!r} is not supported")
        srgb = cs == "sRGB"
        if is_float:
            if srgb:
                # A float image tagged sRGB: Blender hands over linear pixels, but Cycles
                # interpolates them sRGB-encoded and decodes after the lookup (measured: see
                # tests/test_material_programs.py::test_float_image_matches_cycles). Store the
                # encoded values, like a byte image's.
                px = _linear_to_srgb(px)
            arr = px.astype(np.float16)
        else:
            arr = np.clip(np.rint(px * 255.0), 0, 255).astype(np.uint8)
        idx = len(self.images)
        name = f"image{idx}.pixels"
        self.arrays[name] = np.ascontiguousarray(arr)
        self.images.append({"name": image.name, "width": w, "height": h, "srgb": srgb,
                            "array": name})
        self._index[key] = idx
        return idx

    def mean_color(self, idx: int, equirectangular: bool) -> np.ndarray:
        """Mean linear RGB of image ``idx`` (over the sphere, sin θ-weighted by row, for an
        equirectangular map): a textured world's constant stand-in (the viewport's)."""
        arr = self.arrays[self.images[idx]["array"]]
        lin = arr[..., :3].astype(np.float64) / (255.0 if arr.dtype == np.uint8 else 1.0)
        if self.images[idx]["srgb"]:  # stored sRGB-encoded (docs/materials.md, Images)
            lin = np.where(lin < 0.04045, lin / 12.92, ((np.maximum(lin, 0.0) + 0.055) / 1.055) ** 2.4)
        h = lin.shape[0]
        w = np.sin(np.pi * (np.arange(h) + 0.5) / h) if equirectangular else np.ones(h)
        return (lin.mean(axis=1) * w[:, None]).sum(axis=0) / w.sum()


from .procedural_nodes import PROCEDURAL_COMPILERS  # noqa: E402  (it imports this module's names)
from .converter_nodes import CONVERTER_COMPILERS, vector_map_range  # noqa: E402  (likewise)
