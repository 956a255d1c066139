"""docs/headless.md's example script, run as written from a folder outside the repository: a
.blend rendered with DRT through the bpy module, the add-on imported as the installed
``drt_blender`` package."""

import os
import re
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("bpy")
pytestmark = pytest.mark.blender

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_documented_headless_script_renders(tmp_path):
    with open(os.path.join(REPO, "docs", "headless.md"), encoding="utf-8") as f:
        blocks = re.findall(r"```python\n(.*?)```", f.read(), re.S)
    assert len(blocks) == 1
    script = tmp_path / "render_with_drt.py"
    script.write_text(blocks[0])
    out = tmp_path / "cornell.exr"
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    p = subprocess.run([sys.executable, str(script), os.path.join(REPO, "blend_scenes", "cornell_box.blend"),
                        str(out), "2"], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-2000:]
    assert f"wrote {out}" in p.stdout
    import OpenEXR

    with OpenEXR.File(str(out)) as f:
        rgba = np.array(f.parts[0].channels["RGBA"].pixels)
    assert rgba.shape == (96, 96, 4) and np.isfinite(rgba).all()
    assert 0.05 < rgba[..., :3].mean() < 1.0
