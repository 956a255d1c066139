"""Work numba's type inference does for nothing on DRT's kernels, skipped.

A first render types ~400 kernels (textures: the program interpreter and its nodes), and most of
a cold compile is numba's own Python — type inference and lowering — rather than LLVM. A
profile of that compile (cProfile over the whole plan of the textured scene, one process, 2026-12-07)
found three costs that change no compiled code:

- **Colouring error messages.** Typing an operator tries every overload template and builds an
  error message for each that does not match; with ``colorama`` importable, numba highlights
  every such message, initialising colorama (which scans the environment) per message: ~77 000
  messages for one first render, all discarded. ``NUMBA_DISABLE_ERROR_MESSAGE_HIGHLIGHTING``
  (numba's documented switch) turns the highlighting off; DRT sets it unless the user did, before
  numba is first imported (numba reads it at import: in a process that imported numba earlier —
  another add-on in Blender — it stays as it was).
- **Comparing compiler flags.** Overload templates cache their implementations under a key that
  holds the current compile's ``Flags``; looking one up hashes and compares the flags' values,
  which numba builds as a dict through a property per option (~40), ~330 000 times. The hash
  (numba's: of the sorted option names) is the same for every instance of a class, and two
  flags of a class differ only where one of them stores a value: both are answered without
  building the dicts, and ``values()`` reads the stored values and the options' defaults
  directly (what each property's getter returns).
- **NumPy's ufunc rules on scalar operators.** numba types ``a + b`` of two floats also through
  the array-operator template, which looks up NumPy's ufunc loop for the argument types and only
  then returns "not mine" because no argument is an array (~35 000 times). The template now
  returns that answer first.

Private numba API (pinned range in pyproject.toml): each patch checks the shape of what it
replaces and leaves numba alone when it differs. Serial compile of the textured scene's kernels
(one core): docs/kernels.md.
"""

from __future__ import annotations

import os

#: numba's switch for plain (uncoloured) error messages
HIGHLIGHTING_ENV = "NUMBA_DISABLE_ERROR_MESSAGE_HIGHLIGHTING"


def plain_error_messages() -> None:
    """Ask numba for uncoloured error messages unless the user chose (call before numba's
    first import; later it has no effect)."""
    os.environ.setdefault(HIGHLIGHTING_ENV, "1")


def _flags_compare_without_properties() -> None:
    from numba.core import targetconfig

    config = getattr(targetconfig, "TargetConfig", None)
    if config is None or getattr(config.values, "_drt", False) or "_values" not in getattr(config, "__slots__", ()):
        return
    original_eq = config.__eq__

    def values(self):
        """Returns a dict of all the values"""
        stored = self._values
        return {name: stored.get(name, option.default) for name, option in self.options.items()}

    def __hash__(self):
        # numba hashes the sorted option names (the keys of ``values()``): one value per class
        return hash(tuple(sorted(self.options)))

    def __eq__(self, other):
        if type(self) is not type(other):
            return original_eq(self, other)
        # an option neither stored is at its default in both: compare only the stored ones
        mine, theirs, options = self._values, other._values, self.options
        for name in mine.keys() | theirs.keys():
            default = options[name].default
            if mine.get(name, default) != theirs.get(name, default):
                return False
        return True

    for f in (values, __hash__, __eq__):
        f._drt = True
    config.values = values
    config.__hash__ = __hash__
    config.__eq__ = __eq__


def _scalar_operators_skip_ufunc_rules() -> None:
    from numba.core import types
    from numba.core.typing import npydecl

    rules = getattr(npydecl, "NumpyRulesArrayOperator", None)
    if rules is None or getattr(rules.generic, "_drt", False):
        return
    original = rules.generic
    array = types.ArrayCompatible

    def generic(self, args, kws):
        # the original answers None whenever no argument is an array, after matching a loop
        if not any(isinstance(a.type if isinstance(a, types.Optional) else a, array) for a in args):
            return None
        return original(self, args, kws)

    generic._drt = True
    generic.__doc__ = original.__doc__
    rules.generic = generic


def skip_typing_overheads() -> None:
    """Install the patches (after numba is imported)."""
    _flags_compare_without_properties()
    _scalar_operators_skip_ufunc_rules()
