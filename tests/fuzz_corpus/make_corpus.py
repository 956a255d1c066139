"""Rebuild the regression inputs in this folder (each once crashed the loader or the renderer).

Run from the repository root: ``python tests/fuzz_corpus/make_corpus.py``. ``expected.json``
says what each input must give: ``{"field": F}`` a SceneError naming F, or ``{"renders": true}``
a valid scene that renders finite pixels.
"""

import io
import json
import os
import sys
import zipfile

import numpy as np
from numpy.lib import format as npf

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))
from scene_builders import add_material, add_mesh, base_header, quad, translation, uv_sphere  # noqa: E402


def npy(arr):
    b = io.BytesIO()
    npf.write_array(b, np.asarray(arr))
    return b.getvalue()


def archive(name, members):
    with zipfile.ZipFile(os.path.join(HERE, name), "w", zipfile.ZIP_DEFLATED) as z:
        for n, data in members.items():
            z.writestr(zipfile.ZipInfo(n) if n == "" else n, data)  # zipfile cannot name "" itself


def header_npy(text: bytes):
    return npy(np.frombuffer(text, np.uint8))


def small_scene():
    h = base_header(8, 8, 4, world=(0.2, 0.2, 0.2))
    a = {}
    m = add_material(h, "m", [{"type": "DIFFUSE", "color": [0.8, 0.8, 0.8]}])
    add_mesh(h, a, "floor", *quad((0, 0, -1), (2, 0, 0), (0, 2, 0)), material=m)
    pos, tri, nrm = uv_sphere(0.5, rings=6, segments=8)
    add_mesh(h, a, "ball", pos, tri, material=m, normals=nrm, matrix=translation(0, 0, 0))
    return h, a


def scene_archive(name, h, a):
    archive(name, {"header.npy": header_npy(json.dumps(h).encode()), **{k + ".npy": npy(v) for k, v in a.items()}})


expected = {}
# json.loads raised RecursionError
archive("nested_json.npz", {"header.npy": header_npy(b"[" * 50000 + b"]" * 50000)})
expected["nested_json.npz"] = {"field": "header"}
# json.loads raised ValueError (Python's 4300-digit integer limit)
archive("bigint_json.npz", {"header.npy": header_npy(b'{"format":"drt-scene","version":' + b"7" * 5000 + b"}")})
expected["bigint_json.npz"] = {"field": "header"}
# numpy allocated the declared 2.4 TB shape: MemoryError
h, a = small_scene()
b = io.BytesIO()
npf.write_array_header_1_0(b, {"descr": "<f8", "fortran_order": False, "shape": (10**11, 3)})
archive("huge_declared_shape.npz", {"header.npy": header_npy(json.dumps(h).encode()),
                                     **{k + ".npy": npy(v) for k, v in a.items() if k != "mesh0.positions"},
                                     "mesh0.positions.npy": b.getvalue()})
expected["huge_declared_shape.npz"] = {"field": "mesh0.positions"}
# a plain .npy instead of an archive: TypeError (ndarray is no context manager)
with open(os.path.join(HERE, "plain_array.npz"), "wb") as f:
    f.write(npy(np.zeros(3)))
expected["plain_array.npz"] = {"field": "file"}
# a member with an empty name: IndexError inside zipfile (found by the bounded fuzz run)
archive("empty_member_name.npz", {"header.npy": header_npy(b"{}"), "": b"x"})
expected["empty_member_name.npz"] = {"field": "file"}
# integers too large for a float: OverflowError
for name, mutate, field in [
    ("bigint_lens.npz", lambda h: h["camera"].update(lens=10**400), "camera.lens"),
    ("bigint_color.npz", lambda h: h["world"].update(color=[10**400, 0, 0]), "world.color"),
    ("version_true.npz", lambda h: h.update(version=True), "version"),
]:
    h, a = small_scene()
    mutate(h)
    scene_archive(name, h, a)
    expected[name] = {"field": field}
# valid scenes that rendered Inf pixels or raised LinAlgError (found by the bounded fuzz run)
h, a = small_scene()
h["materials"][0]["emission"] = [1e308, 0, 0]
scene_archive("emission_1e308.npz", h, a)
# once rendered (Inf samples dropped); numbers beyond ±1e30 are now refused (scene.MAX_MAGNITUDE)
expected["emission_1e308.npz"] = {"field": "materials[0].emission"}
h, a = small_scene()
h["objects"][1]["matrix_world"][0][0] = 0.0  # the sphere (with normals) scaled to zero in x
scene_archive("zero_scale_object.npz", h, a)
expected["zero_scale_object.npz"] = {"renders": True}
# a point light of radius 1e308: radius ** 2 raised OverflowError (found by the bounded fuzz run)
h, a = small_scene()
h["lights"].append({"type": "POINT", "matrix_world": translation(0, 0, 2), "power": 10.0, "radius": 1e308})
scene_archive("light_radius_1e308.npz", h, a)
expected["light_radius_1e308.npz"] = {"field": "lights[0].radius"}

with open(os.path.join(HERE, "expected.json"), "w") as f:
    json.dump(expected, f, indent=1, sort_keys=True)
