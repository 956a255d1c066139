"""Build the installable DRT packages for Blender.

    python scripts/build_extension.py [--out dist] [--no-download] [--legacy-only]

1. Stages ``addon/`` with the core (``core/drt``) copied in as the sub-package ``drt`` and the
   wheels (embreex, numba, llvmlite) listed in ``addon/blender_manifest.toml`` (downloaded with pip into
   ``build/wheels``, reused when present).
2. Extension (Blender 4.2+): runs Blender's own extension builder, shipped in the bpy wheel at
   ``bpy/<ver>/scripts/addons_core/bl_pkg/cli/blender_ext.py``, with ``--split-platforms``:
   one ``drt-<version>-<platform>.zip`` per platform. Install with
   Edit > Preferences > Get Extensions > Install from Disk, or ``blender --command extension
   install-file -r user_default <zip>``. Built on Linux x86-64, the linux-x64 zip also holds its
   kernels compiled in advance for a portable CPU (``drt/prebuilt_kernels``,
   drt.kernels.prebuilt) by this interpreter (Python 3.11: Blender 4.2 - 5.0) and each
   ``--prebuild-python`` (3.13: Blender 5.1+) that has the numba the zip carries: a first render
   there starts in seconds, not minutes, when installed into the default repository
   (``user_default``: compiled code names its modules). ``--no-prebuilt-kernels`` leaves them out.
3. Legacy add-on (Blender 3.4 - 4.1): ``drt_legacy-<version>-linux-x64.zip`` holding the folder
   ``drt_blender/`` with embreex unpacked into ``drt_blender/_vendor`` (appended to sys.path by
   the add-on). Install with Preferences > Add-ons > Install... Blender builds without numpy
   (Debian's package) also need numpy: ``apt-get install python3-numpy``.

``stage_addon(dest, vendor=True)`` is importable: tests use it to install the add-on into a
temporary user scripts directory.
"""

import argparse
import glob
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import zipfile

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ADDON = os.path.join(REPO, "addon")
CORE = os.path.join(REPO, "core", "drt")
WHEEL_CACHE = os.path.join(REPO, "build", "wheels")
LEGACY_NAME = "drt_blender"
IGNORE = shutil.ignore_patterns("__pycache__", "*.pyc", "_vendor", "wheels")


def manifest_wheels() -> list[str]:
    with open(os.path.join(ADDON, "blender_manifest.toml"), encoding="utf-8") as f:
        text = f.read()
    return re.findall(r'"\./wheels/([^"]+\.whl)"', text)


def manifest_version() -> str:
    with open(os.path.join(ADDON, "blender_manifest.toml"), encoding="utf-8") as f:
        text = f.read()
    return re.search(r'^version = "([^"]+)"', text, re.M).group(1)


#: Python of each Blender line the extension supports: 4.2 LTS - 5.0 run 3.11, 5.1 / 5.2 LTS 3.13
PYTHON_TAGS = ("cp311", "cp313")
#: a manifest platform -> the test a wheel's platform tag must pass to run there
PLATFORM_TAGS = {
    "linux-x64": lambda tag: tag.startswith("manylinux") and tag.endswith("_x86_64"),
    "windows-x64": lambda tag: tag == "win_amd64",
    # universal2 wheels hold both architectures (Blender's builder maps them to both, too)
    "macos-arm64": lambda tag: tag.startswith("macosx_") and tag.endswith(("_arm64", "_universal2")),
    "macos-x64": lambda tag: tag.startswith("macosx_") and tag.endswith(("_x86_64", "_universal2")),
}


def manifest_platforms() -> list[str]:
    with open(os.path.join(ADDON, "blender_manifest.toml"), encoding="utf-8") as f:
        text = f.read()
    block = re.search(r"^platforms = \[([^\]]*)\]", text, re.M)
    return re.findall(r'"([^"]+)"', block.group(1)) if block else []


def check_wheel_matrix(wheels: list[str] | None = None, platforms: list[str] | None = None) -> list[str]:
    """Problems with the manifest's wheel list (empty when it is complete): every distribution
    needs, for every listed platform and every Python in PYTHON_TAGS, exactly one wheel whose
    tags install there (a pure ``py3-none-any`` wheel covers them all, a ``cp39-abi3`` wheel every
    Python from 3.9 on), and no wheel may be for
    a platform or Python the manifest does not list."""
    wheels = manifest_wheels() if wheels is None else wheels
    platforms = manifest_platforms() if platforms is None else platforms
    problems, covered = [], {}
    for name in wheels:
        parts = name[:-4].split("-")
        if len(parts) not in (5, 6):
            problems.append(f"{name}: not a wheel file name")
            continue
        dist, py_tags, abi, plat_tags = parts[0].lower(), parts[-3].split("."), parts[-2], parts[-1].split(".")
        if "py3" in py_tags and abi == "none" and plat_tags == ["any"]:
            for plat in platforms:
                for py in PYTHON_TAGS:
                    covered.setdefault((dist, plat, py), []).append(name)
            continue
        pys = [t for t in py_tags if t in PYTHON_TAGS]
        if abi == "abi3":  # the stable ABI: a cp39-abi3 wheel runs on every CPython >= 3.9
            pys = [py for py in PYTHON_TAGS if any(t.startswith("cp") and int(t[3:] or 0) <= int(py[3:])
                                                   and t[2] == py[2] for t in py_tags)]
        plats = [p for p in platforms if any(PLATFORM_TAGS.get(p, lambda t: False)(t) for t in plat_tags)]
        if not pys:
            problems.append(f"{name}: built for {'.'.join(py_tags)}, not one of {', '.join(PYTHON_TAGS)}")
        if not plats:
            problems.append(f"{name}: platform {'.'.join(plat_tags)} is not one the manifest lists")
        for plat in plats:
            for py in pys:
                covered.setdefault((dist, plat, py), []).append(name)
    for dist in sorted({k[0] for k in covered}):
        for plat in platforms:
            for py in PYTHON_TAGS:
                found = covered.get((dist, plat, py), [])
                if len(found) != 1:
                    what = "no wheel" if not found else f"{len(found)} wheels"
                    problems.append(f"{dist}: {what} for {plat} / {py}")
    return problems


def download_wheels(names: list[str], dest: str = WHEEL_CACHE) -> list[str]:
    """Fetch the listed wheels with pip (one platform at a time); returns their paths."""
    os.makedirs(dest, exist_ok=True)
    paths = []
    for name in names:
        path = os.path.join(dest, name)
        if not os.path.exists(path):
            dist, version, py, abi, plat = name[:-4].split("-", 4)
            target = []
            if plat != "any":  # binary: this wheel's platform and Python (abi3: its minimum)
                platform = plat.split(".")[-1]
                python = f"{py[2]}.{py[3:]}"  # cp311 -> 3.11, cp313 -> 3.13
                target = ["--python-version", python, "--platform", platform]
            subprocess.run([sys.executable, "-m", "pip", "download", f"{dist}=={version}",
                            "--no-deps", "--only-binary=:all:", *target, "-d", dest], check=True)
        if not os.path.exists(path):
            raise SystemExit(f"wheel {name} was not downloaded")
        paths.append(path)
    return paths


def stage_addon(dest: str, vendor_wheels: list[str] | None = None) -> str:
    """Copy the add-on and the core into ``dest`` (created); unpack wheels into _vendor."""
    if os.path.exists(dest):
        shutil.rmtree(dest)
    shutil.copytree(ADDON, dest, ignore=IGNORE)
    shutil.copytree(CORE, os.path.join(dest, "drt"), ignore=IGNORE)
    for whl in vendor_wheels or []:
        with zipfile.ZipFile(whl) as z:
            z.extractall(os.path.join(dest, "_vendor"))
    return dest


#: the import name Blender gives the extension's package when it is installed from disk into the
#: default repository (its core is ``<name>.drt``); shipped kernels are compiled under it, as
#: compiled code names its modules (docs/kernels.md)
EXTENSION_PACKAGE = "bl_ext.user_default.drt"
#: the folder, inside the extension, of the kernels compiled in advance (drt.kernels.prebuilt)
PREBUILT_IN_ZIP = "drt/prebuilt_kernels"

_PREBUILD_CHILD = r"""
import json, os, sys, types, importlib
from dataclasses import replace
stage, package, scenes = json.loads(sys.argv[1])
names = package.split(".")
for i in range(1, len(names) + 1):  # the parents Blender would create, without running the add-on
    module = types.ModuleType(".".join(names[:i]))
    module.__path__ = [stage] if i == len(names) else []
    sys.modules[module.__name__] = module
kernels = importlib.import_module(package + ".drt.kernels")
assert kernels.PREBUILT_TARGET is None and os.environ.get("NUMBA_CPU_NAME"), "the target must come from the build"
render = importlib.import_module(package + ".drt.render")
scene_file = importlib.import_module(package + ".drt.scene_file")
for path in scenes:
    scene = scene_file.load_scene(path)
    scene.render = replace(scene.render, width=24, height=16)
    render.render(scene, spp=2)
    print("compiled for", os.path.basename(path), flush=True)
import numba
print("PREBUILT " + json.dumps([os.environ["NUMBA_CACHE_DIR"], kernels.source_key(), numba.__version__]), flush=True)
"""


def _prebuilt_module():
    """``drt.kernels.prebuilt`` of this tree, loaded alone (importing ``drt.kernels`` would
    configure numba in this process)."""
    import importlib.util
    spec = importlib.util.spec_from_file_location("_drt_prebuilt", os.path.join(CORE, "kernels", "prebuilt.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


_PROBE = ("import sys, platform; from importlib.metadata import version; "
          "print(sys.platform, platform.machine(), f'cp{sys.version_info[0]}{sys.version_info[1]}', version('numba'))")


def can_prebuild_kernels(python: str = sys.executable) -> str | None:
    """Why the interpreter ``python`` cannot compile kernels for the linux-x64 extension in
    advance, or None: it must run on Linux x86-64, be a Python the extension supports
    (``PYTHON_TAGS``: 3.11 for Blender 4.2 - 5.0, 3.13 for 5.1+) and have the numba the zip
    carries (the cache is keyed on both), with numpy and embreex to render."""
    try:
        p = subprocess.run([python, "-c", _PROBE], capture_output=True, text=True, timeout=120)
        system, machine, tag, numba_version = p.stdout.split()
    except (OSError, ValueError, subprocess.SubprocessError) as e:
        said = p.stderr.strip().splitlines()[-1:] if isinstance(e, ValueError) else [str(e)]
        return f"{python} cannot run the build's probe ({'; '.join(said) or 'no answer'})"
    if system != "linux" or machine != "x86_64":
        return f"not Linux x86-64 ({system}, {machine})"
    if tag not in PYTHON_TAGS:
        return f"{tag}, not a Python the extension supports ({', '.join(PYTHON_TAGS)})"
    shipped = {w.split("-")[1] for w in manifest_wheels() if w.startswith("numba-")}
    if numba_version not in shipped:
        return f"numba {numba_version} in {python}, the extension carries {', '.join(sorted(shipped))}"
    return None


def prebuild_kernels(stage: str, dest: str, package: str = EXTENSION_PACKAGE,
                     scenes: list[str] | None = None, python: str = sys.executable) -> str:
    """Compile the kernels of the staged extension ``stage`` (its core in ``stage/drt``, imported
    as ``package``.drt) with the interpreter ``python`` for the portable CPU target by rendering
    every shipped scene at 24 x 16, and copy them into ``dest/<source key>``
    (drt.kernels.prebuilt; the key differs per Python). Returns that folder."""
    prebuilt = _prebuilt_module()
    scenes = scenes if scenes is not None else sorted(glob.glob(os.path.join(REPO, "blend_scenes", "*.npz")))
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, DRT_CACHE_DIR=cache, NUMBA_CPU_NAME=prebuilt.PORTABLE_X86_64[0],
                   NUMBA_CPU_FEATURES=prebuilt.PORTABLE_X86_64[1])
        for var in ("NUMBA_CACHE_DIR", "DRT_SET_NUMBA_CACHE_DIR", "DRT_NO_PRECOMPILE", "PYTHONPATH"):
            env.pop(var, None)
        p = subprocess.run([python, "-c", _PREBUILD_CHILD, json.dumps([stage, package, scenes])],
                           env=env, capture_output=True, text=True)
        line = [ln for ln in p.stdout.splitlines() if ln.startswith("PREBUILT ")]
        if p.returncode != 0 or not line:
            raise SystemExit(f"compiling the kernels in advance failed:\n{p.stdout[-2000:]}{p.stderr[-3000:]}")
        keyed, key, numba_version = json.loads(line[-1][len("PREBUILT "):])
        out = os.path.join(dest, key)
        if os.path.exists(out):
            shutil.rmtree(out)
        shutil.copytree(keyed, out)
        prebuilt.write_target(out, prebuilt.PORTABLE_X86_64, numba_version)
    return out


def add_prebuilt_to_zip(zip_path: str, folder: str) -> None:
    """Append the kernels in ``folder`` (one source key's, from ``prebuild_kernels``) to an
    extension zip, under ``PREBUILT_IN_ZIP``."""
    key = os.path.basename(os.path.normpath(folder))
    with zipfile.ZipFile(zip_path, "a", zipfile.ZIP_DEFLATED) as z:
        for root, _dirs, files in os.walk(folder):
            for f in sorted(files):
                full = os.path.join(root, f)
                z.write(full, "/".join([PREBUILT_IN_ZIP, key, os.path.relpath(full, folder).replace(os.sep, "/")]))


def blender_ext_cli() -> str:
    import importlib.util
    spec = importlib.util.find_spec("bpy")  # the bpy wheel's directory, without importing it
    if spec is None or spec.origin is None:
        raise SystemExit("the bpy module (pip install bpy) is needed for Blender's builder")
    root = os.path.dirname(spec.origin)
    found = glob.glob(os.path.join(root, "*", "scripts", "addons_core", "bl_pkg", "cli",
                                   "blender_ext.py"))
    if not found:
        raise SystemExit("blender_ext.py not found in the bpy wheel")
    return found[0]


def build_extension(out: str, wheels: list[str], prebuild_pythons: list[str] | None = None) -> list[str]:
    """One zip per platform; the linux-x64 one with its kernels compiled in advance by each of
    ``prebuild_pythons`` (default: this interpreter) that can (``can_prebuild_kernels``; ~3 min
    each on two cores; [] for none)."""
    stage = os.path.join(REPO, "build", "extension", "drt")
    stage_addon(stage)
    os.makedirs(os.path.join(stage, "wheels"))
    for w in wheels:
        shutil.copy2(w, os.path.join(stage, "wheels"))
    os.makedirs(out, exist_ok=True)
    subprocess.run([sys.executable, blender_ext_cli(), "build", "--source-dir", stage,
                    "--output-dir", out, "--split-platforms"], check=True)
    zips = sorted(glob.glob(os.path.join(out, f"drt-{manifest_version()}-*.zip")))
    linux = [z for z in zips if z.endswith("-linux_x64.zip") or z.endswith("-linux-x64.zip")]
    pythons = [sys.executable] if prebuild_pythons is None else prebuild_pythons
    for python in pythons:
        why_not = can_prebuild_kernels(python)
        if why_not or not linux:
            print(f"no kernels compiled in advance with {python}: {why_not or 'no linux-x64 zip'}")
            continue
        folder = prebuild_kernels(stage, os.path.join(REPO, "build", "prebuilt_kernels"), python=python)
        for z in linux:
            add_prebuilt_to_zip(z, folder)
        print(f"{os.path.basename(linux[0])} carries kernels compiled by {python} for "
              f"{_prebuilt_module().PORTABLE_X86_64[0]}")
    return zips


def legacy_wheels(wheels: list[str]) -> list[str]:
    """The wheels the legacy add-on vendors: Linux x86-64 for Python 3.11 (Blender 3.4 - 4.1):
    cp311 and abi3 manylinux wheels, and the pure-Python ones (Dask)."""
    def fits(name):
        _dist, _version, py, abi, plat = name[:-4].split("-", 4)
        if plat == "any":
            return True
        return "manylinux" in plat and (py == "cp311" or (abi == "abi3" and int(py[3:]) <= 11))
    return [w for w in wheels if fits(os.path.basename(w))]


def build_legacy(out: str, linux_wheels: list[str]) -> str:
    stage = os.path.join(REPO, "build", "legacy", LEGACY_NAME)
    stage_addon(stage, linux_wheels)
    os.remove(os.path.join(stage, "blender_manifest.toml"))  # would mark it an extension
    os.makedirs(out, exist_ok=True)
    path = os.path.join(out, f"drt_legacy-{manifest_version()}-linux-x64.zip")
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for root, _dirs, files in os.walk(stage):
            for f in files:
                full = os.path.join(root, f)
                z.write(full, os.path.relpath(full, os.path.dirname(stage)))
    return path


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default=os.path.join(REPO, "dist"))
    p.add_argument("--legacy-only", action="store_true")
    p.add_argument("--prebuild-python", action="append", metavar="PYTHON",
                   help="an interpreter (3.11 or 3.13, with the zip's numba, numpy and embreex) that "
                        "compiles the linux-x64 extension's kernels in advance; repeatable "
                        "(default: this one)")
    p.add_argument("--no-prebuilt-kernels", action="store_true",
                   help="do not compile the linux-x64 extension's kernels in advance")
    opts = p.parse_args(argv)
    problems = check_wheel_matrix()
    if problems:
        raise SystemExit("blender_manifest.toml's wheels are incomplete:\n  " + "\n  ".join(problems))
    wheels = download_wheels(manifest_wheels())
    built = []
    if not opts.legacy_only:
        built += build_extension(opts.out, wheels,
                                 prebuild_pythons=[] if opts.no_prebuilt_kernels else opts.prebuild_python)
    built.append(build_legacy(opts.out, legacy_wheels(wheels)))
    for b in built:
        print(f"built {b} ({os.path.getsize(b) / 1e6:.1f} MB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
