"""Scene file round trip and validation: every malformed input names its field."""

import json

import numpy as np
import pytest

from drt.scene import SceneError, scene_from_dict
from drt.scene_file import load_scene, read_scene_arrays, save_scene
from scene_builders import cornell_box


def test_round_trip(tmp_path):
    h, a = cornell_box()
    path = tmp_path / "box.npz"
    save_scene(path, h, a)
    header, arrays = read_scene_arrays(path)
    assert header == json.loads(json.dumps(h))
    for k, v in a.items():
        assert np.array_equal(arrays[k], v)
    scene = load_scene(path)
    assert scene.render.width == 64 and len(scene.objects) == 7
    assert scene.triangle_count == 5 * 2 + 2 * 12


@pytest.mark.parametrize(
    "mutate, field",
    [
        (lambda h, a: h.update(version=99), "version"),
        (lambda h, a: h.update(format="x"), "format"),
        (lambda h, a: h["camera"].update(lens=-5), "camera.lens"),
        (lambda h, a: h["camera"].update(lens=float("nan")), "camera.lens"),
        (lambda h, a: h["camera"].update(matrix_world=[[1, 0], [0, 1]]), "camera.matrix_world"),
        (lambda h, a: h["render"].update(resolution=[0, 10]), "render.resolution"),
        (lambda h, a: h["render"].update(spp="many"), "render.spp"),
        (lambda h, a: h["lights"][0].update(power=-1), "lights[0].power"),
        (lambda h, a: h["lights"][0].update(type="LASER"), "lights[0].type"),
        (lambda h, a: h["materials"][0]["lobes"][0].update(color=[1, 2]), "materials[0].lobes[0].color"),
        (lambda h, a: h["objects"][0].update(mesh=99), "objects[0].mesh"),
        (lambda h, a: a.update({"mesh0.triangles": np.array([[0, 1, 7]], np.int32)}), "mesh0.triangles"),
        (lambda h, a: a.update({"mesh0.positions": np.full((4, 3), np.nan, np.float32)}), "mesh0.positions"),
        (lambda h, a: a.update({"mesh0.positions": np.zeros((4, 2), np.float32)}), "mesh0.positions"),
        (lambda h, a: a.update({"mesh0.triangles": np.zeros((2, 3), np.float32)}), "mesh0.triangles"),
        (lambda h, a: a.pop("mesh0.positions"), "mesh0.positions"),
        (lambda h, a: a.update({"mesh0.material_index": np.array([0, 9], np.int32)}), "mesh0.material_index"),
    ],
)
def test_bad_fields_are_named(mutate, field):
    h, a = cornell_box()
    mutate(h, a)
    with pytest.raises(SceneError) as e:
        scene_from_dict(h, a)
    assert e.value.field == field, str(e.value)
    assert field in str(e.value)


def test_truncated_and_foreign_files(tmp_path):
    h, a = cornell_box()
    good = tmp_path / "good.npz"
    save_scene(good, h, a)
    data = good.read_bytes()
    bad = tmp_path / "bad.npz"
    bad.write_bytes(data[: len(data) // 2])
    with pytest.raises(SceneError, match="file|header"):
        load_scene(bad)
    bad.write_bytes(b"not a zip at all")
    with pytest.raises(SceneError, match="not a readable scene archive"):
        load_scene(bad)
    with pytest.raises(SceneError, match="does not exist"):
        load_scene(tmp_path / "missing.npz")


def test_pickled_arrays_are_refused(tmp_path):
    path = tmp_path / "evil.npz"
    np.savez(path, header=np.frombuffer(b"{}", np.uint8), evil=np.array([object()], dtype=object))
    with pytest.raises(SceneError, match="pickle"):
        load_scene(path)


@pytest.mark.parametrize("version", [(1, 0), (2, 0), (3, 0)])
def test_npy_members_of_each_format_version(tmp_path, version):
    """Members in .npy format 1.0 and 2.0 (what numpy writes) are read through numpy's public
    header readers, the same in numpy 1 and 2 (Blender 5.1+); 3.0 is refused by name."""
    import zipfile
    h, a = cornell_box()
    good = tmp_path / "good.npz"
    save_scene(good, h, a)
    path = tmp_path / f"v{version[0]}.npz"
    with zipfile.ZipFile(good) as src, zipfile.ZipFile(path, "w") as dst:
        for info in src.infolist():
            data = src.read(info)
            if info.filename == "mesh0.positions.npy":
                import io
                arr = np.lib.format.read_array(io.BytesIO(data))
                buf = io.BytesIO()
                np.lib.format.write_array(buf, arr, version=version)
                data = buf.getvalue()
            dst.writestr(info.filename, data)
    if version == (3, 0):
        with pytest.raises(SceneError, match=r"mesh0.positions.*format version 3.0"):
            load_scene(path)
    else:
        _, arrays = read_scene_arrays(path)
        assert np.array_equal(arrays["mesh0.positions"], a["mesh0.positions"])


NAN, INF = float("nan"), float("inf")


@pytest.mark.parametrize(
    "mutate, field",
    [
        # unknown or mistyped versions
        (lambda h, a: h.update(version="1"), "version"),
        (lambda h, a: h.update(version=0), "version"),
        (lambda h, a: h.update(version=True), "version"),
        (lambda h, a: h.pop("version"), "version"),
        # a scene needs a camera (the add-on reports "no camera" itself; the core refuses)
        (lambda h, a: h.pop("camera"), "camera"),
        (lambda h, a: h.update(camera=None), "camera"),
        (lambda h, a: h["camera"].pop("matrix_world"), "camera.matrix_world"),
        # negative or zero sizes
        (lambda h, a: h["render"].update(resolution=[-4, 4]), "render.resolution"),
        (lambda h, a: h["render"].update(resolution=[4.5, 4]), "render.resolution"),
        (lambda h, a: h["render"].update(resolution=[65537, 1]), "render.resolution"),
        (lambda h, a: h["render"].update(pixel_aspect=[0, 1]), "render.pixel_aspect"),
        (lambda h, a: h["render"].update(filter={"type": "BOX", "width": -1}), "render.filter.width"),
        (lambda h, a: h["render"].update(shutter=[0.5, -0.5]), "render.shutter"),
        (lambda h, a: h["render"].update(border=[0.5, 0, 0.2, 1]), "render.border"),
        (lambda h, a: h["render"].update(max_bounces=-1), "render.max_bounces"),
        (lambda h, a: h["camera"].update(sensor_width=0), "camera.sensor_width"),
        (lambda h, a: h["camera"].update(clip_start=5.0, clip_end=1.0), "camera.clip_end"),
        (lambda h, a: h["camera"].update(dof={"use": True, "fstop": 0}), "camera.dof.fstop"),
        (lambda h, a: h["camera"].update(dof={"use": True, "focus_distance": -1}), "camera.dof.focus_distance"),
        (lambda h, a: h["lights"][0].update(size=-1), "lights[0].size"),
        (lambda h, a: h["lights"][0].update(size_y=-0.5), "lights[0].size_y"),
        (lambda h, a: h["lights"][0].update(spread=-1), "lights[0].spread"),
        (lambda h, a: h["lights"].append({"type": "POINT", "matrix_world": np.eye(4).tolist(), "radius": -1}), "lights[1].radius"),
        (lambda h, a: h["lights"].append({"type": "SUN", "matrix_world": np.eye(4).tolist(), "angle": -0.1}), "lights[1].angle"),
        (lambda h, a: h["lights"].append({"type": "SPOT", "matrix_world": np.eye(4).tolist(), "spot_size": -1}), "lights[1].spot_size"),
        (lambda h, a: h["materials"][0].update(emission=[-1, 0, 0]), "materials[0].emission"),
        (lambda h, a: h["materials"][0]["lobes"].append({"type": "GLASS", "color": [1, 1, 1], "ior": 0}), "materials[0].lobes[1].ior"),
        (lambda h, a: h["materials"][0]["lobes"].append({"type": "GLOSSY", "color": [1, 1, 1], "roughness": 2}), "materials[0].lobes[1].roughness"),
        # NaN / Inf / numbers too large for a float
        (lambda h, a: h["world"].update(color=[NAN, 0, 0]), "world.color"),
        (lambda h, a: h["lights"][0].update(power=INF), "lights[0].power"),
        (lambda h, a: h["camera"].update(lens=10**400), "camera.lens"),
        (lambda h, a: h["render"].update(spp=10**30), "render.spp"),
        (lambda h, a: h["objects"][0].update(matrix_world=[[INF, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]), "objects[0].matrix_world"),
        (lambda h, a: h["objects"][0].update(matrix_world=[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [1, 0, 0, 1]]), "objects[0].matrix_world"),
        (lambda h, a: h["objects"][0].update(motion={"matrix_open": np.eye(4).tolist()}), "objects[0].motion.matrix_close"),
        # arrays: wrong shapes / counts / values
        (lambda h, a: a.update({"mesh0.normals": np.zeros((2, 3), np.float32)}), "mesh0.normals"),
        (lambda h, a: a.update({"mesh0.uvs": np.full((2, 3, 2), NAN, np.float32)}), "mesh0.uvs"),
        (lambda h, a: a.update({"mesh0.uvs": np.zeros((3, 3, 2), np.float32)}), "mesh0.uvs"),
        (lambda h, a: a.update({"mesh0.material_index": np.zeros(5, np.int32)}), "mesh0.material_index"),
        (lambda h, a: a.update({"mesh0.triangles": np.array([[0, 1, -1]], np.int64)}), "mesh0.triangles"),
        (lambda h, a: a.update({"mesh0.positions": np.zeros((4, 3), np.complex64)}), "mesh0.positions"),
        (lambda h, a: h["meshes"][0].update(deforming=True), "mesh0.positions_close"),
        (lambda h, a: (h["meshes"][0].update(deforming=True), a.update({"mesh0.positions_close": np.zeros((3, 3))})), "mesh0.positions_close"),
    ],
)
def test_more_bad_fields_are_named(mutate, field):
    h, a = cornell_box()
    mutate(h, a)
    with pytest.raises(SceneError) as e:
        scene_from_dict(h, a)
    assert e.value.field == field, str(e.value)
    assert str(e.value).startswith(f"scene field '{field}': ")


def _mesh_scene(noise_floats: bool):
    """A Cornell box plus one big mesh (~3 MB of per-corner floats): smooth values (deflate
    saves most of them) or noise (deflate saves little)."""
    h, a = cornell_box()
    rng = np.random.default_rng(2)
    n = 90_000
    tris = np.arange(3 * n).reshape(n, 3)
    pos = rng.random((3 * n, 3)) if noise_floats else np.repeat(np.linspace(0, 1, n), 9).reshape(3 * n, 3)
    k = len(h["meshes"])
    h["meshes"].append({"name": "big", "deforming": False})
    h["objects"].append({"name": "big", "mesh": k, "matrix_world": np.eye(4).tolist(), "motion": None})
    a[f"mesh{k}.positions"] = pos.astype(np.float32)
    a[f"mesh{k}.triangles"] = tris.astype(np.int32)
    a[f"mesh{k}.material_index"] = np.zeros(n, np.int32)
    normals = rng.normal(size=(n, 3, 3)) if noise_floats else np.tile([0.0, 0.0, 1.0], (n, 3, 1))
    a[f"mesh{k}.normals"] = normals.astype(np.float32)
    return h, a, k


@pytest.mark.parametrize("noise", [False, True])
def test_big_members_that_deflate_poorly_are_stored(tmp_path, noise):
    """Big members whose deflate saving is under STORE_BELOW_SAVING are stored (read as a copy,
    no inflating); smooth ones and small ones stay deflated; both read back exactly, also by
    np.load (the file is still a plain .npz)."""
    import zipfile

    from drt import scene_file

    h, a, k = _mesh_scene(noise)
    path = tmp_path / "big.npz"
    save_scene(path, h, a)
    methods = {i.filename[:-4]: i.compress_type for i in zipfile.ZipFile(path).infolist()}
    big = zipfile.ZIP_STORED if noise else zipfile.ZIP_DEFLATED
    assert methods[f"mesh{k}.normals"] == big and methods[f"mesh{k}.positions"] == big
    assert methods["mesh0.positions"] == zipfile.ZIP_DEFLATED  # small: always deflated
    assert methods[f"mesh{k}.material_index"] == zipfile.ZIP_DEFLATED  # big but all zeros
    saving = scene_file._deflate_saving(memoryview(a[f"mesh{k}.normals"].reshape(-1).view(np.uint8)))
    assert (saving < scene_file.STORE_BELOW_SAVING) == noise
    _, arrays = read_scene_arrays(path)
    with np.load(path) as z:
        for name, v in a.items():
            assert np.array_equal(arrays[name], v) and arrays[name].dtype == v.dtype, name
            assert np.array_equal(z[name], v), name
    save_scene(tmp_path / "plain.npz", h, a, compress=False)
    assert {i.compress_type for i in zipfile.ZipFile(tmp_path / "plain.npz").infolist()} == {zipfile.ZIP_STORED}


def test_threaded_read_equals_serial_read(tmp_path, monkeypatch):
    """Members of at least PARALLEL_MIN_BYTES inflate on worker threads: same arrays, same
    order of the dict, also for a Fortran-ordered member."""
    from drt import scene_file

    h, a, k = _mesh_scene(False)
    a[f"mesh{k}.normals"] = np.asfortranarray(a[f"mesh{k}.normals"])
    path = tmp_path / "big.npz"
    np.savez_compressed(path, header=scene_file.encode_header(h), **a)  # keeps Fortran order
    monkeypatch.setattr(scene_file.os, "cpu_count", lambda: 4)
    _, threaded = read_scene_arrays(path)
    monkeypatch.setattr(scene_file, "PARALLEL_MIN_BYTES", 1 << 40)
    _, serial = read_scene_arrays(path)
    assert list(threaded) == list(serial)
    for name, v in a.items():
        assert np.array_equal(threaded[name], v) and np.array_equal(serial[name], v), name
    assert sum(v.nbytes >= (1 << 20) for v in a.values()) >= 2  # the threaded path ran
