"""Fuzzing the scene loader (issue 5, bullet 1): whatever bytes, JSON or arrays a scene file
holds, loading either gives a ``Scene`` or raises one ``SceneError`` naming a field, never any
other exception, and a scene that validates also renders (finite pixels, no exception).

Property-based (hypothesis) mutations of a valid scene that uses every feature: header values
replaced by arbitrary JSON, keys deleted, arrays replaced by arbitrary dtypes and shapes, file
bytes truncated or flipped. The default suite runs a few examples of each; the slow suite runs a
time-bounded mutation loop and prints how many inputs it tried. Inputs that once found bugs live
in ``tests/fuzz_corpus/`` and are replayed by ``test_robust_loader.py``.
"""

from __future__ import annotations

import copy
import io
import json
import math
import os
import random
import time
import zipfile
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from drt.render import render
from drt.scene import SceneError, scene_from_dict
from drt.scene_file import encode_header, load_scene, save_scene
from scene_builders import add_material, add_mesh, base_header, look_at, quad, translation, uv_sphere

FUZZ_SECONDS = float(os.environ.get("DRT_FUZZ_SECONDS", "60"))


# ------------------------------------------------------------------------------ the seed scene


def rich_scene():
    """A tiny scene that touches every header section and array kind: all light types, all
    lobes, DOF with blades, motion blur (rigid and deforming), normals, uvs, border."""
    cam = {"type": "PERSP", "matrix_world": look_at((0, -4, 1), (0, 0, 0.5)), "lens": 35.0,
           "sensor_width": 36.0, "sensor_height": 24.0, "sensor_fit": "AUTO", "shift_x": 0.0, "shift_y": 0.0,
           "clip_start": 0.1, "clip_end": 100.0, "ortho_scale": 7.0,
           "dof": {"use": True, "focus_distance": 4.0, "fstop": 8.0, "blades": 5, "rotation": 0.1, "ratio": 1.0},
           "motion": None}
    h = base_header(6, 4, 2, camera=cam, world=(0.1, 0.1, 0.1), shutter=[-0.25, 0.25], border=[0.0, 0.0, 1.0, 1.0],
                    pixel_aspect=[1.0, 1.0], film_transparent=False, clamp_direct=0.0, clamp_indirect=0.0)
    a = {}
    diffuse = add_material(h, "diffuse", [{"type": "DIFFUSE", "color": [0.8, 0.7, 0.6]}])
    mixed = add_material(h, "mixed", [{"type": "DIFFUSE", "color": [0.4, 0.4, 0.4]},
                                      {"type": "GLOSSY", "color": [0.5, 0.5, 0.5], "roughness": 0.3}])
    glass = add_material(h, "glass", [{"type": "GLASS", "color": [1, 1, 1], "roughness": 0.0, "ior": 1.45}])
    emit = add_material(h, "emit", [], emission=(2.0, 2.0, 2.0))
    add_mesh(h, a, "floor", *quad((0, 0, 0), (2, 0, 0), (0, 2, 0)), material=diffuse)
    pos, tri, nrm = uv_sphere(0.4, rings=4, segments=6)
    k = add_mesh(h, a, "ball", pos, tri, material=[mixed] * len(tri), normals=nrm,
                 matrix=translation(-0.6, 0, 0.4),
                 motion={"matrix_open": translation(-0.6, 0, 0.4), "matrix_close": translation(-0.5, 0, 0.4)})
    a[f"mesh{k}.uvs"] = np.zeros((len(tri), 3, 2), np.float32)
    add_mesh(h, a, "glass", pos, tri, material=glass, normals=nrm, matrix=translation(0.6, 0, 0.4))
    qp, qt = quad((0, 1, 1), (0.3, 0, 0), (0, 0, 0.3))
    add_mesh(h, a, "panel", qp, qt, material=emit, positions_close=qp + np.array([0, 0, 0.1]))
    h["lights"] += [
        {"name": "pt", "type": "POINT", "matrix_world": translation(1, -1, 2), "color": [1, 1, 1], "power": 50.0,
         "radius": 0.1, "soft_falloff": True},
        {"name": "spot", "type": "SPOT", "matrix_world": look_at((-1, -1, 2), (0, 0, 0)), "color": [1, 0.9, 0.8],
         "power": 80.0, "radius": 0.0, "soft_falloff": False, "spot_size": 0.8, "spot_blend": 0.2},
        {"name": "sun", "type": "SUN", "matrix_world": look_at((1, 1, 3), (0, 0, 0)), "color": [1, 1, 1],
         "strength": 2.0, "angle": 0.05},
        {"name": "area", "type": "AREA", "matrix_world": translation(0, 0, 2.5), "color": [1, 1, 1], "power": 40.0,
         "shape": "RECTANGLE", "size": 0.5, "size_y": 0.3, "spread": 2.0},
        {"name": "disk", "type": "AREA", "matrix_world": translation(0, 0.5, 2.5), "color": [1, 1, 1], "power": 10.0,
         "shape": "ELLIPSE", "size": 0.2, "size_y": 0.4, "spread": math.pi, "visible_camera": True},
    ]
    return h, a


def header_paths(node, prefix=()):
    """Every (path tuple) to a value inside a JSON-like header, containers included."""
    out = []
    if isinstance(node, dict):
        for k, v in node.items():
            out.append(prefix + (k,))
            out += header_paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out.append(prefix + (i,))
            out += header_paths(v, prefix + (i,))
    return out


BASE_HEADER, BASE_ARRAYS = rich_scene()
PATHS = header_paths(BASE_HEADER)
ARRAY_NAMES = sorted(BASE_ARRAYS) + ["mesh0.normals", "mesh0.uvs", "mesh0.positions_close", "mesh9.positions"]


def set_path(h, path, value, delete=False):
    node = h
    for k in path[:-1]:
        node = node[k]
    if delete:
        if isinstance(node, dict):
            node.pop(path[-1], None)
        else:
            node.pop(path[-1])
    else:
        node[path[-1]] = value


# ------------------------------------------------------------------------------ the properties


def check_scene(header, arrays, render_it=True):
    """The invariant: a Scene or a SceneError; a valid scene renders finite pixels."""
    try:
        scene = scene_from_dict(header, arrays)
    except SceneError as e:
        assert e.field and str(e).startswith(f"scene field '{e.field}'")
        return "rejected"
    if render_it:
        check_renders(scene)
    return "accepted"


def check_renders(scene):
    """Render a small version (few pixels, 1 spp) of a scene that validated."""
    r = scene.render
    scene.render = replace(r, width=min(r.width, 6), height=min(r.height, 4), spp=1,
                           max_bounces=min(r.max_bounces, 4), adaptive_threshold=0.0)
    try:
        film = render(scene, spp=1, threads=1, parallel="threads")
    except SceneError:
        return  # e.g. a light the light module itself refuses: still a named, clean error
    img = film.combined
    assert np.all(np.isfinite(img)), "a valid scene rendered NaN/Inf pixels"
    assert np.all(img[..., :3] >= 0)


def check_file(path):
    try:
        load_scene(path)
    except SceneError as e:
        assert e.field
        return "rejected"
    return "accepted"


# ------------------------------------------------------------------------------ strategies

json_scalars = st.one_of(
    st.none(), st.booleans(),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.sampled_from([0, 1, -1, 2**31, 2**63, 10**400, -(10**400), 65536, 65537]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, 1e-320, 1e-45, 1e38, 1e39, 1e308, float("nan"), float("inf"), -float("inf")]),
    st.text(max_size=8),
    st.sampled_from(["POINT", "SUN", "AREA", "GLASS", "DIFFUSE", "ORTHO", "SOBOL", "BOX", "DISK", "drt-scene"]),
)
json_values = st.recursive(
    json_scalars,
    lambda children: st.one_of(st.lists(children, max_size=5), st.dictionaries(st.text(max_size=6), children, max_size=4)),
    max_leaves=12,
)
# plausible-looking replacements: lists of the right length with odd numbers
number_lists = st.lists(st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-5, 5)), min_size=0, max_size=5)
matrix_like = st.lists(st.lists(st.floats(-1e3, 1e3) | st.sampled_from([0.0, float("nan"), 1e30]), min_size=4, max_size=4),
                       min_size=4, max_size=4)


@st.composite
def header_mutation(draw):
    h = copy.deepcopy(BASE_HEADER)
    for _ in range(draw(st.integers(1, 3))):
        path = draw(st.sampled_from(PATHS))
        try:
            kind = draw(st.sampled_from(["value", "delete", "numbers", "matrix", "zero", "negate"]))
            if kind == "delete":
                set_path(h, path, None, delete=True)
            elif kind == "numbers":
                set_path(h, path, draw(number_lists))
            elif kind == "matrix":
                set_path(h, path, draw(matrix_like))
            elif kind == "zero":
                set_path(h, path, 0)
            elif kind == "negate":
                node = h
                for k in path:
                    node = node[k]
                if isinstance(node, (int, float)) and not isinstance(node, bool):
                    set_path(h, path, -node)
            else:
                set_path(h, path, draw(json_values))
        except (KeyError, IndexError, TypeError, AttributeError):
            pass  # an earlier mutation removed or replaced the parent
    return h


dtypes = st.sampled_from([np.float32, np.float64, np.float16, np.int32, np.int64, np.uint32, np.uint8, np.int8,
                          np.bool_, np.complex64, ">f4", ">i4"])


@st.composite
def array_mutation(draw):
    a = dict(BASE_ARRAYS)
    for _ in range(draw(st.integers(1, 2))):
        name = draw(st.sampled_from(ARRAY_NAMES))
        kind = draw(st.sampled_from(["replace", "delete", "shape", "values"]))
        if kind == "delete":
            a.pop(name, None)
        elif kind == "replace":
            a[name] = draw(hnp.arrays(draw(dtypes), hnp.array_shapes(min_dims=0, max_dims=3, max_side=6)))
        elif kind == "shape" and name in a:
            a[name] = a[name].reshape(-1)[: draw(st.integers(0, a[name].size))]
        elif kind == "values" and name in a:
            arr = a[name].copy()
            if arr.size:
                flat = arr.reshape(-1)
                i = draw(st.integers(0, flat.size - 1))
                special = [-1, 0, 10**6, 2**31 - 1] if arr.dtype.kind in "iu" else [np.nan, np.inf, -1e30, 1e38, 0.0]
                with np.errstate(all="ignore"):
                    flat[i] = np.array(draw(st.sampled_from(special))).astype(arr.dtype)
            a[name] = arr
    return a


# ------------------------------------------------------------------------------ default suite (brief)

FEW = settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow], derandomize=True)


def test_seed_scene_is_valid_and_renders():
    assert check_scene(*rich_scene()) == "accepted"


@FEW
@given(header_mutation())
def test_fuzz_header_values(h):
    check_scene(h, BASE_ARRAYS)


@FEW
@given(array_mutation())
def test_fuzz_arrays(a):
    check_scene(copy.deepcopy(BASE_HEADER), a)


def _file_bytes(header_bytes: bytes, arrays) -> bytes:
    buf = io.BytesIO()
    np.savez_compressed(buf, header=np.frombuffer(header_bytes, np.uint8), **arrays)
    return buf.getvalue()


SEED_FILE = _file_bytes(json.dumps(BASE_HEADER).encode(), BASE_ARRAYS)


@settings(max_examples=25, deadline=None, derandomize=True)
@given(st.data())
def test_fuzz_file_bytes(tmp_path_factory, data):
    """Truncations, bit flips and byte overwrites of a valid archive."""
    b = bytearray(SEED_FILE)
    for _ in range(data.draw(st.integers(1, 4))):
        op = data.draw(st.sampled_from(["truncate", "flip", "overwrite"]))
        if not b:
            break
        i = data.draw(st.integers(0, len(b) - 1))
        if op == "truncate":
            del b[i:]
        elif op == "flip":
            b[i] ^= 1 << data.draw(st.integers(0, 7))
        else:
            b[i] = data.draw(st.integers(0, 255))
    path = tmp_path_factory.mktemp("fuzz") / "s.npz"
    path.write_bytes(bytes(b))
    check_file(path)


@settings(max_examples=25, deadline=None, derandomize=True)
@given(st.binary(max_size=400))
def test_fuzz_header_json_text(tmp_path_factory, raw):
    """Arbitrary bytes as the header's JSON text."""
    path = tmp_path_factory.mktemp("fuzz") / "s.npz"
    path.write_bytes(_file_bytes(raw, {}))
    check_file(path)


# ------------------------------------------------------------------------------ slow: bounded run


def random_json(rng: random.Random, depth: int = 0):
    """An arbitrary JSON-like value (seeded), with the extremes that break validators."""
    r = rng.random()
    if depth < 3 and r < 0.15:
        return [random_json(rng, depth + 1) for _ in range(rng.randint(0, 5))]
    if depth < 3 and r < 0.25:
        return {rng.choice(["type", "use", "x", ""]): random_json(rng, depth + 1) for _ in range(rng.randint(0, 3))}
    return rng.choice([
        None, True, False, 0, 1, -1, 2**31, 2**63, 10**400, -(10**400), 65536, 65537, 0.0, -0.0, 1e-320, 1e38, 1e39,
        1e308, float("nan"), float("inf"), -float("inf"), rng.uniform(-10, 10), rng.randint(-5, 5), "", "x", "POINT",
        "SUN", "AREA", "GLASS", "ORTHO", "DISK", "drt-scene", [1, 2, 3], [0, 0, 0, 1], [[1, 0], [0, 1]],
    ])


def _mutate_file_bytes(rng: random.Random, seed: bytes) -> bytes:
    b = bytearray(seed)
    for _ in range(rng.randint(1, 6)):
        if not b:
            break
        op, i = rng.random(), rng.randrange(len(b))
        if op < 0.15:
            del b[i:]
        elif op < 0.6:
            b[i] ^= 1 << rng.randrange(8)
        elif op < 0.8:
            b[i] = rng.randrange(256)
        else:  # overwrite a 4-byte field (zip sizes, offsets) with an extreme value
            b[i:i + 4] = rng.choice([b"\xff\xff\xff\xff", b"\x00\x00\x00\x00", b"\xff\xff\xff\x7f"])
    return bytes(b)


@pytest.mark.slow
def test_fuzz_bounded_run(tmp_path, capsys):
    """FUZZ_SECONDS (env DRT_FUZZ_SECONDS, default 60) of mutation fuzzing: header values
    (hypothesis strategies drawn with ``.example()``-free random choices), arrays and raw bytes.
    Prints the number of inputs tried and how many were accepted."""
    rng = random.Random(20240505)
    tried = {"header": 0, "arrays": 0, "bytes": 0, "rendered": 0}
    outcomes = {"accepted": 0, "rejected": 0}
    deadline = time.monotonic() + FUZZ_SECONDS
    path = tmp_path / "f.npz"
    values = [random_json(rng) for _ in range(300)]
    while time.monotonic() < deadline:
        r = rng.random()
        if r < 0.4:
            h = copy.deepcopy(BASE_HEADER)
            changes = []
            for _ in range(rng.randint(1, 3)):
                p = rng.choice(PATHS)
                v = rng.choice(values + [None, 0, -1, 10**400, float("nan"), float("inf"), [], {}, "x", True, 1e39])
                delete = rng.random() < 0.15
                try:
                    set_path(h, p, v, delete=delete)
                    changes.append((p, "<deleted>" if delete else v))
                except (KeyError, IndexError, TypeError, AttributeError):
                    pass
            do_render = rng.random() < 0.2
            try:
                result = check_scene(h, BASE_ARRAYS, render_it=do_render)
                outcomes[result] += 1
                tried["rendered"] += do_render and result == "accepted"
            except BaseException as e:
                raise AssertionError(f"header changes {changes!r:.2000}: {type(e).__name__}: {e}") from e
            tried["header"] += 1
        elif r < 0.6:
            a = dict(BASE_ARRAYS)
            name = rng.choice(ARRAY_NAMES)
            dt = rng.choice([np.float32, np.float64, np.int32, np.uint8, np.bool_, np.complex64, np.int64])
            shape = tuple(rng.randint(0, 5) for _ in range(rng.randint(0, 3)))
            with np.errstate(all="ignore"):
                a[name] = (np.random.default_rng(rng.randrange(2**32)).standard_normal(shape) * rng.choice([1, 3, 1e6])).astype(dt)
            try:
                outcomes[check_scene(copy.deepcopy(BASE_HEADER), a, render_it=rng.random() < 0.2)] += 1
            except BaseException as e:
                raise AssertionError(f"array {name} = {a[name]!r:.500}: {type(e).__name__}: {e}") from e
            tried["arrays"] += 1
        else:
            data = _mutate_file_bytes(rng, SEED_FILE)
            path.write_bytes(data)
            try:
                outcomes[check_file(path)] += 1
            except BaseException:
                (tmp_path / "failing.npz").write_bytes(data)  # keep it for tests/fuzz_corpus/
                raise
            tried["bytes"] += 1
    total = tried["header"] + tried["arrays"] + tried["bytes"]
    with capsys.disabled():
        print(f"\nfuzz: {total} inputs in {FUZZ_SECONDS:.0f}s ({tried}); outcomes {outcomes}")
    assert total > 0


@pytest.mark.slow
@settings(max_examples=400, deadline=None, suppress_health_check=list(HealthCheck))
@given(header_mutation(), st.booleans())
def test_fuzz_header_values_long(h, do_render):
    check_scene(h, BASE_ARRAYS, render_it=do_render)


@pytest.mark.slow
@settings(max_examples=400, deadline=None, suppress_health_check=list(HealthCheck))
@given(array_mutation())
def test_fuzz_arrays_long(a):
    check_scene(copy.deepcopy(BASE_HEADER), a)
