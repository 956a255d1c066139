"""Blender's loop triangles rebuilt from raw arrays (drt.mesh_tessellation), against float32
emulations of Blender's two quad tests; tests/test_export.py checks it against Blender itself."""

from __future__ import annotations

import numpy as np
import pytest

from drt.kernels import kernel
from drt.mesh_tessellation import QUAD_AMBIGUOUS, QUAD_CLEAR, QUAD_FLIP, corner_triangles, quad_split


@kernel
def _splits(p, out):
    for k in range(p.shape[0]):
        out[k] = quad_split((p[k, 0, 0], p[k, 0, 1], p[k, 0, 2]), (p[k, 1, 0], p[k, 1, 1], p[k, 1, 2]),
                            (p[k, 2, 0], p[k, 2, 1], p[k, 2, 2]), (p[k, 3, 0], p[k, 3, 1], p[k, 3, 2]))


def _split_all(quads32):
    p = np.ascontiguousarray(quads32, np.float32).astype(np.float64)
    out = np.empty(len(p), np.int64)
    _splits(p, out)
    return out


def _cross32(a, b):
    """cross_v3_v3v3 in float32, Blender's order of operations."""
    return np.stack([a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1],
                     a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
                     a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]], axis=1)


def _dot32(a, b):
    return a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1] + a[:, 2] * b[:, 2]


def _blender_flip_plain(q):
    """is_quad_flip_v3_first_third_fast, float32."""
    v1, v2, v3, v4 = (q[:, i] for i in range(4))
    return _dot32(_cross32(v2 - v1, v3 - v1), _cross32(v4 - v1, v3 - v1)) > np.float32(0)


def _blender_flip_with_normal(q):
    """is_quad_flip_v3_first_third_fast_with_normal with normal_quad_v3's normal, float32."""
    v1, v2, v3, v4 = (q[:, i] for i in range(4))
    n = _cross32(v1 - v3, v2 - v4)
    n = n / np.sqrt(_dot32(n, n))[:, None]
    tangent = _cross32(v3 - v1, n)
    dot = _dot32(v1, tangent)
    return (_dot32(v4, tangent) >= dot) | (_dot32(v2, tangent) <= dot)


@pytest.mark.parametrize("nonplanar, scale, offset", [(0.0, 1.0, 0.0), (0.2, 1.0, 0.0), (1.0, 1.0, 0.0),
                                                       (0.0, 1e-3, 0.0), (0.01, 1.0, 300.0)])
def test_every_quad_called_clear_is_cut_as_both_blender_tests_cut_it(nonplanar, scale, offset):
    rng = np.random.default_rng(7)
    q = rng.normal(size=(40_000, 4, 3)) * scale
    q[:, :, 2] *= nonplanar
    q = (q + offset).astype(np.float32)
    with np.errstate(invalid="ignore", divide="ignore"):
        plain, with_normal = _blender_flip_plain(q), _blender_flip_with_normal(q)
    split = _split_all(q)
    clear = split != QUAD_AMBIGUOUS
    assert np.array_equal(split[clear] == QUAD_FLIP, plain[clear])
    assert np.array_equal(split[clear] == QUAD_FLIP, with_normal[clear])
    # the bound is not so loose that it gives up: planar quads of any size are decided (only the
    # nearly collinear ones are not), and ambiguity comes from the tests' real disagreements
    if nonplanar == 0.0:
        assert clear.mean() > 0.999
    disagree = plain != with_normal
    assert not np.any(clear & disagree)
    assert (~clear).mean() < max(0.05, 3 * disagree.mean()) or offset > 0


def test_convex_concave_and_degenerate_quads():
    square = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
    dart_at_1 = [(0, 0, 0), (0.8, 0.8, 0), (2, 0, 0), (1, 2, 0)]  # reflex corner 1: the 0-2 cut leaves the face
    dart_at_0 = [(0.8, 0.8, 0), (2, 0, 0), (1, 2, 0), (0, 0, 0)]  # reflex corner 0: the 0-2 cut stays inside
    point = [(0.5, 0.5, 0.5)] * 4
    repeated = [(0, 0, 0), (1, 0, 0), (1, 0, 0), (0, 1, 0)]
    got = _split_all(np.array([square, dart_at_1, dart_at_0, point, repeated]))
    assert list(got) == [QUAD_CLEAR, QUAD_FLIP, QUAD_CLEAR, QUAD_AMBIGUOUS, QUAD_AMBIGUOUS]


def test_triangles_and_quads_become_blenders_corner_triangles():
    # a triangle, a convex quad, a quad cut along 1-3 (reflex corner 1), another triangle
    pos = np.array([(0, 0, 0), (1, 0, 0), (0, 1, 0),
                    (2, 0, 0), (3, 0, 0), (3, 1, 0), (2, 1, 0),
                    (4, 0, 0), (4.8, 0.8, 0), (6, 0, 0), (5, 2, 0),
                    (7, 0, 0), (8, 0, 0), (7, 1, 0)], np.float32)
    corner_verts = np.arange(14, dtype=np.int32)
    tri_faces = np.array([0, 1, 1, 2, 2, 3], np.int32)
    tris = corner_triangles(tri_faces, corner_verts, pos)
    assert tris.dtype == np.int32
    assert tris.tolist() == [[0, 1, 2], [3, 4, 5], [3, 5, 6], [7, 8, 10], [8, 9, 10], [11, 12, 13]]


def test_what_it_cannot_rebuild_exactly_is_left_to_blender():
    pos = np.array([(0, 0, 0), (1, 0, 0), (1.5, 1, 0), (0.5, 1.5, 0), (-0.5, 1, 0)], np.float32)
    cv = np.arange(5, dtype=np.int32)
    assert corner_triangles(np.array([0, 0, 0], np.int32), cv, pos) is None  # a pentagon
    quad_pos = np.array([(0, 0, 0), (1, 0, 0), (1, 0, 0), (0, 1, 0)], np.float32)  # a collapsed corner
    assert corner_triangles(np.array([0, 0], np.int32), np.arange(4, dtype=np.int32), quad_pos) is None
    square = np.array([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], np.float32)
    assert corner_triangles(np.array([1, 1], np.int32), np.arange(4, dtype=np.int32), square) is None  # face 0 missing
    assert corner_triangles(np.array([0, 0], np.int32), np.array([0, 1, 2, 9], np.int32), square) is None  # bad vertex
    assert corner_triangles(np.array([0], np.int32), np.arange(4, dtype=np.int32), square) is None  # corners left over
    assert corner_triangles(np.zeros(0, np.int32), np.zeros(0, np.int32), square) is None
