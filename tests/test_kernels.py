"""The compiled-kernel plumbing: where the cache lives, the first-render notice, and that the
per-source cache key changes with the sources."""

import math
import os
import subprocess
import sys

import pytest

import drt.kernels as kernels

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_cache_dir_follows_drt_cache_dir(monkeypatch, tmp_path):
    monkeypatch.setenv("DRT_CACHE_DIR", str(tmp_path))
    assert kernels.cache_dir() == os.path.join(str(tmp_path), "numba")


def test_compiled_marker(monkeypatch, tmp_path):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    assert not kernels.kernels_compiled()
    kernels.mark_kernels_compiled()
    assert kernels.kernels_compiled()
    # each variant of the stage kernels compiles on its own first use, so has its own mark
    assert not kernels.kernels_compiled("programs")
    kernels.mark_kernels_compiled("programs")
    assert kernels.kernels_compiled("programs") and not kernels.kernels_compiled("media")
    monkeypatch.delenv("NUMBA_CACHE_DIR")
    assert not kernels.kernels_compiled()  # unknown location: every process compiles


def test_source_key_is_stable_and_short():
    assert kernels.source_key() == kernels.source_key()
    assert len(kernels.source_key()) == 16


def _drt_import_graph():
    """{module: set of drt modules it imports} for every module of the drt package (dotted names
    relative to ``drt``; the package itself is ``""``), from the sources' import statements."""
    import ast

    root = os.path.join(REPO, "core", "drt")
    files = {}
    for folder, _dirs, names in os.walk(root):
        for name in names:
            if name.endswith(".py"):
                parts = os.path.relpath(os.path.join(folder, name), root)[:-3].split(os.sep)
                is_pkg = parts[-1] == "__init__"
                files[".".join(parts[:-1] if is_pkg else parts)] = (os.path.join(folder, name), is_pkg)
    graph = {}
    for module, (path, is_pkg) in files.items():
        package = module.split(".") if module else []
        if not is_pkg:
            package = package[:-1]
        deps = set()
        with open(path, encoding="utf-8") as f:
            tree = ast.parse(f.read())
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package[:len(package) - node.level + 1]
                    target = ".".join(base + (node.module.split(".") if node.module else []))
                elif node.module == "drt" or (node.module or "").startswith("drt."):
                    target = node.module[4:]
                else:
                    continue
                for name in [target] + [f"{target}.{a.name}".strip(".") for a in node.names]:
                    if name in files:
                        deps.add(name)
            elif isinstance(node, ast.Import):
                deps.update(a.name[4:] for a in node.names if a.name[4:] in files and a.name.startswith("drt."))
        graph[module] = deps
    return graph


def test_front_end_modules_are_outside_the_kernel_sources():
    """Editing a FRONT_END_MODULES file keeps the kernel cache, which is only safe if no module
    with kernel code imports it (directly or through others) and it defines no kernels itself."""
    graph = _drt_import_graph()
    assert kernels.FRONT_END_MODULES <= set(graph)
    root = os.path.join(REPO, "core", "drt")
    for module in kernels.FRONT_END_MODULES:
        path = os.path.join(root, *module.split("."))
        path = os.path.join(path, "__init__.py") if os.path.isdir(path) else path + ".py"
        with open(path, encoding="utf-8") as f:
            source = f.read()
        assert "numba" not in source and "@kernel" not in source and "inline_kernel" not in source, module
    kernel_modules = {m for m in graph if m not in kernels.FRONT_END_MODULES and m != "__main__"}
    for module in kernel_modules:
        reached, stack = set(), [module]
        while stack:
            m = stack.pop()
            if m not in reached:
                reached.add(m)
                stack.extend(graph[m])
        assert not reached & kernels.FRONT_END_MODULES, (module, reached & kernels.FRONT_END_MODULES)


def test_old_cache_folders_are_pruned(tmp_path):
    old, fresh, keep = tmp_path / "old", tmp_path / "fresh", tmp_path / "keep"
    for d in (old, fresh, keep):
        d.mkdir()
    long_ago = 1e9  # 2001
    os.utime(old, (long_ago, long_ago))
    os.utime(keep, (long_ago, long_ago))
    kernels._prune_old_caches(str(tmp_path), "keep")
    assert not old.exists() and fresh.exists() and keep.exists()


@pytest.mark.slow
def test_first_render_says_it_compiles_and_the_second_starts_warm(tmp_path):
    """A fresh cache (a new install): the CLI announces the compilation on stderr and renders;
    the next run finds the cache and says nothing."""
    env = dict(os.environ, DRT_CACHE_DIR=str(tmp_path / "cache"))
    env.pop("NUMBA_CACHE_DIR", None)
    cmd = [sys.executable, "-m", "drt", "render", os.path.join(REPO, "blend_scenes", "cornell_box.npz"),
           "-o", str(tmp_path / "out.exr"), "--spp", "1"]
    first = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
    assert first.returncode == 0, first.stderr
    assert "compiling DRT's render kernels" in first.stderr
    second = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
    assert second.returncode == 0, second.stderr
    assert "compiling" not in second.stderr


_COMPILE_ONE_KERNEL = """
import numpy as np
from drt.sampling import pixel_filter as pf
pf.lerp_table(0.5, np.array([0.0, 2.0]))
d = pf.lerp_table
print(sum(d.stats.cache_hits.values()), sum(d.stats.cache_misses.values()), d.stats.cache_path)
"""


def test_two_copies_of_the_sources_share_one_compiled_cache(tmp_path):
    """A clone, a pip install and the add-on Blender installed are copies of the same sources
    in different folders: the second copy loads what the first compiled (numba alone keys its
    cache on each file's absolute folder and would compile everything again)."""
    import shutil

    env = dict(os.environ, DRT_CACHE_DIR=str(tmp_path / "cache"))
    env.pop("NUMBA_CACHE_DIR", None)
    runs = []
    for copy in ("one", "two"):
        shutil.copytree(os.path.join(REPO, "core", "drt"), tmp_path / copy / "drt",
                        ignore=shutil.ignore_patterns("__pycache__"))
        env["PYTHONPATH"] = str(tmp_path / copy)
        out = subprocess.run([sys.executable, "-c", _COMPILE_ONE_KERNEL], env=env, cwd=tmp_path,
                             capture_output=True, text=True, timeout=300)
        assert out.returncode == 0, out.stderr
        hits, misses, path = out.stdout.split()
        runs.append((int(hits), int(misses), path))
    assert runs[0][:2] == (0, 1), runs  # the first copy compiles
    assert runs[1][:2] == (1, 0), runs  # the second loads it
    assert runs[0][2] == runs[1][2] and str(tmp_path / "cache") in runs[0][2]
    assert os.path.join("drt", "sampling") in runs[0][2]
    # imported under another name (the add-on's bundled ``drt_blender.drt``), cached code that
    # names ``drt.…`` modules would not load: that copy keeps a cache of its own
    bundle = tmp_path / "three" / "bundle"
    shutil.copytree(os.path.join(REPO, "core", "drt"), bundle / "drt", ignore=shutil.ignore_patterns("__pycache__"))
    (bundle / "__init__.py").write_text("")
    env["PYTHONPATH"] = str(tmp_path / "three")
    out = subprocess.run([sys.executable, "-c", _COMPILE_ONE_KERNEL.replace("from drt.", "from bundle.drt.")],
                         env=env, cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    hits, misses, path = out.stdout.split()
    assert (int(hits), int(misses)) == (0, 1) and path != runs[0][2]
    # a child of a DRT process inherits NUMBA_CACHE_DIR (the viewport's warm-up Blender, a
    # test's subprocess): DRT's own value is recomputed, so the child finds the shared cache
    env["PYTHONPATH"] = str(tmp_path / "two")
    env["NUMBA_CACHE_DIR"] = env["DRT_SET_NUMBA_CACHE_DIR"] = str(tmp_path / "parents_choice")
    out = subprocess.run([sys.executable, "-c", _COMPILE_ONE_KERNEL], env=env, cwd=tmp_path,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    hits, misses, path = out.stdout.split()
    assert (int(hits), int(misses)) == (1, 0) and path == runs[0][2]
    # a user's own NUMBA_CACHE_DIR is kept
    env["DRT_SET_NUMBA_CACHE_DIR"] = "something else"
    out = subprocess.run([sys.executable, "-c", _COMPILE_ONE_KERNEL], env=env, cwd=tmp_path,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert str(tmp_path / "parents_choice") in out.stdout.split()[2]


_LOAD_THEN_LINK = """
import numba, numpy as np
from drt import kernels
from drt.sampling import pixel_filter as pf
ys = np.array([0.0, 2.0])
first = pf.lerp_table(0.25, ys)  # loaded from the cache: its linking bitcode is not parsed
linked = pf.lerp_table.linked()
linked.compile((numba.float64, numba.float64[::1]))  # the form kernels call, loaded too
deferred = len(kernels._UNPARSED)

@numba.njit
def twice(x, ys):  # a new compile that links the loaded kernel in: the bitcode is parsed now
    return 2.0 * pf.lerp_table(x, ys)

lib = next(iter(linked.overloads.values())).library
print(sum(pf.lerp_table.stats.cache_hits.values()) + sum(linked.stats.cache_hits.values()), deferred,
      first, twice(0.25, ys), len(kernels._UNPARSED), len(linked.overloads),
      lib.__dict__.get("_drt_linked", False) and getattr(lib, "_compiled_object", None) is None)
"""

_COMPILE_LINKED_FORM = """
import numba
from drt.sampling import pixel_filter as pf
pf.lerp_table.linked().compile((numba.float64, numba.float64[::1]))
"""


def test_a_loaded_kernel_links_into_a_later_compile(tmp_path):
    """A cached kernel loads without parsing the LLVM bitcode stored for linking it elsewhere
    (``drt.kernels._defer_linking_bitcode``, ~0.2 s of a warm render's start-up); a kernel
    compiled afterwards that calls it links its linked form — cached as LLVM bitcode, no machine
    code (``_no_machine_code_for_linked_kernels``) — and computes the same value."""
    env = dict(os.environ, DRT_CACHE_DIR=str(tmp_path / "cache"))
    env.pop("NUMBA_CACHE_DIR", None)
    for code in (_COMPILE_ONE_KERNEL, _COMPILE_LINKED_FORM):
        out = subprocess.run([sys.executable, "-c", code], env=env, cwd=tmp_path,
                             capture_output=True, text=True, timeout=300)
        assert out.returncode == 0, out.stderr
    out = subprocess.run([sys.executable, "-c", _LOAD_THEN_LINK], env=env, cwd=tmp_path,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    hit, deferred, first, twice, left, overloads, bitcode_only = out.stdout.split()
    # both forms loaded from the cache: the Python-called one as machine code, its bitcode not
    # parsed; the linked one, typed inside `twice`, as bitcode only, and it is the one linked
    assert hit == "2" and int(deferred) >= 1 and overloads == "1" and bitcode_only == "True"
    assert float(first) == 0.5 and float(twice) == 1.0
    assert int(left) == int(deferred)  # linking never needed the Python form's bitcode


def test_a_scene_without_media_or_programs_runs_shade_without_their_code():
    """Model no more than a scene needs, at compile time too: a scene with no participating
    media and no material or world program hands ``shade`` (and the shadow rays' ``shadow_step``)
    None for both, so numba compiles a variant that holds neither the media code nor the program
    interpreter (their branches are resolved away at compile time). That variant renders exactly
    what the full one renders for the same scene: here a Cornell box with a transparent card
    (IOR-1 glass), so the shadow rays go through ``shadow_step`` as well."""
    import numpy as np

    from drt import path_stages
    from drt.render import prepare, render
    from drt.scene import scene_from_dict
    from scene_builders import add_material, add_mesh, cornell_box, quad

    h, a = cornell_box(24, 24, spp=4)
    card = add_material(h, "Card", [{"type": "GLASS", "color": [0.8, 0.6, 0.4], "ior": 1.0, "roughness": 0.0}])
    add_mesh(h, a, "card", *quad((0.0, -0.5, 0.9), (0.4, 0, 0), (0, 0, 0.4)), material=card)
    scene = scene_from_dict(h, a)
    ctx = prepare(scene)
    integ = ctx.integrator
    assert integ.media_arg is None and integ.programs_arg is None
    assert integ.transparent.any()
    lean = render(scene, context=ctx, threads=1).combined
    assert any(str(s).count("none") >= 2 for s in path_stages.shade.signatures)
    integ.media_arg, integ.programs_arg = integ.media, integ.programs  # the full variant
    full = render(scene, context=ctx, threads=1).combined
    assert np.array_equal(lean, full)
    assert lean[..., :3].mean() > 0.01


def test_a_scene_with_homogeneous_media_and_no_programs_runs_shade_without_the_interpreter():
    """The same for the program interpreter alone: a scene whose media are all homogeneous and
    whose materials have no program (the shipped fog box) runs the media variant with ``pd``
    None — the heterogeneous-density code, which runs programs, is resolved away with it — and
    renders exactly what the variant with the interpreter renders."""
    from dataclasses import replace

    import numpy as np

    from drt.render import prepare, render
    from drt.scene_file import load_scene

    scene = load_scene(os.path.join(REPO, "blend_scenes", "volume_fog.npz"))
    scene = replace(scene, render=replace(scene.render, width=24, height=16, border=None))
    ctx = prepare(scene)
    integ = ctx.integrator
    assert integ.media_arg is not None and integ.programs_arg is None
    assert integ.kernel_variant == "media"
    lean = render(scene, spp=4, context=ctx, threads=1).combined
    integ.programs_arg = integ.programs  # the variant with media and programs
    full = render(scene, spp=4, context=ctx, threads=1).combined
    assert np.array_equal(lean, full)
    assert lean[..., :3].mean() > 0.01


def test_a_scene_with_programs_but_no_procedural_texture_compiles_shade_without_them():
    """The same for the procedural textures: the shipped textured scene (images, checker,
    gradient, ramp) has programs but no procedural opcode, so its ``ProgramData.procedural`` is
    None and ``procedural_op`` compiles to nothing in its variant; it renders exactly what the
    variant with the procedural textures renders."""
    from dataclasses import replace

    import numpy as np

    from drt.render import prepare, render
    from drt.scene_file import load_scene

    scene = load_scene(os.path.join(REPO, "blend_scenes", "textured.npz"))
    scene = replace(scene, render=replace(scene.render, width=24, height=16, border=None))
    ctx = prepare(scene)
    integ = ctx.integrator
    assert integ.programs_arg is not None and integ.programs_arg.procedural is None
    assert integ.kernel_variant == "programs"
    lean = render(scene, spp=2, context=ctx, threads=1).combined
    integ.programs_arg = integ.programs_arg._replace(procedural=True)
    full = render(scene, spp=2, context=ctx, threads=1).combined
    assert np.array_equal(lean, full)
    assert lean[..., :3].mean() > 0.01


def test_kernel_variant_names():
    """Three switches; the procedural textures only with programs."""
    assert kernels.kernel_variant(False, False) == ""
    assert kernels.kernel_variant(False, False, True) == ""  # no programs: nothing procedural
    assert kernels.kernel_variant(False, True) == "programs"
    assert kernels.kernel_variant(False, True, True) == "programs-procedural"
    assert kernels.kernel_variant(True, False, True) == "media"
    assert kernels.kernel_variant(True, True) == "media-programs"
    assert kernels.kernel_variant(True, True, True) == "media-programs-procedural"
    names = {kernels.kernel_variant(m, p, q) for m in (False, True) for p in (False, True) for q in (False, True)}
    assert names == set(kernels.KERNEL_VARIANTS)


@pytest.mark.parametrize("name, variant", [("cornell_box", ""), ("textured", "programs"), ("hdri", "programs"),
                                           ("procedural", "programs-procedural"), ("cutout", "programs-procedural"),
                                           ("volume_fog", "media"), ("volume_liquid", "media-programs"),
                                           ("volume_noise", "media-programs-procedural")])
def test_the_notice_and_the_render_agree_on_a_scenes_kernel_variant(name, variant):
    """The CLI and the add-on decide from the scene whether its first render will compile
    (``scene_kernel_variant``); the render marks the variant its ``Integrator`` ran."""
    from drt.render import prepare
    from drt.scene_file import load_scene

    scene = load_scene(os.path.join(REPO, "blend_scenes", f"{name}.npz"))
    assert kernels.scene_kernel_variant(scene) == variant
    assert prepare(scene).integrator.kernel_variant == variant


#: the body of a generated function too large for LLVM to inline on size alone (60 branches of
#: transcendental maths on ``s`` and ``x``, returning ``s``)
_BRANCHY_BODY = "".join(
    f"    if s > {k}.5:\n        s = math.sin(s * x + {k}) + math.sqrt(abs(s) + {k})\n"
    f"    else:\n        s = math.cos(s - x) * {k + 1}.25\n" for k in range(60)) + "    return s\n"


def test_a_kernel_passes_a_callee_only_the_arrays_it_reads():
    """numba passes each array of a namedtuple argument as ~7 scalars; a callee taking a scene
    table of 40 arrays but reading one must not cost a ~280-word call in its caller's machine
    code (``drt.kernels._internalize_linked_kernels``: the linked copy is private to the
    caller's module, so LLVM drops the unread arguments or inlines the call). Checked on the
    caller's optimised LLVM IR: no call left in it passes more than a handful of arguments, and
    the result is the callee's. numba's own linking, which a plain ``numba.njit`` function (not
    DRT's) keeps, leaves two 284-argument calls here."""
    import re
    from collections import namedtuple

    import numpy as np

    Table = namedtuple("Table", [f"a{i}" for i in range(40)])
    table = Table(*(np.full(4, float(i)) for i in range(40)))
    # a callee too large for LLVM to inline on size alone
    source = "def callee(t, i, x):\n    s = t.a7[i % 4]\n" + _BRANCHY_BODY
    namespace = {"math": math}
    exec(source, namespace)  # noqa: S102 - generated test code

    def compiled_pair(name, decorate):
        """(callee, caller named ``name``) compiled by ``decorate``; the caller calls it twice."""
        scope = {"callee": decorate(namespace["callee"])}
        exec(f"def {name}(t, n):\n    acc = 0.0\n    for i in range(n):\n"  # noqa: S102
             "        acc += callee(t, i, 0.5 * i) + callee(t, i + 1, 0.25 * i)\n    return acc\n", scope)
        return decorate(scope[name])

    caller = compiled_pair("caller", lambda f: kernels.kernel(f, cache=False))

    expected = sum(namespace["callee"](table, i, 0.5 * i) + namespace["callee"](table, i + 1, 0.25 * i)
                   for i in range(5))
    assert caller(table, 5) == pytest.approx(expected, rel=1e-12)

    def widest_call(dispatcher):
        ir = next(iter(dispatcher.inspect_llvm().values()))
        return max((line.count(",") + 1 for line in ir.splitlines()
                    if re.search(r"call [^@]*@\S*6calleeB", line)), default=0)  # (its mangled name)

    assert widest_call(caller) < 20, f"a call to callee passes {widest_call(caller)} arguments"

    # numba code that is not DRT's (another add-on in Blender's process) keeps numba's own linking
    import numba

    others = compiled_pair("others", numba.njit(cache=False))
    assert others(table, 5) == pytest.approx(expected, rel=1e-12)
    assert widest_call(others) > 200


def test_a_kernel_reached_along_two_call_paths_is_compiled_once_in_its_caller():
    """A kernel that two linked kernels both call is one function in the module of the kernel
    Python calls, not one copy per path (``drt.kernels._internalize_linked_kernels`` makes the
    linked copies private only in a module with an entry point: a linked form's own module
    keeps them mergeable). Duplicates had made `shade` with material programs compile the
    interpreter three times over (docs/kernels.md)."""
    import re

    source = "def shared(x):\n    s = x\n" + _BRANCHY_BODY
    scope = {"math": math}
    exec(source, scope)  # noqa: S102 - generated test code
    scope["shared"] = kernels.kernel(scope["shared"], cache=False)
    exec("def via_a(x):\n    return shared(x) + shared(x + 1.0)\n"  # noqa: S102
         "def via_b(x):\n    return 2.0 * shared(x - 1.0) - shared(x * 0.5)\n", scope)
    scope["via_a"] = kernels.kernel(scope["via_a"], cache=False)
    scope["via_b"] = kernels.kernel(scope["via_b"], cache=False)
    exec("def top(x):\n    return via_a(x) + via_b(x)\n", scope)  # noqa: S102
    top = kernels.kernel(scope["top"], cache=False)

    def plain(x):
        s = scope["shared"].py_func
        return s(x) + s(x + 1.0) + 2.0 * s(x - 1.0) - s(x * 0.5)

    assert top(0.3) == pytest.approx(plain(0.3), rel=1e-12)
    ir = next(iter(top.dispatcher().inspect_llvm().values()))
    copies = [line for line in ir.splitlines() if re.match(r"define [^@]*@\S*6sharedB", line)]
    assert len(copies) == 1, f"{len(copies)} copies of the shared callee"


def test_kernels_are_built_on_first_use():
    """`kernel` returns a LazyKernel: importing the renderer builds no numba dispatcher (they
    cost ~0.15 ms each at start-up), and a kernel is typed, called and compiled into another
    kernel through the dispatcher it builds when first asked."""
    code = ("import gc, drt.render, drt.film, drt.cli\n"
            "from drt.kernels import LazyKernel\n"
            "ks = [o for o in gc.get_objects() if isinstance(o, LazyKernel)]\n"
            "print(len(ks), sum(k._dispatcher is not None for k in ks))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    n_kernels, n_built = (int(v) for v in out.stdout.split())
    assert n_kernels > 300 and n_built == 0

    @kernels.kernel
    def twice(x):
        return 2.0 * x

    @kernels.kernel
    def twice_plus_one(x):
        return twice(x) + 1.0

    assert twice._dispatcher is None and twice.py_func(3.0) == 6.0 and twice._dispatcher is None
    assert twice_plus_one(3.0) == 7.0  # typing the callee through the proxy builds its linked form
    assert twice._linked is not None and len(twice.linked().overloads) == 1
    assert twice._dispatcher is None  # no Python entry point compiled for a kernel only kernels call
    linked_lib = next(iter(twice.linked().overloads.values())).library
    assert linked_lib._drt_linked and getattr(linked_lib, "_compiled_object", None) is None  # nor machine code
    assert twice(3.0) == 6.0 and len(twice.overloads) == 1
    assert not next(iter(twice.overloads.values())).library.__dict__.get("_drt_linked", False)
    assert twice.__name__ == "twice" and "LazyKernel" not in repr(twice)


def test_good_samples_drops_nan_inf_and_overflowing_radiance():
    import numpy as np

    from drt.path_stages import MAX_SAMPLE_RADIANCE, good_samples

    rows = np.array([[1.0, 2.0, 3.0], [np.nan, 0.0, 0.0], [0.0, np.inf, 0.0], [0.0, 0.0, -np.inf],
                     [MAX_SAMPLE_RADIANCE, -MAX_SAMPLE_RADIANCE, 0.0], [0.0, 2e18, 0.0], [-0.0, 0.0, 1e-300]])
    good = np.empty(len(rows), dtype=bool)
    assert good_samples(rows, good) == 3
    expect = np.all(np.isfinite(rows) & (np.abs(rows) <= MAX_SAMPLE_RADIANCE), axis=1)
    assert good.tolist() == expect.tolist() == [True, False, False, False, True, False, True]
