"""The compile-time patches of numba's type inference (drt.kernels.typing_overheads): each skips
work without changing an answer numba gives."""

from __future__ import annotations

import itertools
import operator
import os
import subprocess
import sys

import numpy as np

import drt.kernels  # noqa: F401 -- installs the patches
from drt.kernels import typing_overheads


def _reference_values(flags) -> dict:
    """numba's own ``TargetConfig.values``: every option through its property."""
    return {name: getattr(flags, name) for name in flags.options}


def test_flags_hash_and_compare_as_numba_defines_them():
    from numba.core import targetconfig
    from numba.core.compiler import Flags

    config = targetconfig.TargetConfig
    assert config.__eq__._drt and config.__hash__._drt and config.values._drt
    # flags set to their defaults, to other values, and not set at all, in every combination
    settings = [("no_cpython_wrapper", (None, False, True)), ("no_cfunc_wrapper", (None, False, True)),
                ("nrt", (None, False, True)), ("error_model", (None, "python", "numpy"))]
    made = []
    for combo in itertools.product(*(values for _, values in settings)):
        f = Flags()
        for (name, _), value in zip(settings, combo):
            if value is not None:
                setattr(f, name, value)
        made.append(f)
    for f in made:
        assert f.values() == _reference_values(f)
        assert hash(f) == hash(tuple(sorted(_reference_values(f))))
    pairs = 0
    for a, b in itertools.product(made, repeat=2):
        assert (a == b) == (_reference_values(a) == _reference_values(b))
        pairs += a == b and a._values != b._values  # equal through a default, not stored values
    assert pairs > 0
    assert Flags().__eq__(object()) is NotImplemented


def test_scalar_operators_skip_the_array_rules_and_arrays_keep_them():
    from numba.core import types
    from numba.core.registry import cpu_target
    from numba.core.typing import npydecl

    rules = npydecl.NumpyRulesArrayOperator
    assert rules.generic._drt
    context = cpu_target.typing_context
    context.refresh()
    template = type("AddRules", (rules,), dict(key=operator.add))(context)
    f64 = types.float64
    assert template.generic((f64, f64), {}) is None
    assert template.generic((types.Optional(f64), types.int64), {}) is None
    sig = template.generic((types.float64[:], f64), {})
    assert sig is not None and sig.return_type.ndim == 1 and sig.return_type.dtype == f64
    sig = template.generic((f64, types.Optional(types.float32[:, :])), {})
    assert sig is not None and sig.return_type.ndim == 2


def test_numpy_code_still_compiles_with_the_patches():
    import numba

    @numba.njit(cache=False)
    def mixed(a, x):
        return a * x + 1.0, x * 2.0 - 3

    arr, scal = mixed(np.arange(3.0), 2.0)
    assert np.array_equal(arr, [1.0, 3.0, 5.0]) and scal == 1.0


def test_error_messages_are_plain_unless_the_user_chose():
    code = ("import os, drt.kernels; from numba.core import errors; "
            "print(os.environ.get('NUMBA_DISABLE_ERROR_MESSAGE_HIGHLIGHTING')); "
            "print(errors.termcolor().errmsg('x') == 'x')")
    env = {k: v for k, v in os.environ.items() if k != typing_overheads.HIGHLIGHTING_ENV}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["1", "True"]
    env[typing_overheads.HIGHLIGHTING_ENV] = ""  # the user's (empty: highlighting on, if colorama is there)
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.splitlines()[0] == ""
