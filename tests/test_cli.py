"""The command line: renders, merges split sample ranges exactly, fails with one-line errors."""

import math
import os
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


# --- newcomer friction (issue 12, section 2) ----------------------------------------------------


def _one_line_error(capsys, message):
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("drt: error:") and message in err, err
    return err


@pytest.mark.parametrize("argv, message", [
    (["render", "{box}", "-o", "{tmp}/x.exr", "--sampler", "nope"], "invalid choice 'nope'"),
    (["render", "{box}"], "the following arguments are required: -o/--output"),
    (["render", "{box}", "-o", "{tmp}/x.exr", "--resolution", "big"], "expected WIDTHxHEIGHT"),
    (["frobnicate"], "invalid choice"),
    ([], "the following arguments are required"),
])
def test_argparse_errors_are_one_line(argv, message, box_file, tmp_path, capsys):
    argv = [a.format(box=box_file, tmp=tmp_path) for a in argv]
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2
    _one_line_error(capsys, message)
    assert not list(tmp_path.iterdir())


def test_sampler_names_in_any_case(box_file, tmp_path):
    for name in ("sobol", "SOBOL", "Stratified"):
        assert main(["render", str(box_file), "-o", str(tmp_path / "x.exr"), "--spp", "1",
                     "--sampler", name, "--direct", "Mis_Power", "--indirect", "BSDF"]) == 0


def test_a_directory_as_the_scene_says_so(tmp_path, capsys):
    assert main(["render", str(tmp_path), "-o", str(tmp_path / "x.exr")]) == 2
    _one_line_error(capsys, "is a directory")


def test_png_to_a_missing_folder_fails_before_rendering(box_file, tmp_path, capsys, monkeypatch):
    import drt.render

    monkeypatch.setattr(drt.render, "render", lambda *a, **k: pytest.fail("rendered before checking --png"))
    out = tmp_path / "x.exr"
    assert main(["render", str(box_file), "-o", str(out), "--png", str(tmp_path / "no" / "x.png")]) == 2
    _one_line_error(capsys, "output directory does not exist")
    assert main(["render", str(box_file), "-o", str(out), "--png", str(tmp_path / "x.jpg")]) == 2
    _one_line_error(capsys, "must end in .png")
    assert not out.exists()


def test_png_preview_needs_no_extra_package(box_file, tmp_path):
    """The PNG is written without Pillow and decodes to the EXR's pixels through sRGB."""
    import zlib

    from drt.preview import linear_to_srgb

    out, png = tmp_path / "x.exr", tmp_path / "x.png"
    assert main(["render", str(box_file), "-o", str(out), "--spp", "2", "--png", str(png)]) == 0
    data = png.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and data[12:16] == b"IHDR"
    w, h = int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")
    assert (w, h) == (24, 16)
    idat = data.index(b"IDAT")
    length = int.from_bytes(data[idat - 4:idat], "big")
    rows = np.frombuffer(zlib.decompress(data[idat + 4:idat + 4 + length]), np.uint8).reshape(h, 1 + 3 * w)
    assert np.all(rows[:, 0] == 0)
    pixels = rows[:, 1:].reshape(h, w, 3)
    ch, _ = read_exr(out)
    rgb = np.stack([ch["R"], ch["G"], ch["B"]], -1)
    expected = (linear_to_srgb(rgb.astype(np.float64)) * 255 + 0.5).astype(np.uint8)
    assert np.array_equal(pixels, expected)


def test_a_film_too_big_for_memory_is_refused_before_rendering(box_file, tmp_path, capsys):
    out = tmp_path / "x.exr"
    assert main(["render", str(box_file), "-o", str(out), "--resolution", "65536x65536"]) == 2
    err = _one_line_error(capsys, "render needs")
    assert "GB of memory" in err and "--resolution" in err
    assert not out.exists()


def test_frame_is_refused_for_an_npz(box_file, tmp_path, capsys):
    assert main(["render", str(box_file), "-o", str(tmp_path / "x.exr"), "--frame", "3"]) == 2
    _one_line_error(capsys, "--frame applies to animated scene files")


def test_adaptive_summary_reports_mean_and_range(box_file, tmp_path, capsys):
    from drt.exr import read_exr as read

    out = tmp_path / "x.exr"
    assert main(["render", str(box_file), "-o", str(out), "--spp", "64", "--adaptive-threshold", "0.2",
                 "--adaptive-min-samples", "4"]) == 0
    summary = capsys.readouterr().out
    counts = read(out)[0]["SampleCount.Y"]
    assert counts.min() < counts.max() == 64
    assert f"{counts.mean():.1f} spp mean ({int(counts.min())}-64 per pixel)" in summary


def test_cancelled_summary_reports_what_the_film_holds():
    from drt.cli import spp_summary
    from drt.render import RenderStats

    st = RenderStats(samples_done=8, spp_min=8, spp_mean=11.5, spp_max=16)
    assert spp_summary(st) == "11.5 spp mean (8-16 per pixel)"
    assert spp_summary(RenderStats(spp_min=16, spp_mean=16.0, spp_max=16)) == "16 spp"


def test_cancel_mid_pass_stats_match_the_film(box_file):
    """A cancel inside a pass leaves some pixels with more samples: stats say what the film holds."""
    from drt.render import render
    from drt.scene import scene_from_dict

    scene = scene_from_dict(*cornell_box(128, 128, 16))  # two batches per pass
    batches = []
    film = render(scene, spp=16, threads=1, tick=lambda f, s: batches.append(f),
                  cancel=lambda: len(batches) >= 7)
    held = film.count
    st = film.stats
    assert st.cancelled
    assert (st.spp_min, st.spp_max) == (int(held.min()), int(held.max()))
    assert st.spp_mean == pytest.approx(held.mean())


def test_eta_extrapolates_from_measured_batches_not_setup():
    """10 s of setup, then 10 % of the work per second: 8 s left at 20 %, not 44 s."""
    from drt.cli import Progress

    now = [10.0]
    bar = Progress(stream=open(os.devnull, "w"), clock=lambda: now[0])
    assert math.isnan(bar.eta(0.1))
    now[0] = 11.0
    assert bar.eta(0.2) == pytest.approx(8.0)
    bar.stream.close()


def test_background_depth_is_blenders_1e10():
    """Cycles writes 1e10 in the Z pass where nothing was hit (measured with bpy 5.0)."""
    from drt.film import BACKGROUND_DEPTH, Film, SampleBatch

    film = Film(2, 1)
    film.add(SampleBatch(pixel=np.array([0, 1]), radiance=np.zeros((2, 3)), alpha=np.zeros(2),
                         depth=np.array([2.5, np.inf]), normal=np.zeros((2, 3)), albedo=np.zeros((2, 3))))
    assert BACKGROUND_DEPTH == 1e10
    assert film.depth.tolist() == [[2.5, 1e10]]


def test_console_script_name_in_usage(monkeypatch, capsys):
    monkeypatch.setattr(sys, "argv", ["/usr/local/bin/drt", "render", "--help"])
    with pytest.raises(SystemExit):
        main(["render", "--help"])
    assert capsys.readouterr().out.startswith("usage: drt render")
    monkeypatch.setattr(sys, "argv", ["/x/drt/__main__.py"])
    with pytest.raises(SystemExit):
        main(["render", "--help"])
    assert capsys.readouterr().out.startswith("usage: python -m drt render")


def test_help_speaks_the_users_language(capsys):
    for command in ("render", "bench", "merge", "export"):
        with pytest.raises(SystemExit):
            main([command, "--help"])
        text = capsys.readouterr().out
        assert "lecture" not in text and "Pillow" not in text


class _Exited(Exception):
    pass


@pytest.mark.parametrize("loaded, fast", [((), True), (("distributed",), False), (("bpy",), False)])
def test_run_leaves_without_teardown_unless_a_module_needs_it(monkeypatch, capsys, loaded, fast):
    """``drt.cli.run`` (the ``drt`` / ``python -m drt`` entry) exits with ``main``'s code through
    ``os._exit`` after flushing its output — skipping the interpreter's slow teardown — but through
    ``sys.exit`` (exit handlers run) when Dask or Blender was loaded."""
    import drt.cli as cli

    def fake_main():
        print("rendered")
        return 3

    calls = []

    def fake_exit(code):
        calls.append(code)
        raise _Exited

    monkeypatch.setattr(cli, "main", fake_main)
    monkeypatch.setattr(cli.os, "_exit", fake_exit)
    for name in cli._NEEDS_TEARDOWN:
        monkeypatch.delitem(sys.modules, name, raising=False)
    for name in loaded:
        monkeypatch.setitem(sys.modules, name, object())
    if fast:
        with pytest.raises(_Exited):
            cli.run()
        assert calls == [3]
    else:
        with pytest.raises(SystemExit) as info:
            cli.run()
        assert info.value.code == 3 and calls == []
    assert capsys.readouterr().out == "rendered\n"


def test_module_entry_point_writes_its_output_and_exit_code(box_file, tmp_path):
    """``python -m drt`` leaves at once after the render, with its file complete and its exit
    code kept (0, then 2 for a missing scene)."""
    out = tmp_path / "box.exr"
    done = subprocess.run([sys.executable, "-m", "drt", "render", str(box_file), "-o", str(out), "--spp", "2",
                           "--threads", "1"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert "rendered 24x16 at 2 spp" in done.stdout
    assert read_exr(out)[0]["R"].shape == (16, 24)
    bad = subprocess.run([sys.executable, "-m", "drt", "render", str(tmp_path / "none.npz"), "-o", str(out)],
                         capture_output=True, text=True)
    assert bad.returncode == 2 and "not found" in bad.stderr


_BLAS_PROBE = """
import os, sys
import drt.cli
drt.cli._single_threaded_blas()
import numpy
threads = [ln.split()[1] for ln in open("/proc/self/status") if ln.startswith("Threads:")]
print(os.environ.get("OPENBLAS_NUM_THREADS"), threads[0] if threads else "?")
"""


@pytest.mark.skipif(not os.path.exists("/proc/self/status"), reason="reads the thread count from /proc")
def test_the_cli_starts_numpy_with_a_single_threaded_blas():
    """The CLI asks for a one-thread BLAS before numpy starts its pool (the renderer calls no
    BLAS; OpenBLAS's per-core threads cost every process ~0.1 s of system time), and keeps a
    size the user set."""
    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}
    done = subprocess.run([sys.executable, "-c", _BLAS_PROBE], capture_output=True, text=True, env=env)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["1", "1"]  # the variable, and the process's only thread
    done = subprocess.run([sys.executable, "-c", _BLAS_PROBE], capture_output=True, text=True,
                          env={**env, "OPENBLAS_NUM_THREADS": "2"})
    assert done.stdout.split()[0] == "2"
