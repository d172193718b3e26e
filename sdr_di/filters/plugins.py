"""Plugin filters: names registered in code, by installed packages, or given as import paths.

A plugin is a *factory*: a callable (usually a class) that receives what
:func:`~sdr_di.filters.make_filter` receives and returns an object with the
:class:`~sdr_di.filters.base.KalmanFilterBase` interface::

    factory(process_model, measurement_model, x0, P0, Q0, R0, **options) -> filter

Three ways to name one (docs/filters.md, "Your own filter"):

``register_filter("my-ekf", MyEKF)``
    in code, before the run (a name like the built-in ones, case-insensitive);
entry-point group ``sdr_di.filters``
    an installed package declares ``my-ekf = "my_pkg.filters:MyEKF"`` under
    ``[project.entry-points."sdr_di.filters"]``; the name is loaded on first use;
``package.module:Attribute``
    an import path, anywhere a filter name is taken (``--filter``, study specs); the module
    must be importable: installed, on ``PYTHONPATH``, or under the current folder (a module
    not found on ``sys.path`` is looked for there, as ``python -m`` does).

A plugin that cannot be imported, is not callable, or returns an object without the interface
raises :class:`~sdr_di.errors.FilterError` (one line; the CLI exits 2 before any work).
Naming a plugin imports its module, which runs the module's code.

Once built, a plugin's methods are called through one guard (:func:`guard_plugin`): an
exception it raises during the run (other than sdr-di's own errors, which keep their
meaning) becomes a :class:`~sdr_di.errors.PluginError` naming the plugin, the call and the
exception: one line and exit 1 from the CLI, a failed run of that filter alone in a study.
"""

from __future__ import annotations

import contextlib
import contextvars
import importlib
import importlib.metadata
import os
import sys
from collections.abc import Callable

import numpy as np

from ..errors import FilterError, PluginError, SdrDiError

__all__ = ["ENTRY_POINT_GROUP", "check_interface", "guard_plugin", "is_import_path",
           "plugin_names",
           "register_filter", "resolve_plugin", "unregister_filter"]

#: Entry-point group through which installed packages add filter names.
ENTRY_POINT_GROUP = "sdr_di.filters"

#: Methods and attributes every filter must have (KalmanFilterBase's interface).
REQUIRED_METHODS = ("predict", "update")
REQUIRED_ARRAYS = ("x", "P", "Q")
#: Attributes the receiver's loops read (``rule`` may be None); a subclass of
#: KalmanFilterBase has them all.
REQUIRED_ATTRS = ("nis", "adaptation_time_s", "rule")

_REGISTERED: dict[str, Callable] = {}

#: True while a specification is checked before its plugins may run (:func:`plugins_deferred`).
_DEFERRED: contextvars.ContextVar[bool] = contextvars.ContextVar("sdr_di_plugins_deferred",
                                                                 default=False)


@contextlib.contextmanager
def plugins_deferred():
    """Check a specification without importing its plugins: inside the block an import path
    or an entry-point name resolves to a stand-in that takes any option, so that everything
    else in the spec is judged first; the caller checks it again after the block, importing
    the plugins (naming a plugin runs its module's code: issue 49 item 11)."""
    token = _DEFERRED.set(True)
    try:
        yield
    finally:
        _DEFERRED.reset(token)


def names_unloaded_plugin(entries) -> bool:
    """Whether filter entries (``"ekf"``, ``"pkg.mod:Cls:opt=1"``, ``"x@tight"``) name a plugin
    whose code is not loaded yet: an import path or an installed entry point (a name
    registered in code has run already)."""
    from .spec import split_filter_spec

    for entry in entries if isinstance(entries, (list, tuple)) else ():
        try:
            name = split_filter_spec(str(entry).partition("@")[0])[0]
        except FilterError:
            continue
        key = name.strip().lower()
        if is_import_path(name) or (key not in _REGISTERED and key in _entry_points()):
            return True
    return False


def _stand_in(*args, **options):
    """The factory of a plugin not yet imported (:func:`plugins_deferred`); never built."""
    raise FilterError("a plugin was built while plugins were deferred")


def _builtin_names() -> tuple[str, ...]:
    from .registry import FILTER_NAMES

    return FILTER_NAMES


def register_filter(name: str, factory: Callable) -> None:
    """Add a filter name (module notes).

    Parameters
    ----------
    name : str
        New name (case-insensitive, no ``:``, ``.``, ``@``, ``,`` or ``=``); not a built-in.
    factory : callable
        ``factory(process_model, measurement_model, x0, P0, Q0, R0, **options)`` returning
        an object with the :class:`~sdr_di.filters.base.KalmanFilterBase` interface.

    Raises
    ------
    FilterError
        A built-in or malformed name, or a factory that is not callable.
    """
    key = str(name).strip().lower()
    if not key or any(c in key for c in ":.@,= "):
        raise FilterError(f"register_filter: name {name!r} must be non-empty without "
                          "':', '.', '@', ',', '=' or spaces")
    if key in _builtin_names():
        raise FilterError(f"register_filter: {key!r} is a built-in filter")
    if not callable(factory):
        raise FilterError(f"register_filter: factory of {key!r} is not callable")
    _REGISTERED[key] = factory


def unregister_filter(name: str) -> None:
    """Remove a name added by :func:`register_filter` (no error if absent)."""
    _REGISTERED.pop(str(name).strip().lower(), None)


def _entry_points() -> dict:
    eps = importlib.metadata.entry_points(group=ENTRY_POINT_GROUP)
    return {ep.name.strip().lower(): ep for ep in eps}


def plugin_names() -> tuple[str, ...]:
    """Names added by :func:`register_filter` and by installed packages' entry points."""
    return tuple(dict.fromkeys([*_REGISTERED, *_entry_points()]))


def is_import_path(name: str) -> bool:
    """Whether a filter name is an import path ``module:Attribute`` (``:`` in it)."""
    return ":" in str(name)


def _import_module(mod_name: str):
    """``importlib.import_module``; a module not found is looked for in the current folder
    too, as ``python -m`` does (the ``sdr-di`` script's own folder is on ``sys.path``, the
    folder it is run from is not)."""
    try:
        return importlib.import_module(mod_name)
    except ModuleNotFoundError as exc:
        cwd = os.getcwd()
        top = mod_name.partition(".")[0]
        if exc.name not in (top, mod_name) or cwd in sys.path or "" in sys.path:
            raise
        sys.path.append(cwd)
        return importlib.import_module(mod_name)


def _import(path: str) -> Callable:
    mod_name, _, attr = path.partition(":")
    if not mod_name or not attr:
        raise FilterError(f"filter {path!r}: an import path is package.module:Name")
    try:
        obj = _import_module(mod_name)
    except Exception as exc:  # ImportError, or the module's own error while importing
        raise FilterError(f"filter {path!r}: cannot import {mod_name!r} "
                          f"({type(exc).__name__}: {exc})") from None
    for part in attr.split("."):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            raise FilterError(f"filter {path!r}: module {mod_name!r} has no {attr!r}") from None
    return obj


def resolve_plugin(name: str) -> Callable | None:
    """The factory of a plugin name (registered, entry point or import path); None when
    ``name`` is none of these.

    Raises
    ------
    FilterError
        An import path or entry point that fails to import, or a factory that is not
        callable.
    """
    name = str(name).strip()
    factory: Callable | None
    if is_import_path(name):
        mod_name, _, attr = name.partition(":")
        if _DEFERRED.get() and mod_name and attr:
            return _stand_in
        factory = _import(name)
    else:
        key = name.lower()
        factory = _REGISTERED.get(key)
        if factory is None:
            ep = _entry_points().get(key)
            if ep is None:
                return None
            if _DEFERRED.get():
                return _stand_in
            try:
                factory = ep.load()
            except Exception as exc:
                raise FilterError(f"filter {key!r} (entry point {ep.value!r}): cannot load "
                                  f"({type(exc).__name__}: {exc})") from None
    if not callable(factory):
        raise FilterError(f"filter {name!r}: {factory!r} is not callable")
    return factory


def check_interface(name: str, filt, n_states: int) -> None:
    """Raise :class:`FilterError` unless ``filt`` has the filter interface: callable
    ``predict`` and ``update``; ``x`` (n,), ``P`` (n, n), ``Q`` (n, n) arrays; ``nis``,
    ``adaptation_time_s`` and ``rule`` attributes."""
    missing = [m for m in REQUIRED_METHODS if not callable(getattr(filt, m, None))]
    missing += [a for a in REQUIRED_ARRAYS if getattr(filt, a, None) is None]
    missing += [a for a in REQUIRED_ATTRS if not hasattr(filt, a)]
    if missing:
        raise FilterError(f"filter {name!r}: {type(filt).__name__} lacks the filter interface "
                          f"({', '.join(missing)}; see docs/filters.md)")
    shapes = {"x": (n_states,), "P": (n_states, n_states), "Q": (n_states, n_states)}
    for a, shape in shapes.items():
        got = np.shape(getattr(filt, a))
        if got != shape:
            raise FilterError(f"filter {name!r}: {a} has shape {got}, expected {shape}")


#: The methods of a plugin the receiver calls during a run, each through :func:`guard_plugin`.
GUARDED_METHODS = ("predict", "update")


def guard_plugin(label: str, filt):
    """Route the run-time calls of the plugin filter ``filt`` (:data:`GUARDED_METHODS`)
    through one guard; returns ``filt``.

    An exception of the plugin's code (not an :class:`~sdr_di.errors.SdrDiError`, not an
    interrupt) is raised again as :class:`~sdr_di.errors.PluginError`: ``filter plugin
    'mod:Cls': update() raised ZeroDivisionError: ... (call 31)``.
    """
    for method in GUARDED_METHODS:
        if not callable(getattr(type(filt), method, None)):
            continue
        try:
            setattr(filt, method, _Guarded(label, method, filt))
        except AttributeError:  # __slots__ without a __dict__: left unguarded
            pass
    return filt


class _Guarded:
    """A plugin's method behind the guard (:func:`guard_plugin`): calls the class's method
    on ``filt``; copies and pickles with the filter (deep-start sharing, the loop process)."""

    def __init__(self, label: str, method: str, filt) -> None:
        self.label, self.method, self.filt, self.calls = label, method, filt, 0

    def __call__(self, *args, **kwargs):
        self.calls += 1
        try:
            return getattr(type(self.filt), self.method)(self.filt, *args, **kwargs)
        except SdrDiError:
            raise
        except Exception as exc:  # noqa: BLE001 - the user's code: its failure, in one line
            text = " ".join(str(exc).split())
            raise PluginError(f"filter plugin {self.label!r}: {self.method}() raised "
                              f"{type(exc).__name__}"
                              + (f": {text[:200]}" if text else "")
                              + f" (call {self.calls})") from None
