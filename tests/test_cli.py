"""The command line: renders, merges split sample ranges exactly, fails with one-line errors."""

import subprocess
import sys

import numpy as np
import pytest

from drt.cli import main
from drt.exr import film_from_exr, read_exr
from drt.scene_file import save_scene
from scene_builders import cornell_box


@pytest.fixture(scope="module")
def box_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("scenes") / "box.npz"
    save_scene(path, *cornell_box(24, 16, 8))
    return path


def test_render_writes_all_channels(box_file, tmp_path, capsys):
    out = tmp_path / "box.exr"
    assert main(["render", str(box_file), "-o", str(out), "--spp", "4", "--threads", "1"]) == 0
    ch, meta = read_exr(out)
    assert {"R", "G", "B", "A", "Z", "Normal.X", "Albedo.R", "SampleCount.Y", "Variance.Y"} <= set(ch)
    assert ch["R"].shape == (16, 24)
    assert np.all(ch["SampleCount.Y"] == 4)
    assert meta["sample_count"] == "4" and meta["spp"] == "4"
    summary = capsys.readouterr().out
    assert "rendered 24x16 at 4 spp" in summary and "Mrays/s" in summary


def test_split_sample_ranges_merge_to_the_full_render(box_file, tmp_path):
    full, a, b, merged = (tmp_path / f"{n}.exr" for n in ("full", "a", "b", "merged"))
    common = ["--spp", "12", "--threads", "2", "--seed", "3"]
    assert main(["render", str(box_file), "-o", str(full)] + common) == 0
    assert main(["render", str(box_file), "-o", str(a), "--sample-offset", "0", "--sample-count", "5"] + common) == 0
    assert main(["render", str(box_file), "-o", str(b), "--sample-offset", "5", "--sample-count", "7"] + common) == 0
    assert main(["merge", str(a), str(b), "-o", str(merged)]) == 0
    f, m = film_from_exr(full), film_from_exr(merged)
    np.testing.assert_allclose(m.combined, f.combined, rtol=1e-6, atol=1e-7)
    assert np.array_equal(m.count, f.count)
    # overlapping ranges are refused: they would count samples twice
    assert main(["merge", str(a), str(a), "-o", str(merged)]) == 2


@pytest.mark.parametrize(
    "args, message",
    [
        (["render", "missing.npz", "-o", "x.exr"], "scene file not found"),
        (["render", "{box}", "-o", "/no/such/dir/x.exr"], "output directory does not exist"),
        (["render", "{box}", "-o", "x.png"], "output must end in .exr"),
        (["render", "{box}", "-o", "{tmp}/x.exr", "--sample-offset", "9", "--spp", "4"], "must be below"),
        (["render", "{bad}", "-o", "{tmp}/x.exr"], "invalid scene"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(args, message, box_file, tmp_path, capsys):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"garbage")
    args = [a.format(box=box_file, tmp=tmp_path, bad=bad) for a in args]
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("drt: error:") and message in err and "\n" not in err


def test_bad_arguments_exit_2_without_traceback(box_file):
    r = subprocess.run([sys.executable, "-m", "drt", "render", str(box_file), "-o", "x.exr", "--spp", "0"],
                       capture_output=True, text=True)
    assert r.returncode == 2 and "Traceback" not in r.stderr and "must be at least 1" in r.stderr
