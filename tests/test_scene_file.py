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
