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
    features = {k for k in plan if k.startswith(CP.FEATURE_PREFIX)}
    assert set(plan) - features == set(K.KERNEL_VARIANTS)
    assert features == {CP.FEATURE_PREFIX + f for f in CP.PLAN_FEATURES}
    for variant, entries in plan.items():
        called = {attr for _, attr, _, linked in entries if not linked}
        if variant not in features:
            # the stage kernels are called from Python; most of the rest only from kernels
            assert {"shade", "camera_stage"} <= called, variant
            assert sum(linked for *_, linked in entries) > 5 * len(called), variant
        missing = [(m, a) for m, a, _, _ in entries if CP._resolve(m, a) is None]
        assert not missing, f"{variant or 'plain'}: {missing[:5]}"
        assert all(len(sigs) >= 1 for _, _, sigs, _ in entries)
    # the media variant holds the whole shade, so it needs more kernels than the plain one
    assert len(plan["media"]) > len(plan[""]) > 100
    # a feature holds what the plain plan lacks: the walk for subsurface scattering, and no
    # signature twice
    assert "walk_local" in {attr for _, attr, _, _ in plan[CP.FEATURE_PREFIX + "sss"]}
    plain = {(m, a, s, linked) for m, a, sigs, linked in plan[""] for s in sigs}
    for feature in features:
        assert not plain & {(m, a, s, linked) for m, a, sigs, linked in plan[feature] for s in sigs}, feature


def test_a_scene_s_features_are_what_it_compiles_beyond_its_variant():
    from drt.scene_file import load_scene

    scenes = os.path.join(os.path.dirname(__file__), "..", "blend_scenes")
    expected = {"cornell_box": (), "sss_head": ("sss",), "motion_blur": ("motion",), "volume_fog": ()}
    for name, features in expected.items():
        assert CP.scene_features(load_scene(os.path.join(scenes, f"{name}.npz"))) == features, name


def test_plan_entries_are_the_variant_s_then_each_feature_s():
    plan = {"": [("a", "f", [1], True)], "media": [("a", "g", [2], True)], "+sss": [("b", "w", [3], False)]}
    assert CP.plan_entries(plan, "") == [("a", "f", [1], True)]
    assert CP.plan_entries(plan, "", ("sss",)) == [("a", "f", [1], True), ("b", "w", [3], False)]
    assert CP.plan_entries(plan, "media", ("sss", "motion")) == [("a", "g", [2], True), ("b", "w", [3], False)]
    assert CP.plan_entries(None, "", ("sss",)) == []
    # a signature of the other form is not the same entry
    assert CP._beyond([("a", "f", [1, 2], True), ("b", "w", [3], True), ("a", "f", [1], False)],
                      [("a", "f", [1], True)]) == [("a", "f", [2], True), ("b", "w", [3], True), ("a", "f", [1], False)]


def test_after_the_critical_kernel_its_helper_gets_nothing_and_the_others_take_turns():
    for parts in (1, 2, 3, 8):
        for split in (None, 0, 5, 6, 19):
            owners = [CP.helper_of(k, split, parts) for k in range(20)]
            assert all(0 <= h < parts for h in owners)
            if split is None or parts == 1:
                assert owners == [k % parts for k in range(20)]
                continue
            # the callees and the critical kernel: turns, as before
            assert owners[:split + 1] == [k % parts for k in range(split + 1)]
            tail = owners[split + 1:]
            assert owners[split] not in tail
            # the others share the rest evenly
            counts = [tail.count(h) for h in range(parts) if h != owners[split]]
            assert max(counts) - min(counts) <= 1, (parts, split, owners)


def test_a_helper_compiles_the_entries_helper_of_gives_it_and_reports_each(monkeypatch):
    compiled = []

    class Fake:
        def __init__(self, name):
            self.name = name

        def dispatcher(self):
            return self

        linked = dispatcher

        def compile(self, sig):
            compiled.append((self.name, sig))

    monkeypatch.setattr(CP, "_resolve", lambda module, attr: Fake(attr))
    entries = [("m", f"k{k}", [k], True) for k in range(6)] + [("path_stages", "shade", ["s"], False)] \
        + [("m", f"r{k}", [k], False) for k in range(4)]
    heard = []
    for part in range(3):
        done = CP.compile_part("", part, 3, {"": entries}, (), lambda k, e, a, b: heard.append((part, k, e[1], b >= a)))
        assert done == sum(len(e[2]) for k, e in enumerate(entries) if CP.helper_of(k, 6, 3) == part)
    assert sorted(k for _, k, _, _ in heard) == list(range(len(entries)))
    assert all(part == CP.helper_of(k, 6, 3) and ordered for part, k, _, ordered in heard)
    assert {part for part, _, name, _ in heard if name.startswith("r")} == {1, 2}  # shade (6th) is helper 0's
    assert len(compiled) == len(entries)


def test_the_critical_kernel_comes_after_its_callees_and_before_the_rest():
    shade = ("path_stages", "shade", ["s"], False)
    entries = [("a", "cam", ["c"], False), ("a", "f", ["1"], True), ("b", "g", ["2"], True),
               ("a", "f", ["1"], False), shade, ("b", "h", ["3"], False)]
    callees = {("a", "f", True), ("b", "g", True), ("path_stages", "shade", False)}
    assert CP.critical_first(entries, callees) == [entries[1], entries[2], shade, entries[0], entries[3], entries[5]]
    assert CP.critical_index(CP.critical_first(entries, callees)) == 2
    # a plan without it (a feature's) keeps its order
    assert CP.critical_first(entries[:4], callees) == entries[:4]
    assert CP.critical_index(entries[:4]) is None


def test_the_shipped_plans_list_shade_after_its_callees_and_its_helper_then_rests():
    """The Python-called kernels `shade` does not call (the camera stage, the film) come after
    it, where the helpers not compiling `shade` take them; its own callees come before it."""
    plan = CP.load_plan()
    for variant in K.KERNEL_VARIANTS:
        entries = plan[variant]
        split = CP.critical_index(entries)
        assert split is not None, variant
        before = {(m, a) for m, a, _, linked in entries[:split]}
        after = {(m, a) for m, a, _, linked in entries[split + 1:] if not linked}
        assert {("path_stages", "camera_stage"), ("film", "_accumulate")} <= after, variant
        assert {("materials.table", "bsdf_sample_bump"), ("lights.area", "_sample_spherical_rect")} <= before, variant
        assert ("path_stages", "camera_stage") not in before, variant


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


def test_a_feature_compiles_alone_when_its_variant_is_compiled(monkeypatch):
    """A subsurface scene after a plain one: the helpers compile the walk's plan only, once per
    process, and not at all after a render marked the feature compiled."""
    import json

    started = []
    real_popen = subprocess.Popen

    def popen(cmd, *args, **kwargs):
        started.append(json.loads(cmd[-1]))
        return real_popen([sys.executable, "-c", "pass"], *args, **kwargs)

    marks = {""}  # the plain variant is compiled; no feature is
    monkeypatch.setattr(CP, "load_plan", lambda: {"": [("m", "k", [1], True)], "+sss": [("m", "walk", [2], True)],
                                                  "+motion": [("m", "moving", [3], True)]})
    monkeypatch.setattr(K, "kernels_compiled", lambda variant="": variant in marks)
    monkeypatch.setattr(K, "mark_kernels_compiled", lambda variant="": marks.add(variant))
    monkeypatch.setattr(CP, "_PRECOMPILED", set())
    monkeypatch.setattr(CP, "helper_count", lambda: 2)
    monkeypatch.setattr(CP.subprocess, "Popen", popen)
    monkeypatch.delenv(CP.NO_PRECOMPILE_ENV, raising=False)
    monkeypatch.setenv("NUMBA_CACHE_DIR", os.environ.get("NUMBA_CACHE_DIR") or "/nonexistent")
    assert CP.precompile("", features=("sss",)) is True
    # [paths, parents, package, variant, part, parts, features]: no variant, the feature alone
    assert [(a[3], a[4], a[5], a[6]) for a in started] == [(None, 0, 2, ["sss"]), (None, 1, 2, ["sss"])]
    assert CP.precompile("", features=("sss",)) is True and len(started) == 2  # once a process
    monkeypatch.setattr(CP, "_PRECOMPILED", set())
    CP.mark_features_compiled(["sss"])
    assert CP.precompile("", features=("sss",)) is True and len(started) == 2  # marked compiled
    assert CP.precompile("", features=("sss", "motion")) is True
    assert [a[6] for a in started[2:]] == [["motion"], ["motion"]]


def test_nothing_starts_when_the_kernels_are_compiled_or_precompiling_is_off(monkeypatch):
    monkeypatch.setattr(CP.subprocess, "Popen", lambda *a, **k: pytest.fail("started a helper"))
    monkeypatch.setattr(K, "kernels_compiled", lambda variant="": True)
    assert CP.precompile("") is True
    monkeypatch.setattr(K, "kernels_compiled", lambda variant="": False)
    monkeypatch.setenv(CP.NO_PRECOMPILE_ENV, "1")
    assert CP.precompile("") is True


@pytest.mark.slow
@pytest.mark.skipif(CP.helper_count() == 0, reason="one core: no helper processes")
@pytest.mark.parametrize("scene, features", [("cornell_box", ()), ("sss_head", ("sss",))])
def test_after_precompiling_a_first_render_compiles_next_to_nothing(tmp_path, scene, features):
    """Into an empty cache: the helpers compile the plain variant's plan (and the subsurface
    walk's, for a scene with subsurface scattering), then the render finds (nearly) every
    kernel it calls in the cache. Without the helpers it compiles ~220."""
    scenes = os.path.join(os.path.dirname(__file__), "..", "blend_scenes")
    code = f"""
import sys, time
from drt import compile_plan as CP
from drt.kernels import LazyKernel
from drt.loaders import load_scene
from drt import render as R
t0 = time.perf_counter()
assert CP.precompile("", features={features!r}) is True
t1 = time.perf_counter()
R.render(load_scene({os.path.join(scenes, scene + '.npz')!r}), spp=1, threads=1)
t2 = time.perf_counter()
misses = 0
for name, mod in list(sys.modules.items()):
    if name.startswith("drt"):
        for obj in list(vars(mod).values()):
            if isinstance(obj, LazyKernel):
                misses += sum(sum(d._cache_misses.values()) for d in (obj._dispatcher, obj._linked) if d is not None)
print(misses, round(t1 - t0, 1), round(t2 - t1, 1))
"""
    env = {k: v for k, v in os.environ.items() if k not in ("DRT_SET_NUMBA_CACHE_DIR", CP.NO_PRECOMPILE_ENV)}
    env["NUMBA_CACHE_DIR"] = str(tmp_path)
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stderr
    misses, helpers_s, render_s = out.stdout.split()[-3:]
    assert int(misses) <= 10, out.stdout
