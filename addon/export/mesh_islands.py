"""The Geometry node's Random Per Island and Parametric outputs as per-corner attributes the
programs read (Cycles computes both at sync or from the hit; see docs/materials.md).

Random Per Island: Cycles joins the mesh's vertices along its edges in a disjoint set (union by
rank, in edge order: ``util/disjoint_set.h``) and gives each triangle the hash of its first
corner vertex's root, ``hash_uint_to_float(root)`` (``attr_create_random_per_island``). The
root a component ends with depends on that join order, so it is replayed as Cycles runs it.

Parametric: Cycles's (1 − u − v, u, 0) of the hit's barycentric coordinates, where its triangle
point is v₀ + u·(v₁ − v₀) + v·(v₂ − v₀): the weights of the first and second corners. Exported
as the constant corner values (1, 0, 0), (0, 1, 0), (0, 0, 0), which the programs' barycentric
interpolation turns into exactly that (the corners in Blender's loop-triangle order, Cycles's).
"""

from __future__ import annotations

import numpy as np

from .. import compat


def island_roots(n_verts: int, edges: np.ndarray) -> np.ndarray:
    """Root vertex of each vertex's island (V,) int64, joined along ``edges`` (E, 2) in order
    with union by rank, as Cycles's DisjointSet does."""
    parent = list(range(n_verts))
    rank = [0] * n_verts

    def find(x):
        root = x
        while parent[root] != root:
            root = parent[root]
        while parent[x] != root:
            parent[x], x = root, parent[x]
        return root

    for a, b in edges.tolist():
        ra, rb = find(a), find(b)
        if ra == rb:
            continue
        if rank[ra] < rank[rb]:
            ra, rb = rb, ra
        parent[rb] = ra
        if rank[ra] == rank[rb]:
            rank[ra] += 1
    return np.array([find(v) for v in range(n_verts)], dtype=np.int64)


def random_per_island(mesh, tri_verts: np.ndarray) -> np.ndarray:
    """Random Per Island of each loop triangle (T,) float32 of an evaluated mesh."""
    edges = np.empty(len(mesh.edges) * 2, dtype=np.int32)
    mesh.edges.foreach_get("vertices", edges)
    roots = island_roots(len(mesh.vertices), edges.reshape(-1, 2))[tri_verts[:, 0]]
    hash_uint = compat.core_module("materials.procedural").hash_uint
    unique, which = np.unique(roots, return_inverse=True)
    value = np.array([hash_uint(int(r)) / float(0xFFFFFFFF) for r in unique], dtype=np.float32)
    return value[which.ravel()]


#: per-corner values whose barycentric interpolation is Cycles's Parametric (1 − u − v, u, 0)
PARAMETRIC_CORNERS = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]], dtype=np.float32)
