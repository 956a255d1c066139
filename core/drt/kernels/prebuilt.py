"""Kernels compiled in advance, shipped with a package (the Linux extension), for a portable CPU.

A first render on a machine compiles DRT's kernels (40-120 s on two cores, docs/kernels.md). An
extension zip built on Linux x86-64 (``scripts/build_extension.py``) can carry them instead:
compiled once for a portable CPU target, ``PORTABLE_X86_64`` (x86-64-v3: AVX2, FMA, BMI2 —
every x86-64 CPU since 2013-2015), in ``<package>/prebuilt_kernels/<source key>/`` with a
``target.json`` naming that target. numba files each compiled kernel under its CPU name and
feature string (``codegen.magic_tuple()``) and checks a source file by a hash of its contents,
so the shipped files load wherever the sources, the import name, Python and numba are the same
and the process compiles for the same target.

At import (``drt.kernels``, before numba is imported) ``choose`` decides whether this process
uses them: the folder for this source key exists, the user has not chosen a CPU target of their
own (``NUMBA_CPU_NAME``), and this CPU has every feature the target needs. Then ``seed`` copies
the shipped files into the user's cache folder once (files already there are kept) and
``apply`` makes numba compile for that target too, so what a render still has to compile (a
feature the build's scenes did not use) lands beside them under the same key. Portable code
rendered within 0-3 % of native code on the development machine (docs/kernels.md). A process
that cannot use them compiles natively, as before.

Nothing here imports numba; kernels/__init__.py calls it before numba's configuration is read.
"""

from __future__ import annotations

import json
import os
import shutil
import sys

#: the folder beside the core's modules that holds shipped kernels, one sub-folder per source key
FOLDER = "prebuilt_kernels"
#: the file in a source key's folder naming the CPU target its kernels were compiled for
TARGET_FILE = "target.json"
#: the mark left in a user cache folder once the shipped kernels were copied into it
SEEDED_MARK = "prebuilt-seeded"
#: set by ``apply`` to the target it chose, so that a child process (the compile helpers, a
#: viewport warm-up) can tell DRT's choice, which it makes again, from a user's NUMBA_CPU_NAME
_DRT_SET_MARK = "DRT_SET_NUMBA_CPU_NAME"

#: x86-64-v3, the portable target of Linux x86-64 builds: LLVM's CPU name and the features
#: numba is told to use (NUMBA_CPU_FEATURES; numba's default is every feature of the host)
PORTABLE_X86_64 = ("x86-64-v3",
                   "+64bit,+avx,+avx2,+bmi,+bmi2,+cmov,+cx16,+cx8,+f16c,+fma,+fxsr,+lzcnt,+mmx,+movbe,"
                   "+popcnt,+sahf,+sse,+sse2,+sse3,+sse4.1,+sse4.2,+ssse3,+xsave")


def folder_for(package_root: str, key: str) -> str:
    """Where a package's kernels for source key ``key`` would be shipped."""
    return os.path.join(package_root, FOLDER, key)


def read_target(folder: str) -> tuple[str, str] | None:
    """(CPU name, feature string) of the kernels in ``folder``, or None (no kernels there, or a
    target file that does not say)."""
    try:
        with open(os.path.join(folder, TARGET_FILE), encoding="utf-8") as f:
            data = json.load(f)
        return str(data["cpu_name"]), str(data["cpu_features"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


def write_target(folder: str, target: tuple[str, str], numba_version: str) -> None:
    with open(os.path.join(folder, TARGET_FILE), "w", encoding="utf-8") as f:
        json.dump({"cpu_name": target[0], "cpu_features": target[1], "numba": numba_version}, f, indent=1)


def host_features() -> set[str] | None:
    """The features this CPU has ("avx2", ...), as LLVM names them; None when LLVM cannot say."""
    try:
        import llvmlite.binding as ll

        flat = ll.get_host_cpu_features().flatten()
    except Exception:  # noqa: BLE001 - no llvmlite, or a platform it cannot query
        return None
    return {f[1:] for f in flat.split(",") if f.startswith("+")}


def runs_here(target: tuple[str, str], features: set[str] | None) -> bool:
    """Can code compiled for ``target`` run on a CPU with ``features``?"""
    needed = {f[1:] for f in target[1].split(",") if f.startswith("+")}
    return features is not None and needed <= features


def _user_chose_a_target(environ) -> bool:
    chosen = environ.get("NUMBA_CPU_NAME") or environ.get("NUMBA_CPU_FEATURES")
    return bool(chosen) and environ.get("NUMBA_CPU_NAME", "") != environ.get(_DRT_SET_MARK)


def choose(package_root: str, key: str, environ=os.environ, features=None) -> tuple[str, tuple[str, str]] | None:
    """(folder, target) of the shipped kernels this process should use, or None.

    ``features``: this CPU's (``host_features()`` when None)."""
    folder = folder_for(package_root, key)
    target = read_target(folder)
    if target is None or _user_chose_a_target(environ):
        return None
    if not runs_here(target, host_features() if features is None else features):
        return None
    return folder, target


def seed(folder: str, cache: str) -> bool:
    """Copy the shipped kernels in ``folder`` into the user cache folder ``cache`` (its files
    that are already there are kept), once. Returns whether the cache holds them."""
    if os.path.exists(os.path.join(cache, SEEDED_MARK)):
        return True
    try:
        for here, _dirs, files in os.walk(folder):
            rel = os.path.relpath(here, folder)
            dest = os.path.normpath(os.path.join(cache, rel))
            os.makedirs(dest, exist_ok=True)
            # numba's index files (.nbi) after the data files (.nbc) they name
            for name in sorted(files, key=lambda n: (n.endswith(".nbi"), n)):
                if rel == "." and name == TARGET_FILE:
                    continue
                target_path = os.path.join(dest, name)
                if not os.path.exists(target_path):
                    # (a copy a killed process left half done is completed by the next one)
                    tmp = target_path + f".{os.getpid()}.tmp"
                    shutil.copyfile(os.path.join(here, name), tmp)
                    os.replace(tmp, target_path)
        with open(os.path.join(cache, SEEDED_MARK), "w", encoding="utf-8") as f:
            f.write(f"{folder}\n")
    except OSError:
        return False
    return True


def apply(target: tuple[str, str]) -> bool:
    """Make numba compile for ``target`` in this process and its children. False when numba's
    CPU target is already set up in this process (another add-on used numba first): then it
    keeps compiling natively."""
    name, features = target
    if "numba" in sys.modules:
        from numba.core import config, registry

        if "_toplevel_target_context" in vars(registry.cpu_target):
            return False  # its code generator already chose the host's CPU
        config.CPU_NAME, config.CPU_FEATURES = name, features
    os.environ["NUMBA_CPU_NAME"] = name
    os.environ["NUMBA_CPU_FEATURES"] = features
    os.environ[_DRT_SET_MARK] = name
    return True


def forget(environ=os.environ) -> None:
    """Drop a CPU target that a parent DRT process chose for its own shipped kernels: this
    process does not use them (other sources, or none shipped), so it compiles natively."""
    mark = environ.pop(_DRT_SET_MARK, None)
    if mark is not None and environ.get("NUMBA_CPU_NAME") == mark:
        environ.pop("NUMBA_CPU_NAME", None)
        environ.pop("NUMBA_CPU_FEATURES", None)
