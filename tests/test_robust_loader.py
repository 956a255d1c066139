"""Untrusted scene files (issue 5, bullet 1): every malformed archive gives one SceneError that
names the field (or 'file' / 'header'), loading never runs code, never raises another exception
type and never allocates more than the archive honestly declares.

Field-by-field naming cases live in ``test_scene_file.py``; this file covers the archive layer
(zip, .npy headers, sizes, JSON parsing) and replays ``fuzz_corpus/`` (inputs that once crashed).
"""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
import tracemalloc
import zipfile

import numpy as np
import pytest
from numpy.lib import format as npf

import drt.scene_file as scene_file
from drt.render import render
from drt.scene import SceneError
from drt.scene_file import load_scene, save_scene
from scene_builders import cornell_box

CORPUS = os.path.join(os.path.dirname(__file__), "fuzz_corpus")
with open(os.path.join(CORPUS, "expected.json"), encoding="utf-8") as _f:
    EXPECTED = json.load(_f)


def npy(arr) -> bytes:
    b = io.BytesIO()
    npf.write_array(b, np.asarray(arr))
    return b.getvalue()


def npy_header_only(shape, descr="<f8") -> bytes:
    b = io.BytesIO()
    npf.write_array_header_1_0(b, {"descr": descr, "fortran_order": False, "shape": shape})
    return b.getvalue()


def write_archive(path, members: dict[str, bytes]):
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for name, data in members.items():
            z.writestr(name, data)


def box_members(**replace) -> dict[str, bytes]:
    h, a = cornell_box(8, 8, 1)
    members = {"header.npy": npy(np.frombuffer(json.dumps(h).encode(), np.uint8))}
    members.update({k + ".npy": npy(v) for k, v in a.items()})
    members.update(replace)
    return {k: v for k, v in members.items() if v is not None}


def load_error(path) -> SceneError:
    with pytest.raises(SceneError) as e:
        load_scene(path)
    msg = str(e.value)
    assert msg.startswith(f"scene field '{e.value.field}': ") and "\n" not in msg
    return e.value


# ------------------------------------------------------------------------------ regression corpus


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_fuzz_corpus(name):
    """Inputs that once crashed the loader or the renderer (see fuzz_corpus/make_corpus.py)."""
    want = EXPECTED[name]
    path = os.path.join(CORPUS, name)
    if "field" in want:
        assert load_error(path).field == want["field"]
    else:
        film = render(load_scene(path), spp=2, threads=1, parallel="threads")
        assert np.all(np.isfinite(film.combined)) and np.all(np.isfinite(film.variance))


# ------------------------------------------------------------------------------ archive layer


def test_declared_shape_must_match_member_size(tmp_path):
    p = tmp_path / "s.npz"
    # a header promising 2.4 TB: refused before numpy allocates anything
    write_archive(p, box_members(**{"mesh0.positions.npy": npy_header_only((10**11, 3))}))
    tracemalloc.start()
    err = load_error(p)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert err.field == "mesh0.positions" and "declares shape" in str(err)
    assert peak < 16 << 20
    # a header promising less than the member holds
    write_archive(p, box_members(**{"mesh0.positions.npy": npy_header_only((1, 3)) + bytes(8 * 30)}))
    assert load_error(p).field == "mesh0.positions"


def test_zip_bomb_over_budget_is_refused_before_decompressing(tmp_path, monkeypatch):
    """A member whose declared (uncompressed) size exceeds the budget is refused up front:
    8 MB of zeros compresses to ~8 kB; with a 1 MB budget nothing is decompressed."""
    p = tmp_path / "bomb.npz"
    write_archive(p, box_members(**{"mesh0.normals.npy": npy(np.zeros((2**18, 1, 1), np.float64))}))
    assert os.path.getsize(p) < 64 << 10
    monkeypatch.setattr(scene_file, "MAX_ARRAY_BYTES", 1 << 20)
    tracemalloc.start()
    err = load_error(p)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert err.field == "file" and "GiB of arrays" in str(err)
    assert peak < 1 << 20


def test_budget_follows_available_memory(monkeypatch):
    monkeypatch.setattr(scene_file, "_available_memory", lambda: 10 << 30)
    assert scene_file._array_budget() == 8 << 30
    monkeypatch.setattr(scene_file, "_available_memory", lambda: None)
    assert scene_file._array_budget() == scene_file.MAX_ARRAY_BYTES


@pytest.mark.parametrize(
    "members, field",
    [
        ({"header.npy": None}, "header"),
        ({"readme.txt": b"hello"}, "readme.txt"),
        ({"header.npy": npy(np.zeros(4, np.float32))}, "header"),
        ({"header.npy": npy(np.zeros((2, 2), np.uint8))}, "header"),
        ({"header.npy": b"\x93NUMPY\x01\x00garbage"}, "header"),
        ({"header.npy": b"not npy"}, "header"),
        ({"mesh0.positions.npy": npy(np.array([{"evil": 1}], dtype=object))}, "mesh0.positions"),
        ({"mesh0.positions.npy": npy_header_only((4, 3), "|O")}, "mesh0.positions"),
        ({"mesh0.positions.npy": npy(np.zeros((4, 3), np.float32))[:-5]}, "mesh0.positions"),
    ],
)
def test_malformed_members(tmp_path, members, field):
    p = tmp_path / "s.npz"
    write_archive(p, box_members(**members))
    assert load_error(p).field == field


@pytest.mark.parametrize("text", [b"[]", b'"drt-scene"', b"42", b"null", b"{", b"\xff\xfe{}", b"", b"NaN"])
def test_header_json_that_is_not_an_object(tmp_path, text):
    p = tmp_path / "s.npz"
    write_archive(p, {"header.npy": npy(np.frombuffer(text, np.uint8))})
    assert load_error(p).field == "header"


def test_every_truncation_is_a_clean_error(tmp_path):
    h, a = cornell_box(8, 8, 1)
    good = tmp_path / "good.npz"
    save_scene(good, h, a)
    data = good.read_bytes()
    bad = tmp_path / "cut.npz"
    for cut in np.linspace(0, len(data) - 1, 40).astype(int):
        bad.write_bytes(data[:cut])
        assert load_error(bad).field in ("file", "header") or load_error(bad).field.startswith("mesh")


def test_corrupt_compressed_data_is_a_clean_error(tmp_path):
    """Flipping bytes inside the deflate streams gives a zlib/CRC error: named 'file'."""
    h, a = cornell_box(8, 8, 1)
    good = tmp_path / "good.npz"
    save_scene(good, h, a)
    data = bytearray(good.read_bytes())
    rng = np.random.default_rng(5)
    bad = tmp_path / "flip.npz"
    for _ in range(40):
        d = bytearray(data)
        for i in rng.integers(0, len(d), 3):
            d[i] ^= 0xFF
        bad.write_bytes(bytes(d))
        try:
            load_scene(bad)
        except SceneError as e:
            assert e.field
    # a directory, an empty file
    with pytest.raises(SceneError, match="does not exist"):
        load_scene(tmp_path)
    (tmp_path / "empty.npz").write_bytes(b"")
    assert load_error(tmp_path / "empty.npz").field == "file"


def test_cli_reports_a_bad_file_in_one_line(tmp_path):
    out = tmp_path / "o.exr"
    r = subprocess.run([sys.executable, "-m", "drt", "render", os.path.join(CORPUS, "nested_json.npz"), "-o", str(out)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2
    assert r.stderr.strip().startswith("drt: error: invalid scene") and "'header'" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    assert not out.exists()
