"""The Rendered viewport in a real Blender window: Debian's ``blender`` 3.4 binary under
``xvfb-run`` (software OpenGL), the legacy add-on installed as in test_blender_cli.py.

A script inside Blender switches a 3D view to Rendered in camera view, waits (a fresh install
first compiles the kernels in a background Blender, see addon/viewport.py), and reads its own
screenshot back (the Cornell box's red wall left, green wall right); moves an object (Blender
calls ``view_update`` with the real ``depsgraph.updates``) and checks the picture changed; then
switches to Solid and records when the last DRT thread ended. The bpy-module tests
(test_viewport.py) cover the update handling itself; this checks the drawing layer and the
engine's own hooks once, end to end.
"""

import json
import shutil
import subprocess

import pytest

import test_blender_cli

BLENDER = test_blender_cli.BLENDER
install = test_blender_cli.install  # its module-scoped fixture: the legacy add-on staged for 3.4

XVFB = shutil.which("xvfb-run")

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(BLENDER is None or XVFB is None,
                       reason="needs the 'blender' binary and xvfb-run (apt-get install xvfb)"),
]

SCRIPT = r'''
import json, sys, threading, time
import bpy
import numpy as np

OUT, ADDON = sys.argv[sys.argv.index("--") + 1:][:2]
scene = bpy.context.scene
scene.render.engine = "DRT"
scene.drt.preview_samples = 8
result = {}

def view():
    for window in bpy.context.window_manager.windows:
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                region = [r for r in area.regions if r.type == "WINDOW"][0]
                return window, area, region, area.spaces.active

def drt_threads():
    return [t.name for t in threading.enumerate() if t.name == "drt-viewport"]

def grab(name):
    window, area, region, space = view()
    path = f"{OUT}/{name}.png"
    with bpy.context.temp_override(window=window, area=area):
        bpy.ops.screen.screenshot_area(filepath=path)
    img = bpy.data.images.load(path)
    w, h = img.size
    px = np.array(img.pixels[:], dtype=np.float32).reshape(h, w, 4)[::-1, :, :3]  # top row first
    bpy.data.images.remove(img)
    return px

def setup():
    window, area, region, space = view()
    space.overlay.show_overlays = False
    space.shading.type = "RENDERED"
    space.region_3d.view_perspective = "CAMERA"
    with bpy.context.temp_override(window=window, area=area, region=region):
        bpy.ops.view3d.view_center_camera()

def first():
    px = grab("rendered")
    h, w, _ = px.shape
    left = px[h // 3: 2 * h // 3, w // 2 - w // 5: w // 2 - w // 6].reshape(-1, 3).mean(0)
    right = px[h // 3: 2 * h // 3, w // 2 + w // 6: w // 2 + w // 5].reshape(-1, 3).mean(0)
    result.update(left=left.tolist(), right=right.tolist(), threads_rendered=drt_threads())
    np.save(f"{OUT}/before.npy", px)

def move():
    bpy.data.objects["TallBox"].location.x += 0.4

def second():
    px = grab("moved")
    before = np.load(f"{OUT}/before.npy")
    result["changed"] = float(np.abs(px - before).mean()) if px.shape == before.shape else -1.0

def solid():
    view()[3].shading.type = "SOLID"
    result["solid_at"] = time.perf_counter()

def wait_threads():
    if drt_threads() and time.perf_counter() - result["solid_at"] < 10.0:
        return 0.02
    result["threads_after_solid"] = drt_threads()
    result["stop_seconds"] = time.perf_counter() - result["solid_at"]
    with open(f"{OUT}/result.json", "w") as f:
        json.dump(result, f)
    bpy.ops.wm.quit_blender()
    return None

def kernels_ready():
    import importlib
    return importlib.import_module(ADDON + ".viewport").kernels_cached()

plan = [(1.0, setup), (10.0, first), (0.5, move), (8.0, second), (0.5, solid)]
started = time.perf_counter()
ready = []

def tick():
    # a fresh install compiles the kernels first (in a background Blender): wait for that,
    # then give the viewport 10 s to render
    if len(plan) == 4 and not ready:
        if not kernels_ready() and time.perf_counter() - started < 1500:
            return 1.0
        ready.append(time.perf_counter() - started)
        result["kernels_ready_after"] = ready[0]
        return 10.0
    if not plan:
        return wait_threads()
    _delay, fn = plan.pop(0)
    try:
        fn()
    except Exception as exc:
        import traceback
        traceback.print_exc()
        result.setdefault("errors", []).append(repr(exc))
    return plan[0][0] if plan else 0.02

bpy.app.timers.register(tick, first_interval=2.0)
'''


def test_rendered_viewport_in_blender(install, tmp_path):
    root, env, name = install
    script = tmp_path / "viewport_check.py"
    script.write_text(SCRIPT)
    # no --factory-startup: it would drop the user scripts' modules folder (numpy)
    cmd = [XVFB, "-a", "-s", "-screen 0 1280x800x24", BLENDER,
           str(root / "cornell_box.blend"), "--addons", name, "--python", str(script), "--",
           str(tmp_path), name]
    p = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=1800, cwd=root)  # cold compile: ~10 min
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    with open(tmp_path / "result.json") as f:
        r = json.load(f)
    assert "errors" not in r, r
    assert "Traceback" not in p.stdout + p.stderr, (p.stdout + p.stderr)[-3000:]
    left, right = r["left"], r["right"]
    assert left[0] > 1.5 * left[1] and right[1] > 1.5 * right[0], (left, right)  # red | green
    assert r["threads_rendered"] == ["drt-viewport"]
    assert r["changed"] > 0.002, r["changed"]  # the moved box re-rendered
    assert r["threads_after_solid"] == [], r
    print(f"viewport stopped {r['stop_seconds'] * 1e3:.0f} ms after switching to Solid")
