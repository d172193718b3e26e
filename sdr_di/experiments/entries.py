"""Filter entries of the experiments and studies: ``NAME[:opt=value...][@mode]``, lists of
them and the coupling modes.

The filter part is parsed by the one parser of filter entries,
:func:`sdr_di.filters.parse_filter_spec` (built-in, registered, entry-point and import-path
names); here its errors become :class:`~sdr_di.errors.ExperimentError` naming the experiment,
and ``@`` and ``,`` (which separate a mode and list entries) are refused inside an entry.
This module draws nothing: a study specification is parsed without a plotting module.
"""

from __future__ import annotations

from collections.abc import Sequence

from ..coupling.config import DEEP_MEASUREMENTS
from ..errors import ExperimentError, SdrDiError
from ..filters.registry import FILTER_NAMES
from ..filters.spec import canonical_entry, parse_filter_spec

__all__ = ["MODES", "check_filter_entry", "filter_list", "mode_list", "split_entry"]

#: Coupling modes of the integration loop (``IntegrationConfig.mode``).
MODES = ("loose", "tight", "deep")


def check_filter_entry(exp: str, spec: str) -> tuple[str, dict]:
    """``"ff-aukf:q_states=nominal:window=25"`` -> ``("ff-aukf", {"q_states": "nominal",
    "window": 25})``: the filter name and its options, typed by
    :func:`sdr_di.filters.parse_filter_spec`.

    Raises
    ------
    ExperimentError
        Unknown filter, a plugin that fails to import, a bad option or value, or a ``@``/``,``
        in the entry.
    """
    if any(c in str(spec) for c in "@,"):
        raise ExperimentError(f"{exp}: filter {spec!r}: '@' and ',' are not allowed in "
                              "a filter entry (they separate modes and entries)")
    try:
        fs = parse_filter_spec(canonical_entry(spec))
    except SdrDiError as exc:
        raise ExperimentError(f"{exp}: {exc}") from None
    return fs.name, dict(fs.options)


def filter_list(exp: str, text: str) -> list[str]:
    """Filter entries of a ``filters`` parameter (``all`` or a comma list), each checked
    (:func:`check_filter_entry`) and returned as labelled (:func:`canonical_entry`)."""
    if str(text).strip().lower() == "all":
        return list(FILTER_NAMES)
    names = [canonical_entry(n) for n in str(text).split(",") if n.strip()]
    if not names:
        raise ExperimentError(f"{exp}: filters={text!r}: unknown filter(s) (none given); "
                              f"valid: all or {', '.join(FILTER_NAMES)}")
    for n in names:
        check_filter_entry(exp, n)
    return names


def mode_list(exp: str, text: str, allowed: Sequence[str] = MODES) -> list[str]:
    """Modes of a ``modes`` parameter (comma list, duplicates dropped, order kept)."""
    names = [m.strip().lower() for m in str(text).split(",") if m.strip()]
    bad = [m for m in names if m not in allowed]
    if bad or not names:
        raise ExperimentError(f"{exp}: modes={text!r}: expected a comma list of "
                              f"{', '.join(allowed)}")
    return list(dict.fromkeys(names))


def split_entry(exp: str, entry: str, mode: str = "deep") -> tuple[str, str]:
    """``"ekf@tight"`` -> ``("ekf", "tight")``; an entry without ``@`` takes ``mode``. After
    the ``@`` may also stand a deep measurement architecture (``"ekf@reset"``: deep mode with
    ``deep_measurements = "reset"``, :attr:`~sdr_di.experiments.variants.Variant.
    architecture`), so that a study pairs architectures on the same files as it pairs
    couplings."""
    spec, at, m = canonical_entry(entry).partition("@")
    if at:
        mode_list(exp, m, MODES + DEEP_MEASUREMENTS)
        return spec, m
    return spec, mode
