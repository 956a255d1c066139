"""The Geometry node's Pointiness: a per-vertex curvature estimate computed at export, as Cycles
computes it when it syncs a mesh (``attr_create_pointiness``), then read like any attribute.

Per vertex v, with n(v) its normal (Blender's vertex normals, summed over the vertices welded
with it and normalised) and e₁…e_k the unit vectors along its edges:

    raw(v) = acos(n(v) · mean(e₁…e_k)) / π        (0.5 on a flat surface, more on a convex
                                                    corner, less in a concave one)
    pointiness(v) = (raw(v) + Σ raw(neighbours)) / (k + 1)   (one blur over the 1-ring)

Vertices at the same position (split seams, duplicated rims) are welded first, so a seam does
not show. Cycles welds vertices closer than √FLT_EPSILON (3.5e-4 units) to each other; this
export welds exactly coincident ones (float32 equality), which is the same on meshes whose
distinct vertices are further apart than that.
"""

from __future__ import annotations

import numpy as np

from .. import compat


def _vertex_normals(mesh) -> np.ndarray:
    """Blender's vertex normals, (V, 3) float64."""
    n = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
    if hasattr(mesh, "vertex_normals"):  # 3.5+
        mesh.vertex_normals.foreach_get("vector", n)
    else:
        mesh.vertices.foreach_get("normal", n)
    return n.reshape(-1, 3).astype(np.float64)


def _edges(mesh) -> np.ndarray:
    """(E, 2) int64 vertex pairs of the mesh's edges."""
    e = np.empty(len(mesh.edges) * 2, dtype=np.int32)
    mesh.edges.foreach_get("vertices", e)
    return e.reshape(-1, 2).astype(np.int64)


def pointiness_of(positions: np.ndarray, vertex_normals: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Pointiness (V,) float32 of a mesh given its vertex positions (V, 3), vertex normals
    (V, 3) and edges (E, 2) (see the module docstring)."""
    nv = len(positions)
    if nv == 0:
        return np.zeros(0, np.float32)
    # weld coincident vertices: every vertex maps to one representative
    _, rep_of, inverse = np.unique(np.asarray(positions, np.float32), axis=0, return_index=True,
                                   return_inverse=True)
    weld = rep_of[inverse.ravel()]
    normal = np.zeros((nv, 3))
    np.add.at(normal, weld, vertex_normals)
    length = np.linalg.norm(normal, axis=1, keepdims=True)
    normal = np.divide(normal, length, out=np.zeros_like(normal), where=length > 0)
    # each welded edge once, in either direction
    e = weld[edges] if len(edges) else np.zeros((0, 2), np.int64)
    e = e[e[:, 0] != e[:, 1]]
    e = np.unique(np.sort(e, axis=1), axis=0)
    p = np.asarray(positions, np.float64)
    d = p[e[:, 1]] - p[e[:, 0]]
    dl = np.linalg.norm(d, axis=1, keepdims=True)
    d = np.divide(d, dl, out=np.zeros_like(d), where=dl > 0)
    accum = np.zeros((nv, 3))
    np.add.at(accum, e[:, 0], d)
    np.add.at(accum, e[:, 1], -d)
    count = np.bincount(e.ravel(), minlength=nv).astype(np.float64)
    mean = np.divide(accum, count[:, None], out=np.zeros_like(accum), where=count[:, None] > 0)
    raw = np.where(count > 0, np.arccos(np.clip((normal * mean).sum(axis=1), -1.0, 1.0)) / np.pi, 0.0)
    blurred = raw.copy()
    np.add.at(blurred, e[:, 0], raw[e[:, 1]])
    np.add.at(blurred, e[:, 1], raw[e[:, 0]])
    blurred /= count + 1.0
    return blurred[weld].astype(np.float32)


def mesh_pointiness(mesh) -> np.ndarray:
    """Pointiness (V,) float32 of an evaluated Blender mesh."""
    return pointiness_of(compat.positions(mesh), _vertex_normals(mesh), _edges(mesh))
