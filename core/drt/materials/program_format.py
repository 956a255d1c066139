"""Material programs in the scene file: opcodes, validation and the arrays the interpreter reads
(``ProgramData``). Plain numpy (no kernels): ``drt.scene`` validates programs with it, and
``drt.materials.programs`` interprets them. See docs/materials.md and docs/scene-format.md.

A material's ``program`` (header JSON):

    {"registers": R,                      # register count (each three float64)
     "constants": [[reg, x, y, z], ...],  # registers loaded before the first operation
     "ops": [[opcode, mode, out0, out1, in0, in1, in2, in3, in4, in5, param], ...],
     "data": [float, ...]}                # colour-ramp tables (RAMP_TABLE_SIZE × RGBA each),
                                          # curve tables ([min_x, max_x, extrapolate, 0] + table),
                                          # brick parameters (4 floats)

and its lobes may carry ``color_reg`` / ``roughness_reg`` (the register that gives the lobe's
weight colour / Blender roughness at a shading point; the lobe's ``color`` and ``roughness``
are then representative values used for light-selection hints), the material
``emission_reg``. ``OP_ATTRIBUTE`` reads the per-corner attribute ``param`` of the header's
``attributes`` list (names like ``"uv:UVMap.001"``, ``"attr:Col"`` (a mesh attribute's
colour/vector, float → replicated), ``"fac:Col"`` (its Fac: float, x of a float2, average of a
vector/colour), ``"alpha:Col"`` (a colour's alpha, 1 for other types); ``"attr:"`` with an empty
name is the render colour attribute); arrays ``mesh<K>.attr<I>`` (T, 3, 3)
float32; zero on meshes without it, as Cycles's missing attributes). Images are a header list ``images`` of {"name", "width", "height", "srgb",
"array"} whose array is (height, width, 4) uint8 or float16, bottom row first; ``srgb``:
the values are sRGB-encoded and decoded to linear after interpolation (byte images, and float
images tagged sRGB, as Cycles does).
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np

RAMP_TABLE_SIZE = 256
OP_UV, OP_GENERATED, OP_OBJECT, OP_ATTRIBUTE = 1, 2, 3, 4
OP_VMATH, OP_MATH, OP_MIX, OP_MAPPING = 10, 11, 12, 13
OP_IMAGE, OP_CHECKER, OP_GRADIENT, OP_RAMP = 20, 21, 22, 23
#: Image Texture: OP_IMAGE's mode = projection (0 Flat, 1 Sphere, 2 Tube)·IMAGE_PROJECTION_STRIDE
#: + interpolation·8 + extension; Box projection is OP_IMAGE_BOX (same mode without the
#: projection; in0 the vector, in1 the Blend; reads the shading normal and the object transform)
IMAGE_PROJECTION_STRIDE = 32
OP_IMAGE_BOX = 24
OP_MAP_RANGE, OP_CLAMP, OP_INVERT, OP_GAMMA, OP_BRIGHT_CONTRAST, OP_HSV = 30, 31, 32, 33, 34, 35
OP_COMPONENT, OP_COMBINE, OP_TO_GRAY, OP_AVERAGE, OP_RGB_TO_HSV, OP_HSV_TO_RGB = 40, 41, 42, 43, 44, 45
#: Environment Texture (the world's opcodes use 70–79): mode = projection·32 + image mode
#: (interpolation·8 + extension, always REPEAT as Cycles), param = image; in0 = the direction
OP_ENVIRONMENT = 70
ENV_PROJECTION_STRIDE = 32
# shading-point inputs of surface hits (docs/materials.md, "Shading-point inputs")
OP_POINT, OP_FRESNEL, OP_LAYER_WEIGHT, OP_NORMAL_MAP, OP_OBJECT_INFO = 90, 91, 92, 93, 94
OP_BUMP_OFFSET, OP_BUMP, OP_CAMERA_COORDS = 95, 96, 97
#: object-space shading inputs (docs/materials.md, "Object spaces and displacement"):
#: Texture Coordinate Normal (mode 0); the Displacement node (mode 0 world, 1 object; ins
#: height, midlevel, scale, normal or −1 for N); Vector Displacement (mode 0 tangent, 1 object,
#: 2 world; ins vector, midlevel, scale (+ tangent, tangent sign in tangent space)); SET_NORMAL writes in0 (normalised) into the point's N row, so
#: the rest of the program sees the bumped normal (Cycles's ``svm_node_set_normal``)
OP_TEXCO_NORMAL, OP_DISPLACEMENT, OP_VECTOR_DISPLACEMENT, OP_SET_NORMAL = 98, 99, 100, 101
# procedural textures and curves (issue 11 phase 2; kernels in drt.materials.procedural). Scalar
# inputs travel packed three to a register (the compiler's COMBINE), see programs.run_program.
OP_NOISE, OP_WHITE_NOISE, OP_VORONOI, OP_WAVE, OP_MAGIC, OP_BRICK, OP_CURVES = 50, 51, 52, 53, 54, 55, 56
PROCEDURAL_OPCODES = {OP_NOISE, OP_WHITE_NOISE, OP_VORONOI, OP_WAVE, OP_MAGIC, OP_BRICK, OP_CURVES}
#: opcodes whose ``param`` is an offset into ``data`` and how many floats they read there
DATA_OPS = {OP_RAMP: 4 * RAMP_TABLE_SIZE, OP_BRICK: 4, OP_CURVES: 4 + 4 * RAMP_TABLE_SIZE}
OPCODES = PROCEDURAL_OPCODES | {OP_TEXCO_NORMAL, OP_DISPLACEMENT, OP_VECTOR_DISPLACEMENT, OP_SET_NORMAL, OP_POINT, OP_FRESNEL, OP_LAYER_WEIGHT, OP_NORMAL_MAP, OP_OBJECT_INFO, OP_BUMP_OFFSET, OP_BUMP,
           OP_CAMERA_COORDS, OP_UV, OP_GENERATED, OP_OBJECT, OP_ATTRIBUTE, OP_VMATH, OP_MATH, OP_MIX, OP_MAPPING, OP_IMAGE,
           OP_CHECKER, OP_GRADIENT, OP_RAMP, OP_MAP_RANGE, OP_CLAMP, OP_INVERT, OP_GAMMA,
           OP_BRIGHT_CONTRAST, OP_HSV, OP_COMPONENT, OP_COMBINE, OP_TO_GRAY, OP_AVERAGE,
           OP_RGB_TO_HSV, OP_HSV_TO_RGB, OP_ENVIRONMENT, OP_IMAGE_BOX}
#: geometry inputs an opcode reads (the scene stores those per-corner arrays only if read)
READS = {OP_UV: "uv", OP_GENERATED: "generated", OP_OBJECT: "object_coords"}
OP_WIDTH = 11
#: rows of the ``point`` array a caller fills for a shading point off any triangle (a volume
#: sample, a world direction): what the coordinate opcodes read there
POINT_GENERATED, POINT_OBJECT, POINT_UV = 0, 1, 2
#: rows the shade stage fills at a surface hit of a material whose program reads them
#: (``ProgramData.reads_point``), all world space with Cycles's orientation: P (Blender world
#: coordinates), N / NG (shading / true normal, flipped to the side the ray came from, Cycles's
#: sd->N / sd->Ng), I (unit vector back along the ray, sd->wi), NSMOOTH (interpolated vertex
#: normal, unnormalised, geometric front side; the true normal when flat shaded), the ray's
#: Light Path values, and XFORM (3 rows: the normal transform of a moving object's hit, identity
#: otherwise; static tangents are stored in world space already)
POINT_P, POINT_N, POINT_NG, POINT_I, POINT_NSMOOTH = 3, 4, 5, 6, 7
POINT_PATH = 8     # (is camera ray, is diffuse ray, is glossy ray)
POINT_PATH2 = 9    # (is singular ray, is reflection ray, is transmission ray)
POINT_DEPTH = 10   # (ray depth, diffuse depth, glossy depth)
POINT_MISC = 11    # (transmission depth, ray length, backfacing)
POINT_XFORM = 12   # rows 12..14
POINT_SHADOW = 15  # (is shadow ray, 0, 0): 1 only where a shadow ray meets a transparent surface
#: rows 16..18: the hit object's normal transform (object → world normals, inv(M)ᵀ of its 3×3
#: matrix M): the moving object's normal transform, a static object's from ``object_info``
#: columns 9..17 (filled only when the scene keeps per-object data), identity otherwise
POINT_OBJECT_XFORM = 16
POINT_ROWS = 19
#: Normal Map spaces (Blender's enum order)
NORMAL_MAP_SPACES = ("TANGENT", "OBJECT", "WORLD", "BLENDER_OBJECT", "BLENDER_WORLD")
#: Rec.709 luminance weights (Blender's default working space): Cycles's colour → float
LUMINANCE = (0.2126729, 0.7151522, 0.0721750)
MAX_REGISTERS = 4096

#: ``ProgramData.coat_normal_reg`` of a coat whose normal is the unmapped (smooth) shading
#: normal: an unlinked Coat Normal under a linked Normal (Cycles links it to the Geometry normal)
COAT_NORMAL_SMOOTH = -2

ProgramData = namedtuple("ProgramData", [
    "prog_of",          # (M,) int64 program of each material, −1: constant material
    "op_start",         # (P+1,) int64 rows of ``ops`` per program
    "ops",              # (N, OP_WIDTH) int64
    "const_start",      # (P+1,) int64 rows of const_reg/const_val per program
    "const_reg",        # (K,) int64
    "const_val",        # (K, 3) float64
    "data",             # (D,) float64 ramp tables
    "lobe_color_reg",   # (M, L) int64, −1: the lobe's constant colour
    "lobe_rough_reg",   # (M, L) int64, −1: constant roughness
    "emission_reg",     # (M,) int64, −1: constant emission
    "img_info",         # (I, 5) int64 [width, height, offset, is_float, srgb]
    "img_u8",           # (X,) uint8
    "img_f32",          # (Y,) float32
    "uv",               # (T, 3, 2) float32 ((0, 3, 2): none)
    "generated",        # (T, 3, 3) float32
    "objco",            # (T, 3, 3) float32
    "attrs",            # (A, T, 3, 3) float32 named per-corner attributes (header "attributes")
    "reads_point",      # (M,) bool: the material's program reads shading-point rows (POINT_P...)
    "normal_reg",       # (M,) int64 register of the shading normal (Normal Map), −1: none
    "coat_normal_reg",  # (M,) int64 the coat's normal (Principled Coat Normal ≠ Normal; the
                        # lobes with ``frame``): a register, COAT_NORMAL_SMOOTH (the unmapped
                        # shading normal), −1: none (the coat uses the shading normal)
    "origin",           # (3,) float64 Blender world position of the renderer's origin (P rows)
    "object_of",        # (T,) int32 object of each global triangle ((0,): no Object Info)
    "object_info",      # (O, 18) float64 [location xyz, colour rgb, alpha, pass index, random,
                        # normal transform inv(M)ᵀ row-major (9)] ((0, 9): none)
    "positions",        # (V, 3) float32 static world-space vertices (the Bump node's tangents)
    "triangles",        # (S, 3) int32 static triangles (global ids < S)
    "footprint",        # (4, 3) float64 a pixel's right/up extent at a hit: abs + t·rel rows
                        # [right abs, right rel, up abs, up rel] (Bump's ray differentials)
    "camera",           # (5, 4) float64: rows 0–2 Blender world → camera (3×4, no scale),
                        # row 3 [ortho, plane_w, plane_h, 0], row 4 [shift_x, shift_y, 0, 0]
    "lobe_weight_reg",  # (M, L) int64 register of a METALLIC lobe's weight / a GLASS lobe's
                        # reflection_weight (lobe_fresnel[..., 4]), −1: constant
    "lobe_layer_reg",   # (M, L, 2) int64 a coat / sheen layer's [k register (k = its largest
                        # component), coat tint register], −1: constant (MaterialData.lobe_coat)
    "lobe_ior_reg",     # (M, L, 3) int64 a lobe's [IOR, Specular IOR Level, specular tint]
                        # registers (DIELECTRIC_SPECULAR: all three or none; METALLIC: tint =
                        # its F82 tint; GLASS / REFRACTION: IOR), −1: constant (lobe_ior,
                        # lobe_fresnel[..., :3]; docs/materials.md "Textured IOR and tint")
    "procedural",       # True when a program has a procedural opcode (PROCEDURAL_OPCODES), else
                        # None: the kernels then compile without the procedural textures (a
                        # variant; `uses_procedural`, drt.kernels.kernel_variant)
])


#: lobe keys of the registers in ``ProgramData.lobe_ior_reg``, in column order
IOR_REG_KEYS = ("ior_reg", "ior_level_reg", "tint_reg")


def validate_program(prog, n_images: int, where: str, n_attributes: int = 0) -> dict:
    """A checked copy of a material's ``program`` dict; raises ValueError naming the field."""
    if not isinstance(prog, dict):
        raise ValueError(f"{where}: must be an object")
    n = prog.get("registers")
    if isinstance(n, bool) or not isinstance(n, int) or not 0 < n <= MAX_REGISTERS:
        raise ValueError(f"{where}.registers: must be an integer in [1, {MAX_REGISTERS}], got {n!r}")
    try:
        consts = np.array(prog.get("constants", []), dtype=np.float64).reshape(-1, 4)
        ops = np.array(prog.get("ops", []), dtype=np.int64).reshape(-1, OP_WIDTH)
        data = np.array(prog.get("data", []), dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f"{where}: constants must be [reg, x, y, z] rows and ops rows of "
                         f"{OP_WIDTH} integers") from None
    if not (np.all(np.isfinite(consts)) and np.all(np.isfinite(data))):
        raise ValueError(f"{where}: constants and data must be finite")
    if len(consts) and (consts[:, 0].min() < 0 or consts[:, 0].max() >= n):
        raise ValueError(f"{where}.constants: register out of range")
    for k, row in enumerate(ops):
        if int(row[0]) not in OPCODES:
            raise ValueError(f"{where}.ops[{k}]: unknown opcode {int(row[0])}")
        regs = row[2:10]
        if regs.max() >= n or regs.min() < -1 or row[2] < 0:
            raise ValueError(f"{where}.ops[{k}]: register out of range")
        if row[0] in (OP_IMAGE, OP_ENVIRONMENT, OP_IMAGE_BOX) and not 0 <= row[10] < n_images:
            raise ValueError(f"{where}.ops[{k}]: image {int(row[10])} does not exist")
        if row[0] == OP_IMAGE and not 0 <= row[1] < 3 * IMAGE_PROJECTION_STRIDE \
                or row[0] == OP_IMAGE_BOX and not (0 <= row[1] < IMAGE_PROJECTION_STRIDE and row[5] >= 0):
            raise ValueError(f"{where}.ops[{k}]: image projection, mode or inputs out of range")
        if row[0] == OP_ATTRIBUTE and not 0 <= row[10] < n_attributes:
            raise ValueError(f"{where}.ops[{k}]: attribute {int(row[10])} does not exist")
        if row[0] == OP_POINT and not (0 <= row[1] < POINT_ROWS and -1 <= row[10] <= 2):
            raise ValueError(f"{where}.ops[{k}]: shading-point row/component out of range")
        if row[0] == OP_NORMAL_MAP and not (0 <= row[1] < len(NORMAL_MAP_SPACES) and min(row[4], row[5]) >= 0):
            raise ValueError(f"{where}.ops[{k}]: normal map space or inputs out of range")
        if row[0] == OP_BUMP_OFFSET and not 0 <= row[1] <= 2:
            raise ValueError(f"{where}.ops[{k}]: bump offset mode out of range")
        if row[0] == OP_BUMP and (min(row[4], row[5], row[6], row[7], row[8]) < 0
                                  or not 0 <= row[10] // 2 < n):
            raise ValueError(f"{where}.ops[{k}]: missing input")
        if row[0] == OP_BUMP_OFFSET and row[1] and row[4] < 0:
            raise ValueError(f"{where}.ops[{k}]: missing filter width")
        if row[0] == OP_CAMERA_COORDS and not 0 <= row[1] <= 1:
            raise ValueError(f"{where}.ops[{k}]: camera coordinate output out of range")
        if row[0] == OP_DISPLACEMENT and not (0 <= row[1] <= 1 and min(row[4], row[5], row[6]) >= 0):
            raise ValueError(f"{where}.ops[{k}]: displacement space or inputs out of range")
        if row[0] == OP_VECTOR_DISPLACEMENT and not (0 <= row[1] <= 2 and min(row[4], row[5], row[6]) >= 0
                                                     and (row[1] or min(row[7], row[8]) >= 0)):
            raise ValueError(f"{where}.ops[{k}]: vector displacement space or inputs out of range")
        if row[0] == OP_SET_NORMAL and row[4] < 0:
            raise ValueError(f"{where}.ops[{k}]: missing input")
        if row[0] == OP_OBJECT_INFO and not 0 <= row[1] < 5:
            raise ValueError(f"{where}.ops[{k}]: object info output out of range")
        if row[0] in (OP_FRESNEL, OP_LAYER_WEIGHT) and row[4] < 0 or row[0] == OP_LAYER_WEIGHT and row[3] < 0:
            raise ValueError(f"{where}.ops[{k}]: missing input or output")
        if int(row[0]) in DATA_OPS and not 0 <= row[10] <= len(data) - DATA_OPS[int(row[0])]:
            raise ValueError(f"{where}.ops[{k}]: data table out of range")
        if row[0] == OP_VORONOI and not -1 <= row[10] < n:  # param: the Position register
            raise ValueError(f"{where}.ops[{k}]: register out of range")
    return {"registers": n, "constants": consts, "ops": ops, "data": data}


def reads(prog: dict) -> set[str]:
    """The geometry inputs (``READS`` values) a validated program reads."""
    return {READS[int(op)] for op in prog["ops"][:, 0] if int(op) in READS}


def _reg(v, n, where):
    if v is None:
        return -1
    if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v < n:
        raise ValueError(f"{where}: must be a register in [0, {n}), got {v!r}")
    return v


#: opcodes that read the shading-point rows a surface hit fills
POINT_OPS = frozenset({OP_POINT, OP_FRESNEL, OP_LAYER_WEIGHT, OP_NORMAL_MAP, OP_BUMP_OFFSET, OP_BUMP,
                       OP_CAMERA_COORDS, OP_TEXCO_NORMAL, OP_DISPLACEMENT, OP_VECTOR_DISPLACEMENT,
                       OP_SET_NORMAL, OP_IMAGE_BOX})


def uses_procedural(ops) -> bool:
    """Does a program with these ops rows ((N, OP_WIDTH) or a list of rows) use a procedural
    texture or curve (``PROCEDURAL_OPCODES``, drt.materials.procedural)?"""
    ops = np.asarray(ops)
    return bool(ops.size) and bool(np.isin(ops.reshape(-1, OP_WIDTH)[:, 0], list(PROCEDURAL_OPCODES)).any())


def build_program_data(materials: list[dict], table, images: list[tuple[dict, np.ndarray]],
                       uv, generated, objco, attrs=None, origin=None,
                       object_of=None, object_info=None, positions=None, triangles=None,
                       footprint=None, camera=None, world=None) -> ProgramData | None:
    """ProgramData for the validated ``materials`` (scene.py) and their ``MaterialTable``; None
    when no material has a program and there is no ``world`` program. Lobes are matched to
    table slots by the table's ``lobe_slot_of`` (file lobe → slot; the lobes it dropped have
    none, so no register of theirs is read). A validated ``world`` program is
    appended after the materials' programs: its index is ``world_program_index(pd)``."""
    if not any(m.get("program") for m in materials) and world is None:
        return None
    m_count = len(materials)
    n_slots = table.lobe_type.shape[1]
    prog_of = np.full(m_count, -1, np.int64)
    color_reg = np.full((m_count, n_slots), -1, np.int64)
    rough_reg = np.full((m_count, n_slots), -1, np.int64)
    weight_reg = np.full((m_count, n_slots), -1, np.int64)
    layer_reg = np.full((m_count, n_slots, 2), -1, np.int64)
    ior_reg = np.full((m_count, n_slots, 3), -1, np.int64)
    emission_reg = np.full(m_count, -1, np.int64)
    normal_reg = np.full(m_count, -1, np.int64)
    coat_normal_reg = np.full(m_count, -1, np.int64)
    reads_point = np.zeros(m_count, bool)
    op_rows, const_rows, data, op_start, const_start = [], [], [], [0], [0]
    for i, mat in enumerate(materials):
        prog = mat.get("program")
        if not prog:
            continue
        n = prog["registers"]
        where = f"material {mat['name']!r}"
        prog_of[i] = len(op_start) - 1
        ops = prog["ops"].copy()
        uses_data = np.isin(ops[:, 0], list(DATA_OPS))
        ops[uses_data, 10] += sum(len(d) for d in data)
        op_rows.append(ops)
        const_rows.append(prog["constants"])
        data.append(prog["data"])
        op_start.append(op_start[-1] + len(ops))
        const_start.append(const_start[-1] + len(prog["constants"]))
        slot_of = table.lobe_slot_of[i]
        for j, lobe in enumerate(mat["lobes"]):
            if j not in slot_of:
                continue
            slot = slot_of[j]
            color_reg[i, slot] = _reg(lobe.get("color_reg"), n, f"{where} lobe {j} color_reg")
            rough_reg[i, slot] = _reg(lobe.get("roughness_reg"), n, f"{where} lobe {j} roughness_reg")
            weight_reg[i, slot] = _reg(lobe.get("weight_reg"), n, f"{where} lobe {j} weight_reg")
            layer_reg[i, slot, 0] = _reg(lobe.get("layer_weight_reg"), n, f"{where} lobe {j} layer_weight_reg")
            layer_reg[i, slot, 1] = _reg(lobe.get("coat_tint_reg"), n, f"{where} lobe {j} coat_tint_reg")
            for c, key in enumerate(IOR_REG_KEYS):
                ior_reg[i, slot, c] = _reg(lobe.get(key), n, f"{where} lobe {j} {key}")
            if lobe["type"] == "DIELECTRIC_SPECULAR" and 0 < (ior_reg[i, slot] >= 0).sum() < 3:
                raise ValueError(f"{where} lobe {j}: a DIELECTRIC_SPECULAR lobe needs all of "
                                 f"{', '.join(IOR_REG_KEYS)} or none")
        emission_reg[i] = _reg(mat.get("emission_reg"), n, f"{where} emission_reg")
        normal_reg[i] = _reg(mat.get("normal_reg"), n, f"{where} normal_reg")
        if mat.get("coat_normal") == "SMOOTH":
            coat_normal_reg[i] = COAT_NORMAL_SMOOTH
        else:
            coat_normal_reg[i] = _reg(mat.get("coat_normal_reg"), n, f"{where} coat_normal_reg")
        reads_point[i] = bool(np.isin(ops[:, 0], list(POINT_OPS)).any()) or normal_reg[i] >= 0
    if world is not None:
        op_rows.append(world["ops"].copy())
        op_rows[-1][np.isin(op_rows[-1][:, 0], list(DATA_OPS)), 10] += sum(len(d) for d in data)
        const_rows.append(world["constants"])
        data.append(world["data"])
        op_start.append(op_start[-1] + len(world["ops"]))
        const_start.append(const_start[-1] + len(world["constants"]))
    info = np.zeros((len(images), 5), np.int64)
    u8, f32 = [], []
    off_u8 = off_f = 0
    for k, (img, px) in enumerate(images):
        is_float = px.dtype != np.uint8
        info[k] = (img["width"], img["height"], off_f if is_float else off_u8, is_float,
                   bool(img["srgb"]))
        if is_float:
            f32.append(px.astype(np.float32).reshape(-1))
            off_f += px.size
        else:
            u8.append(px.reshape(-1))
            off_u8 += px.size
    consts = np.concatenate(const_rows) if const_rows else np.zeros((0, 4))

    def arr(a, dtype, shape):
        return np.ascontiguousarray(a, dtype=dtype) if a is not None else np.zeros(shape, dtype)

    return ProgramData(
        prog_of=prog_of, op_start=np.array(op_start, np.int64),
        ops=np.ascontiguousarray(np.concatenate(op_rows).reshape(-1, OP_WIDTH), np.int64),
        const_start=np.array(const_start, np.int64),
        const_reg=np.ascontiguousarray(consts[:, 0], np.int64),
        const_val=np.ascontiguousarray(consts[:, 1:], np.float64),
        data=np.ascontiguousarray(np.concatenate(data) if data else np.zeros(0), np.float64),
        lobe_color_reg=color_reg, lobe_rough_reg=rough_reg, emission_reg=emission_reg,
        img_info=info,
        img_u8=np.ascontiguousarray(np.concatenate(u8) if u8 else np.zeros(0, np.uint8)),
        img_f32=np.ascontiguousarray(np.concatenate(f32) if f32 else np.zeros(0, np.float32)),
        uv=arr(uv, np.float32, (0, 3, 2)), generated=arr(generated, np.float32, (0, 3, 3)),
        objco=arr(objco, np.float32, (0, 3, 3)), attrs=arr(attrs, np.float32, (0, 0, 3, 3)),
        reads_point=reads_point, normal_reg=normal_reg, coat_normal_reg=coat_normal_reg,
        origin=np.asarray(origin if origin is not None else np.zeros(3), np.float64).reshape(3),
        object_of=arr(object_of, np.int32, (0,)), object_info=arr(object_info, np.float64, (0, 9)),
        positions=arr(positions, np.float32, (0, 3)), triangles=arr(triangles, np.int32, (0, 3)),
        footprint=arr(footprint, np.float64, (0, 3)), camera=arr(camera, np.float64, (0, 4)),
        lobe_weight_reg=weight_reg, lobe_layer_reg=layer_reg, lobe_ior_reg=ior_reg,
        procedural=True if any(uses_procedural(rows) for rows in op_rows) else None)


def world_program_index(pd: ProgramData) -> int:
    """Index of the world program `build_program_data` appended (the last program)."""
    return int(pd.op_start.shape[0]) - 2


def empty_program_data() -> ProgramData:
    """A ProgramData with no programs (for scenes without any): same types, zero-size arrays."""
    z = np.zeros(0, np.int64)
    return ProgramData(prog_of=z, op_start=np.zeros(1, np.int64),
                       ops=np.zeros((0, OP_WIDTH), np.int64), const_start=np.zeros(1, np.int64),
                       const_reg=z, const_val=np.zeros((0, 3)), data=np.zeros(0),
                       lobe_color_reg=np.zeros((0, 0), np.int64),
                       lobe_rough_reg=np.zeros((0, 0), np.int64), emission_reg=z,
                       img_info=np.zeros((0, 5), np.int64), img_u8=np.zeros(0, np.uint8),
                       img_f32=np.zeros(0, np.float32), uv=np.zeros((0, 3, 2), np.float32),
                       generated=np.zeros((0, 3, 3), np.float32),
                       objco=np.zeros((0, 3, 3), np.float32), attrs=np.zeros((0, 0, 3, 3), np.float32),
                       reads_point=np.zeros(0, bool), normal_reg=z, coat_normal_reg=z,
                       origin=np.zeros(3),
                       object_of=np.zeros(0, np.int32), object_info=np.zeros((0, 9)),
                       positions=np.zeros((0, 3), np.float32), triangles=np.zeros((0, 3), np.int32),
                       footprint=np.zeros((0, 3)), camera=np.zeros((0, 4)),
                       lobe_weight_reg=np.zeros((0, 0), np.int64),
                       lobe_layer_reg=np.zeros((0, 0, 2), np.int64),
                       lobe_ior_reg=np.zeros((0, 0, 3), np.int64), procedural=None)
