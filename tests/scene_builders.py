"""Small analytic scenes built directly as (header, arrays), without Blender.

Each builder returns a header dict and an arrays dict in the scene-file format
(``docs/scene-format.md``), ready for ``drt.scene.scene_from_dict``.
"""

from __future__ import annotations

import copy
import math

import numpy as np

IDENTITY = np.eye(4).tolist()


def translation(x, y, z):
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m.tolist()


def look_at(eye, target, up=(0, 0, 1)):
    """Camera/light matrix at ``eye`` whose local −Z points at ``target`` (Blender convention)."""
    eye, target, up = (np.asarray(v, float) for v in (eye, target, up))
    back = eye - target
    back /= np.linalg.norm(back)
    if abs(np.dot(back, up)) > 0.999:
        up = np.array([0.0, 1.0, 0.0])
    right = np.cross(up, back)
    right /= np.linalg.norm(right)
    true_up = np.cross(back, right)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = right, true_up, back, eye
    return m.tolist()


def base_header(width=32, height=32, spp=16, camera=None, world=(0, 0, 0), **render):
    r = {
        "resolution": [width, height],
        "spp": spp,
        "seed": 0,
        "sampler": "SOBOL",
        "filter": {"type": "BLACKMAN_HARRIS", "width": 1.5},
        "max_bounces": 12,
        "diffuse_bounces": 4,
        "glossy_bounces": 4,
        "transmission_bounces": 12,
        "shutter": None,
    }
    r.update(render)
    return {
        "format": "drt-scene",
        "version": 1,
        "render": r,
        "camera": camera or {"type": "PERSP", "matrix_world": look_at((0, -5, 0), (0, 0, 0)), "lens": 50.0},
        "world": {"color": list(world)},
        "materials": [],
        "lights": [],
        "meshes": [],
        "objects": [],
    }


def add_material(header, name, lobes, emission=(0, 0, 0)) -> int:
    header["materials"].append({"name": name, "lobes": lobes, "emission": list(emission)})
    return len(header["materials"]) - 1


def add_mesh(header, arrays, name, positions, triangles, material=0, matrix=None, normals=None, motion=None, positions_close=None) -> int:
    k = len(header["meshes"])
    header["meshes"].append({"name": name, "deforming": positions_close is not None})
    arrays[f"mesh{k}.positions"] = np.asarray(positions, np.float32)
    arrays[f"mesh{k}.triangles"] = np.asarray(triangles, np.int32)
    mi = np.asarray(material, np.int32)
    arrays[f"mesh{k}.material_index"] = np.broadcast_to(mi, (len(triangles),)).copy()
    if normals is not None:
        arrays[f"mesh{k}.normals"] = np.asarray(normals, np.float32)
    if positions_close is not None:
        arrays[f"mesh{k}.positions_close"] = np.asarray(positions_close, np.float32)
    # (a copy of IDENTITY: a test that edits one object's matrix in place must not move others)
    header["objects"].append({"name": name, "mesh": k, "matrix_world": matrix or copy.deepcopy(IDENTITY),
                              "motion": motion})
    return k


def quad(center, u_axis, v_axis):
    """Two triangles spanning center ± u_axis ± v_axis; front side = u × v."""
    c, u, v = (np.asarray(a, float) for a in (center, u_axis, v_axis))
    pos = np.array([c - u - v, c + u - v, c + u + v, c - u + v])
    return pos, np.array([[0, 1, 2], [0, 2, 3]])


def uv_sphere(radius=1.0, center=(0, 0, 0), rings=48, segments=96, inward=False):
    """Triangulated sphere with smooth per-corner normals (outward unless ``inward``)."""
    th = np.linspace(0, np.pi, rings + 1)
    ph = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    T, P = np.meshgrid(th, ph, indexing="ij")
    dirs = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1).reshape(-1, 3)
    pos = np.asarray(center) + radius * dirs
    tris = []
    for i in range(rings):
        for j in range(segments):
            a = i * segments + j
            b = i * segments + (j + 1) % segments
            c = (i + 1) * segments + j
            d = (i + 1) * segments + (j + 1) % segments
            if i > 0:
                tris.append([a, c, b])
            if i < rings - 1:
                tris.append([b, c, d])
    tris = np.array(tris)
    normals = dirs[tris]
    if inward:
        tris = tris[:, ::-1]
        normals = -dirs[tris]
    return pos, tris, normals


def cornell_box(width=64, height=64, spp=16):
    """The classic box (1 m cube-ish) lit by a 0.25 m² area light under the ceiling."""
    h = base_header(width, height, spp, camera={
        "type": "PERSP", "matrix_world": look_at((0, -3.9, 1.0), (0, 0, 1.0)), "lens": 38.0,
        "sensor_width": 36.0, "sensor_fit": "AUTO", "clip_start": 0.1, "clip_end": 100.0,
    })
    a = {}
    white = add_material(h, "White", [{"type": "DIFFUSE", "color": [0.73, 0.73, 0.73]}])
    red = add_material(h, "Red", [{"type": "DIFFUSE", "color": [0.65, 0.05, 0.05]}])
    green = add_material(h, "Green", [{"type": "DIFFUSE", "color": [0.12, 0.45, 0.15]}])
    for name, c, u, v, m in [
        ("floor", (0, 0, 0), (1, 0, 0), (0, 1, 0), white),
        ("ceiling", (0, 0, 2), (0, 1, 0), (1, 0, 0), white),
        ("back", (0, 1, 1), (0, 0, 1), (1, 0, 0), white),
        ("left", (-1, 0, 1), (0, 1, 0), (0, 0, 1), red),
        ("right", (1, 0, 1), (0, 0, 1), (0, 1, 0), green),
    ]:
        add_mesh(h, a, name, *quad(c, u, v), material=m)
    # two boxes
    for name, c, s, rot, ht in [("short", (0.35, -0.3, 0), 0.3, 0.3, 0.6), ("tall", (-0.35, 0.3, 0), 0.3, -0.3, 1.2)]:
        pos, tris = box_mesh(s, ht)
        cz, sz = math.cos(rot), math.sin(rot)
        m = np.array([[cz, -sz, 0, c[0]], [sz, cz, 0, c[1]], [0, 0, 1, 0], [0, 0, 0, 1]]).tolist()
        add_mesh(h, a, name, pos, tris, material=white, matrix=m)
    h["lights"].append({
        "name": "Light", "type": "AREA", "matrix_world": translation(0, 0, 1.98), "color": [1, 1, 1],
        "power": 60.0, "shape": "SQUARE", "size": 0.5, "size_y": 0.5, "spread": math.pi,
    })
    return h, a


def box_mesh(half, height):
    """Axis-aligned box [-half, half]² × [0, height], outward-facing triangles."""
    x0, x1, z0, z1 = -half, half, 0.0, height
    p = np.array([[x0, x0, z0], [x1, x0, z0], [x1, x1, z0], [x0, x1, z0], [x0, x0, z1], [x1, x0, z1], [x1, x1, z1], [x0, x1, z1]])
    t = np.array([
        [0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4],
        [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7],
    ])
    return p, t


def with_render(header, **changes):
    h = copy.deepcopy(header)
    h["render"].update(changes)
    return h


def scene_error_of(change) -> str:
    """The SceneError message of a 4×4 one-quad scene after ``change(header)`` edits its header
    (None when the scene loads): for tests that a bad setting is named."""
    from drt.scene import SceneError, scene_from_dict

    h = base_header(4, 4, 1)
    a = {}
    add_material(h, "m", [{"type": "DIFFUSE", "color": [0.5] * 3}])
    add_mesh(h, a, "q", *quad((0, 0, 0), (1, 0, 0), (0, 1, 0)))
    change(h)
    try:
        scene_from_dict(h, a)
    except SceneError as e:
        return str(e)
    return None
