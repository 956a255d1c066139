"""Evaluated Blender meshes → the core's per-mesh arrays (see docs/scene-format.md).

Only ``foreach_get`` and numpy: no Python loop touches a vertex, corner or triangle.
"""

import numpy as np

from .. import compat

# Object types whose evaluated form can be turned into a mesh with ``to_mesh()``.
MESH_LIKE_TYPES = {"MESH", "CURVE", "SURFACE", "FONT", "META"}


def read_positions(mesh) -> np.ndarray:
    """Vertex positions, (V, 3) float32, object local space."""
    return compat.positions(mesh)


def mesh_arrays(mesh, slot_materials: np.ndarray) -> dict | None:
    """Arrays of one evaluated mesh, or None when it has no triangles.

    slot_materials: (S,) int32, the global material index of each material slot (S >= 1);
    triangles whose slot index is out of range use the last slot, as Blender does.
    Returns {"positions" (V,3) f32, "triangles" (T,3) i32, "material_index" (T,) i32,
    optionally "normals" (T,3,3) f32 and "uvs" (T,3,2) f32}.
    """
    compat.prepare_mesh(mesh)
    if len(mesh.loop_triangles) == 0:
        return None
    tri_corners = compat.triangle_corners(mesh)
    tri_verts = compat.corner_verts(mesh)[tri_corners]
    out = {"positions": read_positions(mesh), "triangles": tri_verts}
    slot = compat.triangle_material_slots(mesh)
    np.clip(slot, 0, len(slot_materials) - 1, out=slot)
    out["material_index"] = slot_materials.astype(np.int32)[slot]
    normals = compat.triangle_normals(mesh, tri_corners, tri_verts)
    if normals is not None:
        out["normals"] = np.ascontiguousarray(normals, dtype=np.float32)
    uvs = compat.active_uvs(mesh)
    if uvs is not None:
        out["uvs"] = uvs[tri_corners]
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
