"""Denoising (drt.denoise, render/merge --denoise, the add-on's Denoise setting).

Needs pyoidn (the denoise extra, part of the test extra); the add-on test needs bpy.
"""

import os
import sys
from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("pyoidn")

from drt import denoise as dn  # noqa: E402
from drt.bench import rel_mse  # noqa: E402
from drt.cli import main  # noqa: E402
from drt.exr import film_from_exr, read_exr  # noqa: E402
from drt.render import render  # noqa: E402
from drt.scene import scene_from_dict  # noqa: E402
from drt.scene_file import load_scene, save_scene  # noqa: E402
from failure_scenes import veach_scene  # noqa: E402
from scene_builders import cornell_box  # noqa: E402

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SHIPPED_BOX = os.path.join(REPO, "blend_scenes", "cornell_box.npz")


@pytest.fixture(scope="module")
def box_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("scenes") / "box.npz"
    save_scene(path, *cornell_box(32, 24, 8))
    return path


def test_denoised_shipped_scene_is_closer_to_the_converged_reference():
    scene = load_scene(SHIPPED_BOX)
    scene.render = replace(scene.render, width=64, height=64)
    ref = render(scene, spp=256, seed=101).combined
    noisy = render(scene, spp=4, seed=0)
    den, info = dn.denoise_film(noisy)
    err_noisy, err_den = rel_mse(noisy.combined, ref), rel_mse(den, ref)
    # measured: noisy ≈ 0.12, denoised ≈ 0.008 (half of it the 256-spp reference's own noise)
    assert err_den < 0.25 * err_noisy, (err_noisy, err_den)
    assert den.shape == (64, 64, 3) and den.dtype == np.float32
    assert info.prefilter == "ACCURATE" and info.quality == "HIGH" and info.replaced_pixels == 0
    # every prefilter and quality runs and helps
    for prefilter in dn.PREFILTERS:
        for quality in dn.QUALITIES:
            assert rel_mse(dn.denoise(noisy.combined, noisy.albedo, noisy.normal, prefilter=prefilter,
                                      quality=quality), ref) < 0.5 * err_noisy


def test_noisy_layer_is_bit_identical_to_the_render_without_denoise(box_file, tmp_path, capsys):
    plain, den = tmp_path / "plain.exr", tmp_path / "den.exr"
    common = ["--spp", "4", "--seed", "5", "--threads", "2"]
    assert main(["render", str(box_file), "-o", str(plain)] + common) == 0
    assert main(["render", str(box_file), "-o", str(den), "--denoise", "--denoise-quality", "balanced"] + common) == 0
    assert "denoised (balanced, prefilter accurate)" in capsys.readouterr().out
    p, _ = read_exr(plain)
    d, meta = read_exr(den)
    for c in "RGBA":
        assert np.array_equal(d[f"Noisy.{c}"], p[c]), c
    for name in p:  # everything but the colour is the plain render's
        if name not in "RGB":
            assert np.array_equal(d[name], p[name]), name
    assert not np.array_equal(d["R"], p["R"])
    assert "quality BALANCED" in meta["denoised"] and "prefilter ACCURATE" in meta["denoised"]
    # reading a denoised file back gives the Monte Carlo film (for merging), not the denoised image
    f = film_from_exr(den)
    assert np.array_equal(f.combined[..., 0], p["R"]) and "denoised" not in f.meta


def test_denoise_runs_once_on_the_merged_image(box_file, tmp_path):
    full, a, b, merged, merged_plain = (tmp_path / f"{n}.exr" for n in ("full", "a", "b", "m", "mp"))
    common = ["--spp", "8", "--threads", "2", "--seed", "3"]
    assert main(["render", str(box_file), "-o", str(full), "--denoise"] + common) == 0
    assert main(["render", str(box_file), "-o", str(a), "--sample-count", "3"] + common) == 0
    assert main(["render", str(box_file), "-o", str(b), "--sample-offset", "3"] + common) == 0
    assert main(["merge", str(a), str(b), "-o", str(merged), "--denoise"]) == 0
    assert main(["merge", str(a), str(b), "-o", str(merged_plain)]) == 0
    f, m, mp = read_exr(full)[0], read_exr(merged)[0], read_exr(merged_plain)[0]
    for c in "RGBA":
        assert np.array_equal(m[f"Noisy.{c}"], mp[c])
    # exactly one denoise, of the merged film (OIDN is deterministic on the CPU)
    once = dn.denoise_film(film_from_exr(merged_plain))[0]
    assert np.array_equal(np.stack([m[c] for c in "RGB"], -1), once)
    # and close to denoising the unsplit render (not equal: a merged EXR's normals are the
    # count-weighted mean of each part's unit normals, which differs at silhouettes)
    den_full, den_merged = (np.stack([x[c] for c in "RGB"], -1) for x in (f, m))
    noisy_full = np.stack([f[f"Noisy.{c}"] for c in "RGB"], -1)
    assert rel_mse(den_merged, den_full) < 0.05 * rel_mse(noisy_full, den_full)
    # a sample range cannot be denoised on its own: the denoiser is not linear
    assert main(["render", str(box_file), "-o", str(tmp_path / "x.exr"), "--sample-count", "3", "--denoise"] + common) == 2
    assert not (tmp_path / "x.exr").exists()


def test_nan_and_inf_never_reach_oidn(monkeypatch):
    """A firefly scene (Veach's plates: small bright lights seen in glossy plates, BSDF-sampled
    paths that find them are fireflies), with NaN, ±Inf, negative and huge pixels written into
    its image: OIDN only ever sees finite, non-negative colour, and returns a finite image."""
    film = render(scene_from_dict(*veach_scene(32, 24, 4)), spp=4, seed=0, direct="BSDF")
    color = film.combined.copy()
    lum = color[..., :3].max(axis=-1)
    assert lum.max() > 100 * max(np.percentile(lum, 90), 1e-3), np.sort(lum.ravel())[-5:]  # fireflies
    color[3, 4, 0] = np.nan
    color[10, 10, :3] = np.inf
    color[11, 10, 1] = -np.inf
    color[20, 5, 2] = -3.0
    color[0, 0, :3] = 1e38  # finite but beyond what float32 sums tolerate
    seen = []
    backend = dn._backend(None, None)
    real_run = backend.run

    def spy(images, bools, quality):
        seen.append({k: v.copy() for k, v in images.items() if k != "output"})
        real_run(images, bools, quality)

    monkeypatch.setattr(backend, "run", spy)
    out, info = dn.denoise(color, film.albedo, film.normal, return_info=True)
    assert len(seen) == 3  # ACCURATE: albedo, normal, then colour
    for images in seen:
        for name, img in images.items():
            assert np.all(np.isfinite(img)), name
    col = seen[-1]["color"]
    assert col.min() >= 0.0
    assert info.replaced_pixels == 3
    # a filled pixel is the mean of its finite neighbours
    nb = color[2:5, 3:6, 0].astype(np.float64)
    mask = np.ones((3, 3), bool)
    mask[1, 1] = False
    assert col[3, 4, 0] == pytest.approx(nb[mask].mean(), rel=1e-5)
    assert np.all(np.isfinite(out))
    # the input was not modified
    assert np.isnan(color[3, 4, 0])


def test_sanitize_and_settings_errors():
    c, a, n, k = dn.sanitize(np.full((2, 2, 3), np.nan), np.full((2, 2, 3), 7.0), np.full((2, 2, 3), -np.inf))
    assert k == 4 and np.all(c == 0) and np.all(a == 1) and np.all(n == 0)
    with pytest.raises(ValueError, match="prefilter"):
        dn.denoise(np.zeros((4, 4, 3)), prefilter="SOMETIMES")
    with pytest.raises(ValueError, match="quality"):
        dn.denoise(np.zeros((4, 4, 3)), quality="ULTRA")
    with pytest.raises(ValueError, match="does not match"):
        dn.denoise(np.zeros((4, 4, 3)), np.zeros((4, 5, 3)))


def test_missing_binding_fails_before_any_work(box_file, tmp_path, monkeypatch, capsys):
    import drt.cli as cli

    monkeypatch.setitem(sys.modules, "pyoidn", None)  # `import pyoidn` now raises ImportError
    monkeypatch.setattr(dn, "_backends", {})

    def no_work(*args, **kwargs):
        raise AssertionError("work started before the denoiser was checked")

    monkeypatch.setattr(cli, "_load", no_work)
    monkeypatch.setattr(cli, "film_from_exr", no_work, raising=False)
    out = tmp_path / "x.exr"
    assert main(["render", str(box_file), "-o", str(out), "--denoise"]) == 2
    assert main(["merge", str(tmp_path / "a.exr"), "-o", str(out), "--denoise"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all(e.startswith("drt: error: denoising needs Open Image Denoise") for e in err)
    assert "pyoidn" in err[0] and "[denoise]" in err[0]
    assert not out.exists()
    with pytest.raises(dn.DenoiserUnavailable):
        dn.denoise(np.zeros((4, 4, 3)))
    # settings without --denoise are a mistake, not silently ignored
    assert main(["render", str(box_file), "-o", str(out), "--denoise-quality", "fast"]) == 2


@pytest.mark.blender
def test_blender_render_with_denoising(tmp_path):
    bpy = pytest.importorskip("bpy")
    if REPO not in sys.path:
        sys.path.insert(0, REPO)
    import addon
    from addon import denoising

    if not hasattr(bpy.types.Scene, "drt"):
        addon.register()
    bpy.ops.wm.open_mainfile(filepath=os.path.join(REPO, "blend_scenes", "cornell_box.blend"))
    scene = bpy.context.scene
    scene.drt.samples = 4
    scene.drt.use_denoising = True
    vl = scene.view_layers[0]
    vl.use_pass_diffuse_color = True
    vl.use_pass_normal = True
    vl.cycles.denoising_store_passes = True  # the view layer's Denoising Data flag, as for Cycles
    assert denoising.blender_oidn_library() is not None  # Blender's own OIDN, not the wheel
    scene.render.filepath = str(tmp_path / "den.exr")
    fmt = scene.render.image_settings
    if hasattr(fmt, "media_type"):
        fmt.media_type = "MULTI_LAYER_IMAGE"
    fmt.file_format = "OPEN_EXR_MULTILAYER"
    fmt.color_depth = "32"
    bpy.ops.render.render(write_still=True)
    import OpenEXR

    with OpenEXR.File(str(tmp_path / "den.exr")) as f:
        ch = {k: np.array(v.pixels) for part in f.parts for k, v in part.channels.items()}

    def get(pass_name):  # "ViewLayer.Combined" is (h, w, 4); vectors come as .X/.Y/.Z channels
        key = f"{vl.name}.{pass_name}"
        if key in ch:
            return ch[key]
        parts = [ch[f"{key}.{a}"] for a in "XYZ" if f"{key}.{a}" in ch]
        return np.stack(parts, axis=-1) if len(parts) > 1 else parts[0]

    combined, noisy = get("Combined"), get("Noisy Image")
    assert combined.shape == noisy.shape == (96, 96, 4)
    assert np.all(np.isfinite(combined))
    assert np.abs(combined[..., :3] - noisy[..., :3]).mean() > 1e-3  # denoised differs from the noisy pass
    assert np.array_equal(combined[..., 3], noisy[..., 3])  # alpha is the film's
    from addon import compat

    albedo, normal = get(compat.pass_name("DiffCol")), get("Normal")
    dalbedo, dnormal = get("Denoising Albedo"), get("Denoising Normal")
    # the guide is DRT's albedo; in this all-Lambert box it equals Cycles's Diffuse Color pass
    np.testing.assert_array_equal(dalbedo, albedo)
    assert dalbedo.max() > 0.5
    lengths = np.linalg.norm(dnormal, axis=-1)
    hit = get("Denoising Depth") < 1e9
    assert hit.mean() > 0.3
    assert np.all(np.abs(lengths[hit] - 1) < 1e-3) and np.all(lengths[~hit] == 0)  # unit normals on surfaces
    assert np.abs(np.linalg.norm(normal, axis=-1) - lengths).max() < 1e-4  # same normals, rotated
    # the back wall faces the camera: camera-space +Z (toward the viewer)
    assert dnormal[48, 48, 2] > 0.9, dnormal[48, 48]
    assert get("Denoising Depth").min() > 1.0  # the camera is 2.9 m from the open front of the box
    # Blender's own OIDN (2.3 in bpy 5.0) gives what the CLI's pyoidn gives on the same passes
    again = dn.denoise(noisy, albedo, normal)
    np.testing.assert_allclose(again, combined[..., :3], atol=2e-3)


def test_bench_denoised_curve(box_file, tmp_path):
    import json

    out = tmp_path / "bench"
    assert main(["bench", str(box_file), "-o", str(out), "--reference-spp", "64", "--spp-list", "1", "4",
                 "--methods", "mis_power", "--denoise", "--no-chart", "--threads", "2"]) == 0
    rows = json.loads((out / "bench.json").read_text())["rows"]
    by = {(r["method"], r["spp"]): r for r in rows}
    assert set(by) == {("mis_power", 1), ("mis_power", 4), ("mis_power+oidn", 1), ("mis_power+oidn", 4)}
    for spp in (1, 4):
        den, noisy = by[("mis_power+oidn", spp)], by[("mis_power", spp)]
        assert den["relmse"] < noisy["relmse"] and den["seconds"] > noisy["seconds"]
    assert main(["bench", str(box_file), "-o", str(out), "--point", "--denoise"]) == 2


@pytest.mark.blender
def test_blender_without_a_denoiser_reports_before_rendering(monkeypatch):
    bpy = pytest.importorskip("bpy")
    if REPO not in sys.path:
        sys.path.insert(0, REPO)
    import addon
    from addon import denoising
    from addon import engine as drt_engine

    if not hasattr(bpy.types.Scene, "drt"):
        addon.register()
    bpy.ops.wm.open_mainfile(filepath=os.path.join(REPO, "blend_scenes", "cornell_box.blend"))
    bpy.context.scene.drt.use_denoising = True
    monkeypatch.setattr(denoising, "blender_oidn_library", lambda: None)
    monkeypatch.setitem(sys.modules, "pyoidn", None)
    monkeypatch.setattr(dn, "_backends", {})

    def no_export(*args, **kwargs):
        raise AssertionError("exported before the denoiser was checked")

    monkeypatch.setattr(drt_engine, "export_depsgraph", no_export)
    with pytest.raises(RuntimeError, match="DRT: denoising needs Open Image Denoise"):
        bpy.ops.render.render()
