"""The extension's wheel matrix, checked statically (this machine can only install linux-x64 /
cp311): every bundled distribution has one wheel per listed platform and per Python of the
Blender lines we support (3.11: Blender 4.2-5.0; 3.13: 5.1 and 5.2 LTS)."""

import os
import sys

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(REPO, "scripts"))

import build_extension as b  # noqa: E402


def test_manifest_wheels_cover_every_platform_and_python():
    assert set(b.manifest_platforms()) == {"linux-x64", "windows-x64", "macos-arm64"}
    assert b.PYTHON_TAGS == ("cp311", "cp313")
    assert b.check_wheel_matrix() == []
    dists = {w.split("-")[0].lower() for w in b.manifest_wheels()}
    assert {"embreex", "numba", "llvmlite"} <= dists
    # Dask for cluster rendering, with its binary dependencies (docs/farm.md)
    assert {"distributed", "dask", "tornado", "msgpack", "psutil", "pyyaml", "markupsafe"} <= dists


def test_the_matrix_check_finds_gaps_and_strays():
    wheels = b.manifest_wheels()
    missing = [w for w in wheels if not ("numba" in w and "win_amd64" in w and "cp313" in w)]
    assert b.check_wheel_matrix(missing) == ["numba: no wheel for windows-x64 / cp313"]
    stray = wheels + ["numba-0.68.1-cp312-cp312-win_amd64.whl"]
    assert any("cp312" in p for p in b.check_wheel_matrix(stray))
    doubled = wheels + ["numba-0.68.1-cp311-cp311-manylinux2014_x86_64.whl"]
    assert "numba: 2 wheels for linux-x64 / cp311" in b.check_wheel_matrix(doubled)
    abi3 = ["psutil-7.0.0-cp36-abi3-manylinux_2_12_x86_64.manylinux2010_x86_64.whl",
            "psutil-7.0.0-cp37-abi3-win_amd64.whl", "psutil-7.0.0-cp36-abi3-macosx_11_0_arm64.whl"]
    assert b.check_wheel_matrix(abi3) == []
    assert b.check_wheel_matrix(["pure-1.0-py3-none-any.whl"]) == []
    universal2 = ["tornado-6.6.1-cp311-abi3-macosx_10_9_universal2.whl"]  # both Mac architectures
    assert b.check_wheel_matrix(universal2, ["macos-arm64"]) == []
