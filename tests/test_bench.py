"""The bench: metrics, time-to-error interpolation, method parsing, and a tiny end-to-end run
of ``python -m drt bench`` on an analytic scene (Cycles and charts are exercised in the slow
test, which needs bpy and a shipped .blend)."""

import json
import math
import os

import numpy as np
import pytest

from drt import bench
from drt.cli import main
from drt.scene_file import save_scene
from scene_builders import cornell_box

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_metrics():
    ref = np.ones((2, 2, 4))
    x = ref.copy()
    x[0, 0, :3] = 2.0
    assert math.isclose(bench.rmse(x, ref), math.sqrt(3 / 12))
    assert math.isclose(bench.rel_mse(x, ref), (3 / 1.01) / 12)
    # black reference pixels are weighted by 1/0.01, not infinity
    assert math.isclose(bench.rel_mse(np.full((1, 1, 3), 0.1), np.zeros((1, 1, 3))), 1.0)


def test_time_to_reach_interpolates_and_extrapolates():
    t, extra = bench.time_to_reach([1, 4], [0.04, 0.01 / 4])
    assert not extra and math.isclose(t, 2.0)
    t, extra = bench.time_to_reach([1, 2], [1.0, 0.5])  # slope −1: 0.01 at t = 100
    assert extra and math.isclose(t, 100.0)
    assert bench.time_to_reach([1, 2], [1.0, 2.0]) == (None, False)
    assert bench.time_to_reach([3, 1], [0.001, 0.005]) == (1.0, False)  # already below at the first point


def test_parse_method():
    assert bench.parse_method("light") == ("LIGHT", "BSDF", "SOBOL", 0.0)
    assert bench.parse_method("bsdf/cosine/random") == ("BSDF", "COSINE", "RANDOM", 0.0)
    assert bench.parse_method("MIS_POWER/BSDF/SOBOL/0.05")[3] == 0.05
    with pytest.raises(ValueError, match="sampler"):
        bench.parse_method("LIGHT/BSDF/HALTON")
    with pytest.raises(ValueError, match="unknown method"):
        bench.parse_method("fast")


def test_bench_command_end_to_end(tmp_path):
    h, a = cornell_box(12, 12, 4)
    h["render"]["max_bounces"] = 2
    path = tmp_path / "box.npz"
    save_scene(path, h, a)
    out = tmp_path / "out"
    code = main(["bench", str(path), "-o", str(out), "--reference-spp", "32", "--spp-list", "1", "4",
                 "--methods", "mis_power", "light/cosine/random", "--threads", "1", "--cycles", "--no-chart"])
    assert code == 0
    rows = (out / "bench.csv").read_text().splitlines()
    assert rows[0].split(",") == ["renderer", "method", "spp", "mean_spp", "seconds", "rmse", "relmse"]
    assert len(rows) == 1 + 4
    summary = json.loads((out / "bench.json").read_text())
    assert set(summary["time_to_relmse_0.01"]) == {"mis_power", "light/cosine/random"}
    assert summary["cycles"].startswith("skipped")  # an .npz with no .blend beside it
    rel = {(r["method"], r["spp"]): r["relmse"] for r in summary["rows"]}
    assert rel[("mis_power", 4)] < rel[("mis_power", 1)]


def test_bench_command_rejects_bad_input(tmp_path, capsys):
    assert main(["bench", str(tmp_path / "missing.npz"), "-o", str(tmp_path / "o")]) == 2
    h, a = cornell_box(8, 8, 4)
    path = tmp_path / "box.npz"
    save_scene(path, h, a)
    assert main(["bench", str(path), "-o", str(tmp_path / "o"), "--methods", "nope"]) == 2
    assert "unknown method" in capsys.readouterr().err


@pytest.mark.slow
def test_bench_with_cycles_on_the_shipped_cornell_box(tmp_path):
    pytest.importorskip("bpy")
    pytest.importorskip("matplotlib")
    scene = os.path.join(ROOT, "blend_scenes", "cornell_box.npz")
    if not os.path.exists(scene) or not os.path.exists(scene[:-4] + ".blend"):
        pytest.skip("shipped cornell_box scene not built")
    summary = bench.bench(scene, str(tmp_path), methods=["mis_power"], spp_list=[4, 16], reference_spp=128,
                          cycles=True, threads=2, resolution=(32, 32))
    assert (tmp_path / "bench.png").exists()
    assert summary["time_to_relmse_0.01"]["cycles"]["seconds"] is not None
    # the two converged images agree (same scene, same units)
    assert summary["reference_agreement_relmse"] < 0.05


def test_summary_with_denoised_curves():
    """The Cycles+OIDN 16-spp error is the bar every curve is timed to; denoised curves never
    stand in for the plain DRT/Cycles ratio."""
    R = bench.BenchRow
    rows = [R("mis_power", 4, 1.0, 0, 0.04, 4), R("mis_power", 16, 4.0, 0, 0.01, 16),
            R("mis_power+oidn", 4, 1.2, 0, 0.004, 4), R("mis_power+oidn", 16, 4.2, 0, 0.002, 16),
            R("cycles", 4, 0.5, 0, 0.04, 4, "cycles"), R("cycles", 16, 2.0, 0, 0.01, 16, "cycles"),
            R("cycles+oidn", 4, 1.0, 0, 0.008, 4, "cycles"), R("cycles+oidn", 16, 2.0, 0, 0.004, 16, "cycles")]
    s = bench.summarize(rows)
    bar = s["time_to_cycles_oidn_16spp"]
    assert bar["spp"] == 16 and bar["relmse"] == 0.004
    assert bar["seconds"]["cycles+oidn"] == {"seconds": 2.0, "extrapolated": False}
    assert bar["seconds"]["mis_power+oidn"] == {"seconds": 1.2, "extrapolated": False}
    t = bar["seconds"]["mis_power"]  # slope −1 in log-log: 0.004 at 10 s, beyond the last point
    assert math.isclose(t["seconds"], 10.0) and t["extrapolated"]
    assert s["drt_method_for_ratio"] == "mis_power" and s["best_drt_method"] == "mis_power"
    assert math.isclose(s["drt_over_cycles"], 2.0)


def test_missing_matplotlib_hint_names_a_command_that_works(tmp_path, monkeypatch, capsys):
    """The distribution is drt-renderer (an unrelated `drt` exists on the index): the hint must not
    say `pip install 'drt[bench]'`."""
    import builtins

    real_import = builtins.__import__

    def no_matplotlib(name, *args, **kwargs):
        if name == "matplotlib" or name.startswith("matplotlib."):
            raise ImportError("No module named 'matplotlib'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_matplotlib)
    bench.plot([], str(tmp_path / "bench.png"))
    err = capsys.readouterr().err
    assert "pip install matplotlib" in err and "drt[bench]" not in err
    assert not (tmp_path / "bench.png").exists()
