"""Tuning before evaluation: each filter's free parameters chosen on training seeds.

A study with a ``[tuning]`` table (:mod:`.tuning_spec`) runs in two stages, both ordinary
studies on the same task machinery (Dask or in-process, records written as they arrive,
resumable):

1. **Training** (``DIR/tuning/``): the tuning cells x the training seeds, with one filter
   entry per grid point (``"ekf:q_scale=5e-1"``, ...), all paired on the same files.
2. **Choice** (:func:`choose`): per study filter (and per cell with ``per_cell``), the grid
   point with the best criterion (mean over the tuning cells and training seeds of each
   run's RMSE or log RMSE; a failed or diverged run scores ``+inf``), among the points whose
   training runs all keep the NIS columns inside the band when a band is given (when no
   point does, the best point is chosen and ``constraint_met`` says so). Ties go to the
   first point in grid order. ``DIR/tuning.csv`` holds one row per (cell, filter, options,
   seed) and one ``mean`` row per (cell group, filter, options); ``chosen`` marks the chosen
   point's rows, and on them ``edge`` is 1 when the chosen point lies on an edge of its grid
   (:func:`grid_edges`: some numeric option at the lowest or highest value its grid gives
   it, so the optimum may lie beyond the grid) and ``edge_options`` names those options.
3. **Evaluation** (``DIR``): the study as written, each cell running the chosen entry of
   every tuned filter (:attr:`~.spec.Cell.entries`; ``runs.csv`` keeps the study's
   filter names and gives the entry run in ``entry``; claims and statistics are unchanged),
   on the evaluation seeds. Its ``study.json`` keeps ``tuned_from`` (the hash of the spec as
   written), so that a rerun of the same spec resumes.
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
from .spec import StudySpec, parse_study
from .tables import write_table
from .tuning_spec import CRITERIA, TuningSpec, grid_entry, training_seeds

__all__ = ["Choice", "choose", "grid_edges", "run_tuned_study", "training_spec",
           "tuned_spec"]


@dataclasses.dataclass(frozen=True)
class Choice:
    """The outcome for one study filter (in one cell with ``per_cell``, else ``cell`` is
    ``None``): its chosen entry and options, the chosen point's score, and whether it met the
    NIS band (``None`` without a band), and the options at an edge of the grid
    (:func:`grid_edges`; empty when the point is inside the grid)."""

    cell: str | None
    filter: str
    entry: str
    options: dict
    score: float
    constraint_met: bool | None
    edge: tuple[str, ...] = ()


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def grid_edges(point, points) -> tuple[str, ...]:
    """The options of ``point`` that lie on an edge of the grid ``points``.

    An option is on an edge when it is numeric (an integer or a float, not a boolean), the
    grid gives it at least two values, and the point's value is the lowest or the highest of
    them (by value, whatever the order they were written in). An option with one value is
    fixed, not tuned; a boolean or text option has no beyond. With two values every point
    is on that option's edge.

    Parameters
    ----------
    point : tuple of (str, value)
        A grid point (``TuningSpec.grids[f][k]``).
    points : sequence of such tuples
        The filter's whole grid.

    Returns
    -------
    tuple of str
        ``"option (lowest)"`` or ``"option (highest)"`` per option on an edge, in the
        point's option order.
    """
    out = []
    for opt, v in point:
        vals = {dict(p)[opt] for p in points}
        if not _is_number(v) or len(vals) < 2 or not all(map(_is_number, vals)):
            continue
        if v == min(vals):
            out.append(f"{opt} (lowest)")
        elif v == max(vals):
            out.append(f"{opt} (highest)")
    return tuple(out)


def _raw_without_tuning(spec: StudySpec) -> dict:
    raw = copy.deepcopy(spec.raw)
    raw.pop("tuning", None)
    return raw


def training_spec(spec: StudySpec) -> StudySpec:
    """The training study: tuning cells x training seeds, one entry per grid point."""
    t = spec.tuning
    assert t is not None                     # a tuned study
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


def tuned_spec(spec: StudySpec, choices: dict) -> StudySpec:
    """The evaluation study: every cell runs the chosen entry of each tuned filter
    (``choices`` from :func:`choose`); ``tuned_from`` is ``spec``'s hash.

    Raises
    ------
    StudyError
        A chosen entry equals another filter entry of the study.
    """
    assert spec.tuning is not None           # a tuned study
    cells = []
    for cell in spec.cells:
        entries = {f: (choices.get((cell.name, f)) or choices[(None, f)]).entry
                   for f in spec.tuning.grids}
        run = [entries.get(f, f) for f in spec.filters]
        if len(set(run)) != len(run):
            raise StudyError(f"cell {cell.name!r}: a chosen entry ({', '.join(run)}) equals "
                             "another filter of the study; take that point out of the grid")
        cells.append(dataclasses.replace(cell, params={**cell.params, "filters": ",".join(run)},
                                         entries=entries))
    return dataclasses.replace(spec, cells=tuple(cells), tuning=None, tuned_from=spec.hash)


def _score(row: dict, quantity: str, log: bool) -> float:
    from .study import _col

    v = row.get(_col(quantity), math.nan)
    v = float(v) if isinstance(v, (int, float)) else math.nan
    if row.get("status") != "ok" or not math.isfinite(v) or v <= 0:
        return math.inf
    return math.log(v) if log else v


def choose(t: TuningSpec, rows: list[dict]) -> tuple[dict, list[dict]]:
    """Choose each filter's grid point from the training runs' rows (``runs.csv`` rows of the
    training study: ``cell``, ``seed_index``, ``seed``, ``filter``, ``status``, the RMSE
    columns and, with a band, the ``t.nis_column`` columns).

    Returns
    -------
    choices : dict
        ``{(cell or None, study filter entry): Choice}`` (``None``: pooled over the cells).
    table : list of dict
        The rows of ``tuning.csv`` (module docstring).

    Raises
    ------
    StudyError
        A NIS band is set but the rows have no such column.
    """
    quantity, log = CRITERIA[t.criterion]
    groups = [(c, (c,)) for c in t.cells] if t.per_cell else [(None, t.cells)]
    choices, table = {}, []
    for group, group_cells in groups:
        by_entry: dict[str, list[dict]] = {}
        for r in rows:
            if r["cell"] in group_cells:
                by_entry.setdefault(r["filter"], []).append(r)
        label = "+".join(group_cells)
        for f, points in t.grids.items():
            scored = [_score_point(t, f, p, by_entry, quantity, log) for p in points]
            eligible = [sc for sc in scored if sc["ok"] is not False] or scored
            best = min(eligible, key=lambda sc: sc["mean"])        # first of equals
            edge = grid_edges(best["point"], points)
            choices[(group, f)] = Choice(group, f, best["entry"], dict(best["point"]),
                                         best["mean"],
                                         None if t.nis_band is None else bool(best["ok"]),
                                         edge)
            for sc in scored:
                table += _table_rows(t, f, sc, label, edge if sc is best else None)
    return choices, table


def _score_point(t: TuningSpec, f: str, point, by_entry: dict, quantity: str,
                 log: bool) -> dict:
    """One grid point's training runs, their scores, the mean and the NIS verdict."""
    entry = grid_entry(f, point)
    runs = by_entry.get(entry, [])
    scores = [_score(r, quantity, log) for r in runs]
    mean = sum(scores) / len(scores) if scores and all(map(math.isfinite, scores)) \
        else math.inf
    ok = None
    if t.nis_band is not None:
        vals = []
        for r in runs:
            for c in t.nis_column or ():
                if c not in r:
                    raise StudyError(f"[tuning] nis_column {c!r} is not a runs.csv column")
                vals.append(r[c])
        ok = bool(runs) and all(isinstance(v, (int, float)) and
                                t.nis_band[0] <= v <= t.nis_band[1] for v in vals)
    return {"point": point, "entry": entry, "runs": runs, "scores": scores, "mean": mean,
            "ok": ok}


def _table_rows(t: TuningSpec, f: str, sc: dict, label: str,
                edge: tuple[str, ...] | None) -> list[dict]:
    """``tuning.csv`` rows of one grid point: one per training run, then its ``mean``;
    ``edge`` is the chosen point's :func:`grid_edges`, None for a point not chosen."""
    opts = " ".join(f"{k}={v}" for k, v in sc["point"])
    band = t.nis_band is not None
    chosen = edge is not None
    extra = {"nis_ok": "" if sc["ok"] is None else int(sc["ok"])} if band else {}
    extra.update(chosen=int(chosen), edge=int(bool(edge)) if chosen else "",
                 edge_options=", ".join(edge) if edge else "")
    out = [{"cell": r["cell"], "filter": f, "options": opts, "seed_index": r["seed_index"],
            "seed": r["seed"], "score": s,
            **({c: r.get(c, "") for c in t.nis_column or ()} if band else {}), **extra}
           for r, s in zip(sc["runs"], sc["scores"])]
    out.append({"cell": label, "filter": f, "options": opts, "seed_index": "", "seed": "mean",
                "score": sc["mean"], **(dict.fromkeys(t.nis_column or (), "") if band else {}),
                **extra})
    return out


def run_tuned_study(spec: StudySpec, out_dir: str | Path, *, runs: int | None = None,
                    scheduler: str | None = None, workers: int | None = None,
                    force: bool = False, on_record: Callable[[dict], None] | None = None,
                    render: bool = True):
    """Train, choose, evaluate (module docstring); arguments as
    :func:`~.study.run_study`. Returns the evaluation's :class:`~.study.StudyResult` with the
    training tasks added to its counts and ``tuning`` set to the choices (:func:`choose`).

    Raises
    ------
    StudyError
        Training seeds overlap the evaluation seeds of ``runs``, or what
        :func:`~.study.run_study` raises.
    """
    from .study import _check_folder, run_study

    out = Path(out_dir)
    t = spec.tuning
    assert t is not None                     # run_study sends only tuned studies here
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
