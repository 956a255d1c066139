"""The add-on rendering on a Dask cluster (bpy module): F12 with a scheduler address gives the
local image; an unreachable scheduler is an error report (exit 1 in ``blender -b``), within the
time-out; Esc cancels the cluster's tasks."""

import os
import socket
import sys
import time

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
pytest.importorskip("distributed")

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if REPO not in sys.path:
    sys.path.insert(0, REPO)

import addon  # noqa: E402
from addon import engine as drt_engine  # noqa: E402

pytestmark = pytest.mark.blender


def open_box():
    if not hasattr(bpy.types.Scene, "drt"):
        addon.register()
    bpy.ops.wm.open_mainfile(filepath=os.path.join(REPO, "blend_scenes", "cornell_box.blend"))
    scene = bpy.context.scene
    scene.render.resolution_percentage = 50
    scene.drt.samples = 4
    return scene


def render_exr(scene, path):
    import OpenEXR

    scene.render.filepath = str(path)
    fmt = scene.render.image_settings
    if hasattr(fmt, "media_type"):
        fmt.media_type = "IMAGE"
    fmt.file_format, fmt.color_depth = "OPEN_EXR", "32"
    bpy.ops.render.render(write_still=True)
    with OpenEXR.File(str(path)) as f:
        return {k: np.array(v.pixels) for part in f.parts for k, v in part.channels.items()}


def test_f12_on_the_cluster_gives_the_local_image(dask_cluster, tmp_path):
    scene = open_box()
    local = render_exr(scene, tmp_path / "local.exr")
    scene.drt.cluster_address = dask_cluster.scheduler_address
    farm = render_exr(scene, tmp_path / "farm.exr")
    assert set(local) == set(farm)
    for k in local:
        assert np.array_equal(local[k], farm[k]), k
    assert farm["RGBA"][..., :3].mean() > 0.01


def test_an_unreachable_scheduler_is_an_error_report(tmp_path):
    scene = open_box()
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    scene.drt.cluster_address = f"tcp://127.0.0.1:{port}"
    scene.drt.cluster_timeout = 1.0
    t0 = time.perf_counter()
    with pytest.raises(RuntimeError, match="cannot reach the Dask scheduler"):
        bpy.ops.render.render()
    assert time.perf_counter() - t0 < 15
    scene.drt.cluster_address = "localhost:8786"
    with pytest.raises(RuntimeError, match="tcp://HOST:PORT"):
        bpy.ops.render.render()


def test_esc_cancels_the_cluster_tasks(dask_cluster, monkeypatch):
    scene = open_box()
    scene.drt.samples = 100000  # hours of work for two workers
    scene.drt.cluster_address = dask_cluster.scheduler_address
    calls = {"n": 0}

    def cancel_requested(self):
        calls["n"] += 1
        return calls["n"] > 20

    monkeypatch.setattr(drt_engine.DRTRenderEngine, "cancel_requested", cancel_requested)
    t0 = time.perf_counter()
    bpy.ops.render.render()
    assert time.perf_counter() - t0 < 30
    # the scheduler forgets the cancelled tasks: nothing of ours is left running
    import distributed

    with distributed.Client(dask_cluster.scheduler_address, set_as_default=False) as c:
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            left = [k for keys in c.processing().values() for k in keys if str(k).startswith("drt-render")]
            if not left:
                break
            time.sleep(0.1)
    assert not left
