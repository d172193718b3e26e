"""Filter entries ``NAME[:opt=value...]``: the one parser of ``--filter``, ``lc``, the
experiments and the study specs.

Grammar
-------
``NAME`` is a built-in name (``ekf``, ``ff-aukf``, ... case-insensitive), a name added by
:func:`~sdr_di.filters.register_filter` or an installed package (entry point), or an import
path ``package.module:Attribute`` (case kept). The fields after it are ``key=value`` options.
An import path is told from options by its second field: ``pkg.mod:Cls:window=5`` is the
filter ``pkg.mod:Cls`` with ``window=5``; ``ekf:window=5`` is ``ekf`` with an option, since
an option holds ``=`` and an attribute never does. A known name (built-in or plugin) is never
read as a module, and a module path is dotted identifiers (``ff-aukf`` is not one).

Option types
------------
Each option is converted by the type of the parameter it reaches (the core filter's or the
rule's constructor, as :func:`~sdr_di.filters.make_filter` routes them; a plugin's own
signature): from its annotation, else from its default.

=========  ===================================================================
``bool``   ``true``/``false``, ``1``/``0``, ``yes``/``no`` (any case); nothing else
``int``    a whole number
``float``  a number (``1e-3``, ``0.95``; not NaN)
``str``    the text; where the rule has fixed choices the rule checks them
``None``   ``none`` where the parameter allows ``None``
=========  ===================================================================

Options whose type text cannot express (tuples, arrays) are refused with the option named.
``error_states`` (``none``, ``sf``, ``gm``, ``sf+gm``) is accepted by every name, plugins
included: it chooses the error states the models carry (:mod:`sdr_di.filters.state`), and
its value is checked here.
``dt`` is never an option: the receiver sets it (``--filter-rate``). A built-in entry is
checked by building it on a 2-state model, so that a bad choice (``q_states=some``) is a
:class:`~sdr_di.errors.FilterError` before any work.
"""

from __future__ import annotations

import dataclasses
import inspect
import math
from collections.abc import Callable

from ..errors import FilterError
from .plugins import is_import_path, resolve_plugin

__all__ = ["FilterSpec", "OptionInfo", "canonical_entry", "filter_option_info",
           "parse_filter_spec", "split_filter_spec"]

_TRUE = ("true", "1", "yes")
_FALSE = ("false", "0", "no")
#: The positional inputs every factory receives (never options).
_INPUTS = ("self", "process_model", "measurement_model", "x0", "P0", "Q0", "R0")
#: Keywords set by make_filter or the receiver, never by an entry.
_RESERVED = ("dt", "name", "rule", "points")


@dataclasses.dataclass(frozen=True)
class OptionInfo:
    """One option of a filter: name, type text (annotation), default and where it goes."""

    name: str
    type: str
    default: object
    target: str  # "core", "rule" or "plugin"


@dataclasses.dataclass(frozen=True)
class FilterSpec:
    """A parsed filter entry.

    Attributes
    ----------
    name : str
        Registry or plugin name (lower case) or import path ``module:Attribute`` (as given).
    options : dict
        Options, converted to their parameters' types.
    """

    name: str
    options: dict

    @property
    def text(self) -> str:
        """The entry in canonical form (``name:key=value...``; the option order kept)."""
        return ":".join([self.name] + [f"{k}={_fmt(v)}" for k, v in self.options.items()])


def _fmt(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    return "none" if v is None else str(v)


def split_filter_spec(text: str) -> tuple[str, list[tuple[str, str]]]:
    """``"pkg.mod:Cls:window=5"`` -> ``("pkg.mod:Cls", [("window", "5")])`` (module notes):
    the name and the raw ``key=value`` pairs, without conversion."""
    raw = str(text).strip()
    fields = raw.split(":")
    head = fields[0].strip()
    rest = fields[1:]
    from .registry import FILTER_NAMES

    module_like = all(part.isidentifier() for part in head.split("."))
    known = head.lower() in FILTER_NAMES or head.lower() in _registered_names()
    if rest and "=" not in rest[0] and module_like and not known:
        attr = rest[0].strip()
        if not head or not attr:
            raise FilterError(f"filter {raw!r}: an import path is package.module:Name")
        name = f"{head}:{attr}"
        rest = rest[1:]
    elif "." in head:
        raise FilterError(f"filter {raw!r}: an import path is package.module:Name (the "
                          "attribute after ':' is missing)")
    else:
        name = head.lower()
    if not name:
        raise FilterError(f"filter {raw!r}: no filter name")
    pairs = []
    for o in rest:
        key, eq, val = o.partition("=")
        key, val = key.strip(), val.strip()
        if not eq or not key or not val:
            raise FilterError(f"filter {raw!r}: option {o!r} is not key=value")
        pairs.append((key if is_import_path(name) else key.lower(), val))
    keys = [k for k, _ in pairs]
    dup = sorted({k for k in keys if keys.count(k) > 1})
    if dup:
        raise FilterError(f"filter {raw!r}: option(s) {', '.join(dup)} given twice")
    return name, pairs


def canonical_entry(entry: str) -> str:
    """A filter entry as the experiments and studies label it: in lower case, except an import
    path (``pkg.mod:MyEKF``) and its options, whose case is kept; the options as written.

    An entry may end with a coupling mode after ``@`` (``ekf@tight``: experiments and
    studies). Two entries that differ only in how an option's value is written
    (``scale=2``, ``scale=2.0``) have different labels but the same :attr:`FilterSpec.text`.
    A malformed entry is returned in lower case (:func:`parse_filter_spec` reports it).
    """
    text = str(entry).strip()
    spec, at, mode = text.partition("@")
    try:
        name, pairs = split_filter_spec(spec)
    except FilterError:
        return text.lower()
    if not is_import_path(name):
        return text.lower()
    return ":".join([name] + [f"{k}={v}" for k, v in pairs]) + (
        f"@{mode.strip().lower()}" if at else "")


def _registered_names() -> tuple[str, ...]:
    from .plugins import plugin_names

    return plugin_names()


def _params(fn: Callable, skip_inputs: bool) -> tuple[list[inspect.Parameter], bool]:
    """Keyword parameters of ``fn`` (no inputs, no reserved names) and whether it takes
    ``**kwargs``."""
    try:
        sig = inspect.signature(fn)
    except (TypeError, ValueError):
        return [], True
    out, var_kw = [], False
    positional = 0
    for p in sig.parameters.values():
        if p.kind is p.VAR_KEYWORD:
            var_kw = True
            continue
        if p.kind is p.VAR_POSITIONAL:
            continue
        if skip_inputs and p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD) \
                and positional < len(_INPUTS) and p.name in _INPUTS:
            positional += 1
            continue
        if p.name in _INPUTS or p.name in _RESERVED:
            continue
        out.append(p)
    return out, var_kw


def _factory_params(factory: Callable, skip_inputs: bool = True) -> tuple[list, bool]:
    """Keyword parameters of a factory; a class's ``__init__`` chain is followed through
    ``**kwargs`` (a subclass of :class:`~sdr_di.filters.EKF` takes ``psd_fallback``)."""
    if not inspect.isclass(factory):
        return _params(factory, skip_inputs)
    seen: set[str] = set()
    out: list[inspect.Parameter] = []
    for klass in factory.__mro__:
        init = klass.__dict__.get("__init__")
        if init is None:
            continue
        if klass is object:
            return out, False
        ps, var_kw = _params(init, skip_inputs)
        out += [p for p in ps if p.name not in seen]
        seen.update(p.name for p in ps)
        if not var_kw:
            return out, False
    return out, True


def _info(p: inspect.Parameter, target: str) -> OptionInfo:
    ann = p.annotation
    if ann is inspect.Parameter.empty:
        d = p.default
        text = "any" if d is inspect.Parameter.empty or d is None else type(d).__name__
        if d is None:
            text = "any | None"
    else:
        text = ann if isinstance(ann, str) else getattr(ann, "__name__", str(ann))
    default = None if p.default is inspect.Parameter.empty else p.default
    return OptionInfo(p.name, text, default, target)


def filter_option_info(name: str) -> tuple[list[OptionInfo], bool]:
    """Options of a filter name and whether it takes others (a plugin with ``**kwargs``).

    Raises
    ------
    FilterError
        Unknown name, or a plugin that fails to import.
    """
    from .registry import _CORE_OPTIONS, _REGISTRY

    from .registry import MODEL_OPTIONS

    model = [OptionInfo(k, t, d, "model") for k, (t, d) in MODEL_OPTIONS.items()]
    key = str(name).strip() if is_import_path(name) else str(name).strip().lower()
    if key in _REGISTRY:
        core_cls, rule_cls = _REGISTRY[key]
        core, _ = _factory_params(core_cls)
        infos = [_info(p, "core") for p in core if p.name in _CORE_OPTIONS[core_cls]]
        if rule_cls is not None:
            rule, _ = _factory_params(rule_cls, skip_inputs=False)
            infos += [_info(p, "rule") for p in rule]
        return infos + model, False
    factory = resolve_plugin(key)
    if factory is None:
        from .plugins import plugin_names
        from .registry import FILTER_NAMES

        raise FilterError(f"unknown filter {name!r}; valid names: "
                          f"{', '.join(FILTER_NAMES + plugin_names())} or an import path "
                          "package.module:Name")
    ps, var_kw = _factory_params(factory)
    return [_info(p, "plugin") for p in ps if p.name not in MODEL_OPTIONS] + model, var_kw


def _convert(where: str, key: str, raw: str, type_text: str):
    alts = [a.strip() for a in type_text.split("|")]
    if "None" in alts and raw.lower() == "none":
        return None
    alts = [a for a in alts if a != "None"] or ["any"]
    if len(alts) > 1 or alts[0] == "any":
        return _guess(raw)
    kind = alts[0]
    if kind == "bool":
        low = raw.lower()
        if low in _TRUE or low in _FALSE:
            return low in _TRUE
        raise FilterError(f"{where}: option {key}={raw!r}: expected true/false/1/0/yes/no")
    if kind == "int":
        try:
            return int(raw)
        except ValueError:
            raise FilterError(f"{where}: option {key}={raw!r}: expected a whole number") \
                from None
    if kind == "float":
        try:
            v = float(raw)
        except ValueError:
            v = math.nan
        if math.isnan(v):
            raise FilterError(f"{where}: option {key}={raw!r}: expected a number")
        return v
    if kind == "str":
        return raw
    raise FilterError(f"{where}: option {key} ({type_text}) cannot be given as text; set it "
                      "from Python (make_filter keyword)")


def _guess(raw: str):
    """Value of an option of unknown type: ``none``, a whole number, a number, a boolean
    word, else the text."""
    low = raw.lower()
    if low == "none":
        return None
    for kind in (int, float):
        try:
            return kind(raw)
        except ValueError:
            pass
    if low in ("true", "yes"):
        return True
    if low in ("false", "no"):
        return False
    return raw


def parse_filter_spec(text: str) -> FilterSpec:
    """Parse and check a filter entry ``NAME[:opt=value...]`` (module notes).

    Parameters
    ----------
    text : str
        ``"ff-aukf:q_states=nominal:adapt_q=false"``, ``"my_pkg.filters:MyEKF:gain=2"``.

    Returns
    -------
    FilterSpec
        The name and the options converted to their types.

    Raises
    ------
    FilterError
        Unknown name, a plugin that fails to import, an unknown option, a value that is not
        of the option's type or choices. One line.
    """
    name, pairs = split_filter_spec(text)
    where = f"filter {str(text).strip()!r}"
    infos, open_ended = filter_option_info(name)
    by_name = {i.name: i for i in infos}
    options = {}
    for key, raw in pairs:
        if key in _RESERVED:
            raise FilterError(f"{where}: {key} is set by the receiver (dt: --filter-rate), "
                              "not by a filter option")
        info = by_name.get(key)
        if info is None and not open_ended:
            raise FilterError(f"{where}: unknown option {key!r}; accepted: "
                              f"{', '.join(by_name) or '(none)'}")
        options[key] = _convert(where, key, raw, info.type if info else "any")
        if info is not None and info.target == "model":
            from .state import state_layout

            try:
                options[key] = state_layout(options[key]).error_states
            except FilterError as exc:
                raise FilterError(f"{where}: {exc}") from None
    if not is_import_path(name) and name in _builtin():
        _try_build(where, name, options)
    return FilterSpec(name, options)


def _builtin() -> tuple[str, ...]:
    from .registry import FILTER_NAMES

    return FILTER_NAMES


def _try_build(where: str, name: str, options: dict) -> None:
    """Build a built-in filter with ``options`` on a 2-state model: the core's and the rule's
    own checks (choices, ranges) run now, before any work."""
    import numpy as np

    from .models import LinearProcessModel
    from .registry import make_filter

    try:
        make_filter(name, LinearProcessModel(np.eye(2)), None, np.zeros(2), np.eye(2),
                    np.eye(2), **options)
    except FilterError as exc:
        raise FilterError(f"{where}: {exc}") from None
    except (TypeError, ValueError) as exc:
        raise FilterError(f"{where}: {exc}") from None
