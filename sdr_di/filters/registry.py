"""Filter registry: ``make_filter(name, ...)`` builds a core filter with its adaptive rule.

=================  ======  ==============================================================
name               core    adaptive rule
=================  ======  ==============================================================
``ekf``            EKF     --
``ukf``            UKF     --
``ckf``            CKF     --
``ff-aukf``        UKF     :class:`~.adaptive.ForgettingFactorAUKF` (paper 004)
``rae-aukf``       UKF     :class:`~.adaptive.SageWindowAUKF` (paper 004 baseline)
``ml-q-ukf``       UKF     :class:`~.adaptive.MLProcessNoiseUKF` (paper 000)
``sage-husa-ukf``  UKF     :class:`~.adaptive.SageHusaUKF` (paper 001)
``q-scaling-ekf``  EKF     :class:`~.adaptive.ProcessNoiseScaling` (paper 002)
``q-scaling-ukf``  UKF     :class:`~.adaptive.ProcessNoiseScaling` (paper 002)
``ml-r-ckf``       CKF     :class:`~.adaptive.MLMeasurementNoiseCKF` (paper 003)
=================  ======  ==============================================================

Options are routed by name: ``dt``, ``psd_fallback``, ``q_scale``, ``r_scale`` (all cores),
``alpha``, ``beta``, ``kappa`` (UKF cores) go to the core filter, the others to the rule's
constructor (see each rule); an unknown option raises :class:`~.errors.FilterError` listing
the accepted ones. ``error_states`` (:data:`MODEL_OPTIONS`) is an option of every name,
built-in or plugin, that goes to neither: it chooses the *models* (the error states of
:func:`~.state.state_layout`), which the caller builds before ``make_filter``
(:func:`sdr_di.integration.filter_setup.make_integration_filter`); ``make_filter`` checks its
value and that the process model's ``layout`` agrees, and never passes it on, so a filter
(a plugin too) sees only the layout it is given (``x0.size``, ``process_model.layout``).

Any other name is a plugin (:mod:`.plugins`): one added by :func:`~.plugins.register_filter`
or an installed package's entry point, or an import path ``package.module:Name``; its factory
receives the same inputs and options and must return an object with the filter interface.
Entries with options as text (``ff-aukf:q_states=nominal``) are parsed by
:func:`~.spec.parse_filter_spec`; :func:`filter_table` lists every name with its options.
"""

from __future__ import annotations

import dataclasses
import inspect

import numpy as np

from ..errors import FilterError
from .adaptive import (
    ForgettingFactorAUKF,
    MLMeasurementNoiseCKF,
    MLProcessNoiseUKF,
    ProcessNoiseScaling,
    SageHusaUKF,
    SageWindowAUKF,
)
from .base import KalmanFilterBase
from .ekf import EKF
from .models import MeasurementModel, ProcessModel
from .sigma_filter import CKF, UKF
from .state import state_layout

__all__ = ["FILTER_NAMES", "MODEL_OPTIONS", "filter_options", "filter_record", "filter_table",
           "make_filter"]

_REGISTRY = {
    "ekf": (EKF, None),
    "ukf": (UKF, None),
    "ckf": (CKF, None),
    "ff-aukf": (UKF, ForgettingFactorAUKF),
    "rae-aukf": (UKF, SageWindowAUKF),
    "ml-q-ukf": (UKF, MLProcessNoiseUKF),
    "sage-husa-ukf": (UKF, SageHusaUKF),
    "q-scaling-ekf": (EKF, ProcessNoiseScaling),
    "q-scaling-ukf": (UKF, ProcessNoiseScaling),
    "ml-r-ckf": (CKF, MLMeasurementNoiseCKF),
}

#: Paper and equations behind each built-in name (the adaptive rules' module docstrings;
#: the cores' in ekf.py and sigma_filter.py).
_EQUATIONS = {
    "ekf": "EKF: x^- = f(x), P^- = F P F^T + Q; correction paper 004 eq 22-25",
    "ukf": "UKF, scaled unscented points: paper 004 eq 13-25",
    "ckf": "CKF, cubature points: paper 003 eq 17-28",
    "ff-aukf": "forgetting-factor AUKF: paper 004 eq 26-39, Table 2",
    "rae-aukf": "Sage-window RAE/IAE AUKF: paper 004 baseline (section III.B)",
    "ml-q-ukf": "maximum-likelihood Q: paper 000 eq 47/49, sec. 3.3",
    "sage-husa-ukf": "Sage-Husa noise statistics: paper 001 eq 30-33",
    "q-scaling-ekf": "covariance-matching Q scaling: paper 002 eq 16-22",
    "q-scaling-ukf": "covariance-matching Q scaling: paper 002 eq 16-22",
    "ml-r-ckf": "maximum-likelihood R by SQP: paper 003 eq 35-38",
}

#: Valid registry names, in table order.
FILTER_NAMES: tuple[str, ...] = tuple(_REGISTRY)

_BASE_OPTIONS = ("dt", "psd_fallback", "q_scale", "r_scale")
#: Options of every filter name that choose the models, not the filter (module notes):
#: name -> (type text, default).
MODEL_OPTIONS: dict[str, tuple[str, str]] = {"error_states": ("str", "none")}


def _take_model_options(who: str, process_model, options: dict) -> dict:
    """``options`` without :data:`MODEL_OPTIONS`, after checking them: a valid
    ``error_states`` that agrees with ``process_model.layout`` where the model has one."""
    if "error_states" not in options:
        return options
    try:
        layout = state_layout(options["error_states"])
    except FilterError as exc:
        raise FilterError(f"{who}: {exc}") from None
    have = getattr(process_model, "layout", None)
    if have is not None and getattr(have, "error_states", None) != layout.error_states:
        raise FilterError(f"{who}: error_states={layout.error_states} but the process model "
                          f"has the layout of error_states={have.error_states}; build the "
                          "models for the option (sdr_di.integration.filter_setup)")
    return {k: v for k, v in options.items() if k not in MODEL_OPTIONS}
_CORE_OPTIONS: dict[type, tuple[str, ...]] = {
    EKF: _BASE_OPTIONS, CKF: _BASE_OPTIONS, UKF: _BASE_OPTIONS + ("alpha", "beta", "kappa")}


def _rule_options(rule_cls) -> tuple[str, ...]:
    if rule_cls is None:
        return ()
    sig = inspect.signature(rule_cls.__init__)
    return tuple(p for p in sig.parameters if p != "self")


def filter_options(name: str) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """Accepted ``(core options, rule options)`` of a registry name (the model options,
    :data:`MODEL_OPTIONS`, are accepted by every name besides these)."""
    core_cls, rule_cls = _lookup(name)
    return _CORE_OPTIONS[core_cls], _rule_options(rule_cls)


def _lookup(name: str):
    key = name.strip().lower() if isinstance(name, str) else name
    try:
        return _REGISTRY[key]
    except (KeyError, TypeError):
        raise FilterError(f"unknown filter {name!r}; valid names: "
                          f"{', '.join(FILTER_NAMES)}") from None


def make_filter(name: str, process_model: ProcessModel, measurement_model: MeasurementModel | None,
                x0, P0, Q0, R0=None, **options) -> KalmanFilterBase:
    """Build a filter by registry name.

    Parameters
    ----------
    name : str
        One of :data:`FILTER_NAMES` (case-insensitive), a plugin name or an import path
        ``package.module:Name`` (:mod:`.plugins`).
    process_model : ProcessModel
        State propagation ``f(x, dt)`` and its Jacobian ``F``
        (:class:`~sdr_di.filters.models.ProcessModel`).
    measurement_model : MeasurementModel or None
        ``h(x)`` and its Jacobian ``H`` (:class:`~sdr_di.filters.models.MeasurementModel`);
        None when every update brings its own.
    x0 : (n,) array_like
        Initial state.
    P0 : (n, n) array_like
        Initial state covariance (positive definite).
    Q0 : (n, n) array_like
        Process noise covariance per step.
    R0 : (m, m) array_like, optional
        Measurement noise covariance; None when ``R`` is given to every update.
    **options
        Core options (``dt``, ``psd_fallback``, ``q_scale``, ``r_scale``; ``alpha``, ``beta``,
        ``kappa`` for the UKF cores), rule options (e.g. ``window``, ``d`` for
        ``ff-aukf``) and ``error_states`` (checked against ``process_model.layout``, not
        passed on: module notes).

    Returns
    -------
    KalmanFilterBase
        The core filter (EKF/UKF/CKF) with its ``rule`` attached; ``.name`` is the registry
        name.

    Raises
    ------
    FilterError
        Unknown name (the message lists the valid names), unknown option, invalid input, a
        plugin that fails to import or lacks the interface.
    """
    who = str(name).strip() if isinstance(name, str) and ":" in name else \
        str(name).strip().lower()
    options = _take_model_options(who, process_model, options)
    if isinstance(name, str) and name.strip().lower() not in _REGISTRY:
        return _make_plugin(name, process_model, measurement_model, x0, P0, Q0, R0, options)
    core_cls, rule_cls = _lookup(name)
    key = name.strip().lower()
    core_names = _CORE_OPTIONS[core_cls]
    rule_names = _rule_options(rule_cls)
    unknown = sorted(set(options) - set(core_names) - set(rule_names))
    if unknown:
        raise FilterError(f"{key}: unknown option(s) {', '.join(unknown)}; accepted: "
                          f"{', '.join(core_names + rule_names + tuple(MODEL_OPTIONS))}")
    core_opts = {k: v for k, v in options.items() if k in core_names}
    rule_opts = {k: v for k, v in options.items() if k in rule_names}
    filt = core_cls(process_model, measurement_model, x0, P0, Q0, R0, name=key, **core_opts)
    if rule_cls is not None:
        filt.attach_rule(rule_cls(**rule_opts))
    return filt


def _make_plugin(name: str, process_model, measurement_model, x0, P0, Q0, R0,
                 options: dict) -> KalmanFilterBase:
    """A plugin filter (:mod:`.plugins`): its factory with the inputs and the options; ``dt``
    only where the factory takes it. The result's ``name`` is set to ``name``."""
    from .plugins import check_interface, guard_plugin, resolve_plugin
    from .spec import _factory_params

    factory = resolve_plugin(name)
    if factory is None:
        _lookup(name)  # raises: unknown filter
    assert factory is not None
    label = name.strip() if ":" in name else name.strip().lower()
    params, var_kw = _factory_params(factory)
    takes = {p.name for p in params}
    if "dt" in options and not var_kw and "dt" not in takes:
        options = {k: v for k, v in options.items() if k != "dt"}
    unknown = sorted(set(options) - takes - {"dt"}) if not var_kw else []
    if unknown:
        raise FilterError(f"filter {label!r}: unknown option(s) {', '.join(unknown)}; "
                          f"accepted: {', '.join(sorted(takes)) or '(none)'}")
    try:
        filt = factory(process_model, measurement_model, x0, P0, Q0, R0, **options)
    except FilterError:
        raise
    except Exception as exc:
        raise FilterError(f"filter {label!r}: the factory failed ({type(exc).__name__}: "
                          f"{exc})") from None
    check_interface(label, filt, np.asarray(x0).size)
    try:
        filt.name = label
    except AttributeError:
        pass
    return guard_plugin(label, filt)


def plugin_summary(name: str) -> str:
    """What ``sdr-di filters`` says of a plugin: the first line of its factory's docstring,
    and, first, ``NOT USABLE: lacks update`` where a class factory lacks a method the
    receiver calls (:data:`~.plugins.REQUIRED_METHODS`; issue 49 item 17)."""
    import inspect

    from .plugins import REQUIRED_METHODS, resolve_plugin

    try:
        factory = resolve_plugin(name)
    except FilterError as exc:
        return str(exc)
    doc = (inspect.getdoc(factory) or "").strip().splitlines()
    text = doc[0] if doc else "(plugin without a docstring)"
    if isinstance(factory, type):
        missing = [m for m in REQUIRED_METHODS if not callable(getattr(factory, m, None))]
        if missing:
            text = f"NOT USABLE: lacks {', '.join(missing)}; {text}"
    return text


def filter_table() -> list[dict]:
    """Every filter name (built-in, then plugins) with its core, rule, the paper equations
    and its options (``name``, ``type``, ``default``, ``target``); ``sdr-di filters``."""
    from .plugins import plugin_names
    from .spec import filter_option_info

    rows = []
    for name in FILTER_NAMES + plugin_names():
        entry = _REGISTRY.get(name)
        try:
            infos, open_ended = filter_option_info(name)
        except FilterError as exc:  # a broken installed plugin: listed with its error
            rows.append({"name": name, "core": "plugin", "rule": "", "equations": str(exc),
                         "options": [], "open": False})
            continue
        rows.append({
            "name": name,
            "core": entry[0].__name__ if entry else "plugin",
            "rule": entry[1].__name__ if entry and entry[1] else "",
            "equations": _EQUATIONS.get(name) or plugin_summary(name),
            "options": [dataclasses.asdict(i) for i in infos],
            "open": open_ended,
        })
    return rows


def filter_record(filt, name: str, options: dict) -> dict:
    """Summary entry of a built filter: what it actually uses, read from the object (not from
    the settings that asked for it), so that a plugin's own ``Q`` or ``P0`` is recorded.

    Returns
    -------
    dict
        ``spec`` (``name:key=value...``), ``name``, ``class`` (``module:QualName``),
        ``options``, ``rule`` (class name or None), ``Q0_diag``, ``P0_diag`` and ``R0_diag``
        (None where the filter is given ``R`` at each update) as built.
    """
    def _diag(a):
        if a is None:
            return None
        d = np.diag(np.atleast_2d(np.asarray(a, float)))
        return [float(v) if np.isfinite(v) else None for v in d]

    def _plain(v):
        return v if v is None or isinstance(v, (bool, int, float, str)) else repr(v)

    from .spec import FilterSpec

    opts = {k: _plain(v) for k, v in options.items()}
    rule = getattr(filt, "rule", None)
    cls = type(filt)
    return {"spec": FilterSpec(name, dict(options)).text, "name": name,
            "class": f"{cls.__module__}:{cls.__qualname__}", "options": opts,
            "rule": None if rule is None else type(rule).__name__,
            "Q0_diag": _diag(getattr(filt, "Q", None)),
            "P0_diag": _diag(getattr(filt, "P", None)),
            "R0_diag": _diag(getattr(filt, "R", None))}
