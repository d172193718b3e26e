"""The ``[tuning]`` table of a study spec: training seeds, grids, criterion (checked).

Format (``docs/studies.md``)::

    [tuning]
    base_seed = 1000                 # training seed i = run_seed(base_seed, i), i < runs;
    runs = 4                         # at least 4 (the default); refused if any training
                                     # seed equals an evaluation seed
    criterion = "mean_log_pos_rmse"  # or mean_log_{vel,att}_rmse, mean_{pos,vel,att}_rmse
    cells = ["baseline"]             # cells the scores are pooled over (default: all)
    per_cell = false                 # true: one choice per cell and filter (all cells tuned)
    nis_column = ["nis_code", "nis_rate"]   # optional constraint, off unless both are
    nis_band = [0.5, 2.0]            # given: a grid point is eligible when every training
                                     # run's runs.csv value of each column (one name or a
                                     # list) lies in the band
    [tuning.grid.ekf]                # per study filter entry, a grid over its options
    q_scale = [0.5, 1.0, 2.0]
    r_scale = [1.0, 4.0]
    [tuning.grid."my_filters:ScaledQEKF"]   # a plugin: import path or entry-point name
    scale = [0.5, 2.0]

A grid key names a study filter by the canonical text of its entry (one parser,
:func:`~sdr_di.filters.parse_filter_spec`): built-in, entry-point and import-path names all
work, in any case for the first two.

The grid of a filter is the product of its option lists. One choice is made per filter for
the whole study, from the scores pooled over the tuning cells and the training seeds, or,
with ``per_cell = true``, one per cell and filter from that cell's training runs. Grid
values are checked against the type of the option's default (:func:`check_option_value`): a
boolean option takes ``true``/``false``, not strings.
"""

from __future__ import annotations

import dataclasses
import decimal
import itertools
import math

from ..errors import FilterError, StudyError
from ..filters.spec import (
    canonical_entry,
    filter_option_info,
    parse_filter_spec,
    split_filter_spec,
)
from .seeds import run_seed

__all__ = ["CRITERIA", "MIN_TRAINING_SEEDS", "TuningSpec", "check_option_value", "grid_entry", "parse_tuning",
           "study_filter_of", "training_seeds"]

#: criterion name -> (quantity, take the log of each run's RMSE)
CRITERIA: dict[str, tuple[str, bool]] = {
    **{f"mean_log_{q}_rmse": (q, True) for q in ("pos", "vel", "att")},
    **{f"mean_{q}_rmse": (q, False) for q in ("pos", "vel", "att")}}

#: Fewest training seeds a ``[tuning]`` table may ask for, and its default (issue 46): the
#: choice ranks grid points by a mean over the training runs, and on one or two seeds that
#: ranking follows those seeds' draws as much as the points.
MIN_TRAINING_SEEDS = 4

_KEYS = {"base_seed", "runs", "criterion", "cells", "per_cell", "nis_column", "nis_band",
         "grid"}


@dataclasses.dataclass(frozen=True)
class TuningSpec:
    """A checked ``[tuning]`` table (module docstring); ``grids`` maps a study filter entry
    to its grid points, each a tuple of ``(option, value)`` pairs."""

    base_seed: int
    runs: int
    criterion: str
    cells: tuple[str, ...]
    per_cell: bool
    nis_column: tuple[str, ...] | None
    nis_band: tuple[float, float] | None
    grids: dict

    def canonical(self) -> dict:
        """JSON-able form (part of the study's hash)."""
        return {"base_seed": self.base_seed, "runs": self.runs, "criterion": self.criterion,
                "cells": list(self.cells), "per_cell": self.per_cell,
                "nis_column": list(self.nis_column) if self.nis_column else None,
                "nis_band": list(self.nis_band) if self.nis_band else None,
                "grids": {f: [list(map(list, p)) for p in pts] for f, pts in self.grids.items()}}


def training_seeds(t: TuningSpec) -> list[int]:
    """The training seeds, in index order."""
    return [run_seed(t.base_seed, i) for i in range(t.runs)]


def check_option_value(filter_name: str, option: str, value, where: str) -> None:
    """Refuse a grid value whose type is not that of the option's default.

    The options are the filter's own (:func:`~sdr_di.filters.spec.filter_option_info`: a
    built-in's core and rule constructors, a plugin's signature). A boolean default takes a
    TOML boolean; an integer default an integer; a float default a number; a string default
    a string; an option without a default takes its annotation's type (``bool``, ``int``,
    ``float``, ``str``), else any scalar; a plugin that takes ``**kwargs`` any other option
    as a scalar.

    Raises
    ------
    StudyError
        Unknown filter or option, or a value of the wrong type.
    """
    try:
        infos, open_ended = filter_option_info(filter_name)
    except FilterError as exc:
        raise StudyError(f"{where}: {exc}") from None
    by_name = {i.name: i for i in infos}
    info = by_name.get(option)
    if info is None and not open_ended:
        raise StudyError(f"{where}: {filter_name} has no option {option!r}; accepted: "
                         f"{', '.join(by_name)}")
    d = None if info is None else info.default
    kind = type(d) if d is not None else {"bool": bool, "int": int, "float": float,
                                          "str": str}.get(info.type if info else "")
    if kind is bool:
        ok = isinstance(value, bool)
        want = "true or false (a TOML boolean, not a string)"
    elif kind is int:
        ok = isinstance(value, int) and not isinstance(value, bool)
        want = "an integer"
    elif kind is float:
        ok = isinstance(value, (int, float)) and not isinstance(value, bool) \
            and math.isfinite(value)
        want = "a finite number"
    elif kind is str:
        ok = isinstance(value, str)
        want = "a string"
    else:
        ok = isinstance(value, (bool, int, float, str))
        want = "a scalar"
    if not ok:
        raise StudyError(f"{where}: {filter_name} option {option}={value!r} must be {want}")
    if isinstance(value, str) and (not value or any(c in value for c in ".@,:=")):
        raise StudyError(f"{where}: {filter_name} option {option}={value!r}: a string value "
                         "must be non-empty without '.', '@', ',', ':' or '='")


def study_filter_of(key: str, filters, where: str) -> str:
    """The study filter entry a ``[tuning.grid."KEY"]`` table names: the one whose filter
    has the same canonical spec text (:attr:`~sdr_di.filters.spec.FilterSpec.text`) and
    coupling mode as ``key``, so ``"my_filters:ScaledQEKF"``, an entry-point name, or an
    entry written with other case or number spelling all find theirs.

    Raises
    ------
    StudyError
        A key that is no filter entry, or names none of the study's filters.
    """
    def canon(entry: str) -> tuple[str, str]:
        spec, _, mode = canonical_entry(entry).partition("@")
        return parse_filter_spec(spec).text, mode

    try:
        want = canon(key)
    except FilterError as exc:
        raise StudyError(f"{where}: {exc}") from None
    for f in filters:
        if canon(f) == want:
            return f
    raise StudyError(f"{where}: not one of the study's filters ({', '.join(filters)})")


def _text(value) -> str:
    """A value as written in a filter entry, without '.' (which separates figure names):
    0.5 -> ``5e-1``, 2.0 -> ``2``, True -> ``true``."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if value == int(value) and abs(value) < 1e15:
            return str(int(value))
        sign, digits, exp = decimal.Decimal(repr(value)).normalize().as_tuple()
        return f"{'-' if sign else ''}{''.join(map(str, digits))}e{exp}"
    return str(value).lower()


def grid_entry(entry: str, point) -> str:
    """The study filter ``entry`` (``"ekf"``, ``"ff-aukf:q_states=nominal@tight"``,
    ``"my_filters:ScaledQEKF"``) with the grid point's options set:
    ``"ekf:q_scale=5e-1@tight"``. An option the entry already gives is replaced."""
    spec, at, mode = entry.partition("@")
    name, pairs = split_filter_spec(spec)
    keep = [f"{k}={v}" for k, v in pairs if k not in dict(point)]
    new = [f"{k}={_text(v)}" for k, v in point]
    return ":".join([name, *keep, *new]) + (f"@{mode}" if at else "")


def parse_tuning(raw, *, where: str, filters, cells, base_seed: int, runs: int
                 ) -> TuningSpec | None:
    """Check a ``[tuning]`` table against the study's filters, cells and evaluation seeds.

    Raises
    ------
    StudyError
        Unknown key, bad type, fewer than :data:`MIN_TRAINING_SEEDS` training seeds, an
        unknown filter or option, a grid value of the wrong type, an unknown criterion or
        cell, or training seeds that overlap the evaluation seeds.
    """
    if raw is None:
        return None
    w = f"{where}: [tuning]"
    if not isinstance(raw, dict):
        raise StudyError(f"{w} must be a table")
    bad = set(raw) - _KEYS
    if bad:
        raise StudyError(f"{w} unknown key(s) {', '.join(sorted(bad))}")
    tb = raw.get("base_seed")
    if isinstance(tb, bool) or not isinstance(tb, int) or tb < 0:
        raise StudyError(f"{w} base_seed must be an integer >= 0, got {tb!r}")
    tr = raw.get("runs", MIN_TRAINING_SEEDS)
    if isinstance(tr, bool) or not isinstance(tr, int) or tr < MIN_TRAINING_SEEDS:
        raise StudyError(f"{w} runs must be an integer >= {MIN_TRAINING_SEEDS} (training "
                         f"seeds: a choice on fewer follows the seeds' noise), got {tr!r}")
    crit = raw.get("criterion")
    if crit not in CRITERIA:
        raise StudyError(f"{w} criterion must be one of {', '.join(CRITERIA)}, got {crit!r}")
    tc = raw.get("cells", list(cells))
    if not (isinstance(tc, list) and tc and all(c in cells for c in tc)):
        raise StudyError(f"{w} cells must be a non-empty list of the study's cell names "
                         f"({', '.join(cells)})")
    per_cell = raw.get("per_cell", False)
    if not isinstance(per_cell, bool):
        raise StudyError(f"{w} per_cell must be true or false, got {per_cell!r}")
    if per_cell and set(tc) != set(cells):
        raise StudyError(f"{w} per_cell = true tunes every cell: leave out cells")
    col, band = raw.get("nis_column"), raw.get("nis_band")
    if (col is None) != (band is None):
        raise StudyError(f"{w} nis_column and nis_band go together")
    if band is not None:
        col = [col] if isinstance(col, str) else col
        if not (isinstance(col, list) and col and all(isinstance(c, str) and c for c in col)
                and isinstance(band, list) and len(band) == 2
                and all(isinstance(b, (int, float)) and not isinstance(b, bool) for b in band)
                and 0 <= band[0] < band[1]):
            raise StudyError(f"{w} nis_column must be runs.csv column name(s) and nis_band "
                             f"[low, high] with 0 <= low < high, got {col!r}, {band!r}")
        band, col = (float(band[0]), float(band[1])), tuple(col)
    grid_raw = raw.get("grid")
    if not (isinstance(grid_raw, dict) and grid_raw):
        raise StudyError(f"{w} grid must be a table of filter entries, each a table of "
                         "option lists")
    grids = {}
    for entry, table in grid_raw.items():
        gw = f"{w} grid.{entry}"
        e = study_filter_of(str(entry), filters, gw)
        name = parse_filter_spec(e.partition("@")[0]).name
        if not (isinstance(table, dict) and table and all(
                isinstance(v, list) and v for v in table.values())):
            raise StudyError(f"{gw} must map options to non-empty lists of values")
        for opt, vals in table.items():
            for v in vals:
                check_option_value(name, opt, v, gw)
            if len(set(map(_text, vals))) != len(vals):
                raise StudyError(f"{gw}: {opt} has duplicate values")
        grids[e] = tuple(tuple(zip(table, combo))
                         for combo in itertools.product(*table.values()))
    train = {run_seed(tb, i) for i in range(tr)}
    evals = {run_seed(base_seed, i) for i in range(runs)}
    if train & evals:
        raise StudyError(f"{w} training seeds overlap the evaluation seeds ([tuning] "
                         f"base_seed {tb}, [study] base_seed {base_seed}); use another "
                         "[tuning] base_seed")
    return TuningSpec(base_seed=tb, runs=tr, criterion=crit, cells=tuple(tc),
                      per_cell=per_cell, nis_column=col,
                      nis_band=band, grids=grids)
