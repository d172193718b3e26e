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
the accepted ones.
"""

from __future__ import annotations

import inspect

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

__all__ = ["FILTER_NAMES", "filter_options", "make_filter"]

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

#: Valid registry names, in table order.
FILTER_NAMES: tuple[str, ...] = tuple(_REGISTRY)

_BASE_OPTIONS = ("dt", "psd_fallback", "q_scale", "r_scale")
_CORE_OPTIONS = {EKF: _BASE_OPTIONS, CKF: _BASE_OPTIONS,
                 UKF: _BASE_OPTIONS + ("alpha", "beta", "kappa")}


def _rule_options(rule_cls) -> tuple[str, ...]:
    if rule_cls is None:
        return ()
    sig = inspect.signature(rule_cls.__init__)
    return tuple(p for p in sig.parameters if p != "self")


def filter_options(name: str) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """Accepted ``(core options, rule options)`` of a registry name."""
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
        One of :data:`FILTER_NAMES` (case-insensitive).
    process_model, measurement_model, x0, P0, Q0, R0
        As :class:`~sdr_di.filters.base.KalmanFilterBase` (``R0`` may be ``None`` when ``R``
        is given to every update).
    **options
        Core options (``dt``, ``psd_fallback``, ``q_scale``, ``r_scale``; ``alpha``, ``beta``,
        ``kappa`` for the UKF cores) and rule options (e.g. ``window``, ``d`` for
        ``ff-aukf``).

    Returns
    -------
    KalmanFilterBase
        The core filter (EKF/UKF/CKF) with its ``rule`` attached; ``.name`` is the registry
        name.

    Raises
    ------
    FilterError
        Unknown name (the message lists the valid names), unknown option, invalid input.
    """
    core_cls, rule_cls = _lookup(name)
    key = name.strip().lower()
    core_names = _CORE_OPTIONS[core_cls]
    rule_names = _rule_options(rule_cls)
    unknown = sorted(set(options) - set(core_names) - set(rule_names))
    if unknown:
        raise FilterError(f"{key}: unknown option(s) {', '.join(unknown)}; accepted: "
                          f"{', '.join(core_names + rule_names)}")
    core_opts = {k: v for k, v in options.items() if k in core_names}
    rule_opts = {k: v for k, v in options.items() if k in rule_names}
    filt = core_cls(process_model, measurement_model, x0, P0, Q0, R0, name=key, **core_opts)
    if rule_cls is not None:
        filt.attach_rule(rule_cls(**rule_opts))
    return filt
