"""The kernel compile plan (drt.compile_plan): helper processes compile a first render's
kernels on every core. The plan is shipped data; these tests keep it in step with the kernels
and check that a cancel stops the helpers."""

from __future__ import annotations

import os
import subprocess
import sys
import time
import types

import pytest

import drt.kernels as K
from drt import compile_plan as CP


def test_the_shipped_plan_loads_and_every_entry_is_a_kernel():
    """Fails when a kernel the plan names was renamed or removed (or the pinned numba changed)
    without regenerating the plan: ``python -m drt.compile_plan``."""
    plan = CP.load_plan()
    assert plan is not None, "compile_plan.pkl missing or unreadable: regenerate it"
    assert set(plan) == set(K.KERNEL_VARIANTS)
    for variant, entries in plan.items():
        names = {attr for _, attr, _ in entries}
        assert {"shade", "camera_stage"} <= names, variant
        missing = [(m, a) for m, a, _ in entries if CP._resolve(m, a) is None]
        assert not missing, f"{variant or 'plain'}: {missing[:5]}"
        assert all(len(sigs) >= 1 for _, _, sigs in entries)
    # the media variant holds the whole shade, so it needs more kernels than the plain one
    assert len(plan["media"]) > len(plan[""]) > 100


def test_plan_classes_map_to_this_copys_package(monkeypatch):
    """Types recorded under ``drt`` load from the add-on's copy (another package name)."""
    import drt.kernels.vec3 as vec3

    monkeypatch.setattr(CP, "PACKAGE", "addon_copy.drt")
    monkeypatch.setitem(sys.modules, "addon_copy", types.ModuleType("addon_copy"))
    monkeypatch.setitem(sys.modules, "addon_copy.drt", types.ModuleType("addon_copy.drt"))
    monkeypatch.setitem(sys.modules, "addon_copy.drt.kernels", types.ModuleType("addon_copy.drt.kernels"))
    fake = types.ModuleType("addon_copy.drt.kernels.vec3")
    fake.dot = "the copy's dot"
    monkeypatch.setitem(sys.modules, "addon_copy.drt.kernels.vec3", fake)
    import io

    up = CP._PackageUnpickler(io.BytesIO())
    assert up.find_class("drt.kernels.vec3", "dot") == "the copy's dot"
    assert up.find_class("numpy", "float64") is __import__("numpy").float64
    assert vec3.dot is not fake.dot


def test_a_helper_imports_the_core_without_the_addon_package_above_it(tmp_path, monkeypatch):
    """Inside Blender the core is ``<addon>.drt`` and the add-on's __init__ imports bpy, which
    a helper (a plain Python) has not: the helper stands in empty packages above the core."""
    addon = tmp_path / "fakeaddon"
    addon.mkdir()
    (addon / "__init__.py").write_text("raise ImportError('no bpy in a helper')\n")
    (addon / "drt").symlink_to(os.path.dirname(CP.__file__))
    stub = types.ModuleType("fakeaddon")
    stub.__path__ = [str(addon)]
    monkeypatch.setitem(sys.modules, "fakeaddon", stub)
    monkeypatch.syspath_prepend(str(tmp_path))
    cmd = CP._helper_command(sys.executable, "no-such-variant", 0, 1, package="fakeaddon.drt")
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "DRT_SET_NUMBA_CACHE_DIR")}
    env["DRT_CACHE_DIR"] = str(tmp_path / "cache")
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr


def test_a_cancel_stops_the_helpers(monkeypatch):
    started = []
    real_popen = subprocess.Popen

    def popen(*args, **kwargs):
        p = real_popen(*args, **kwargs)
        started.append(p)
        return p

    monkeypatch.setattr(K, "kernels_compiled", lambda variant="": False)
    monkeypatch.setattr(CP, "_PRECOMPILED", set())  # an earlier test's render may have run them
    monkeypatch.setattr(CP, "helper_count", lambda: 2)
    monkeypatch.setattr(CP, "_CHILD", "import time; time.sleep(60)")
    monkeypatch.setattr(CP.subprocess, "Popen", popen)
    monkeypatch.delenv(CP.NO_PRECOMPILE_ENV, raising=False)
    t0 = time.perf_counter()
    assert CP.precompile("", cancel=lambda: time.perf_counter() - t0 > 0.3) is False
    assert time.perf_counter() - t0 < 3.0
    assert len(started) == 2 and all(p.poll() is not None for p in started)
    # helpers that ran to the end are not started again in this process
    monkeypatch.setattr(CP, "_CHILD", "pass")
    assert CP.precompile("") is True and len(started) == 4
    assert CP.precompile("") is True and len(started) == 4


def test_nothing_starts_when_the_kernels_are_compiled_or_precompiling_is_off(monkeypatch):
    monkeypatch.setattr(CP.subprocess, "Popen", lambda *a, **k: pytest.fail("started a helper"))
    monkeypatch.setattr(K, "kernels_compiled", lambda variant="": True)
    assert CP.precompile("") is True
    monkeypatch.setattr(K, "kernels_compiled", lambda variant="": False)
    monkeypatch.setenv(CP.NO_PRECOMPILE_ENV, "1")
    assert CP.precompile("") is True


@pytest.mark.slow
@pytest.mark.skipif(CP.helper_count() == 0, reason="one core: no helper processes")
def test_after_precompiling_a_first_render_compiles_next_to_nothing(tmp_path):
    """Into an empty cache: the helpers compile the plain variant's plan, then the render finds
    (nearly) every kernel it calls in the cache. Without the helpers it compiles ~220."""
    scenes = os.path.join(os.path.dirname(__file__), "..", "blend_scenes")
    code = f"""
import sys, time
from drt import compile_plan as CP
from drt.kernels import LazyKernel
from drt.loaders import load_scene
from drt import render as R
t0 = time.perf_counter()
assert CP.precompile("") is True
t1 = time.perf_counter()
R.render(load_scene({os.path.join(scenes, 'cornell_box.npz')!r}), spp=1, threads=1)
t2 = time.perf_counter()
misses = 0
for name, mod in list(sys.modules.items()):
    if name.startswith("drt"):
        for obj in list(vars(mod).values()):
            if isinstance(obj, LazyKernel) and obj._dispatcher is not None:
                misses += sum(obj._dispatcher._cache_misses.values())
print(misses, round(t1 - t0, 1), round(t2 - t1, 1))
"""
    env = {k: v for k, v in os.environ.items() if k not in ("DRT_SET_NUMBA_CACHE_DIR", CP.NO_PRECOMPILE_ENV)}
    env["NUMBA_CACHE_DIR"] = str(tmp_path)
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stderr
    misses, helpers_s, render_s = out.stdout.split()[-3:]
    assert int(misses) <= 10, out.stdout
