"""Scene geometry prepared for tracing: world-space triangle arrays plus moving objects.

Static objects are flattened into one world-space triangle set (instances are expanded; the file
stores each mesh once). Objects with rigid motion keep their local-space triangles and a
``RigidMotion``; deforming meshes also keep their shutter-close positions.

Every position is translated by ``-origin_shift`` (the camera position) in float64 before it
becomes float32 for Embree: float32 has ~7 digits, so a scene 10⁵ m from Blender's origin would
otherwise lose centimetres. Everything downstream (lights, camera) works in this shifted frame.

Triangles get global ids: static ones first (in object order), then each moving object's.
Per-triangle tables (material, shading normals, uvs) are indexed by that global id.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import math

import numpy as np

from .cryptomatte import name_id
from .kernels import kernel
from .kernels.row_chunks import over_rows

from .motion import RigidMotion, invert_linear
from .scene import VIS_ALL, VIS_HOLDOUT, Scene


@dataclass
class MovingMesh:
    """One object that moves or deforms during the shutter. Positions are in the object's local
    space; ``motion`` maps local → shifted world at shutter fraction τ (None: static matrix)."""

    name: str
    prim_offset: int
    positions: np.ndarray  # (V, 3) float64, local, at shutter open
    positions_close: np.ndarray | None  # (V, 3) float64 for deforming meshes
    triangles: np.ndarray  # (T, 3) int64
    motion: RigidMotion


@dataclass
class SceneGeometry:
    origin_shift: np.ndarray  # (3,) float64: subtract from Blender world positions
    static_positions: np.ndarray  # (V, 3) float32, shifted world space
    static_triangles: np.ndarray  # (T, 3) int32
    moving: list[MovingMesh] = field(default_factory=list)
    material: np.ndarray = None  # (T_all,) int32 per global triangle
    normals: np.ndarray | None = None  # (T_all, 3, 3) float32 shading normals (world for static, local for moving)
    has_normals: np.ndarray = None  # (T_all,) bool; False: flat shading
    uvs: np.ndarray | None = None  # (T_all, 3, 2) float32
    #: (T_all,) bool: the triangle's mesh has a UV map (zeros in ``uvs`` otherwise); with ``uvs``
    has_uvs: np.ndarray | None = None
    #: (T_all,) int32 object of each global triangle and (O, 9) float64 Object Info rows
    #: (location xyz in Blender world, colour rgb, alpha, pass index, random); only when some
    #: object carries Object Info (a material program reads it), else None
    object_of: np.ndarray | None = None
    object_info: np.ndarray | None = None
    #: (T_all, 2) float32 [object, material] pass index of each global triangle (the Object /
    #: Material Index passes); only when the render asks for one of them, else None
    pass_ids: np.ndarray | None = None
    #: (T, 3) float32 Cryptomatte ids [object, material, asset] (drt.cryptomatte.name_id), or
    #: None when the scene asks for no Cryptomatte layer
    crypto_ids: np.ndarray | None = None
    #: (T_all,) uint8 VIS_* bits of the rays that see each triangle (drt.scene.RAY_VISIBILITY),
    #: plus VIS_HOLDOUT on a holdout object's; None when every object is visible to every ray
    #: and none is a holdout
    visibility: np.ndarray | None = None
    #: per-corner attributes material programs read, (T_all, 3, 3) float32 by name ("generated",
    #: "object_coords"); only those some mesh has (zeros on the other meshes' triangles)
    corner_attrs: dict = field(default_factory=dict)
    #: (T_all,) float32 shadow terminator geometry offset of each global triangle's object
    #: (static smooth-shaded meshes only; drt.terminator); None when no triangle has one
    terminator: np.ndarray | None = None
    #: (T_all,) float32 shadow terminator shading offset (Blender's value in [0, 1]) of each
    #: triangle's object, any shading; None when no object sets one
    terminator_shading: np.ndarray | None = None
    triangle_count: int = 0
    scene_radius: float = 1.0  # radius of the bounding sphere of all geometry (scene units)
    #: (T_all,) int32 index into scene.objects of each global triangle (volume stack keys)
    object_id: np.ndarray = None
    #: [(first, end)) global triangle ranges of the static objects, in object order (objects
    #: without triangles omitted): subsurface walks stay inside one object (drt.subsurface)
    static_ranges: list = field(default_factory=list)

    @property
    def static_count(self) -> int:
        return len(self.static_triangles)


def _shift_matrix(m: np.ndarray, shift: np.ndarray) -> np.ndarray:
    out = np.array(m, dtype=np.float64)
    out[:3, 3] -= shift
    return out


@kernel
def _points_to_world(positions, m, out, lo, hi):
    """out (V, 3) float32 = m[:3, :3]·p + m[:3, 3] for each local point p (computed in float64);
    lo, hi (3,) are widened to the float64 world points' bounds."""
    for i in range(positions.shape[0]):
        x, y, z = float(positions[i, 0]), float(positions[i, 1]), float(positions[i, 2])
        for r in range(3):
            w = m[r, 0] * x + m[r, 1] * y + m[r, 2] * z + m[r, 3]
            out[i, r] = w
            if w < lo[r]:
                lo[r] = w
            if w > hi[r]:
                hi[r] = w


@kernel
def _normals_to_world(normals, inv_t, out):
    """out (T, 3, 3) float32: per-corner normals through the inverse transpose ``inv_t`` (3, 3),
    renormalised in float64 (a zero normal stays zero)."""
    for t in range(normals.shape[0]):
        for c in range(3):
            x, y, z = float(normals[t, c, 0]), float(normals[t, c, 1]), float(normals[t, c, 2])
            a = inv_t[0, 0] * x + inv_t[0, 1] * y + inv_t[0, 2] * z
            b = inv_t[1, 0] * x + inv_t[1, 1] * y + inv_t[1, 2] * z
            e = inv_t[2, 0] * x + inv_t[2, 1] * y + inv_t[2, 2] * z
            length = math.sqrt(a * a + b * b + e * e)
            if length > 0.0:  # one division, not three: they bound this loop's speed
                inv = 1.0 / length
                a, b, e = a * inv, b * inv, e * inv
            else:
                a = b = e = 0.0
            out[t, c, 0] = a
            out[t, c, 1] = b
            out[t, c, 2] = e


def _transform_normals(n: np.ndarray, m: np.ndarray) -> np.ndarray:
    """Per-corner normals (T, 3, 3) to world space by the object matrix m (4×4): inverse
    transpose of its linear part, renormalised; float32."""
    inv_t = np.ascontiguousarray(invert_linear(m[:3, :3]).T, dtype=np.float64)
    out = np.empty(np.shape(n), dtype=np.float32)
    over_rows(_normals_to_world, (np.ascontiguousarray(n), inv_t, out), sliced=(0, 2))
    return out


@kernel
def _tangents_to_world(rows, inv_t, out):
    """out (n, 3) float32: vectors ``rows`` (n, 3) through the inverse transpose ``inv_t``
    (3, 3), each keeping its length (computed in float64; one mapped to zero becomes zero)."""
    for i in range(rows.shape[0]):
        x, y, z = float(rows[i, 0]), float(rows[i, 1]), float(rows[i, 2])
        a = inv_t[0, 0] * x + inv_t[0, 1] * y + inv_t[0, 2] * z
        b = inv_t[1, 0] * x + inv_t[1, 1] * y + inv_t[1, 2] * z
        e = inv_t[2, 0] * x + inv_t[2, 1] * y + inv_t[2, 2] * z
        after = math.sqrt(a * a + b * b + e * e)
        if after > 0.0:
            before = math.sqrt(x * x + y * y + z * z)
            a, b, e = a * before / after, b * before / after, e * before / after
        else:
            a = b = e = 0.0
        out[i, 0] = a
        out[i, 1] = b
        out[i, 2] = e


def _transform_tangents(t: np.ndarray, m: np.ndarray) -> np.ndarray:
    """Per-corner tangents (T, 3, 3) to world space by the normal transform of object matrix m,
    each keeping its length: the Normal Map node combines tangent and normal in object space and
    maps the result by the normal transform (Cycles), which this matches for rotations and
    uniform scales (non-uniform scales: approximately). A kernel over the rows: numpy's
    ``t @ M`` over a (T, 3, 3) stack made one small BLAS call per triangle (~1 s for a million)."""
    inv_t = np.ascontiguousarray(invert_linear(np.asarray(m, np.float64)[:3, :3]).T)
    rows = np.ascontiguousarray(np.asarray(t, np.float32).reshape(-1, 3))
    out = np.empty(rows.shape, dtype=np.float32)
    over_rows(_tangents_to_world, (rows, inv_t, out), sliced=(0, 2))
    return out.reshape(np.shape(t))


def build_geometry(scene: Scene) -> SceneGeometry:
    """Flatten ``scene`` into tracer-ready arrays (see the module docstring)."""
    shift = np.asarray(scene.camera.matrix, dtype=np.float64)[:3, 3].copy()
    motion_on = scene.has_motion
    static_pos, static_tri, moving = [], [], []
    mats_static, nrm_static, hasn_static, uv_static = [], [], [], []
    mats_moving, nrm_moving, hasn_moving, uv_moving = [], [], [], []
    # meshes in global triangle order (for corner_attrs): (mesh, world matrix of a static one,
    # corners swapped, mirrored)
    order_static, order_moving = [], []
    obj_static, obj_moving = [], []  # object index per triangle block (Object Info)
    term_static = []  # shadow terminator geometry offset per static triangle block
    shade_static, shade_moving = [], []  # shadow terminator shading offset per triangle block
    v_offset = 0
    t_offset = 0
    ranges = []
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    any_normals = any(m.normals is not None for m in scene.meshes)
    any_uvs = any(m.uvs is not None for m in scene.meshes)

    def per_tri(mesh, normals_world, flip):
        t = len(mesh.triangles)
        nrm = _corners(normals_world, flip) if normals_world is not None else np.zeros((t, 3, 3), np.float32)
        # no copies of arrays already of the right type: a 1M-triangle mesh's normals and UVs
        # are 60 MB, and nothing writes into the flattened arrays
        uv = _corners(mesh.uvs, flip).astype(np.float32, copy=False) if mesh.uvs is not None \
            else np.zeros((t, 3, 2), np.float32)
        return (mesh.material_index.astype(np.int32, copy=False), nrm.astype(np.float32, copy=False),
                np.full(t, mesh.normals is not None), uv)

    for oi, obj in enumerate(scene.objects):
        mesh = scene.meshes[obj.mesh]
        if len(mesh.triangles) == 0:
            continue
        moves = motion_on and (obj.motion is not None or mesh.positions_close is not None)
        if moves:
            m_open, m_close = obj.motion if obj.motion is not None else (obj.matrix, obj.matrix)
            rm = RigidMotion(_shift_matrix(m_open, shift), _shift_matrix(m_close, shift))
            # (a moving object's true normal goes through its inverse transpose at the hit
            # and faces out whatever the matrix: its corners stay as they are)
            moving.append(MovingMesh(obj.name, 0, mesh.positions, mesh.positions_close, mesh.triangles, rm))
            m, n, h, u = per_tri(mesh, mesh.normals, False)
            mats_moving.append(m), nrm_moving.append(n), hasn_moving.append(h), uv_moving.append(u)
            order_moving.append((mesh, None, False, _mirrors(m_open)))
            obj_moving.append(np.full(len(mesh.triangles), oi, np.int32))
            shade_moving.append(np.full(len(mesh.triangles), obj.terminator_shading, np.float32))
            ends = np.empty((len(mesh.positions), 3), dtype=np.float32)  # only their bounds are kept
            for mat in (m_open, m_close):
                for pos in (mesh.positions, mesh.positions_close if mesh.positions_close is not None else mesh.positions):
                    _points_to_world(np.ascontiguousarray(pos), np.ascontiguousarray(_shift_matrix(mat, shift)),
                                     ends, lo, hi)
            continue
        m = _shift_matrix(obj.matrix, shift)
        world = np.empty((len(mesh.positions), 3), dtype=np.float32)
        _points_to_world(np.ascontiguousarray(mesh.positions), np.ascontiguousarray(m, dtype=np.float64), world, lo, hi)
        static_pos.append(world)
        flip = _mirrors(m)
        tri = _corners(mesh.triangles, flip)
        static_tri.append((tri + v_offset).astype(np.int32, copy=False) if v_offset
                          else tri.astype(np.int32, copy=False))
        v_offset += len(world)
        ranges.append((t_offset, t_offset + len(mesh.triangles)))
        t_offset += len(mesh.triangles)
        nw = _transform_normals(mesh.normals, m) if mesh.normals is not None else None
        a, b, c, d = per_tri(mesh, nw, flip)
        mats_static.append(a), nrm_static.append(b), hasn_static.append(c), uv_static.append(d)
        order_static.append((mesh, m, flip, flip))
        obj_static.append(np.full(len(mesh.triangles), oi, np.int32))
        shade_static.append(np.full(len(mesh.triangles), obj.terminator_shading, np.float32))
        term_static.append(np.full(len(mesh.triangles), obj.terminator_geometry if mesh.normals is not None else 0.0,
                                   np.float32))

    def cat(parts, empty):
        if len(parts) == 1:  # one object: its own array, not a copy
            return parts[0]
        return np.concatenate(parts) if parts else empty

    geom = SceneGeometry(
        origin_shift=shift,
        static_positions=cat(static_pos, np.zeros((0, 3), np.float32)),
        static_triangles=cat(static_tri, np.zeros((0, 3), np.int32)),
    )
    geom.static_ranges = ranges
    offset = geom.static_count
    for mm in moving:
        mm.prim_offset = offset
        offset += len(mm.triangles)
    geom.moving = moving

    geom.material = cat(mats_static + mats_moving, np.zeros(0, np.int32))
    geom.has_normals = cat(hasn_static + hasn_moving, np.zeros(0, bool))
    geom.normals = cat(nrm_static + nrm_moving, np.zeros((0, 3, 3), np.float32)) if any_normals else None
    geom.uvs = cat(uv_static + uv_moving, np.zeros((0, 3, 2), np.float32)) if any_uvs else None
    if any_uvs:
        object_has_uvs = np.array([scene.meshes[o.mesh].uvs is not None for o in scene.objects] or [False])
        geom.has_uvs = object_has_uvs[cat(obj_static + obj_moving, np.zeros(0, np.int32))]
    geom.triangle_count = offset
    if any(t.any() for t in shade_static + shade_moving):
        geom.terminator_shading = np.concatenate(shade_static + shade_moving)
    if any(t.any() for t in term_static):  # moving meshes: no offset (drt.terminator)
        geom.terminator = np.concatenate(term_static + [np.zeros(offset - geom.static_count, np.float32)])
    per_object = np.array([o.visibility | (VIS_HOLDOUT if o.holdout else 0) for o in scene.objects], np.uint8)
    if np.any(per_object != VIS_ALL):
        geom.visibility = per_object[cat(obj_static + obj_moving, np.zeros(0, np.int32))]
    if any(o.info is not None for o in scene.objects):
        geom.object_of = cat(obj_static + obj_moving, np.zeros(0, np.int32))
        geom.object_info = np.array([np.concatenate([np.asarray(o.matrix, np.float64)[:3, 3],
                                                     o.info if o.info is not None else [1, 1, 1, 1, 0, 0],
                                                     _normal_matrix(o.matrix).reshape(9)])
                                     for o in scene.objects], np.float64).reshape(-1, 18)
    if {"object_index", "material_index"} & set(getattr(scene.render, "data_passes", ())):
        obj_of = cat(obj_static + obj_moving, np.zeros(0, np.int32))
        obj_pass = np.array([o.pass_index for o in scene.objects] or [0], np.float32)
        mat_pass = np.array([m.get("pass_index", 0) if isinstance(m, dict) else 0 for m in scene.materials]
                            or [0], np.float32)
        geom.pass_ids = np.stack([obj_pass[obj_of], mat_pass[np.minimum(geom.material, len(mat_pass) - 1)]],
                                 axis=1).astype(np.float32)
    if getattr(scene.render, "cryptomatte", ()):
        geom.crypto_ids = _crypto_ids(scene, cat(obj_static + obj_moving, np.zeros(0, np.int32)), geom.material)
    if any(isinstance(m, dict) and m.get("volume") for m in scene.materials):
        geom.object_id = cat(obj_static + obj_moving, np.zeros(0, np.int32))  # volume stack keys
    names = getattr(scene, "attributes", [])
    kinds = corner_attribute_kinds(names)

    def attr_of(mesh, matrix, swapped, mirrored, name):
        if name not in mesh.corner_attrs:
            return np.zeros((len(mesh.triangles), 3, 3), np.float32)
        return corner_attribute(np.asarray(mesh.corner_attrs[name], np.float32), kinds.get(name),
                                matrix, swapped, mirrored)

    for name in sorted({k for m in scene.meshes for k in m.corner_attrs}):
        geom.corner_attrs[name] = cat([attr_of(mesh, *rest, name) for mesh, *rest in order_static + order_moving],
                                      np.zeros((0, 3, 3), np.float32))
    if np.all(np.isfinite(lo)):
        center = 0.5 * (lo + hi)
        geom.scene_radius = float(max(np.linalg.norm(hi - center), 1e-3))
    return geom


def _crypto_ids(scene: Scene, obj_of: np.ndarray, material: np.ndarray) -> np.ndarray:
    """(T, 3) float32 [object, material, asset] Cryptomatte ids of each global triangle."""
    objs = np.array([(name_id(o.crypto_object or o.name), name_id(o.crypto_asset or o.name))
                     for o in scene.objects] or [(0.0, 0.0)], np.float32).reshape(-1, 2)
    mats = np.array([name_id(str(m.get("cryptomatte", m.get("name", f"material{i}")))) if isinstance(m, dict) else 0.0
                     for i, m in enumerate(scene.materials)] or [0.0], np.float32)
    mat_id = mats[np.clip(np.asarray(material, np.int64), 0, len(mats) - 1)]
    return np.stack([objs[obj_of, 0], mat_id, objs[obj_of, 1]], axis=1).astype(np.float32)


def corner_attribute_kinds(names) -> dict:
    """{"attr<I>": "tangent" | "sign"} for the scene's attribute names that are Normal Map
    tangents ("tangent:<uv>") and bitangent signs ("tangent_sign:<uv>")."""
    kinds = {}
    for i, a in enumerate(names):
        if a.startswith("tangent:"):
            kinds[f"attr{i}"] = "tangent"
        elif a.startswith("tangent_sign:"):
            kinds[f"attr{i}"] = "sign"
    return kinds


def corner_attribute(a: np.ndarray, kind, matrix, swapped: bool, mirrored: bool) -> np.ndarray:
    """One mesh's per-corner attribute (T, 3, 3) as the flattened geometry holds it: tangents of
    a static object (``matrix`` not None) mapped to world space, corners swapped as its
    triangles are (`_corners`), and the bitangent sign negated for a mirroring object — the
    Normal Map forms its bitangent as sign · N × T from vectors already mapped by the normal
    transform, and under a mirroring matrix that cross product turns the other way
    (M⁻ᵀa × M⁻ᵀb = M(a × b)/det M), where Cycles's object-space one keeps it."""
    if kind == "tangent" and matrix is not None:  # static: world space (moving: at the hit)
        a = _transform_tangents(a, matrix)
    a = _corners(a, swapped)
    return -a if kind == "sign" and mirrored else a


def _mirrors(matrix) -> bool:
    """Whether a 4×4 object matrix mirrors: its 3×3 part has a negative determinant (expanded
    here, not LAPACK's: docs/decisions.md, "No BLAS or LAPACK on a render's path")."""
    (a, b, c, _), (d, e, f, _), (g, h, i, _) = np.asarray(matrix, np.float64)[:3].tolist()
    return a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g) < 0.0


def _corners(a: np.ndarray, flip: bool) -> np.ndarray:
    """A per-triangle-corner array (triangles (T, 3), or (T, 3, …) corner data) with corners 1
    and 2 swapped when ``flip``: a mirroring object matrix turns its triangles' winding, and so
    the true normal, inside out in world space (Cycles flips its Ng back for such objects);
    swapping two corners of every triangle and of all its corner data turns it back without
    changing what any point interpolates."""
    return a[:, (0, 2, 1)] if flip else a


def _normal_matrix(matrix) -> np.ndarray:
    """inv(M)ᵀ of a 4×4 matrix's 3×3 part (object → world normals; the object's normal
    transform the shading inputs use, docs/materials.md); identity for a singular M."""
    # not np.linalg.inv: OpenBLAS runs it on threads that spin on after it (docs/decisions.md)
    inv = invert_linear(np.asarray(matrix, np.float64)[:3, :3])
    return inv.T if inv.any() else np.eye(3)


def static_triangle_vertices(geom: SceneGeometry, prims: np.ndarray) -> np.ndarray:
    """World (shifted) corner positions (n, 3, 3) float64 of static triangles ``prims``."""
    return geom.static_positions[geom.static_triangles[prims]].astype(np.float64)
