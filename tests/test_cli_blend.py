"""The command line on .blend files (through the bpy module and the add-on's exporter)."""

import os
import sys

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


def test_blend_is_exported_at_render_levels_like_f12(tmp_path):
    """`drt render/export X.blend` evaluates the scene as F12 does (a render-mode depsgraph): a
    Subdivision Surface with viewport level 0 and render level 2 exports its render level."""
    import bpy

    sys.path.insert(0, SCENES)
    import _common as C

    C.reset()
    ball = C.uv_sphere("Ball", 1.0, (0, 0, 1), C.diffuse("Grey", (0.5, 0.5, 0.5)), segments=8, rings=4)
    coarse = sum(len(p.vertices) - 2 for p in ball.data.polygons)
    subd = ball.modifiers.new("Subd", "SUBSURF")
    subd.levels, subd.render_levels = 0, 2
    C.light("Sun", "SUN", (0, 0, 5), energy=3.0)
    C.camera((0, -5, 1), (0, 0, 1))
    blend = tmp_path / "subd.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    npz = tmp_path / "subd.npz"
    assert main(["export", str(blend), "-o", str(npz)]) == 0
    scene = load_scene(npz)
    # level 2 splits each quad into 16 quads (32 triangles): far more than the viewport's cage
    assert scene.triangle_count >= 10 * coarse
    assert bpy.context.scene.render.engine != "DRT_RENDER_EXPORT"  # the helper engine is gone
    assert not hasattr(bpy.types, "DRT_RENDER_EXPORT")
