"""Compiling the kernels on every core: a shipped plan of what a render compiles.

The kernel compiler works on one function at a time under a process-wide lock, so the first
render of an install compiled its ~240 kernels (the plain variant; 270–410 with textures or media)
on one core: ~55 s on the 2-vCPU development machine. Most of them are callees of `shade` that
the compiler would compile anyway when it types `shade`; compiled first, each lands in the
on-disk cache, where `shade`'s compilation finds it. ``compile_plan.pkl`` beside this file lists
every kernel the render of one shipped scene per variant compiles, with the argument types
(compiler signatures) it compiles them for, in the order the compiler finished them (callees
first; `shade`'s own callees before it and the kernels it does not call after it). On a first
render (`drt.render.render`, before the scene is prepared) `precompile` starts one helper
process per core, which take turns at the entries up to `shade` and leave the rest to the
helpers not compiling `shade` (`helper_of`), compiling into the shared cache, and waits for
them; the render then loads what they compiled and compiles only what the plan lacks.
Kernels outside `shade` that only some scenes need are planned per feature (``PLAN_FEATURES``:
the subsurface walk, moving objects) and compiled by the helpers when the scene uses them
(`scene_features`); others (transparent shadows) the render compiles itself.

Measured (first render into an empty cache, whole process, 2 vCPUs, 2026-12-04): Cornell box
53.6 → 40.6 s, textured 128.2 → 72.4 s, volume_fog 166.6 → 124.1 s; the render's own part after
the helpers is mostly `shade`, whose body with every callee inlined LLVM optimises as one
function (docs/kernels.md). Since 2026-12-07 kernels only other kernels call compile without
entry points or machine code (`drt.kernels.LazyKernel.linked`): 22.8 s, 42.2 s and 53.4 s on a
faster machine.

The plan is data, regenerated with ``python -m drt.compile_plan`` after kernel signatures change
(~8 min: each variant is recorded, then `shade` is compiled alone for its call graph). A stale plan is harmless: an entry that no longer resolves or types is skipped, a
missing one is compiled by the render as before. The pickled signature types name DRT's classes
(namedtuple records) under the import name ``drt``; `load_plan` maps them to this copy's package
name (the Blender add-on imports the core as ``drt_blender.drt`` or
``bl_ext.<repo>.drt_blender.drt``).
"""

from __future__ import annotations

import json
import os
import pickle
import subprocess
import sys
import threading
import time
from dataclasses import replace

PLAN_FILE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "compile_plan.pkl")

#: the package this copy of the core is imported as ("drt", or the add-on's "….drt"); from the
#: module spec, which keeps the name when this file runs as ``python -m``
PACKAGE = (__spec__.name if __spec__ is not None else __name__).rsplit(".compile_plan", 1)[0]

#: at most this many helper processes (each holds a compiler, ~0.3–0.5 GB at its peak)
MAX_HELPERS = 8

#: how often `precompile` polls its helpers and the cancel callback, seconds
POLL_SECONDS = 0.05

#: set (to anything) to compile in the render's own process, one kernel at a time, as the
#: compiler does by itself (recording a plan needs that: kernels loaded from the cache do not
#: tell which callees they hold)
NO_PRECOMPILE_ENV = "DRT_NO_PRECOMPILE"

_RUN_LOCK = threading.Lock()  # one precompile at a time in a process (render threads, farm tasks)
#: variants (and FEATURE_PREFIX + feature) whose helpers ran to the end in this process: a render
#: marks its variant compiled only when it finishes, and renders cancelled before that (viewport
#: edits during a first use) must not start helpers again, each loading a few hundred cached
#: kernels for nothing
_PRECOMPILED: set = set()


class _PackageUnpickler(pickle.Unpickler):
    """Unpickles classes recorded under ``drt.…`` from this copy's package."""

    def find_class(self, module, name):
        if module == "drt" or module.startswith("drt."):
            module = PACKAGE + module[3:]
        return super().find_class(module, name)


def load_plan(path: str = PLAN_FILE) -> dict | None:
    """{variant: [(module relative to the package, attribute, [signature, ...], linked), ...]}, or
    None when there is no plan or it does not load (another compiler version, a renamed record
    type). ``linked``: the entry is the kernel's form other kernels call (`LazyKernel.linked`),
    not its Python-callable one."""
    from .kernels import compiler_version

    try:
        with open(path, "rb") as f:
            plan = _PackageUnpickler(f).load()
    except Exception:  # noqa: BLE001 -- a plan that does not load only costs the speed-up
        return None
    if not isinstance(plan, dict) or plan.get("compiler") != compiler_version():
        return None
    return plan.get("variants")


def _resolve(module: str, attr: str):
    """The kernel ``attr`` of ``PACKAGE.module``, or None."""
    from . import render  # noqa: F401 -- imports every module that holds a planned kernel
    from .kernels import LazyKernel

    obj = getattr(sys.modules.get(f"{PACKAGE}.{module}"), attr, None)
    return obj if isinstance(obj, LazyKernel) else None


def plan_entries(plan: dict | None, variant: str | None, features=()) -> list:
    """The entries a render of ``variant`` with ``features`` compiles: the variant's (none for
    None), then each feature's (stored under ``FEATURE_PREFIX + feature``)."""
    plan = plan or {}
    entries = list(plan.get(variant, ()))
    for feature in features:
        entries += plan.get(FEATURE_PREFIX + feature, ())
    return entries


def scene_features(scene) -> tuple:
    """The kernel features ``scene`` (a ``drt.scene.Scene``) uses beyond its variant's plan
    (``PLAN_FEATURES``): "sss" when a material has a SUBSURFACE lobe, "motion" when the camera
    or an object moves or a mesh deforms. A wrong guess costs only helper time."""
    features = []
    mats = getattr(scene, "materials", None) or []
    if any(isinstance(lobe, dict) and lobe.get("type") == "SUBSURFACE"
           for m in mats if isinstance(m, dict) for lobe in (m.get("lobes") or ())):
        features.append("sss")
    camera = getattr(scene, "camera", None)
    moving = getattr(camera, "motion", None) is not None
    moving = moving or any(getattr(o, "motion", None) is not None for o in getattr(scene, "objects", None) or ())
    moving = moving or any(getattr(m, "positions_close", None) is not None for m in getattr(scene, "meshes", None) or ())
    if moving:
        features.append("motion")
    return tuple(features)


#: the kernel whose compile is a first render's critical path: `shade`, called from Python, whose
#: module LLVM optimises with every callee inlined (~12 of a media scene's ~55 s of compile work
#: on one core), and which cannot start before its callees are in the cache. A variant's plan
#: lists its callees first, then it, then the kernels it does not call (`critical_first`);
#: `helper_of` gives those to the helpers that are not compiling it.
CRITICAL_KERNEL = ("path_stages", "shade")


def critical_index(entries: list) -> int | None:
    """The index of the entry of `CRITICAL_KERNEL`'s Python-called form in ``entries`` (plan
    entries), None when there is none (a feature's plan alone)."""
    for k, (module, attr, _, linked) in enumerate(entries):
        if (module, attr) == CRITICAL_KERNEL and not linked:
            return k
    return None


def helper_of(k: int, split: int | None, parts: int) -> int:
    """The helper (0 … ``parts`` − 1) that compiles entry ``k`` of a plan whose critical entry
    is at ``split`` (`critical_index`). Up to and including it the helpers take turns (the
    entries before it are its callees, which all helpers compile together so that it can start
    early); after it the helper compiling it gets nothing, the others take turns: on two cores
    the kernels `shade` does not call (the camera stage, the tracer's glue, a volume scene's
    shadow rounds, the subsurface walk) compile beside it instead of after it (media scenes
    ~4 s sooner)."""
    if split is None or parts < 2 or k <= split:
        return k % parts
    owner = split % parts
    h = (k - split - 1) % (parts - 1)
    return h + (h >= owner)


def critical_first(entries: list, callees: set) -> list:
    """``entries`` (a variant's plan, in the order the compiler finished them) reordered for
    `helper_of`: the kernels in ``callees`` ((module, attr, linked) triples: what compiling
    `CRITICAL_KERNEL` alone compiles) first, then the critical entry, then the rest, each
    group in its old order. Unchanged when there is no critical entry."""
    split = critical_index(entries)
    if split is None:
        return list(entries)
    inside, outside = [], []
    for k, entry in enumerate(entries):
        if k != split:
            (inside if (entry[0], entry[1], entry[3]) in callees else outside).append(entry)
    return inside + [entries[split]] + outside


def compile_part(variant: str | None, part: int, parts: int, plan: dict | None = None, features=(),
                 on_entry=None) -> int:
    """Compile the entries of the plan of ``variant`` and ``features`` (`plan_entries`) that
    `helper_of` gives helper ``part`` of ``parts`` into the cache (what a helper process
    runs). Entries that do not resolve or compile are skipped. ``on_entry(k, entry, start,
    end)``, if given, hears of each entry compiled (``time.perf_counter`` seconds; for
    ``benchmarks/compile_cost.py --timeline``). Returns the number of signatures compiled (or
    loaded from the cache)."""
    plan = load_plan() if plan is None else plan
    done = 0
    entries = plan_entries(plan, variant, features)
    split = critical_index(entries)
    for k, (module, attr, sigs, linked) in enumerate(entries):
        if helper_of(k, split, parts) != part:
            continue
        kern = _resolve(module, attr)
        if kern is None:
            continue
        start = time.perf_counter()
        dispatcher = kern.linked() if linked else kern.dispatcher()
        for sig in sigs:
            try:
                dispatcher.compile(sig)
                done += 1
            except Exception:  # noqa: BLE001 -- stale entry: the render compiles what it needs
                pass
        if on_entry is not None:
            on_entry(k, entries[k], start, time.perf_counter())
    return done


# A helper: the caller's import path; the packages above the core (the Blender add-on's, whose
# __init__ imports bpy) as empty stand-ins, so that importing the core runs only the core.
_CHILD = (
    "import importlib, json, sys, types\n"
    "paths, parents, package, variant, part, parts, features = json.loads(sys.argv[1])\n"
    "sys.path[:0] = paths\n"
    "for name, path in parents:\n"
    "    stub = sys.modules[name] = types.ModuleType(name)\n"
    "    stub.__path__ = path\n"
    "importlib.import_module(package + '.compile_plan').compile_part(variant, part, parts, None, features)\n"
)


def _helper_command(python: str, variant: str, part: int, parts: int, package: str = PACKAGE,
                    features=()) -> list:
    """The command line of helper ``part`` of ``parts``."""
    names = package.split(".")
    parents = []
    for i in range(1, len(names)):
        name = ".".join(names[:i])
        path = getattr(sys.modules.get(name), "__path__", None)
        if path is not None:
            parents.append((name, list(path)))
    paths = [p for p in sys.path if isinstance(p, str)]
    return [python, "-c", _CHILD, json.dumps([paths, parents, package, variant, part, parts, list(features)])]


def _python() -> str | None:
    """A Python interpreter to run helpers with: this one, when ``sys.executable`` is a Python
    (inside Blender it is Blender's bundled Python; None when it is not a Python at all)."""
    exe = sys.executable or ""
    return exe if "python" in os.path.basename(exe).lower() and os.path.isfile(exe) else None


def helper_count() -> int:
    """How many helper processes `precompile` starts: one per core, at most MAX_HELPERS; 0 on a
    single core (one helper would only add its start-up to the serial compile)."""
    n = os.cpu_count() or 1
    return 0 if n < 2 else min(n, MAX_HELPERS)


def _feature_mark(feature: str) -> str:
    """The ``drt.kernels.kernels_compiled`` name of a feature's ready mark."""
    return f"feature-{feature}"


def mark_features_compiled(features) -> None:
    """Record that a render compiled and cached these features' kernels (as
    ``drt.kernels.mark_kernels_compiled`` does for a variant)."""
    from .kernels import mark_kernels_compiled

    for feature in features:
        mark_kernels_compiled(_feature_mark(feature))


def precompile(variant: str, cancel=None, features=()) -> bool:
    """Compile ``variant``'s kernels on every core before a render that would compile them
    (``drt.kernels.kernels_compiled(variant)`` false), by helper processes into the shared cache;
    and the kernels of the scene's ``features`` (`scene_features`: the subsurface walk, moving
    objects) that no render has compiled yet (`mark_features_compiled`), alone when the variant
    is compiled. Does nothing when all are compiled, there is no plan, one core, or no Python to
    run helpers with. Returns False when ``cancel()`` turned True meanwhile (the helpers are
    stopped)."""
    from .kernels import kernels_compiled

    def todo():
        """(the variant, or None when it needs nothing; the features that need compiling)"""
        v = None if variant in _PRECOMPILED or kernels_compiled(variant) else variant
        fs = tuple(f for f in features if FEATURE_PREFIX + f not in _PRECOMPILED
                   and not kernels_compiled(_feature_mark(f)))
        return v, fs

    if not os.environ.get("NUMBA_CACHE_DIR") or os.environ.get(NO_PRECOMPILE_ENV) or todo() == (None, ()):
        return True
    while not _RUN_LOCK.acquire(timeout=POLL_SECONDS):  # another render's helpers are at work
        if cancel is not None and cancel():
            return False
    helpers = []
    try:
        need_variant, need_features = todo()
        plan = load_plan()
        parts, python = helper_count(), _python()
        if not plan_entries(plan, need_variant, need_features) or parts == 0 or python is None:
            return True
        for part in range(parts):
            helpers.append(subprocess.Popen(_helper_command(python, need_variant, part, parts, features=need_features),
                                            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                            stderr=subprocess.DEVNULL))
        while any(h.poll() is None for h in helpers):
            if cancel is not None and cancel():
                return False
            time.sleep(POLL_SECONDS)
        _PRECOMPILED.update([FEATURE_PREFIX + f for f in need_features] + ([] if need_variant is None else [variant]))
        return True
    except OSError:  # could not start a helper: the render compiles by itself
        return True
    finally:
        for h in helpers:
            if h.poll() is None:
                h.kill()
                h.wait()
        _RUN_LOCK.release()


# --------------------------------------------------------------------------- making the plan

#: the shipped scenes each variant's plan is recorded from (blend_scenes/<name>.npz): one plain
#: scene per variant, so that the plan holds what every render of the variant compiles.
#: Feature kernels outside `shade` are planned apart (``PLAN_FEATURES``): recorded from all
#: shipped scenes the plain plan held 382 kernels against the Cornell box's 214, and helpers
#: compiling 80 % more than a plain render needs gained nothing on two cores.
PLAN_SCENES = {
    "": ("cornell_box",),
    "programs": ("textured",),
    "programs-procedural": ("procedural",),
    "media": ("volume_fog",),
    "media-programs": ("volume_liquid",),
    "media-programs-procedural": ("volume_noise",),
}

#: features whose kernels a render compiles only when its scene uses them (`scene_features`),
#: each recorded from one plain shipped scene that has it: the entries that scene compiles
#: beyond the plain plan, stored under FEATURE_PREFIX + feature
PLAN_FEATURES = {
    "sss": "sss_head",
    "motion": "motion_blur",
}
FEATURE_PREFIX = "+"


def _beyond(entries: list, base: list) -> list:
    """``entries`` without the signatures ``base`` holds for the same kernel."""
    known = {}
    for module, attr, sigs, linked in base:
        known.setdefault((module, attr, linked), []).extend(sigs)
    out = []
    for module, attr, sigs, linked in entries:
        new = [s for s in sigs if s not in known.get((module, attr, linked), ())]
        if new:
            out.append((module, attr, new, linked))
    return out


def record_variant(variant: str, scenes: list[str]) -> list:
    """Render ``scenes`` (paths of .npz files) small into the current, empty NUMBA_CACHE_DIR and
    return this variant's plan entries: every DRT kernel compiled, with its signatures and its
    form (linked into other kernels or called from Python), in the order the compiler finished
    them (by their cache index files' times: callees before callers)."""
    from . import render as render_mod
    from .loaders import load_scene

    for path in scenes:
        scene = load_scene(path)
        scene = replace(scene, render=replace(scene.render, width=16, height=12, border=None))
        film = render_mod.render(scene, spp=1, threads=1)
        # the passes every output reads (the CLI's EXR, Blender's result, the viewport): their
        # kernels compile on the helper not compiling `shade`, instead of after the render
        _passes = (film.combined, film.normal, film.albedo, film.variance)
    entries = []
    for module, attr, linked, dispatcher in _compiled_kernels():
        try:
            finished = os.path.getmtime(dispatcher._cache._cache_file._index_path)
        except (AttributeError, OSError):
            finished = float("inf")
        entries.append((finished, module, attr, list(dispatcher.signatures), linked))
    entries.sort(key=lambda e: e[0])
    return [(m, a, s, linked) for _, m, a, s, linked in entries]


def _compiled_kernels():
    """(module relative to the package, attr, linked, dispatcher) of every form of every DRT
    kernel this process has compiled (or loaded) at least one signature of."""
    from .kernels import LazyKernel

    for name, module in list(sys.modules.items()):
        if not (name == PACKAGE or name.startswith(PACKAGE + ".")):
            continue
        for attr, obj in list(vars(module).items()):
            if not isinstance(obj, LazyKernel) or obj.__module__ != name:
                continue
            for linked, dispatcher in ((False, obj._dispatcher), (True, obj._linked)):
                if dispatcher is not None and dispatcher.signatures:
                    yield name[len(PACKAGE) + 1:], attr, linked, dispatcher


def record_callees(entries: list) -> set:
    """Compile the critical entry of ``entries`` (`critical_index`) alone, into the current
    empty NUMBA_CACHE_DIR, and return its call graph: the (module, attr, linked) of every
    kernel form that compiled on the way, itself included."""
    split = critical_index(entries)
    if split is not None:
        module, attr, sigs, linked = entries[split]
        kern = _resolve(module, attr)
        dispatcher = kern.linked() if linked else kern.dispatcher()
        for sig in sigs:
            dispatcher.compile(sig)
    return {(module, attr, linked) for module, attr, linked, _ in _compiled_kernels()}


def _main(argv=None) -> int:
    import argparse
    import shutil
    import tempfile

    ap = argparse.ArgumentParser(description="Write the kernel compile plan (compile_plan.pkl) from "
                                             "small renders of the shipped scenes into empty caches.")
    ap.add_argument("--scenes", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "blend_scenes"))
    ap.add_argument("--out", default=PLAN_FILE)
    ap.add_argument("--record", nargs=2, metavar=("VARIANT", "OUT"), help=argparse.SUPPRESS)
    ap.add_argument("--callees", nargs=2, metavar=("ENTRIES", "OUT"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.callees:  # a child: the critical kernel's call graph, into the empty cache its parent chose
        with open(args.callees[0], "rb") as f:
            entries = pickle.load(f)
        with open(args.callees[1], "wb") as f:
            pickle.dump(record_callees(entries), f)
        return 0
    if args.record:  # a child: one variant or feature, into the empty cache its parent chose
        label = args.record[0]
        if label.startswith(FEATURE_PREFIX):
            variant, names = "", (PLAN_FEATURES[label[len(FEATURE_PREFIX):]],)
        else:
            variant = "" if label == "plain" else label
            names = PLAN_SCENES[variant]
        scenes = [os.path.join(args.scenes, f"{s}.npz") for s in names]
        with open(args.record[1], "wb") as f:
            pickle.dump(record_variant(variant, scenes), f)
        return 0
    from .kernels import compiler_version

    variants = {}
    with tempfile.TemporaryDirectory() as tmp:
        for variant in [*PLAN_SCENES, *(FEATURE_PREFIX + f for f in PLAN_FEATURES)]:
            label = variant or "plain"
            cache = os.path.join(tmp, label)
            os.makedirs(cache)
            out = os.path.join(tmp, f"{label}.pkl")
            env = {k: v for k, v in os.environ.items() if k != "DRT_SET_NUMBA_CACHE_DIR"}
            env["NUMBA_CACHE_DIR"] = cache
            env[NO_PRECOMPILE_ENV] = "1"
            t0 = time.perf_counter()
            subprocess.run([sys.executable, "-m", f"{PACKAGE}.compile_plan", "--scenes", args.scenes,
                            "--record", label, out], env=env, check=True)
            shutil.rmtree(cache, ignore_errors=True)
            with open(out, "rb") as f:
                variants[variant] = pickle.load(f)
            if variant.startswith(FEATURE_PREFIX):  # only what the plain plan lacks
                variants[variant] = _beyond(variants[variant], variants[""])
            elif critical_index(variants[variant]) is not None:  # its callees first (helper_of)
                os.makedirs(cache)
                graph = os.path.join(tmp, f"{label}.callees.pkl")
                subprocess.run([sys.executable, "-m", f"{PACKAGE}.compile_plan", "--callees", out, graph],
                               env=env, check=True)
                with open(graph, "rb") as f:
                    variants[variant] = critical_first(variants[variant], pickle.load(f))
                shutil.rmtree(cache, ignore_errors=True)
            print(f"{label}: {len(variants[variant])} kernels, "
                  f"{sum(len(s) for _, _, s, _ in variants[variant])} signatures, {time.perf_counter() - t0:.0f} s")
    plan = {"compiler": compiler_version(), "variants": variants}
    with open(args.out, "wb") as f:
        pickle.dump(plan, f, protocol=4)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(_main())
