"""Compiled kernels: the one decorator every per-sample function of the renderer uses.

DRT's per-sample work (camera rays, BSDFs, lights, MIS, film accumulation) is written as scalar
Python functions compiled by numba. ``@kernel`` is ``numba.njit`` with the project's fixed
choices:

- ``nogil=True``: a compiled call releases the GIL, so the render loop's Python threads run
  kernels on every core of one process (also inside Blender, where worker processes cannot be
  spawned).
- ``cache=True``: machine code is cached on disk, so only the very first render of an install
  compiles (tens of seconds); later processes load it in well under a second. The cache lives in
  a per-user directory (``cache_dir()``), never beside the sources: an installed Blender
  extension's folder may be read-only. One sub-folder per state of the sources
  (``source_key``), because numba does not notice when a kernel called from another file
  changed.
- ``error_model="numpy"``: division by zero gives inf/nan as numpy does instead of raising, so
  kernels keep the numpy code's IEEE semantics (and skip a branch per division).
- no ``fastmath``: NaN checks and the order of floating-point operations must survive compilation
  (renders are bit-identical for a seed).
- ``_nrt=False`` (numba's reference-counting runtime off): a kernel taking a per-scene namedtuple
  of ~50 arrays otherwise increments and decrements every array's count atomically on each call
  where numba's refcount pruning gives up (~0.6 µs per call, measured on `world_pdf`). Kernels
  never allocate arrays (callers pass preallocated outputs), so nothing needs the runtime; an
  allocation inside a kernel is a compile error. ``_nrt`` is a private numba option, hence the
  pinned numba range in pyproject.toml.

Conventions shared by all kernels (see docs/kernels.md): a 3-vector is a tuple ``(x, y, z)`` of
float64 (``drt.kernels.vec3``); per-scene read-only data (materials, lights, camera, sampler) is
a namedtuple of numpy arrays built once in Python and passed as the first argument.
"""

from __future__ import annotations

import functools
import os
import sys
import threading


def cache_dir() -> str:
    """The per-user directory of numba's compiled-kernel cache: ``$DRT_CACHE_DIR`` if set, else
    the platform's user cache folder (``$XDG_CACHE_HOME`` or ``~/.cache`` on Linux,
    ``~/Library/Caches`` on macOS, ``%LOCALAPPDATA%`` on Windows) + ``drt/numba``."""
    explicit = os.environ.get("DRT_CACHE_DIR")
    if explicit:
        return os.path.join(explicit, "numba")
    if sys.platform == "win32":
        base = os.environ.get("LOCALAPPDATA") or os.path.expanduser("~\\AppData\\Local")
    elif sys.platform == "darwin":
        base = os.path.expanduser("~/Library/Caches")
    else:
        base = os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache")
    return os.path.join(base, "drt", "numba")


#: top-level modules of ``drt`` that hold no kernel code and that no kernel module imports, so
#: editing them does not invalidate the compiled-kernel cache (checked by tests/test_kernels.py)
FRONT_END_MODULES = frozenset({"__main__", "bench", "cli", "compile_plan", "denoise", "estimators", "exr",
                               "interactive", "loaders", "integrator", "preview", "render",
                               "scene_file", "frames",
                               "farm", "farm._remote", "farm.cli", "farm.client", "farm.plan",
                               "farm.tasks"})


def _module_name(root: str, path: str) -> str:
    """Dotted module name of a file under the ``drt`` folder ``root`` ("farm.client", "farm")."""
    parts = os.path.relpath(path, root)[:-3].split(os.sep)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def source_key() -> str:
    """A short hash of the ``drt`` source files that kernels are compiled from, of the
    numba/Python versions and of the name the package is imported under.

    numba's cache checks only the stamp of a kernel's *own* file, not of the kernels it calls in
    other files: after an upgrade (or an edit) a cached caller could keep stale inlined code. The
    cache therefore lives in a folder per source state, and any change to kernel code recompiles
    everything. Edits to the front-end modules (``FRONT_END_MODULES``: command line, render
    loop, file formats) keep the cache; tests/test_kernels.py checks that no kernel module
    imports them."""
    import hashlib

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    # the package's import name too ("drt", or "drt_blender.drt" inside the add-on): cached
    # kernels refer to their modules by name, so copies imported under different names cannot
    # share a cache (docs/kernels.md)
    package = __name__.rpartition(".")[0]
    h = hashlib.sha1(f"{sys.version_info[:2]}|{_numba_version()}|{package}".encode())
    for folder, dirs, files in sorted(os.walk(root)):
        dirs.sort()
        for name in sorted(files):
            path = os.path.join(folder, name)
            if name.endswith(".py") and _module_name(root, path) not in FRONT_END_MODULES:
                h.update(os.path.relpath(path, root).encode())
                try:
                    with open(path, "rb") as f:
                        h.update(f.read())
                except OSError:
                    pass
    return h.hexdigest()[:16]


def _numba_version() -> str:
    try:
        from importlib.metadata import version

        return version("numba")
    except Exception:  # noqa: BLE001 - metadata missing (vendored copy): fall back to the import
        import numba

        return numba.__version__


def compiler_version() -> str:
    """The kernel compiler's minor version ("0.68"): what compiled code and its recorded argument
    types are tied to (numba's own cache index holds the full version)."""
    return _numba_version().rsplit(".", 1)[0]


STALE_CACHE_DAYS = 14


def _prune_old_caches(parent: str, keep: str) -> None:
    """Remove cache folders of other source states unused for STALE_CACHE_DAYS (several DRT
    versions — an extension and a CLI install — may share the parent and stay warm)."""
    import shutil
    import time

    try:
        entries = os.listdir(parent)
    except OSError:
        return
    for name in entries:
        path = os.path.join(parent, name)
        if name == keep or not os.path.isdir(path):
            continue
        try:
            if time.time() - os.path.getmtime(path) > STALE_CACHE_DAYS * 86400:
                shutil.rmtree(path, ignore_errors=True)
        except OSError:
            pass


#: the source-keyed cache folder this process chose (None: the user set NUMBA_CACHE_DIR, or
#: the user cache folder is not writable)
_KEYED_CACHE_DIR = None


#: environment variable holding the NUMBA_CACHE_DIR value DRT itself set, so that a child
#: process (a viewport warm-up Blender, a test's subprocess) inheriting NUMBA_CACHE_DIR can tell
#: DRT's choice — which it recomputes for its own sources and import name — from a user's
_DRT_SET_MARK = "DRT_SET_NUMBA_CACHE_DIR"


def _configure_numba_cache() -> None:
    """Point numba's cache at ``cache_dir()/<source_key()>`` unless the user chose one
    (NUMBA_CACHE_DIR not set by a DRT process)."""
    inherited = os.environ.get("NUMBA_CACHE_DIR")
    ours = bool(inherited) and inherited == os.environ.get(_DRT_SET_MARK)
    if inherited and not ours:
        return
    parent = cache_dir()
    key = source_key()
    path = os.path.join(parent, key)
    fresh = not os.path.isdir(path)
    try:
        os.makedirs(path, exist_ok=True)
        os.utime(path)  # marks the folder as in use for _prune_old_caches
    except OSError:
        if ours:  # another process's folder, maybe of other sources: not for this one
            os.environ.pop("NUMBA_CACHE_DIR", None)
        return  # numba falls back to its own locations (beside the sources or the user dir)
    if fresh:
        _prune_old_caches(parent, key)
    os.environ["NUMBA_CACHE_DIR"] = path
    os.environ[_DRT_SET_MARK] = path
    global _KEYED_CACHE_DIR
    _KEYED_CACHE_DIR = path
    if "numba" in sys.modules:  # imported earlier (another add-on in Blender): set it live
        import numba.core.config as _config

        _config.CACHE_DIR = path
    _use_prebuilt_kernels(key, path)


#: the CPU target (name, features) of the shipped kernels this process uses, or None: it
#: compiles for its own CPU (drt.kernels.prebuilt)
PREBUILT_TARGET = None


def _use_prebuilt_kernels(key: str, cache: str) -> None:
    """Use the kernels shipped with this copy of the package for this source key, if any and if
    they run on this CPU: copy them into the cache folder and compile for their CPU target
    (drt.kernels.prebuilt)."""
    from . import prebuilt

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    chosen = prebuilt.choose(root, key)
    if chosen is None:
        prebuilt.forget()
        return
    folder, target = chosen
    if prebuilt.seed(folder, cache) and prebuilt.apply(target):
        global PREBUILT_TARGET
        PREBUILT_TARGET = target
    else:
        prebuilt.forget()


_configure_numba_cache()

from . import typing_overheads  # noqa: E402

typing_overheads.plain_error_messages()

import numba  # noqa: E402  (after the cache location and the error messages are set)

typing_overheads.skip_typing_overheads()


def _load_cached_kernels_without_registry_refresh() -> None:
    """Skip numba's target-context refresh when a kernel is loaded from the cache.

    numba's ``Cache.load_overload`` first calls ``target_context.refresh()``, which imports and
    installs every typing and lowering registry numba has (~0.3 s, a third of a warm CLI run's
    start-up, measured with cProfile). Rebuilding cached machine code needs none of them: it
    unserialises the library and links it. On a cache miss the registries are refreshed here
    and again by numba's compiler, so compiling is unchanged. Private numba API (pinned range in
    pyproject.toml); if it changes shape, numba's own loader is kept."""
    from numba.core import caching

    cache = caching.Cache
    if getattr(cache.load_overload, "_drt", False) or not hasattr(cache, "_load_overload") \
            or not hasattr(cache, "_guard_against_spurious_io_errors"):
        return

    def load_overload(self, sig, target_context):
        data = None
        with self._guard_against_spurious_io_errors():
            data = self._load_overload(sig, target_context)
        if data is None:
            target_context.refresh()  # numba compiles next: give it its registries
        return data

    load_overload._drt = True
    load_overload.__doc__ = cache.load_overload.__doc__
    cache.load_overload = load_overload


_load_cached_kernels_without_registry_refresh()


#: how the names of numba's entry points of a compiled function begin: the CPython wrapper
#: (``cpython`` prepended to the mangled name) and the C-callable one
_ENTRY_POINT_PREFIXES = ("_ZN7cpython", "cfunc.")


def _defines_entry_point(module) -> bool:
    """Whether an LLVM module defines a CPython or C entry point (a kernel Python calls)."""
    return any(fn.name.startswith(_ENTRY_POINT_PREFIXES) and not fn.is_declaration for fn in module.functions)


#: cached libraries loaded without parsing their linking bitcode yet (``_defer_linking_bitcode``)
_UNPARSED = None


def _defer_linking_bitcode() -> None:
    """Load a cached kernel's machine code without parsing the LLVM bitcode stored beside it.

    numba caches a kernel as its object code plus the bitcode of its whole module, kept so that a
    kernel compiled later can link it in; loading parses that bitcode and walks every function
    and global in it to record their names. For DRT's kernels that was ~0.19 of the ~0.25 s a
    warm render spends loading the six kernels it calls from Python (`shade`'s module holds
    every lobe, light and medium inlined; cProfile, Cornell box at 1 spp). A render that only
    loads cached kernels never links them, so the bitcode is parsed when something first needs
    it: numba linking the library into a new compile (``_get_module_for_linking``), or asking
    whether a symbol is defined that the loaded machine code does not answer for. The symbol
    check for the kernel's own entry points asks the execution engine, which already holds the
    object code. Private numba API (pinned range in pyproject.toml); if it changes shape,
    numba's own loader is kept."""
    import weakref

    from numba.core import codegen

    lib_cls = getattr(codegen, "CPUCodeLibrary", None)
    engine_cls = getattr(codegen, "JitEngine", None)
    if lib_cls is None or engine_cls is None or getattr(lib_cls._unserialize, "_drt", False) \
            or not all(hasattr(lib_cls, a) for a in ("_get_module_for_linking", "_finalize_final_module",
                                                     "enable_object_caching", "_set_compiled_object")) \
            or not all(hasattr(engine_cls, a) for a in ("is_symbol_defined", "_load_defined_symbols")):
        return
    global _UNPARSED
    _UNPARSED = weakref.WeakSet()
    original_unserialize = lib_cls._unserialize.__func__
    original_linking = lib_cls._get_module_for_linking
    original_defined = engine_cls.is_symbol_defined
    ll = codegen.ll

    def parse(lib):
        bitcode = lib.__dict__.pop("_drt_bitcode", None)
        if bitcode is not None:
            _UNPARSED.discard(lib)
            lib._shared_module = ll.parse_bitcode(bitcode)
            lib._codegen._engine._load_defined_symbols(lib._shared_module)

    def parse_all():
        for lib in list(_UNPARSED):
            parse(lib)

    def _unserialize(cls, codegen_, state):
        name, kind, data = state
        if kind != "object":
            return original_unserialize(cls, codegen_, state)
        object_code, shared_bitcode = data
        self = codegen_.create_library(name)
        self.enable_object_caching()
        self._set_compiled_object(object_code)
        self._drt_bitcode = shared_bitcode
        _UNPARSED.add(self)
        self._finalize_final_module()
        return self

    def _get_module_for_linking(self):
        parse(self)
        return original_linking(self)

    def is_symbol_defined(self, name):
        if original_defined(self, name):
            return True
        if not _UNPARSED:
            return False
        # a function of an already loaded object: the engine knows its address (a name the
        # engine cannot find may still be a global of an unparsed module: parse them all)
        if not name.startswith(".") and self._ee.get_function_address(name):
            self._defined_symbols.add(name)
            return True
        if name.startswith(_ENTRY_POINT_PREFIXES):
            # a wrapper is a function, which the engine would have found: a kernel's linked form
            # (`LazyKernel.linked`) has none, and numba asks for it on every load
            return False
        parse_all()
        return original_defined(self, name)

    _unserialize._drt = True
    lib_cls._unserialize = classmethod(_unserialize)
    lib_cls._get_module_for_linking = _get_module_for_linking
    engine_cls.is_symbol_defined = is_symbol_defined


_defer_linking_bitcode()


#: qualified names of the functions ``@kernel`` compiled (``_internalize_linked_kernels``)
_KERNEL_NAMES = set()


def _internalize_linked_kernels() -> None:
    """Let LLVM see the kernels a kernel calls as its own private functions.

    numba compiles each kernel into a module of its own and links a copy of every kernel it calls
    into it, marked ``linkonce_odr`` (a weak, replaceable definition) so copies merge. LLVM may
    not change the signature of such a function: numba's calling convention passes each array
    of a namedtuple argument as ~7 scalars, so a call taking ``LightData`` or ``MaterialData``
    moved ~150–450 words through the stack even when the callee reads two arrays of it
    (``shade`` of the Cornell box made ~10 such calls a path vertex). Made ``internal`` before
    the module is optimised, the copies are this module's own: LLVM drops the arguments a
    callee never reads, passes the rest in registers where it can and inlines single-call
    callees. Only in a module with an entry point (one Python calls, where machine code is
    made): nothing outside it refers to these copies. A linked form's module (never machine
    code) keeps them ``linkonce_odr``, so that a kernel reached along several call paths merges
    into one copy in its caller instead of arriving privately once per path. Same arithmetic,
    same images (no fast-math; inlining does not reorder floating-point operations); `shade`
    ~15–30 % cheaper (docs/kernels.md). Only modules of DRT's own kernels (``_KERNEL_NAMES``:
    numba names a kernel's module by its qualified name) — numba in a shared process (Blender,
    other add-ons) keeps its own code generation. Private numba API (pinned range in
    pyproject.toml); if it changes shape, numba's own optimisation is kept."""
    from numba.core import codegen

    lib_cls = getattr(codegen, "CPUCodeLibrary", None)
    if lib_cls is None or not hasattr(lib_cls, "_optimize_final_module") \
            or getattr(lib_cls._optimize_final_module, "_drt", False):
        return
    original = lib_cls._optimize_final_module
    weak = codegen.ll.Linkage.linkonce_odr

    def _optimize_final_module(self):
        if self.name in _KERNEL_NAMES and _defines_entry_point(self._final_module):
            for fn in self._final_module.functions:
                if not fn.is_declaration and fn.linkage == weak:
                    fn.linkage = "internal"
        return original(self)

    _optimize_final_module._drt = True
    lib_cls._optimize_final_module = _optimize_final_module


_internalize_linked_kernels()


def _no_machine_code_for_linked_kernels() -> None:
    """Compile a kernel's linked form (`LazyKernel.linked`) to LLVM code only.

    numba finalises every compiled function the same way: it hands the optimised module to its
    execution engine, which compiles it to machine code, and caches that object code. A linked
    form has no entry point: its machine code is never run — every caller links the LLVM code
    in and compiles it again as part of its own module. Here a linked form's module is kept out
    of the engine and cached as its LLVM bitcode (kind ``"drt-linked"``), which is what linking
    reads. A library is a linked form when it is one of DRT's kernels (``_KERNEL_NAMES``), was
    compiled here (not loaded from object code) and its module defines no entry point (numba
    names them ``_ZN7cpython…`` and ``cfunc.…``). numba writes the function's environment
    pointer into the engine's copy of its global after compiling; a linked form has none there
    (nothing reads it), so that write is skipped when the engine does not know the global.
    Private numba API (pinned range in pyproject.toml); if it changes shape, numba's own
    finalisation is kept."""
    from numba.core import codegen

    lib_cls = getattr(codegen, "CPUCodeLibrary", None)
    gen_cls = getattr(codegen, "JITCPUCodegen", None)
    if lib_cls is None or gen_cls is None \
            or getattr(lib_cls._finalize_final_module, "_drt", False) \
            or not all(hasattr(lib_cls, a) for a in ("_finalize_dynamic_globals", "_verify_declare_only_symbols",
                                                     "serialize_using_object_code", "_unserialize")) \
            or not hasattr(gen_cls, "set_env"):
        return
    original_finalize = lib_cls._finalize_final_module
    original_serialize = lib_cls.serialize_using_object_code
    original_unserialize = lib_cls._unserialize.__func__
    original_set_env = gen_cls.set_env
    ll = codegen.ll

    def is_linked_form(lib):
        if lib.name not in _KERNEL_NAMES or getattr(lib, "_compiled_object", None) is not None:
            return False  # (a library loaded from cached object code: its module is empty)
        # (nor a C entry point: a numba ``cfunc`` of the same name elsewhere in the process is
        # called through its address)
        return not _defines_entry_point(lib._final_module)

    def _finalize_final_module(self):
        if not self.__dict__.get("_drt_linked", False) and not is_linked_form(self):
            return original_finalize(self)
        self._drt_linked = True
        self._finalize_dynamic_globals()
        self._verify_declare_only_symbols()
        self._finalized = True

    def serialize_using_object_code(self):
        if not self.__dict__.get("_drt_linked", False):
            return original_serialize(self)
        self._ensure_finalized()
        return (self.name, "drt-linked", self._final_module.as_bitcode())

    def _unserialize(cls, codegen_, state):
        name, kind, data = state
        if kind != "drt-linked":
            return original_unserialize(cls, codegen_, state)
        self = codegen_.create_library(name)
        self._final_module = ll.parse_bitcode(data)
        self._drt_linked = True
        self._finalize_final_module()
        return self

    def set_env(self, env_name, env):
        if self._engine.get_global_value_address(env_name):
            original_set_env(self, env_name, env)

    for f in (_finalize_final_module, serialize_using_object_code, _unserialize, set_env):
        f._drt = True
    lib_cls._finalize_final_module = _finalize_final_module
    lib_cls.serialize_using_object_code = serialize_using_object_code
    lib_cls._unserialize = classmethod(_unserialize)
    gen_cls.set_env = set_env


_no_machine_code_for_linked_kernels()


def _share_the_cache_between_copies_of_drt() -> None:
    """Let every copy of these sources imported under the same name use one compiled cache: a
    git clone and the pip install (``drt``), each legacy add-on folder or test install of the
    add-on (``drt_blender.drt``).

    numba files a kernel's cache under a hash of its source file's *absolute folder*, so each
    copy of identical sources compiled everything again (~10 min of one core, docs/kernels.md).
    Inside the source-keyed folder (``source_key`` hashes every kernel source, Python, numba
    and the package's import name — cached code names its modules, so the add-on's
    ``drt_blender.drt`` keeps a cache apart from the CLI's ``drt``) the file's place *within*
    the package is enough: same key, same sources. numba's
    own per-file check (a hash of the file's contents) and per-signature check (bytecode, CPU)
    still guard every entry. Only for files of this package and only when DRT chose the folder;
    a user-set NUMBA_CACHE_DIR keeps numba's own locations. Private numba API (pinned range in
    pyproject.toml); if it changes shape, numba's locators are kept."""
    from numba.core import caching, config

    base = getattr(caching, "UserProvidedCacheLocator", None) \
        or getattr(caching, "_UserProvidedCacheLocator", None)
    impl = getattr(caching, "CacheImpl", None)
    if _KEYED_CACHE_DIR is None or base is None or impl is None \
            or not isinstance(getattr(impl, "_locator_classes", None), list) \
            or any(getattr(c, "_drt", False) for c in impl._locator_classes):
        return
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

    class PackageRelativeLocator(base):
        """numba's user-folder locator, with the cache sub-folder named by the file's folder
        relative to the ``drt`` package (``drt/materials``) instead of its absolute path."""
        _drt = True

        def __init__(self, py_func, py_file):
            super().__init__(py_func, py_file)
            rel = os.path.relpath(os.path.dirname(os.path.abspath(py_file)), root)
            self._cache_path = os.path.join(config.CACHE_DIR, "drt", *rel.split(os.sep)) \
                if rel != "." else os.path.join(config.CACHE_DIR, "drt")

        @classmethod
        def from_function(cls, py_func, py_file):
            inside = os.path.abspath(py_file).startswith(root + os.sep)
            if not inside or os.path.abspath(config.CACHE_DIR or "") != os.path.abspath(_KEYED_CACHE_DIR):
                return None
            return super().from_function(py_func, py_file)

    impl._locator_classes.insert(0, PackageRelativeLocator)


_share_the_cache_between_copies_of_drt()

_READY_MARK = "compiled"
#: what a user is told before the first render of a version (measured 2026-12-07, twenty-seventh
#: session, on the 2-vCPU development machine, CLI: 20 s for a plain scene, 23 s with homogeneous
#: volumes, 27 s with image textures, ~30 s with procedural ones or with homogeneous volumes and
#: textures, ~40 s with heterogeneous volumes, docs/kernels.md)
COMPILING_NOTICE = ("compiling DRT's render kernels: the first render of this version takes "
                    "about half a minute longer (once per version and machine, and again the first "
                    "time a scene with textures or volumes renders); later renders start in "
                    "about a second")


#: the variants of the stage kernels a scene compiles (``drt.path_stages.shade``): a scene
#: compiles the media code only if it has media, the program interpreter only if it has
#: material or world programs (a heterogeneous medium's density is one), and the procedural
#: textures (Noise, Voronoi, Wave, Magic, Brick, White Noise, curves) only if a program uses one
#: (``ProgramData.procedural``). Each variant's compile plan is recorded from a shipped scene
#: (``drt.compile_plan.PLAN_SCENES``).
KERNEL_VARIANTS = ("", "programs", "programs-procedural", "media", "media-programs", "media-programs-procedural")


def kernel_variant(media: bool, programs: bool, procedural: bool = False) -> str:
    """The name of the stage kernels' variant for a scene with (or without) participating media,
    material or world programs, and procedural textures in them (`KERNEL_VARIANTS`)."""
    procedural = programs and procedural
    return "-".join(name for name, used in (("media", media), ("programs", programs),
                                             ("procedural", procedural)) if used)


def scene_kernel_variant(scene) -> str:
    """Which variant of the stage kernels ``scene`` (a ``drt.scene.Scene``) renders with
    (`kernel_variant`). The same choice as the ``Integrator``'s ``kernel_variant``."""
    from ..materials.program_format import uses_procedural

    mats = getattr(scene, "materials", None) or []
    world = getattr(scene, "world_program", None)
    programs = [m["program"] for m in mats if m.get("program")] + ([world] if world is not None else [])
    media = getattr(scene, "world_volume", None) is not None or any(m.get("volume") for m in mats)
    return kernel_variant(media, bool(programs), any(uses_procedural(p["ops"]) for p in programs))


def _ready_mark(variant: str) -> str:
    return _READY_MARK + (f"-{variant}" if variant else "")


def kernels_compiled(variant: str = "") -> bool:
    """Has a render already compiled and cached the kernels of this source state, in this
    ``variant`` (``scene_kernel_variant``; "": the plain scene's)? (False also when the cache
    location is unknown: then every process compiles.)"""
    path = os.environ.get("NUMBA_CACHE_DIR")
    return bool(path) and os.path.exists(os.path.join(path, _ready_mark(variant)))


def mark_kernels_compiled(variant: str = "") -> None:
    """Record that the render kernels of ``variant`` are in the cache (called after a render
    finished)."""
    path = os.environ.get("NUMBA_CACHE_DIR")
    if path and not os.path.exists(os.path.join(path, _ready_mark(variant))):
        try:
            with open(os.path.join(path, _ready_mark(variant)), "w") as f:
                f.write(f"numba {numba.__version__}\n")
        except OSError:
            pass

#: ``forceinline=False`` is explicit so that a plain kernel never inherits it from the caller
#: that happens to be compiling when numba first compiles it (numba's flags inherit when unset)
KERNEL_OPTIONS = dict(nogil=True, cache=True, error_model="numpy", _nrt=False, forceinline=False)


def kernel(fn=None, **overrides):
    """``numba.njit`` with DRT's options (see the module docstring). Use as ``@kernel``.

    Returns a `LazyKernel`: the numba dispatcher is made when the kernel is first called,
    compiled into a caller or asked about."""
    opts = {**KERNEL_OPTIONS, **overrides}

    def compiled(f):
        _KERNEL_NAMES.add(f.__qualname__)
        return LazyKernel(f, opts)

    return compiled if fn is None else compiled(fn)


_DISPATCHER_LOCK = threading.Lock()


class LazyKernel:
    """A kernel whose numba dispatchers are built on first use: one for calls from Python, one
    for calls from other kernels.

    A warm render calls a few dozen of DRT's ~440 kernels from Python; the rest live only inside
    their callers' cached machine code and are never looked at. Building a numba dispatcher is
    ~0.15 ms (it inspects the function's signature and sets up a compiler), ~0.06 s of every
    process's start-up for all of them (`import drt.render` 0.43 -> 0.37 s, five runs each).
    ``py_func`` is the Python function, available without building anything.

    **Two compiled forms.** Called from Python (``kern(...)``, `dispatcher`), a kernel needs
    numba's wrappers: a CPython entry point that unboxes every argument (each array of a
    per-scene namedtuple: hundreds of values for `MaterialData`) and a C-callable one. Called
    from another kernel it needs neither: the caller links the kernel's LLVM code in. Building,
    optimising and compiling the two wrappers to machine code was a third of the compile time of
    a first render (55 -> 37 s of one core for the Cornell box, 2026-12-07, docs/kernels.md), for
    ~230 kernels no Python code calls. So numba types a kernel used inside another kernel
    through a second dispatcher (`linked`, compiled with ``no_cpython_wrapper`` and
    ``no_cfunc_wrapper``, cached apart under a ``linked-`` file name): numba asks a global for
    ``_numba_type_``, which this object answers with the linked dispatcher's type. Its entry
    point must never be called from Python (it has none); nothing hands it out but `linked`.
    Nor is a linked form compiled to machine code (``_no_machine_code_for_linked_kernels``):
    31.9 s of one core in all."""

    def __init__(self, py_func, options):
        functools.update_wrapper(self, py_func)
        self.py_func = py_func
        self._options = dict(options)
        self._dispatcher = None
        self._linked = None

    def dispatcher(self):
        """The numba dispatcher for calls from Python (built once; render threads may ask at the
        same time)."""
        d = self._dispatcher
        return d if d is not None else self._build_once("_dispatcher", linked=False)

    def linked(self):
        """The numba dispatcher other kernels call (no Python entry point: never call it from
        Python)."""
        d = self._linked
        return d if d is not None else self._build_once("_linked", linked=True)

    def _build_once(self, attr: str, linked: bool):
        with _DISPATCHER_LOCK:
            d = self.__dict__[attr]
            if d is None:
                d = self._build(linked)
                self.__dict__[attr] = d
        return d

    def _build(self, linked: bool):
        opts = dict(self._options)
        cache = opts.pop("cache", False)
        if linked:
            opts.update(no_cpython_wrapper=True, no_cfunc_wrapper=True)
        d = numba.njit(cache=False, **opts)(self.py_func)
        if cache and hasattr(d, "_cache"):
            d._cache = _CacheOnFirstUse(d.py_func, linked)
        return _typed_without_literals(d)

    @property
    def _numba_type_(self):
        """How numba types this kernel where another kernel refers to it: the linked form."""
        return self.linked()._numba_type_

    @property
    def targetoptions(self):
        """The options numba's compiler reads off a callee (its inlining pass): the linked form's."""
        return self.linked().targetoptions

    def __call__(self, *args, **kwargs):
        return self.dispatcher()(*args, **kwargs)

    def __getattr__(self, name):
        if name.startswith("__") or name in ("_dispatcher", "_linked", "_options", "name", "_name"):
            # (numba's call-name lookup asks every global for "name" and "_name", which its
            # dispatcher does not have: answered without building one)
            raise AttributeError(name)
        return getattr(self.dispatcher(), name)

    def __repr__(self):
        return f"<DRT kernel {self.__module__}.{self.__qualname__}>"


class _CacheOnFirstUse:
    """numba's per-kernel disk cache (``FunctionCache``), created when numba first asks for it.

    ``numba.njit(cache=True)`` builds each kernel's cache object at decoration: a locator per
    kernel, which stats its source, makes its folder and writes and deletes a temporary file to
    test it. Of DRT's ~430 kernels a render calls a few dozen from Python (the rest are compiled
    into their callers' machine code and never looked up alone), and building all 430 caches was
    ~0.13 s of every process's ~0.6 s start-up (cProfile, ``drt render`` at 1 spp). Behaviour is
    numba's own once created; attributes are forwarded to it. ``linked``: the cache of a
    kernel's linked form (`LazyKernel.linked`), in files of its own."""

    __slots__ = ("_py_func", "_cache", "_linked")

    def __init__(self, py_func, linked=False):
        self._py_func = py_func
        self._cache = None
        self._linked = linked

    def __getattr__(self, name):
        if name in _CacheOnFirstUse.__slots__:  # not initialised (a copy): no recursion
            raise AttributeError(name)
        if self._cache is None:
            from numba.core.caching import FunctionCache

            self._cache = (_linked_cache_class() if self._linked else FunctionCache)(self._py_func)
        return getattr(self._cache, name)


_LINKED_CACHE_CLASS = None


def _linked_cache_class():
    """numba's ``FunctionCache`` with its index and data files named ``linked-<numba's name>``:
    a kernel's two forms have the same function, signatures and source, which is all numba's
    cache keys on, and a Python call must never load the form without a Python entry point."""
    global _LINKED_CACHE_CLASS
    if _LINKED_CACHE_CLASS is None:
        from numba.core.caching import FunctionCache, IndexDataCacheFile

        class LinkedKernelCache(FunctionCache):
            def __init__(self, py_func):
                super().__init__(py_func)
                self._cache_file = IndexDataCacheFile(
                    cache_path=self._cache_path, filename_base="linked-" + self._impl.filename_base,
                    source_stamp=self._impl.locator.get_source_stamp())

        _LINKED_CACHE_CLASS = LinkedKernelCache
    return _LINKED_CACHE_CLASS


def _typed_without_literals(dispatcher):
    """Make calls from other kernels compile ``dispatcher`` for the plain types of their
    arguments. numba otherwise compiles one more copy of a kernel for every constant a caller
    passes (``f(ld, 0)``, ``f(ld, 1)``, ...: 178 of the 469 compiled functions of a render, e.g.
    58 copies of ``load_col3``, 16 of the light selection's per-strategy weights, two of
    ``run_program``). What a constant argument is worth, LLVM still gets: small kernels and
    ``inline_kernel`` functions are inlined into the caller, where the constant folds."""
    from numba.core import types

    typed = dispatcher.get_call_template

    def get_call_template(args, kws):
        return typed(tuple(types.unliteral(a) for a in args),
                     {k: types.unliteral(v) for k, v in kws.items()})

    dispatcher.get_call_template = get_call_template
    return dispatcher


def inline_kernel(fn=None, **overrides):
    """``@kernel`` that LLVM inlines into every caller (numba's ``forceinline``: the LLVM
    ``alwaysinline`` attribute), for the functions that take a per-scene namedtuple (lights,
    materials, camera). numba passes a namedtuple of N arrays to a call as ~7N scalar arguments —
    about 4 KB for `LightData` — and LLVM does not inline large callees by itself: measured,
    `light_sample` cost 425 ns a call that way and 62 ns inlined. (Since 2026-12-03 a plain
    call passes only the arrays its callee reads, ``_internalize_linked_kernels``; these entry
    points stay inlined: no call at all, and a caller's constants fold into them.)

    Inlined by LLVM, not at numba's IR level (``inline="always"``, as before 2026-12-02): numba
    then types and lowers each such function once, instead of once per call site inside a
    caller whose type inference grows faster than linearly with its size — that made `shade`
    alone ~280 s of a ~390 s cold compile (docs/kernels.md)."""
    return kernel(fn, **{"forceinline": True, **overrides})
