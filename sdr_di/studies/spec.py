"""Study specifications (``sdr-di study SPEC.toml``): reading, checking, expanding into cells.

A study crosses *cells* (conditions: truth keys of the scenario, the filter's assumptions,
coupling mode, filter rate, sampling rate, any parameter of the experiment) with a list of
*filters* and *seeds*. Format (``docs/studies.md`` has the full reference)::

    [study]
    name = "smoke"
    experiment = "compare"           # the run of a cell (default)
    filters = ["ekf", "ff-aukf"]     # entries may carry options: "ff-aukf:q_states=nominal",
                                     # and a coupling of their own: "ekf@tight"
    baseline = "ekf"                 # paired differences are against this filter
    runs = 2                         # seeds per cell (sdr-di study --runs overrides)
    base_seed = 0                    # seed i = SeedSequence(base_seed, spawn_key=(i,))
    alpha = 0.05                     # family-wise level (Holm over cells x filters x quantities)
    interval = "log_ratio"           # or "difference": the interval a claim looks at

    [base]                           # experiment parameters of every cell
    sampling_rate_hz = 2.5e6
    duration_s = 16.0
    [base.truth]                     # scenario keys (the truth) of every cell
    [base.assume]                    # filter assumptions of every cell

    [[cells]]                        # one table per condition (one factor at a time...)
    name = "baseline"
    [[cells]]
    name = "imu-noise-10x"
    truth = { "imu.accel_random_walk_mps_sqrth" = 0.5 }

    [factorial]                      # optional: every cell crossed with every combination
    filter_rate_hz = [50.0, 5.0]

    [tuning]                         # optional: options chosen on training seeds first
    base_seed = 1000                 # (sdr_di.studies.tuning_spec, .tuning)
    criterion = "mean_log_pos_rmse"
    [tuning.grid.ekf]
    q_scale = [0.5, 1.0, 2.0]

    [[claims]]
    text = "ff-aukf beats ekf in position and velocity"
    filter = "ff-aukf"
    against = "ekf"                  # default: the baseline
    quantities = ["pos", "vel"]
    min_wins = 7
    max_sign_p = 0.035               # one-sided exact sign test, uncorrected
    interval_excludes_zero = true    # the Holm/Bonferroni-corrected interval

The *spec hash* covers everything that decides a run's result (the expanded cells, filters,
experiment, seeds' base, statistics settings, claims, the content of the scenario files the
cells read), not ``runs``: adding seeds to a
finished study reuses its runs. A cell's *run key* (:meth:`StudySpec.run_key`) covers only
what decides that cell's runs (experiment, filters, seeds' base, the cell's parameters and
scenario file), not its name, the other cells, the baseline, the statistics or the claims:
a forced rerun of an edited spec (a cell added, a claim reworded) keeps every run whose run
key is unchanged.
"""

from __future__ import annotations

import copy
import dataclasses
import hashlib
import itertools
import json
import math
from pathlib import Path

from ..errors import SdrDiError, StudyError
from ..experiments.entries import MODES, check_filter_entry, split_entry
from ..experiments.registry import get_experiment, parse_params
from ..filters.spec import canonical_entry
from .tuning_spec import TuningSpec, parse_tuning

__all__ = ["QUANTITY_KEYS", "Cell", "Claim", "StudySpec", "load_study", "parse_study"]

#: Claim/statistics quantity -> (figure stem, unit) of the RMSE compared.
QUANTITY_KEYS: dict[str, tuple[str, str]] = {
    "pos": ("pos_m", "m"), "vel": ("vel_mps", "m/s"), "att": ("att_deg", "deg")}

_STUDY_KEYS = {"name", "description", "experiment", "filters", "baseline", "runs",
               "base_seed", "alpha", "interval"}
_CLAIM_KEYS = {"text", "filter", "against", "quantities", "min_wins", "max_sign_p",
               "interval_excludes_zero", "cells"}


@dataclasses.dataclass(frozen=True)
class Claim:
    """A claim evaluated per cell with the criterion written before the run."""

    text: str
    filter: str
    against: str
    quantities: tuple[str, ...]
    min_wins: int
    max_sign_p: float
    interval_excludes_zero: bool
    cells: tuple[str, ...] | None


@dataclasses.dataclass(frozen=True)
class Cell:
    """One condition: its name, the factor values that define it (for the tables) and the
    experiment parameters it runs with."""

    name: str
    factors: dict
    params: dict
    entries: dict = dataclasses.field(default_factory=dict)  # study filter -> entry run here
                                                             # (tuned); empty: as written


@dataclasses.dataclass(frozen=True)
class StudySpec:
    """A checked study specification (module docstring)."""

    name: str
    description: str
    source: Path | None
    experiment: str
    filters: tuple[str, ...]
    baseline: str
    runs: int
    base_seed: int
    alpha: float
    interval: str
    mode: str
    cells: tuple[Cell, ...]
    claims: tuple[Claim, ...]
    raw: dict = dataclasses.field(repr=False, compare=False)
    tuning: TuningSpec | None = None     # the [tuning] table (sdr_di.studies.tuning)
    tuned_from: str = ""                 # evaluation spec of a tuned study: the spec's hash

    @property
    def hash(self) -> str:
        """SHA-256 (hex, 16 characters) of what decides the results (module docstring)."""
        canon = {"experiment": self.experiment, "filters": self.filters,
                 "baseline": self.baseline, "base_seed": self.base_seed, "alpha": self.alpha,
                 "interval": self.interval,
                 "cells": [[c.name, c.params] for c in self.cells],
                 "claims": [dataclasses.asdict(c) for c in self.claims],
                 "scenario_files": _scenario_digests(self.cells)}
        if self.tuning is not None:          # only then: untuned studies keep their hash
            canon["tuning"] = self.tuning.canonical()
        text = json.dumps(canon, sort_keys=True, default=str).encode()
        return hashlib.sha256(text).hexdigest()[:16]

    def run_key(self, c: int) -> str:
        """SHA-256 (hex, 16 characters) of what decides the runs of cell ``c`` (module
        docstring); equal in two specs exactly when the cell's runs would be the same."""
        cell = self.cells[c]
        canon = {"experiment": self.experiment, "filters": self.filters,
                 "base_seed": self.base_seed, "params": cell.params,
                 # the scenario's content, not where this checkout keeps it
                 "scenario_files": sorted(map(str, _scenario_digests([cell]).values()))}
        text = json.dumps(canon, sort_keys=True, default=str).encode()
        return hashlib.sha256(text).hexdigest()[:16]


def _scenario_digests(cells) -> dict:
    """SHA-256 of each scenario file the cells read (an edited scenario is another study)."""
    from ..scenario import DEFAULT_SCENARIO

    out: dict[str, str | None] = {}
    for c in cells:
        path = Path(str(c.params.get("scenario") or DEFAULT_SCENARIO))
        if str(path) not in out:
            try:
                out[str(path)] = hashlib.sha256(path.read_bytes()).hexdigest()[:16]
            except OSError:
                out[str(path)] = None
    return out


#: (cell, seed) runs a study may have without ``force`` (``--force``): beyond it the spec is
#: refused before its cells are expanded (a factorial of 10^6 cells grew by about 2 MB/s
#: while it was expanded, issue 49 item 5).
MAX_STUDY_RUNS = 10_000
#: Memory the expanded spec holds per cell, and a run's record while the study runs [bytes]
#: (8.4 kB per cell measured on a 100-cell factorial, 2026-12-07; rounded up).
CELL_BYTES, RECORD_BYTES = 10_000, 5_000


class StudySizeError(StudyError, ValueError):
    """A study larger than :data:`MAX_STUDY_RUNS` (cell, seed) runs, without ``force``."""


def check_study_size(where: str, n_cells: int, runs: int, force: bool) -> None:
    """Refuse ``n_cells`` x ``runs`` beyond :data:`MAX_STUDY_RUNS` unless ``force``; the
    message gives the count and the memory estimate.

    Raises
    ------
    StudySizeError
    """
    n = n_cells * runs
    if n > MAX_STUDY_RUNS and not force:
        mem = n_cells * CELL_BYTES + n * RECORD_BYTES
        raise StudySizeError(
            f"{where}: {n_cells:,} cells x {runs} runs = {n:,} (cell, seed) runs, more than "
            f"the {MAX_STUDY_RUNS:,} a study runs without --force (about {mem / 1e9:.3g} GB "
            "of memory for the spec and the records alone, before any run's own)")


def load_study(path: str | Path, *, force: bool = False) -> StudySpec:
    """Read and check a study TOML file.

    Raises
    ------
    StudyError
        Missing file, not TOML, or anything :func:`parse_study` rejects.
    """
    from ..paths import read_toml

    path = Path(path)
    raw = read_toml(path, "study", StudyError)
    return parse_study(raw, source=path, force=force)


def _need(cond: object, where: str, msg: str) -> None:
    if not cond:
        raise StudyError(f"{where}: {msg}")


def _merge(base: dict, over: dict) -> dict:
    """``base`` updated by ``over``; the ``truth`` and ``assume`` tables merge key by key."""
    out = copy.deepcopy(base)
    for k, v in over.items():
        if k in ("truth", "assume") and isinstance(v, dict):
            out[k] = {**out.get(k, {}), **copy.deepcopy(v)}
        else:
            out[k] = copy.deepcopy(v)
    return out


def _resolve_scenario(params: dict, source: Path | None) -> dict:
    scen = params.get("scenario")
    if scen is not None and source is not None and not Path(str(scen)).is_absolute():
        from ..scenario import REPO_ROOT

        # relative to the spec file, else to the repository (studies/ ships beside signals/)
        cand = (source.parent / str(scen)).resolve()
        params["scenario"] = str(cand if cand.is_file() else (REPO_ROOT / str(scen)).resolve())
    return params


def _factor_values(cell_over: dict) -> dict:
    """Flat ``{factor: value}`` of a cell's own settings (for the tables)."""
    out = {}
    for k, v in cell_over.items():
        if k in ("truth", "assume") and isinstance(v, dict):
            for kk, vv in v.items():
                out[f"{k}.{kk}"] = vv if not isinstance(vv, (list, dict)) else json.dumps(vv)
        elif k != "name":
            out[k] = v if not isinstance(v, (list, dict)) else json.dumps(v)
    return out


def parse_study(raw: dict, *, source: Path | None = None, force: bool = False) -> StudySpec:
    """Check a study table (as read from TOML) and expand its cells.

    The spec is checked first with its plugin filters unimported
    (:func:`~sdr_di.filters.plugins.plugins_deferred`), then again with them: a spec refused
    for anything else has run no plugin code.

    Raises
    ------
    StudyError
        Unknown key, wrong type, unknown filter or baseline, bad cell parameter (the
        experiment's own check), duplicate cell names, a claim naming an unknown filter,
        quantity or cell. The message names the spec and the key.
    """
    from ..filters.plugins import names_unloaded_plugin, plugins_deferred

    study = raw.get("study") if isinstance(raw, dict) else None
    if isinstance(study, dict) and names_unloaded_plugin(study.get("filters")):
        with plugins_deferred():
            _parse_study(raw, source, force)
    return _parse_study(raw, source, force)


def _parse_study(raw: dict, source: Path | None, force: bool) -> StudySpec:
    """:func:`parse_study` once."""
    from ..experiments._deep import check_truth

    where = f"study {source}" if source is not None else "study"
    _need(isinstance(raw.get("study"), dict), where, "missing [study] table")
    unknown = set(raw) - {"study", "base", "cells", "factorial", "claims", "tuning"}
    _need(not unknown, where, f"unknown table(s) {', '.join(sorted(unknown))}")
    st = raw["study"]
    bad = set(st) - _STUDY_KEYS
    _need(not bad, where, f"[study] unknown key(s) {', '.join(sorted(bad))}")
    name = st.get("name", source.stem if source is not None else "study")
    exp_name = st.get("experiment", "compare")
    try:
        exp = get_experiment(exp_name)
    except SdrDiError as exc:  # ExperimentError: name it as a spec error
        raise StudyError(f"{where}: [study] experiment: {exc}") from None
    filters = st.get("filters")
    _need(isinstance(filters, list) and filters and all(isinstance(f, str) for f in filters),
          where, "[study] filters must be a non-empty list of filter entries")
    filters = [canonical_entry(f) for f in filters]
    _need(len(set(filters)) == len(filters), where, "[study] filters has duplicates")
    for f in filters:
        try:
            check_filter_entry(f"{where}: [study] filters",
                              split_entry(f"{where}: [study] filters", f)[0])
        except SdrDiError as exc:
            raise StudyError(str(exc)) from None
    baseline = canonical_entry(st.get("baseline", filters[0]))
    _need(baseline in filters, where, f"[study] baseline {baseline!r} is not in filters")
    runs = st.get("runs", 8)
    _need(isinstance(runs, int) and not isinstance(runs, bool) and runs >= 1, where,
          f"[study] runs must be an integer >= 1, got {runs!r}")
    base_seed = st.get("base_seed", 0)
    _need(isinstance(base_seed, int) and base_seed >= 0, where,
          f"[study] base_seed must be an integer >= 0, got {base_seed!r}")
    alpha = st.get("alpha", 0.05)
    _need(isinstance(alpha, (int, float)) and 0 < alpha < 1, where,
          f"[study] alpha must be in (0, 1), got {alpha!r}")
    interval = st.get("interval", "log_ratio")
    _need(interval in ("log_ratio", "difference"), where,
          f"[study] interval must be 'log_ratio' or 'difference', got {interval!r}")

    base = raw.get("base", {})
    _need(isinstance(base, dict), where, "[base] must be a table")
    _need("filters" not in base, where, "[base] filters: give the filters in [study] filters")
    cells_raw = raw.get("cells", [{"name": "baseline"}])
    _need(isinstance(cells_raw, list) and cells_raw and all(isinstance(c, dict)
                                                            for c in cells_raw),
          where, "[[cells]] must be a list of tables")
    fact = raw.get("factorial", {})
    _need(isinstance(fact, dict) and all(isinstance(v, list) and v for v in fact.values()),
          where, "[factorial] must map keys to non-empty lists of values")
    check_study_size(where, len(cells_raw) * math.prod(len(v) for v in fact.values()), runs,
                     force)   # before the expansion
    combos = [dict(zip(fact, vals)) for vals in itertools.product(*fact.values())] or [{}]

    cells: list[Cell] = []
    modes = set()
    for i, c in enumerate(cells_raw):
        cname = str(c.get("name", f"cell{i}"))
        for combo in combos:
            over = {k: v for k, v in c.items() if k != "name"}
            flat = dict(over)
            for k, v in combo.items():      # factorial keys: truth.x / assume.x / param
                head, dot, tail = k.partition(".")
                if dot and head in ("truth", "assume"):
                    over = _merge(over, {head: {tail: v}})
                else:
                    over = _merge(over, {k: v})
                flat[k] = v
            full = cname + "".join(f" {k}={v}" for k, v in combo.items())
            _need("/" not in full and full.strip(), where, f"cell name {full!r}: no '/'")
            _need("filters" not in over, where,
                  f"cell {full!r}: filters are the study's, not a cell's")
            params = _merge(base, over)
            params["filters"] = ",".join(filters)
            params = _resolve_scenario(params, source)
            try:
                params = parse_params(exp, overrides=params)
                check_truth(params)     # scenario keys checked now, not by each run
            except SdrDiError as exc:
                raise StudyError(f"{where}: cell {full!r}: {exc}") from None
            m = str(params.get("modes", "deep"))
            _need(m in MODES, where, f"cell {full!r}: modes={m!r}: a study cell runs one "
                  f"coupling mode ({', '.join(MODES)}); make the mode a factor")
            modes.add(m)
            cells.append(Cell(full, _factor_values(flat) if flat else {}, params))
    names = [c.name for c in cells]
    _need(len(set(names)) == len(names), where, "cell names are not unique")

    claims = []
    for j, cl in enumerate(raw.get("claims", [])):
        cw = f"{where}: claim {j + 1}"
        _need(isinstance(cl, dict), cw, "must be a table")
        bad = set(cl) - _CLAIM_KEYS
        _need(not bad, cw, f"unknown key(s) {', '.join(sorted(bad))}")
        f = canonical_entry(cl.get("filter", ""))
        ag = canonical_entry(cl.get("against", baseline))
        _need(f in filters and ag in filters and f != ag, cw,
              f"filter {f!r} and against {ag!r} must be two of the study's filters")
        qs = cl.get("quantities", ["pos", "vel", "att"])
        _need(isinstance(qs, list) and qs and all(q in QUANTITY_KEYS for q in qs), cw,
              f"quantities must be a list of {', '.join(QUANTITY_KEYS)}")
        mw = cl.get("min_wins")
        _need(isinstance(mw, int) and mw >= 1, cw, "min_wins must be an integer >= 1")
        mp = cl.get("max_sign_p", 0.05)
        _need(isinstance(mp, (int, float)) and 0 < mp <= 1, cw, "max_sign_p must be in (0, 1]")
        ex = cl.get("interval_excludes_zero", True)
        _need(isinstance(ex, bool), cw, "interval_excludes_zero must be true or false")
        cc = cl.get("cells")
        if cc is not None:
            _need(isinstance(cc, list) and all(x in names for x in cc), cw,
                  f"cells must be a list of the study's cell names ({', '.join(names)})")
            cc = tuple(cc)
        claims.append(Claim(str(cl.get("text", f"{f} beats {ag}")), f, ag, tuple(qs), mw,
                            float(mp), ex, cc))
    return StudySpec(name=str(name), description=str(st.get("description", "")),
                     source=source, experiment=exp.name, filters=tuple(filters),
                     baseline=baseline, runs=runs, base_seed=int(base_seed),
                     alpha=float(alpha), interval=interval,
                     mode=next(iter(modes)) if len(modes) == 1 else "mixed",
                     cells=tuple(cells), claims=tuple(claims), raw=raw,
                     tuning=parse_tuning(raw.get("tuning"), where=where, filters=filters,
                                         cells=names, base_seed=int(base_seed), runs=runs))


def spec_summary(spec: StudySpec) -> dict:
    """JSON-able description of the design (``study.json``)."""
    return {"name": spec.name, "description": spec.description,
            "source": str(spec.source) if spec.source else None, "hash": spec.hash,
            "experiment": spec.experiment, "filters": list(spec.filters),
            "baseline": spec.baseline, "base_seed": spec.base_seed, "alpha": spec.alpha,
            "interval": spec.interval,
            "cells": [{"name": c.name, "factors": c.factors, "params": c.params}
                      for c in spec.cells],
            "claims": [dataclasses.asdict(c) for c in spec.claims],
            **({"tuned_from": spec.tuned_from} if spec.tuned_from else {})}
