"""The core (``core/drt``) never imports Blender or the add-on, statically or dynamically; .blend
files reach it through the scene-loader registry (``drt.loaders``), which the add-on package
fills through an entry point."""

import ast
import os
import subprocess
import sys
import tomllib

import pytest

from drt import loaders

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CORE = os.path.join(REPO, "core", "drt")
FORBIDDEN = ("bpy", "addon", "drt_blender", "mathutils", "gpu")


def _core_sources():
    for folder, _dirs, files in os.walk(CORE):
        for name in files:
            if name.endswith(".py"):
                yield os.path.join(folder, name)


def test_core_has_no_static_import_of_blender_or_the_addon():
    offenders = []
    for path in _core_sources():
        with open(path, encoding="utf-8") as f:
            tree = ast.parse(f.read())
        for node in ast.walk(tree):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and not node.level:
                names = [node.module or ""]
            elif isinstance(node, ast.Call):
                # dynamic imports by name: only the entry-point registry may load plugins
                fn = node.func
                called = fn.attr if isinstance(fn, ast.Attribute) else getattr(fn, "id", "")
                if called in ("import_module", "__import__", "spec_from_file_location"):
                    offenders.append(f"{os.path.relpath(path, REPO)}:{node.lineno} calls {called}")
            for n in names:
                if n.split(".")[0] in FORBIDDEN:
                    offenders.append(f"{os.path.relpath(path, REPO)}:{node.lineno} imports {n}")
    assert not offenders, offenders


def test_rendering_an_npz_loads_nothing_of_blender(tmp_path):
    """Every core module imported and a CLI render done in one process: no bpy, no add-on."""
    code = (
        "import pkgutil, sys, drt\n"
        "for m in pkgutil.walk_packages(drt.__path__, 'drt.'):\n"
        "    if m.name != 'drt.__main__': __import__(m.name)\n"
        "from drt.cli import main\n"
        f"rc = main(['render', {os.path.join(REPO, 'blend_scenes', 'cornell_box.npz')!r}, '-o', "
        f"{str(tmp_path / 'x.exr')!r}, '--spp', '1', '--resolution', '16x16'])\n"
        "bad = sorted(n for n in sys.modules if n.split('.')[0] in ('bpy', 'addon', 'drt_blender'))\n"
        "print(rc, bad)\n"
    )
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip().splitlines()[-1] == "0 []", p.stdout


def test_every_package_is_listed_in_pyproject():
    """pyproject.toml lists packages explicitly (two source roots); a forgotten sub-package would
    be missing from a wheel."""
    with open(os.path.join(REPO, "pyproject.toml"), "rb") as f:
        listed = set(tomllib.load(f)["tool"]["setuptools"]["packages"])
    found = set()
    for root, name in ((CORE, "drt"), (os.path.join(REPO, "addon"), "drt_blender")):
        for folder, _dirs, files in os.walk(root):
            if "__init__.py" in files:
                rel = os.path.relpath(folder, root)
                found.add(name if rel == "." else name + "." + rel.replace(os.sep, "."))
    assert found == listed, (found - listed, listed - found)


def test_the_blend_loader_is_an_installed_plugin():
    ep = loaders._entry_point(".blend")
    assert ep is not None and ep.value == "drt_blender.scene_loader:read_blend"
    assert loaders.is_plugin_format("x.BLEND") and not loaders.is_plugin_format("x.npz")


def test_registered_loader_serves_the_cli(tmp_path, monkeypatch, capsys):
    """A run-time loader for a new suffix: the CLI renders its scene and prints its warnings."""
    from drt.cli import main
    from drt.scene_file import read_scene_arrays

    header, arrays = read_scene_arrays(os.path.join(REPO, "blend_scenes", "cornell_box.npz"))
    seen = {}

    def read(path, frame=None):
        seen["args"] = (path, frame)
        return header, arrays, ["a warning from the loader"]

    monkeypatch.setitem(loaders._registered, ".fake", read)
    src = tmp_path / "scene.fake"
    src.write_text("anything")
    out = tmp_path / "out.exr"
    assert main(["render", str(src), "-o", str(out), "--spp", "1", "--resolution", "8x8", "--frame", "3"]) == 0
    assert seen["args"] == (str(src), 3) and out.exists()
    assert "drt: warning: a warning from the loader" in capsys.readouterr().err


def test_loader_failures_are_one_line_errors(tmp_path, monkeypatch, capsys):
    from drt.cli import main

    def broken(path, frame=None):
        raise RuntimeError("the file is truncated")

    monkeypatch.setitem(loaders._registered, ".fake", broken)
    src = tmp_path / "scene.fake"
    src.write_text("anything")
    assert main(["render", str(src), "-o", str(tmp_path / "o.exr")]) == 2
    assert capsys.readouterr().err.strip() == f"drt: error: cannot read {src}: the file is truncated"


def test_a_plugin_needing_a_missing_module_says_what_to_install(monkeypatch):
    class FakeEntryPoint:
        name, value = "blend", "nowhere:read"

        def load(self):
            raise ModuleNotFoundError("No module named 'bpy'", name="bpy")

    monkeypatch.setattr(loaders, "_entry_point", lambda suffix: FakeEntryPoint() if suffix == ".blend" else None)
    monkeypatch.delitem(loaders._registered, ".blend", raising=False)
    with pytest.raises(loaders.LoaderError, match=r"needs Blender as a Python module: pip install 'bpy==5\.0\.1'"):
        loaders.loader_for("scene.blend")
