"""Kernels compiled in advance (drt.kernels.prebuilt): when a process uses shipped kernels, how
they are copied into the user cache, and how the extension build packs them. The end-to-end
check (a built extension renders without compiling) is in test_extension_install.py (slow)."""

import json
import os
import sys
import zipfile

import pytest

from drt.kernels import prebuilt

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
V3 = prebuilt.PORTABLE_X86_64
V3_FEATURES = {f[1:] for f in V3[1].split(",")}


def _shipped(tmp_path, key="k123", target=V3):
    """A package root holding shipped kernels for source key ``key``."""
    root = tmp_path / "pkg"
    folder = root / prebuilt.FOLDER / key
    (folder / "drt" / "materials").mkdir(parents=True)
    (folder / "drt" / "materials" / "table.f-10.py311.nbi").write_bytes(b"index")
    (folder / "drt" / "materials" / "table.f-10.py311.1.nbc").write_bytes(b"code")
    (folder / "kernels-ready-").write_text("numba\n")
    prebuilt.write_target(str(folder), target, "0.68.1")
    return str(root), str(folder)


def test_a_process_uses_shipped_kernels_only_where_they_run_and_the_user_chose_no_target(tmp_path):
    root, folder = _shipped(tmp_path)
    assert prebuilt.choose(root, "k123", environ={}, features=V3_FEATURES | {"avx512f"}) == (folder, V3)
    # another source state, a CPU without FMA, no target file: compile natively
    assert prebuilt.choose(root, "other", environ={}, features=V3_FEATURES) is None
    assert prebuilt.choose(root, "k123", environ={}, features=V3_FEATURES - {"fma"}) is None
    assert prebuilt.choose(root, "k123", environ={}, features=set()) is None
    os.remove(os.path.join(folder, prebuilt.TARGET_FILE))
    assert prebuilt.choose(root, "k123", environ={}, features=V3_FEATURES) is None
    # a user's own NUMBA_CPU_NAME wins; the one a DRT parent process set does not count as theirs
    root, folder = _shipped(tmp_path / "again")
    assert prebuilt.choose(root, "k123", environ={"NUMBA_CPU_NAME": "haswell"}, features=V3_FEATURES) is None
    inherited = {"NUMBA_CPU_NAME": V3[0], "NUMBA_CPU_FEATURES": V3[1], "DRT_SET_NUMBA_CPU_NAME": V3[0]}
    assert prebuilt.choose(root, "k123", environ=inherited, features=V3_FEATURES) == (folder, V3)


def test_a_broken_target_file_means_no_shipped_kernels(tmp_path):
    root, folder = _shipped(tmp_path)
    with open(os.path.join(folder, prebuilt.TARGET_FILE), "w") as f:
        f.write("{not json")
    assert prebuilt.choose(root, "k123", environ={}, features=V3_FEATURES) is None
    with open(os.path.join(folder, prebuilt.TARGET_FILE), "w") as f:
        json.dump({"cpu_name": "x86-64-v3"}, f)
    assert prebuilt.choose(root, "k123", environ={}, features=V3_FEATURES) is None


def test_seeding_copies_the_kernels_once_and_keeps_what_the_cache_holds(tmp_path):
    _, folder = _shipped(tmp_path)
    cache = tmp_path / "cache"
    (cache / "drt" / "materials").mkdir(parents=True)
    mine = cache / "drt" / "materials" / "table.f-10.py311.1.nbc"
    mine.write_bytes(b"compiled here")
    assert prebuilt.seed(folder, str(cache))
    assert (cache / "drt" / "materials" / "table.f-10.py311.nbi").read_bytes() == b"index"
    assert mine.read_bytes() == b"compiled here"  # (kept)
    assert (cache / "kernels-ready-").exists() and (cache / prebuilt.SEEDED_MARK).exists()
    assert not (cache / prebuilt.TARGET_FILE).exists()
    assert not [p for p in cache.rglob("*.tmp")]
    # once seeded, never again: a file the user's numba removed stays removed
    (cache / "drt" / "materials" / "table.f-10.py311.nbi").unlink()
    assert prebuilt.seed(folder, str(cache))
    assert not (cache / "drt" / "materials" / "table.f-10.py311.nbi").exists()


def test_seeding_into_an_unwritable_cache_says_so(tmp_path):
    _, folder = _shipped(tmp_path)
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    assert not prebuilt.seed(folder, str(blocker / "cache"))


def test_forget_drops_only_the_target_a_drt_process_set():
    env = {"NUMBA_CPU_NAME": V3[0], "NUMBA_CPU_FEATURES": V3[1], "DRT_SET_NUMBA_CPU_NAME": V3[0]}
    prebuilt.forget(env)
    assert env == {}
    users = {"NUMBA_CPU_NAME": "skylake", "NUMBA_CPU_FEATURES": "+avx2"}
    prebuilt.forget(users)
    assert users == {"NUMBA_CPU_NAME": "skylake", "NUMBA_CPU_FEATURES": "+avx2"}


def test_this_process_compiles_for_its_own_cpu_without_shipped_kernels():
    """A source checkout ships no kernels: the tests' own process compiles natively."""
    from drt import kernels
    assert kernels.PREBUILT_TARGET is None
    assert not os.path.isdir(os.path.join(REPO, "core", "drt", prebuilt.FOLDER))


def test_the_build_packs_shipped_kernels_under_the_core_in_the_zip(tmp_path):
    sys.path.insert(0, os.path.join(REPO, "scripts"))
    try:
        import build_extension as b
    finally:
        sys.path.pop(0)
    _, folder = _shipped(tmp_path)
    z = tmp_path / "ext.zip"
    with zipfile.ZipFile(z, "w") as f:
        f.writestr("drt/integrator.py", "")
    b.add_prebuilt_to_zip(str(z), folder)
    names = set(zipfile.ZipFile(z).namelist())
    assert {"drt/prebuilt_kernels/k123/target.json", "drt/prebuilt_kernels/k123/kernels-ready-",
            "drt/prebuilt_kernels/k123/drt/materials/table.f-10.py311.nbi"} <= names
    assert b.PREBUILT_IN_ZIP.split("/")[0] == "drt" and b.EXTENSION_PACKAGE.startswith("bl_ext.user_default.")


@pytest.mark.skipif(sys.platform != "linux", reason="the host CPU's features as LLVM names them")
def test_this_cpu_is_described_in_llvms_feature_names():
    features = prebuilt.host_features()
    assert features and "64bit" in features and "sse2" in features


@pytest.mark.skipif(sys.platform == "win32", reason="fake interpreters are shell scripts")
def test_the_build_says_why_an_interpreter_cannot_compile_the_kernels(tmp_path):
    sys.path.insert(0, os.path.join(REPO, "scripts"))
    try:
        import build_extension as b
    finally:
        sys.path.pop(0)
    assert "/nonexistent/python" in b.can_prebuild_kernels("/nonexistent/python")

    def fake(answer):
        path = tmp_path / f"python-{abs(hash(answer))}"
        path.write_text(f"#!/bin/sh\necho {answer}\n")
        path.chmod(0o755)
        return str(path)

    numba = [w.split("-")[1] for w in b.manifest_wheels() if w.startswith("numba-")][0]
    assert "cp312" in b.can_prebuild_kernels(fake(f"linux x86_64 cp312 {numba}"))
    assert "not Linux x86-64" in b.can_prebuild_kernels(fake(f"win32 AMD64 cp311 {numba}"))
    assert "numba 0.1.0" in b.can_prebuild_kernels(fake("linux x86_64 cp313 0.1.0"))
    assert b.can_prebuild_kernels(fake(f"linux x86_64 cp313 {numba}")) is None
