"""The command line on .blend files (through the bpy module and the add-on's exporter)."""

import os

import numpy as np
import pytest

pytest.importorskip("bpy")

from drt.cli import main  # noqa: E402
from drt.exr import read_exr  # noqa: E402
from drt.scene_file import load_scene  # noqa: E402

SCENES = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "blend_scenes")


def test_render_and_export_a_blend(tmp_path):
    out = tmp_path / "box.exr"
    assert main(["render", os.path.join(SCENES, "cornell_box.blend"), "-o", str(out), "--spp", "2"]) == 0
    ch, _ = read_exr(out)
    assert ch["R"].shape == (96, 96) and np.isfinite(ch["R"]).all() and ch["R"].mean() > 0.05
    npz = tmp_path / "dof.npz"
    assert main(["export", os.path.join(SCENES, "dof.blend"), "-o", str(npz)]) == 0
    scene = load_scene(npz)
    assert scene.camera.dof_use and scene.triangle_count > 0


def test_unreadable_blend_is_a_one_line_error(tmp_path, capsys):
    bad = tmp_path / "bad.blend"
    bad.write_bytes(b"not a blend file")
    assert main(["render", str(bad), "-o", str(tmp_path / "x.exr")]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith("drt: error: cannot read")
