"""Evaluated Blender meshes → the core's per-mesh arrays (see docs/scene-format.md).

Only ``foreach_get`` and numpy: no Python loop touches a vertex, corner or triangle.
"""

import numpy as np

from .. import compat

# Object types whose evaluated form can be turned into a mesh with ``to_mesh()``.
MESH_LIKE_TYPES = {"MESH", "CURVE", "SURFACE", "FONT", "META"}


def read_positions(mesh) -> np.ndarray:
    """Vertex positions, (V, 3) float32, object local space."""
    pos = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
    mesh.vertices.foreach_get("co", pos)
    return pos.reshape(-1, 3)


def mesh_arrays(mesh, slot_materials: np.ndarray) -> dict | None:
    """Arrays of one evaluated mesh, or None when it has no triangles.

    slot_materials: (S,) int32, the global material index of each material slot (S >= 1);
    triangles whose slot index is out of range use the last slot, as Blender does.
    Returns {"positions" (V,3) f32, "triangles" (T,3) i32, "material_index" (T,) i32,
    optionally "normals" (T,3,3) f32 and "uvs" (T,3,2) f32}.
    """
    compat.prepare_mesh(mesh)
    tris = mesh.loop_triangles
    n_tri = len(tris)
    if n_tri == 0:
        return None

    out = {"positions": read_positions(mesh)}

    tri_verts = np.empty(n_tri * 3, dtype=np.int32)
    tris.foreach_get("vertices", tri_verts)
    out["triangles"] = tri_verts.reshape(-1, 3)

    slot = np.empty(n_tri, dtype=np.int32)
    tris.foreach_get("material_index", slot)
    np.clip(slot, 0, len(slot_materials) - 1, out=slot)
    out["material_index"] = slot_materials.astype(np.int32)[slot]

    tri_loops = None
    if not compat.mesh_is_flat(mesh):
        tri_loops = np.empty(n_tri * 3, dtype=np.int32)
        tris.foreach_get("loops", tri_loops)
        normals = compat.corner_normals(mesh)
        out["normals"] = np.ascontiguousarray(normals[tri_loops].reshape(n_tri, 3, 3),
                                              dtype=np.float32)

    uv_data = compat.active_uv_data(mesh)
    if uv_data is not None and len(uv_data):
        if tri_loops is None:
            tri_loops = np.empty(n_tri * 3, dtype=np.int32)
            tris.foreach_get("loops", tri_loops)
        uv = np.empty(len(uv_data) * 2, dtype=np.float32)
        uv_data.foreach_get("uv", uv)
        out["uvs"] = uv.reshape(-1, 2)[tri_loops].reshape(n_tri, 3, 2)
    return out


def evaluated_mesh_arrays(obj, slot_materials: np.ndarray) -> dict | None:
    """``mesh_arrays`` of an evaluated object (modifiers, curves, text, geometry nodes)."""
    try:
        mesh = obj.to_mesh()
    except RuntimeError:
        return None
    try:
        if mesh is None:
            return None
        return mesh_arrays(mesh, slot_materials)
    finally:
        obj.to_mesh_clear()


def evaluated_positions(obj) -> np.ndarray | None:
    """Vertex positions of an evaluated object, (V, 3) float32 (for deformation motion)."""
    try:
        mesh = obj.to_mesh()
    except RuntimeError:
        return None
    try:
        return None if mesh is None else read_positions(mesh)
    finally:
        obj.to_mesh_clear()
