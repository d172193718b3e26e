"""Old import names that keep working for one release, with a :class:`DeprecationWarning`.

Two kinds of old names, two helpers:

* a **module** that moved (``sdr_di.deep.vector_loop`` -> ``sdr_di.integration.receiver``):
  :func:`alias_modules`, called by the old package, installs an import hook that answers the
  old dotted name with the new module object itself (same classes, same functions; ``is``
  holds), warning once per import. No file stays at the old path, so a version-control merge
  sees a plain rename.
* a **name** that a package re-exported (``sdr_di.deep.DeepReceiver``):
  :func:`forwarding_getattr` makes the package's module ``__getattr__`` (PEP 562), which
  imports the new home lazily, warns and returns the object.

Both warnings name the old and the new spelling, so the fix is one search-and-replace.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import types
import warnings
from collections.abc import Callable, Mapping

__all__ = ["alias_modules", "forwarding_getattr"]


def _caller_stacklevel() -> int:
    """``stacklevel`` that points :func:`warnings.warn`, called by this module, at the first
    frame outside this module and the import machinery (the line that wrote the old name).
    :func:`warnings.warn` itself skips the ``importlib._bootstrap`` frames when counting."""
    level = 1
    f = sys._getframe(2)                  # the caller of the function that warns
    while f is not None:
        name = f.f_code.co_filename
        if "importlib" in name and "_bootstrap" in name:
            f = f.f_back
            continue
        level += 1
        if name not in (__file__, importlib.__file__):     # import_module is the machinery
            return level
        f = f.f_back
    return 1


class _MovedModuleFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Import hook: old dotted module name -> the module at its new name."""

    def __init__(self) -> None:
        self.moved: dict[str, str] = {}
        self._spec_of: dict[str, importlib.machinery.ModuleSpec] = {}

    def find_spec(self, fullname, path=None, target=None):
        if fullname not in self.moved:
            return None
        return importlib.machinery.ModuleSpec(fullname, self)

    def create_module(self, spec):
        new = self.moved[spec.name]
        warnings.warn(f"{spec.name} is deprecated and will be removed in the next release: "
                      f"import {new}", DeprecationWarning, stacklevel=_caller_stacklevel())
        module = importlib.import_module(new)
        self._spec_of[spec.name] = module.__spec__
        return module

    def exec_module(self, module) -> None:
        # the import system stamped the old name's spec on the shared module: give it back
        # its own, so that the new name stays the module's one identity
        for old, spec in list(self._spec_of.items()):
            if spec is not None and spec.name == module.__name__:
                module.__spec__ = spec
                del self._spec_of[old]


_FINDER = _MovedModuleFinder()


def alias_modules(package: str, moved: Mapping[str, str]) -> None:
    """Answer ``package.OLD`` imports with the module ``moved[OLD]`` (a full dotted name).

    Parameters
    ----------
    package : str
        The old package (its ``__name__``).
    moved : mapping
        Old submodule name (no dots) -> new full module name.
    """
    _FINDER.moved.update({f"{package}.{old}": new for old, new in moved.items()})
    if _FINDER not in sys.meta_path:
        sys.meta_path.insert(0, _FINDER)


def forwarding_getattr(package: str, moved: Mapping[str, str]) -> Callable[[str], object]:
    """A PEP 562 module ``__getattr__`` for names that moved out of ``package``.

    Parameters
    ----------
    package : str
        The module whose ``__getattr__`` this becomes (its ``__name__``).
    moved : mapping
        Old attribute name -> ``"new.module:new_name"`` (or ``"new.module"``: the same
        name there).

    Returns
    -------
    callable
        ``__getattr__(name)``: warns with a :class:`DeprecationWarning` and returns the
        object; :class:`AttributeError` for any other name.
    """

    def __getattr__(name: str):
        if name not in moved:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        target = moved[name]
        mod_name, _, new_name = target.partition(":")
        new_name = new_name or name
        warnings.warn(f"{package}.{name} is deprecated and will be removed in the next "
                      f"release: use {mod_name}.{new_name}",
                      DeprecationWarning, stacklevel=2)
        module: types.ModuleType = importlib.import_module(mod_name)
        return getattr(module, new_name)

    return __getattr__
