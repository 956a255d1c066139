"""Blender's loop triangles of a mesh of triangles and quads, computed from its raw arrays.

Reading ``Mesh.loop_triangles`` through bpy's ``foreach_get`` walks Blender's RNA per triangle
(~70 ms for a million triangles, half of a large mesh's export), while the face of each triangle
(``Mesh.loop_triangle_polygons``), the corners' vertices and the positions are plain arrays that
copy in well under a millisecond. For faces of three and four corners the triangles follow from
those: this module rebuilds them exactly, and says when it cannot be sure.

Blender's rule (``mesh_tessellate.cc``): a triangle is kept, corners (0, 1, 2). A quad is cut
along its 0–2 diagonal, (0, 1, 2) and (0, 2, 3), unless that diagonal lies outside it; then along
1–3, (0, 1, 3) and (1, 2, 3). Blender decides "outside" with one of two float32 tests, depending on
whether the mesh's face normals happen to be cached:

- ``is_quad_flip_v3_first_third_fast``: flip when (v1−v0)×(v2−v0) · (v3−v0)×(v2−v0) > 0 (v1 and
  v3 on the same side of the diagonal);
- ``…_with_normal``: with t = (v2−v0)×n (n the face normal), flip when v3·t ≥ v0·t or
  v1·t ≤ v0·t.

They agree on planar quads away from the boundary. Near it (a degenerate, folded or nearly
collinear quad) float32 rounding decides, and on strongly twisted quads the two tests can
disagree outright (14–25 % of random twisted quads). So each test is evaluated
here in float64 with a bound on Blender's float32 rounding, and a quad whose two tests do not
both clear their bounds with the same answer is *ambiguous*: the caller then reads Blender's own
loop triangles (the result is Blender's either way; only the time differs). N-gons (five corners
and up, Blender's ear clipping) are left to Blender too.
"""

from __future__ import annotations

import numpy as np

from .kernels import kernel

__all__ = ["corner_triangles", "quad_split"]

#: the unit roundoff of float32 (2^-24) times a safety factor over the operation count of
#: Blender's tests: a test whose float64 value is further from its threshold than this bound
#: (scaled by the magnitudes involved) has Blender's sign whatever its rounding
_F32_BOUND = 64.0 * 2.0 ** -24

QUAD_CLEAR, QUAD_FLIP, QUAD_AMBIGUOUS = 0, 1, 2


@kernel
def quad_split(p0, p1, p2, p3):
    """How Blender cuts the quad (p0, p1, p2, p3) (float64 3-tuples, the corners' positions in
    face order): QUAD_CLEAR (diagonal 0–2), QUAD_FLIP (diagonal 1–3) or QUAD_AMBIGUOUS (the two
    float32 tests Blender may run could disagree, or round either way)."""
    d1x, d1y, d1z = p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]
    d2x, d2y, d2z = p2[0] - p0[0], p2[1] - p0[1], p2[2] - p0[2]
    d3x, d3y, d3z = p3[0] - p0[0], p3[1] - p0[1], p3[2] - p0[2]
    # lengths by their L1 norms, which bound the Euclidean ones from above: a looser bound only
    # calls a few more quads ambiguous, and no root or division is needed
    l1 = abs(d1x) + abs(d1y) + abs(d1z)
    l2 = abs(d2x) + abs(d2y) + abs(d2z)
    l3 = abs(d3x) + abs(d3y) + abs(d3z)
    # test A: the normals of (0, 1, 2) and of (0, 3, 2) point the same way -> flip
    ax, ay, az = d1y * d2z - d1z * d2y, d1z * d2x - d1x * d2z, d1x * d2y - d1y * d2x
    bx, by, bz = d3y * d2z - d3z * d2y, d3z * d2x - d3x * d2z, d3x * d2y - d3y * d2x
    dot_a = ax * bx + ay * by + az * bz
    bound_a = _F32_BOUND * l1 * l2 * l2 * l3
    if dot_a > bound_a:
        flip_a = 1
    elif dot_a < -bound_a:
        flip_a = 0
    else:
        return QUAD_AMBIGUOUS
    # test B: the face normal n (Blender's normal_quad_v3: the diagonals' cross product,
    # normalised), the in-plane tangent t = (p2 - p0) x n, and the side of the 0-2 diagonal p1
    # and p3 lie on. Left unnormalised here: the signs and the bound scale alike with |n|.
    ex, ey, ez = p0[0] - p2[0], p0[1] - p2[1], p0[2] - p2[2]
    fx, fy, fz = p1[0] - p3[0], p1[1] - p3[1], p1[2] - p3[2]
    nx, ny, nz = ey * fz - ez * fy, ez * fx - ex * fz, ex * fy - ey * fx
    n_len = abs(nx) + abs(ny) + abs(nz)
    if not n_len > 0.0:
        return QUAD_AMBIGUOUS
    tx, ty, tz = d2y * nz - d2z * ny, d2z * nx - d2x * nz, d2x * ny - d2y * nx
    s1 = d1x * tx + d1y * ty + d1z * tz  # (p1 - p0) . t: Blender flips when <= 0
    s3 = d3x * tx + d3y * ty + d3z * tz  # (p3 - p0) . t: Blender flips when >= 0
    # Blender forms p . t with absolute positions: its rounding scales with their size
    size = (abs(p0[0]) + abs(p0[1]) + abs(p0[2]) + abs(p1[0]) + abs(p1[1]) + abs(p1[2])
            + abs(p3[0]) + abs(p3[1]) + abs(p3[2]) + l1 + l2 + l3)
    bound_b = _F32_BOUND * l2 * n_len * size
    if s1 > bound_b and s3 < -bound_b:
        flip_b = 0
    elif s1 < -bound_b or s3 > bound_b:
        flip_b = 1
    else:
        return QUAD_AMBIGUOUS
    if flip_a != flip_b:
        return QUAD_AMBIGUOUS
    return QUAD_FLIP if flip_a else QUAD_CLEAR


@kernel
def _corner_triangles(tri_faces, corner_verts, positions, out):
    """Fill out (T, 3) int32 with each triangle's corner indices; return the number of corners
    the faces used, or -1 (an n-gon, faces out of order), -2 (an ambiguous quad)."""
    n_tri = tri_faces.shape[0]
    t = 0
    corner = 0
    face = -1
    while t < n_tri:
        f = tri_faces[t]
        if f != face + 1:  # Blender lists every face's triangles, in face order
            return -1
        face = f
        n = 1
        while t + n < n_tri and tri_faces[t + n] == f:
            n += 1
        if n == 1:
            out[t, 0] = corner
            out[t, 1] = corner + 1
            out[t, 2] = corner + 2
        elif n == 2:
            if corner + 4 > corner_verts.shape[0]:
                return -1
            q0 = positions[corner_verts[corner]]
            q1 = positions[corner_verts[corner + 1]]
            q2 = positions[corner_verts[corner + 2]]
            q3 = positions[corner_verts[corner + 3]]
            split = quad_split((float(q0[0]), float(q0[1]), float(q0[2])),
                               (float(q1[0]), float(q1[1]), float(q1[2])),
                               (float(q2[0]), float(q2[1]), float(q2[2])),
                               (float(q3[0]), float(q3[1]), float(q3[2])))
            if split == QUAD_AMBIGUOUS:
                return -2
            if split == QUAD_CLEAR:
                out[t, 0], out[t, 1], out[t, 2] = corner, corner + 1, corner + 2
                out[t + 1, 0], out[t + 1, 1], out[t + 1, 2] = corner, corner + 2, corner + 3
            else:
                out[t, 0], out[t, 1], out[t, 2] = corner, corner + 1, corner + 3
                out[t + 1, 0], out[t + 1, 1], out[t + 1, 2] = corner + 1, corner + 2, corner + 3
        else:
            return -1
        corner += n + 2
        t += n
    return corner


def corner_triangles(tri_faces: np.ndarray, corner_verts: np.ndarray, positions: np.ndarray) -> np.ndarray | None:
    """Blender's loop triangles as corner indices, (T, 3) int32, of a mesh whose faces all have
    three or four corners; None when Blender's own must be read (an n-gon, an ambiguous quad, or
    arrays that do not describe such a mesh).

    tri_faces: (T,) int, the face of each loop triangle (``Mesh.loop_triangle_polygons``);
    corner_verts: (L,) int, the vertex of each face corner; positions: (V, 3) float32, the
    vertices in the mesh's local space (any space: the cut does not depend on it)."""
    tri_faces = np.ascontiguousarray(tri_faces, dtype=np.int32)
    corner_verts = np.ascontiguousarray(corner_verts, dtype=np.int32)
    positions = np.ascontiguousarray(positions, dtype=np.float32).reshape(-1, 3)
    n_corners = len(corner_verts)
    if len(tri_faces) == 0 or n_corners == 0:
        return None
    if int(corner_verts.min()) < 0 or int(corner_verts.max()) >= len(positions):
        return None
    out = np.empty((len(tri_faces), 3), np.int32)
    used = _corner_triangles(tri_faces, corner_verts, positions, out)
    return out if used == n_corners else None
