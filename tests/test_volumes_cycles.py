"""DRT vs Cycles on the shipped volume scenes at equal samples (issue 14 acceptance: channel
means within 1 %, ≥ 95 % of 16×16 blocks within 3 % or 3σ). Slow: ~1.5 min on 2 cores."""

import os
import subprocess
import sys

import pytest

pytest.importorskip("bpy")

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

pytestmark = [pytest.mark.slow, pytest.mark.blender]


@pytest.mark.parametrize("name", ["volume_fog", "volume_liquid", "volume_world"])
def test_volume_scene_matches_cycles(name, tmp_path):
    blend = os.path.join(REPO, "blend_scenes", f"{name}.blend")
    p = subprocess.run([sys.executable, os.path.join(REPO, "scripts", "compare_volumes.py"), blend,
                        "--spp", "256", "--out", str(tmp_path)], capture_output=True, text=True)
    line = [ln for ln in p.stdout.splitlines() if ln.startswith(name + ":")]
    assert line, p.stdout[-2000:] + p.stderr[-2000:]
    assert p.returncode == 0 and line[-1].endswith("OK"), line[-1]
