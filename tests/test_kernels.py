"""The compiled-kernel plumbing: where the cache lives, the first-render notice, and that the
per-source cache key changes with the sources."""

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
    monkeypatch.delenv("NUMBA_CACHE_DIR")
    assert not kernels.kernels_compiled()  # unknown location: every process compiles


def test_source_key_is_stable_and_short():
    assert kernels.source_key() == kernels.source_key()
    assert len(kernels.source_key()) == 16


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
