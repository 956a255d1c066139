"""The Blender 4.2+ extension package: built with Blender's own builder, installed from the zip
into a fresh user directory of the bpy module (5.0; or 5.1+ under Python 3.13) the way Install
from Disk does, enabled, and
used for an F12-style render of a shipped scene. Runs in a subprocess (an install must not
touch the test process's Blender state). Linux-x64 only: the one platform this machine can run.
"""

import os
import re
import shutil
import subprocess
import sys

import numpy as np
import pytest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(REPO, "scripts"))

pytestmark = pytest.mark.slow
bpy_spec = pytest.importorskip("importlib.util").find_spec("bpy")
if bpy_spec is None:
    pytest.skip("needs the bpy module", allow_module_level=True)

INSTALL_AND_RENDER = r"""
import sys, bpy
zip_path, blend, out = sys.argv[1:4]
res = bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default",
                                               enable_on_install=True)
print("INSTALL", res, flush=True)
print("ENABLED", sorted(k for k in bpy.context.preferences.addons.keys() if k.endswith(".drt")))
bpy.ops.wm.open_mainfile(filepath=blend, load_ui=False)
sc = bpy.context.scene
sc.render.engine = "DRT"
sc.render.resolution_percentage = 25
sc.drt.samples = 4
fmt = sc.render.image_settings
if hasattr(fmt, "media_type"):
    fmt.media_type = "IMAGE"
fmt.file_format, fmt.color_depth = "OPEN_EXR", "32"
sc.render.filepath = out
bpy.ops.render.render(write_still=True)
print("RENDERED", flush=True)
print("CORE", sorted(m for m in sys.modules if m.endswith("drt.integrator")), flush=True)
kernels = sys.modules["bl_ext.user_default.drt.drt.kernels"]
print("PREBUILT", kernels.PREBUILT_TARGET, "CACHE", kernels._KEYED_CACHE_DIR, flush=True)
"""


def linux_wheels() -> list[str]:
    """The manifest's linux-x64 wheels for this Python (embreex, numba, llvmlite; Dask and its
    dependencies: pure-Python, this CPython's and abi3 wheels): cp311 with the bpy 5.0 module,
    cp313 with bpy 5.1+ (Blender 5.1+'s Python)."""
    import build_extension as b
    minor = sys.version_info[1]

    def fits(name):
        _dist, _version, py, abi, plat = name[:-4].split("-", 4)
        return plat == "any" or ("manylinux" in plat and (
            py == f"cp3{minor}" or (abi == "abi3" and int(py[3:]) <= minor)))
    return b.download_wheels([w for w in b.manifest_wheels() if fits(w)])


def build_linux_extension(tmp, wheels, prebuilt_kernels: bool = False) -> str:
    """A linux-x64 extension zip of the current tree (manifest narrowed to that platform), with
    its kernels compiled in advance if asked (as ``build_extension.build_extension`` adds them)."""
    import build_extension as b
    stage = b.stage_addon(os.path.join(tmp, "stage", "drt"))
    if prebuilt_kernels:
        folder = b.prebuild_kernels(stage, os.path.join(tmp, "prebuilt"))
        shutil.copytree(folder, os.path.join(stage, b.PREBUILT_IN_ZIP, os.path.basename(folder)))
    os.makedirs(os.path.join(stage, "wheels"))
    for wheel in wheels:
        shutil.copy2(wheel, os.path.join(stage, "wheels"))
    manifest = os.path.join(stage, "blender_manifest.toml")
    with open(manifest, encoding="utf-8") as f:
        text = f.read()
    text = re.sub(r"platforms = \[[^\]]*\]", 'platforms = ["linux-x64"]', text)
    listed = ", ".join(f'"./wheels/{os.path.basename(w)}"' for w in wheels)
    text = re.sub(r"wheels = \[[^\]]*\]", f"wheels = [{listed}]", text)
    with open(manifest, "w", encoding="utf-8") as f:
        f.write(text)
    out = os.path.join(tmp, "dist")
    os.makedirs(out)
    subprocess.run([sys.executable, b.blender_ext_cli(), "build", "--source-dir", stage,
                    "--output-dir", out], check=True, capture_output=True, timeout=300)
    (zip_path,) = [os.path.join(out, f) for f in os.listdir(out) if f.endswith(".zip")]
    return zip_path


def test_extension_zip_installs_enables_and_renders(tmp_path):
    try:
        wheels = linux_wheels()
    except (subprocess.CalledProcessError, SystemExit) as e:
        pytest.skip(f"could not fetch the wheels: {e}")
    names = {os.path.basename(w).split("-")[0] for w in wheels}
    assert {"embreex", "numba", "llvmlite", "distributed", "dask", "tornado", "msgpack", "psutil"} <= names
    import build_extension as b
    # with its kernels compiled in advance where this machine can (Linux x86-64, the zip's
    # Python and numba): the installed extension must then render without compiling any
    prebuilt_kernels = b.can_prebuild_kernels() is None
    zip_path = build_linux_extension(str(tmp_path), wheels, prebuilt_kernels)
    user = tmp_path / "user"
    user.mkdir()
    cache = tmp_path / "kernel_cache"  # an empty user cache: a fresh machine
    out = tmp_path / "render.exr"
    script = tmp_path / "install_and_render.py"
    script.write_text(INSTALL_AND_RENDER)
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(user), DRT_CACHE_DIR=str(cache))
    for var in ("PYTHONPATH", "NUMBA_CACHE_DIR", "DRT_SET_NUMBA_CACHE_DIR", "NUMBA_CPU_NAME", "NUMBA_CPU_FEATURES"):
        env.pop(var, None)  # the installed extension, not the source tree, must do the work
    p = subprocess.run([sys.executable, str(script), zip_path,
                        os.path.join(REPO, "blend_scenes", "cornell_box.blend"), str(out)],
                       env=env, cwd=str(tmp_path), capture_output=True, text=True, timeout=1800)  # cold compile: ~10 min
    log = p.stdout + p.stderr
    assert p.returncode == 0, log[-3000:]
    assert "INSTALL {'FINISHED'}" in log and "ENABLED ['bl_ext.user_default.drt']" in log, log[-3000:]
    assert "RENDERED" in log
    assert "CORE ['bl_ext.user_default.drt.drt.integrator']" in log, log[-3000:]
    if prebuilt_kernels:
        from drt.kernels import prebuilt
        assert f"PREBUILT {prebuilt.PORTABLE_X86_64!r}" in log, log[-3000:]
        keyed = re.search(r"CACHE (\S+)", log).group(1)
        seeded = os.path.getmtime(os.path.join(keyed, prebuilt.SEEDED_MARK))
        compiled = [os.path.relpath(os.path.join(d, f), keyed) for d, _, files in os.walk(keyed) for f in files
                    if f.endswith((".nbi", ".nbc")) and os.path.getmtime(os.path.join(d, f)) > seeded]
        assert not compiled, compiled  # the render found every kernel it called in the shipped ones
    # the engine that rendered is the installed copy, with embreex from the bundled wheel
    installed = user / "extensions" / "user_default" / "drt"
    assert (installed / "drt" / "integrator.py").exists()
    # Dask's wheels (the cluster client) were installed into the extensions' site-packages
    site = list((user / "extensions").glob(".local/lib/python3.*/site-packages"))
    for package in ("distributed", "dask", "tornado", "msgpack", "yaml", "psutil"):
        assert site and (site[0] / package / "__init__.py").exists(), (package, site)
    import OpenEXR
    with OpenEXR.File(str(out)) as f:
        rgba = np.array(f.parts[0].channels["RGBA"].pixels)
    assert rgba.shape == (24, 24, 4) and np.isfinite(rgba).all()
    assert rgba[..., :3].mean() > 0.01  # the lit box, not a black frame
