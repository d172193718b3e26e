"""The integrated receiver's settings from what a user gives: a filter entry, settings fields
and assumptions (:func:`build_integration_config`), the one builder of ``sdr-di run``,
:func:`sdr_di.run` (:meth:`sdr_di.options.RunOptions.integration_config`) and the
experiments (:func:`sdr_di.experiments._deep.run_deep_variant`).
"""

from __future__ import annotations

from ..coupling.config import IntegrationConfig
from ..errors import OptionsError

__all__ = ["build_integration_config"]


def build_integration_config(filter: str = "ekf", *, assume=None,
                             **fields) -> IntegrationConfig:
    """The receiver's settings from a filter entry, settings fields and assumptions: the one
    builder of ``sdr-di run``, ``sdr_di.run`` and the experiments.

    Parameters
    ----------
    filter : str
        Filter entry ``NAME[:OPT=VALUE...]`` (:func:`~sdr_di.filters.parse_filter_spec`:
        built-in, registered, entry-point or import-path name); its options are set over
        ``fields["filter_options"]``.
    assume : path, Assumptions or None
        What the filter believes (``--assume``, docs/assumptions.md): an assumptions file or
        a parsed :class:`~sdr_di.integration.assumptions.Assumptions`, applied over the
        defaults (:func:`~sdr_di.integration.assumptions.apply_to_deep`).
    **fields
        Further :class:`IntegrationConfig` fields (``mode``, ``filter_rate_hz``, ...); those
        left out keep their defaults.

    Returns
    -------
    IntegrationConfig

    Raises
    ------
    FilterError
        Unknown filter, a plugin that does not import, a bad option.
    OptionsError
        A field out of range or fields that do not fit together (IntegrationConfig's own
        checks).
    AssumptionsError
        Bad assumptions file, or assumptions the mode cannot use.
    """
    from ..filters.spec import parse_filter_spec
    from .assumptions import Assumptions, apply_to_deep, load_assumptions

    spec = parse_filter_spec(filter)
    options = {**fields.pop("filter_options", {}), **spec.options}
    try:
        cfg = IntegrationConfig(filter=spec.name, filter_options=options, **fields)
    except ValueError as exc:
        raise OptionsError(str(exc)) from None
    if assume is not None:
        cfg = apply_to_deep(cfg, assume if isinstance(assume, Assumptions)
                            else load_assumptions(assume))
    return cfg
