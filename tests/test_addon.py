"""The add-on inside Blender (bpy module): registration, F12-style renders, errors, cancel, passes.

Run with the bpy module installed (pip install bpy==5.0.1); skipped otherwise.
"""

import os
import sys
import time

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = os.path.join(REPO, "blend_scenes")
if REPO not in sys.path:
    sys.path.insert(0, REPO)

import addon  # noqa: E402
from addon import compat  # noqa: E402
from addon import engine as drt_engine  # noqa: E402

pytestmark = pytest.mark.blender


class FakeLayout:
    """A panel's layout that records what it draws: ``drawn`` (data, property name) and
    ``props`` the names; a property missing from its data raises AttributeError (a typo would
    otherwise only show in the UI)."""
    use_property_split = use_property_decorate = active = False

    def __init__(self):
        self.drawn = []

    @property
    def props(self):
        return [name for _, name in self.drawn]

    def column(self, **_kw):
        return self

    def prop(self, data, name, **_kw):
        getattr(data, name)
        self.drawn.append((data, name))


def ensure_registered():
    if not hasattr(bpy.types.Scene, "drt"):
        addon.register()


@pytest.fixture
def registered():
    ensure_registered()
    yield


def open_scene(name):
    ensure_registered()
    bpy.ops.wm.open_mainfile(filepath=os.path.join(SCENES, f"{name}.blend"))
    return bpy.context.scene


def read_exr(path):
    import OpenEXR
    with OpenEXR.File(path) as f:
        chans = {k: np.array(v.pixels) for part in f.parts for k, v in part.channels.items()}
        return chans, dict(f.header())


def render_to(scene, path, multilayer=False):
    scene.render.filepath = str(path)
    fmt = scene.render.image_settings
    if hasattr(fmt, "media_type"):  # 5.0: multilayer is a media type
        fmt.media_type = "MULTI_LAYER_IMAGE" if multilayer else "IMAGE"
        fmt.file_format = "OPEN_EXR_MULTILAYER" if multilayer else "OPEN_EXR"
    else:
        fmt.file_format = "OPEN_EXR_MULTILAYER" if multilayer else "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    bpy.ops.render.render(write_still=True)
    return read_exr(str(path))


def test_register_unregister_twice():
    if hasattr(bpy.types.Scene, "drt"):
        addon.unregister()
    for _ in range(2):
        addon.register()
        assert drt_engine.DRTRenderEngine.is_registered
        # a new scene shows the defaults (the context scene may carry another test's settings)
        fresh = bpy.data.scenes.new("drt_register_twice")
        try:
            assert fresh.drt.max_bounces == 12
        finally:
            bpy.data.scenes.remove(fresh)
        assert "DRT" in bpy.types.DATA_PT_camera_dof.COMPAT_ENGINES
        addon.unregister()
        assert not hasattr(bpy.types.Scene, "drt")
        assert "DRT" not in bpy.types.DATA_PT_camera_dof.COMPAT_ENGINES
    addon.register()


def test_defaults_match_cycles(registered):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    d = bpy.context.scene.drt
    assert (d.max_bounces, d.diffuse_bounces, d.glossy_bounces, d.transmission_bounces) == (12, 4, 4, 12)
    assert d.clamp_direct == 0.0 and d.clamp_indirect == 0.0
    assert d.sampler == "SOBOL" and d.filter_type == "BLACKMAN_HARRIS"


def test_the_pixel_filter_and_exposure_are_cycles_film_settings(registered):
    """DRT renders with Cycles's Film > Pixel Filter (one .blend, one filter), not with Blender's
    render.filter_size (EEVEE's, which Cycles ignores); Cycles's box is one pixel wide whatever
    the width; without the Cycles add-on DRT's own type and Blender's Filter Size."""
    from types import SimpleNamespace

    from addon.export.scene_parts import pixel_filter, render_settings

    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.render.filter_size = 2.0
    sc.cycles.pixel_filter_type, sc.cycles.filter_width = "GAUSSIAN", 0.7
    assert render_settings(sc)["filter"] == {"type": "GAUSSIAN", "width": 0.7}
    sc.cycles.filter_width = 0.01  # Blender's float32 minimum, rounded up to the validator's 0.01
    assert pixel_filter(sc) == {"type": "GAUSSIAN", "width": 0.01}
    sc.cycles.pixel_filter_type = "BOX"
    assert pixel_filter(sc) == {"type": "BOX", "width": 1.0}
    no_cycles = SimpleNamespace(drt=SimpleNamespace(filter_type="BLACKMAN_HARRIS"),
                                render=SimpleNamespace(filter_size=2.5))
    assert pixel_filter(no_cycles) == {"type": "BLACKMAN_HARRIS", "width": 2.5}

    # DRT's Film panel edits those same properties (the width hidden for a box, as in Cycles)
    from addon import ui

    def film_panel_props():
        panel = type("FakePanel", (), {"layout": FakeLayout()})()
        ui.DRT_RENDER_PT_film.draw(panel, bpy.context)
        return panel.layout.drawn

    assert film_panel_props()[:2] == [(sc.cycles, "film_exposure"), (sc.cycles, "pixel_filter_type")]
    sc.cycles.pixel_filter_type = "BLACKMAN_HARRIS"
    assert film_panel_props()[1:3] == [(sc.cycles, "pixel_filter_type"), (sc.cycles, "filter_width")]
    # and Cycles's Film > Exposure
    sc.cycles.film_exposure = 1.75
    assert render_settings(sc)["exposure"] == 1.75


def test_render_cornell_box(tmp_path):
    scene = open_scene("cornell_box")
    assert scene.render.engine == "DRT"
    chans, _ = render_to(scene, tmp_path / "cb.exr")
    rgba = chans["RGBA"]
    assert rgba.shape == (96, 96, 4)
    assert np.all(np.isfinite(rgba))
    mean = rgba[..., :3].mean()
    assert 0.05 < mean < 1.0
    # red wall on the left, green on the right (image rows top first in the EXR)
    mid = rgba[30:70]
    left, right = mid[:, 22:28, :3].mean((0, 1)), mid[:, 68:74, :3].mean((0, 1))
    assert left[0] > 2 * left[1], left
    assert right[1] > 1.5 * right[0], right
    # the light is at the top: the upper half of the back wall is brighter than the floor edge
    assert rgba[:5].sum() == pytest.approx(0.0, abs=1e-6) or rgba[:5, :, :3].mean() < mean


@pytest.mark.slow
@pytest.mark.parametrize("name", ["dof", "motion_blur", "glossy_glass", "all_lights"])
def test_render_each_scene(tmp_path, name):
    scene = open_scene(name)
    scene.drt.samples = 8
    chans, _ = render_to(scene, tmp_path / f"{name}.exr")
    rgba = chans["RGBA"]
    w, h = scene.render.resolution_x, scene.render.resolution_y
    assert rgba.shape == (h, w, 4)
    assert np.all(np.isfinite(rgba))
    assert 0.01 < rgba[..., :3].mean() < 5.0


def test_passes_written(tmp_path):
    scene = open_scene("cornell_box")
    scene.drt.samples = 2
    vl = scene.view_layers[0]
    vl.use_pass_z = True
    vl.use_pass_normal = True
    vl.use_pass_diffuse_color = True
    chans, _ = render_to(scene, tmp_path / "passes.exr", multilayer=True)
    names = " ".join(chans)
    for p in ("Depth", "Normal", compat.pass_name("DiffCol")):
        assert p in names, names
    depth = next(v for k, v in chans.items() if "Depth" in k)
    assert np.nanmin(depth) > 1.0  # the camera is 2.9 m from the open front of the box


def test_passes_drt_does_not_render_are_named(monkeypatch):
    """Passes the view layer enables that DRT has no figures for (Vector, Shadow, AOVs…) are
    named in one warning instead of silently missing from the result; the ones it renders
    (Position and Cryptomatte here) are not."""
    scene = open_scene("cornell_box")
    scene.drt.samples = 1
    vl = scene.view_layers[0]
    assert compat.unrendered_passes(vl) == []
    vl.use_pass_position = vl.use_pass_vector = vl.use_pass_shadow = vl.use_pass_cryptomatte_object = True
    vl.aovs.add().name = "dirt"
    reports = []
    monkeypatch.setattr(drt_engine.DRTRenderEngine, "warn", lambda self, msg: reports.append(msg))
    bpy.ops.render.render()
    passes = [r for r in reports if "passes not rendered" in r]
    assert len(passes) == 1, reports
    for name in ("Vector", "Shadow", "AOV 'dirt'"):
        assert name in passes[0], passes[0]
    assert "Position" not in passes[0] and "Cryptomatte" not in passes[0], passes[0]


def test_error_is_reported_not_raised_silently(registered):
    """An unrenderable scene must abort the render (RuntimeError here, exit 1 in blender -b):
    here a camera whose far clip lies before its near one."""
    open_scene("cornell_box")
    cam = bpy.context.scene.camera.data
    cam.clip_start, cam.clip_end = 10.0, 1.0
    with pytest.raises(RuntimeError, match="DRT"):
        bpy.ops.render.render()


def test_cancel_stops_quickly(monkeypatch):
    scene = open_scene("cornell_box")
    scene.drt.samples = 100000
    calls = {"n": 0}

    def cancel_requested(self):
        calls["n"] += 1
        return calls["n"] > 3

    monkeypatch.setattr(drt_engine.DRTRenderEngine, "cancel_requested", cancel_requested)
    t0 = time.perf_counter()
    bpy.ops.render.render()
    assert time.perf_counter() - t0 < 30
    assert calls["n"] > 3


def test_sample_subset_settings(registered):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    d = bpy.context.scene.drt
    d.samples = 64
    assert drt_engine.sample_range(bpy.context.scene) == (64, 0, None)
    d.use_sample_subset, d.sample_offset, d.sample_count = True, 16, 16
    assert drt_engine.sample_range(bpy.context.scene) == (64, 16, 16)
    d.sample_count = 0
    assert drt_engine.sample_range(bpy.context.scene) == (64, 16, 48)


def test_border_crop_matches_region():
    class R:
        use_border = True
        border_min_x, border_min_y, border_max_x, border_max_y = 0.25, 0.0, 0.75, 0.5

    class S:
        render = R()

    rows, cols = drt_engine.border_crop(S(), 100, 80)
    assert (cols.start, cols.stop) == (25, 75)
    assert (rows.start, rows.stop) == (40, 80)  # bottom half, rows counted from the top


def test_denoise_panels_draw_existing_settings(registered):
    """The final-render and viewport Denoise panels share one draw; each shows its own settings,
    all of which exist on scene.drt (a typo would only show in the UI otherwise)."""
    from addon import ui

    class Context:
        scene = bpy.context.scene

    drawn = {}
    for cls in (ui.DRT_RENDER_PT_sampling_denoise, ui.DRT_RENDER_PT_sampling_viewport_denoise):
        layout = FakeLayout()
        panel = type("FakePanel", (), {"layout": layout, "switch": cls.switch, "prefix": cls.prefix,
                                       "extra": cls.extra})()
        ui._DenoisePanel.draw_header(panel, Context)
        ui._DenoisePanel.draw(panel, Context)
        drawn[cls.bl_label] = layout.props
    assert drawn["Denoise"] == ["use_denoising", "denoising_input_passes", "denoising_prefilter", "denoising_quality"]
    assert drawn["Viewport Denoise"][0] == "use_preview_denoising" and \
        drawn["Viewport Denoise"][-1] == "preview_denoising_start_sample"
