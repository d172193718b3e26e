"""Tuning before evaluation: each filter's free parameters chosen on training seeds.

A study with a ``[tuning]`` table (:mod:`.tuning_spec`) runs in two stages, both ordinary
studies on the same task machinery (Dask or in-process, records written as they arrive,
resumable):

1. **Training** (``DIR/tuning/``): the tuning cells x the training seeds, with one filter
   entry per grid point (``"ekf:q_scale=5e-1"``, ...), all paired on the same files.
2. **Choice** (:func:`choose`): per study filter, the grid point with the best criterion
   (mean over the tuning cells and training seeds of each run's RMSE or log RMSE; a failed or
   diverged run scores ``+inf``), among the points whose training runs all keep the NIS
   column inside the band when a band is given (when no point does, the best point is
   chosen and ``constraint_met`` says so). Ties go to the first point in grid order.
   ``DIR/tuning.csv`` holds one row per (cell, filter, options, seed) and one ``mean`` row
   per (filter, options); ``chosen`` marks the chosen point's rows.
3. **Evaluation** (``DIR``): the study with each tuned filter entry replaced by its chosen
   entry (claims and the baseline follow), on the evaluation seeds. Its ``study.json`` keeps
   ``tuned_from`` (the hash of the spec as written) and ``tuning`` (the choices), so that a
   rerun of the same spec resumes.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from collections.abc import Callable
from pathlib import Path

from ..errors import StudyError
from .campaign import run_seed
from .execute import read_json
from .study_spec import StudySpec, parse_study
from .tables import write_table
from .tuning_spec import CRITERIA, TuningSpec, grid_entry, training_seeds

__all__ = ["Choice", "choose", "run_tuned_study", "training_spec", "tuned_spec"]


@dataclasses.dataclass(frozen=True)
class Choice:
    """The outcome for one study filter: its chosen entry and options, the chosen point's
    score, and whether it met the NIS band (``None`` without a band)."""

    filter: str
    entry: str
    options: dict
    score: float
    constraint_met: bool | None


def _raw_without_tuning(spec: StudySpec) -> dict:
    raw = copy.deepcopy(spec.raw)
    raw.pop("tuning", None)
    return raw


def training_spec(spec: StudySpec) -> StudySpec:
    """The training study: tuning cells x training seeds, one entry per grid point."""
    t = spec.tuning
    raw = _raw_without_tuning(spec)
    entries = [grid_entry(f, p) for f, pts in t.grids.items() for p in pts]
    raw["study"] = {**raw["study"], "name": f"{spec.name}-tuning", "filters": entries,
                    "baseline": entries[0], "runs": t.runs, "base_seed": t.base_seed}
    raw.pop("claims", None)
    raw.pop("factorial", None)       # the spec's cells are already expanded: keep the chosen
    raw["cells"] = [{"name": c.name, **_cell_over(spec, c.name)} for c in spec.cells
                    if c.name in t.cells]
    return parse_study(raw, source=spec.source)


def _cell_over(spec: StudySpec, name: str) -> dict:
    """The expanded cell's own parameters (everything but ``filters``), as a cell table."""
    cell = next(c for c in spec.cells if c.name == name)
    return {k: v for k, v in cell.params.items() if k != "filters"}


def tuned_spec(spec: StudySpec, choices: dict[str, Choice]) -> StudySpec:
    """The evaluation study: each tuned entry replaced by its chosen entry (the baseline and
    the claims follow); ``tuned_from`` is ``spec``'s hash."""
    ren = {f: c.entry for f, c in choices.items()}
    raw = _raw_without_tuning(spec)
    st = raw["study"]
    filters = [str(f).strip().lower() for f in st["filters"]]
    base = str(st.get("baseline", filters[0])).strip().lower()
    raw["study"] = {**st, "filters": [ren.get(f, f) for f in filters],
                    "baseline": ren.get(base, base)}
    for cl in raw.get("claims", []):
        for k in ("filter", "against"):
            if k in cl:
                v = str(cl[k]).strip().lower()
                cl[k] = ren.get(v, v)
        if "against" not in cl:
            cl["against"] = ren.get(base, base)
    out = parse_study(raw, source=spec.source)
    return dataclasses.replace(out, tuned_from=spec.hash, raw=raw)


def _score(row: dict, quantity: str, log: bool) -> float:
    from .study import _col

    v = row.get(_col(quantity), math.nan)
    v = float(v) if isinstance(v, (int, float)) else math.nan
    if row.get("status") != "ok" or not math.isfinite(v) or v <= 0:
        return math.inf
    return math.log(v) if log else v


def choose(t: TuningSpec, rows: list[dict]) -> tuple[dict[str, Choice], list[dict]]:
    """Choose each filter's grid point from the training runs' rows (``runs.csv`` rows of the
    training study: ``cell``, ``seed_index``, ``seed``, ``filter``, ``status``, the RMSE
    columns and, with a band, the ``t.nis_column`` columns).

    Returns
    -------
    choices : dict
        ``{study filter entry: Choice}``.
    table : list of dict
        The rows of ``tuning.csv`` (module docstring).

    Raises
    ------
    StudyError
        A NIS band is set but the rows have no such column.
    """
    quantity, log = CRITERIA[t.criterion]
    by_entry: dict[str, list[dict]] = {}
    for r in rows:
        by_entry.setdefault(r["filter"], []).append(r)
    choices, table = {}, []
    for f, points in t.grids.items():
        scored = []
        for p in points:
            entry = grid_entry(f, p)
            runs = by_entry.get(entry, [])
            scores = [_score(r, quantity, log) for r in runs]
            mean = sum(scores) / len(scores) if scores and all(map(math.isfinite, scores)) \
                else math.inf
            ok = None
            if t.nis_band is not None:
                vals = []
                for r in runs:
                    for c in t.nis_column:
                        if c not in r:
                            raise StudyError(f"[tuning] nis_column {c!r} is not a runs.csv "
                                             "column")
                        vals.append(r[c])
                ok = bool(runs) and all(isinstance(v, (int, float)) and
                                        t.nis_band[0] <= v <= t.nis_band[1] for v in vals)
            scored.append((p, entry, runs, scores, mean, ok))
        eligible = [s for s in scored if s[5] is not False] or scored
        best = min(eligible, key=lambda s: s[4])           # first of equals: grid order
        choices[f] = Choice(f, best[1], dict(best[0]), best[4],
                            None if t.nis_band is None else bool(best[5]))
        for p, entry, runs, scores, mean, ok in scored:
            opts = " ".join(f"{k}={v}" for k, v in p)
            extra = {} if t.nis_band is None else {"nis_ok": "" if ok is None else int(ok)}
            for r, s in zip(runs, scores):
                nis = {} if t.nis_band is None else {
                    c: r.get(c, "") for c in t.nis_column}
                table.append({"cell": r["cell"], "filter": f, "options": opts,
                              "seed_index": r["seed_index"], "seed": r["seed"], "score": s,
                              **nis, **extra, "chosen": int(entry == best[1])})
            table.append({"cell": "+".join(t.cells), "filter": f, "options": opts,
                          "seed_index": "", "seed": "mean", "score": mean,
                          **({} if t.nis_band is None else dict.fromkeys(t.nis_column, "")),
                          **extra,
                          "chosen": int(entry == best[1])})
    return choices, table


def run_tuned_study(spec: StudySpec, out_dir: str | Path, *, runs: int | None = None,
                    scheduler: str | None = None, workers: int | None = None,
                    force: bool = False, on_record: Callable[[dict], None] | None = None,
                    render: bool = True):
    """Train, choose, evaluate (module docstring); arguments as
    :func:`~.study.run_study`. Returns the evaluation's :class:`~.study.StudyResult` with the
    training tasks added to its counts and ``tuning`` set to the choices.

    Raises
    ------
    StudyError
        Training seeds overlap the evaluation seeds of ``runs``, or what
        :func:`~.study.run_study` raises.
    """
    from .study import _check_folder, run_study

    out = Path(out_dir)
    t = spec.tuning
    n_eval = spec.runs if runs is None else runs
    if isinstance(n_eval, int) and not isinstance(n_eval, bool) and n_eval >= 1 and \
            set(training_seeds(t)) & {run_seed(spec.base_seed, i) for i in range(n_eval)}:
        raise StudyError(f"--runs {n_eval}: the evaluation seeds overlap the training seeds "
                         "([tuning] base_seed)")
    _check_folder(spec, out, force)
    shown = None if on_record is None else (                # training records name their
        lambda rec: on_record({**rec, "cell": f"tuning: {rec['cell']}"}))     # stage
    train = run_study(training_spec(spec), out / "tuning", scheduler=scheduler,
                      workers=workers, force=force, on_record=shown, render=False)
    choices, table = choose(t, train.runs)
    write_table(out, "tuning", table)
    ev = tuned_spec(spec, choices)
    try:
        same_source = read_json(out / "study.json").get("tuned_from") == spec.hash
    except (OSError, ValueError, AttributeError):
        same_source = False
    res = run_study(ev, out, runs=runs, scheduler=scheduler, workers=workers,
                    force=force or same_source, on_record=on_record, render=render)
    res.n_run += train.n_run
    res.n_skipped += train.n_skipped
    res.elapsed_s += train.elapsed_s
    res.tuning = choices
    return res
