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
