"""``sdr-di study``: cells x filters x seeds, paired on the same files, with statistics.

Execution
---------
* The task unit is one (cell, seed): the cell's experiment run (default ``compare``) with
  every filter of the study on the same generated files (a paired design). Seed ``i`` is
  :func:`~.campaign.run_seed` ``(base_seed, i)`` in every cell. Tasks are ordered seed by
  seed, so that the files of a seed are generated once, reused by every cell that can, and
  deleted when the seed's last task is done.
* **File cache** (``DIR/cache``): a generated file is kept under a hash of only the
  scenario keys it depends on (:func:`~sdr_di.experiments._deep.file_keys`): cells that differ in IMU errors
  share the IF file, cells that differ in the filter's assumptions, the mode or the filter
  rate share every file. Local workers share the folder; on a cluster whose workers do not
  see ``DIR``, each generates its own (correct, slower).
* Tasks run on the same path as ``campaign`` (:func:`~.tasks.run_tasks`: a local Dask
  cluster by default, ``scheduler`` for a cluster; ``workers=0`` runs them in this process).
  Each record is written to ``runs/<cell>_<seed>.json`` the moment it arrives, so a killed
  worker loses only its task and an interrupted study keeps what it had.
* **Resumption**: ``study.json`` holds the spec hash (:attr:`~.spec.StudySpec.hash`).
  Re-running the same spec into the same folder skips every (cell, seed) with a record of
  that hash (except tasks lost with their worker, which run again); a different spec is
  refused unless ``force``. A forced rerun keeps every run whose cell run key
  (:meth:`~.spec.StudySpec.run_key`: what decides the cell's runs, not its name, the
  other cells or the claims) is unchanged, moved under the cell's new index, and removes the
  others: adding a cell (say, the combination that one-factor results point to) or rewording
  a claim reruns nothing else. ``runs`` may grow: the first seeds are the same.

Outputs: ``cells.csv``, ``runs.csv``, ``comparisons.csv``, ``study.json``, ``report.html``
(:mod:`.study_report`); ``docs/studies.md``.
"""

from __future__ import annotations

import dataclasses
import math
import shutil
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..errors import StudyError
from ..integration.consistency import CONSISTENCY_KEYS
from ..io.atomic import ensure_output_dir
from ..experiments._deep import FILE_CACHE
from .campaign import _client, _quiet_on_sigint, run_seed
from .ensemble import ensemble_consistency
from .execute import (
    execute_run,
    read_json,
    restore_floats,
    write_json,
    write_run_record,
)
from .paired import Comparison, claim_verdict, compare_pair, holm, ratio_of_log
from ..experiments.registry import get_experiment
from .spec import QUANTITY_KEYS, StudySpec, check_study_size, spec_summary
from .tables import write_table
from .tasks import Task, run_tasks, run_tasks_here
from ..experiments.variants import entry_label

__all__ = ["StudyResult", "execute_cell_run", "run_study", "study_outputs",
           "summarize_study"]


def execute_cell_run(exp, params: dict, seed: int, index: int, cache_dir: str | None) -> dict:
    """:func:`~.execute.execute_run` with the study's file cache set for this task, and its
    temporary folder in ``cache_dir/tmp`` (removed with the cache when the study completes;
    the system's temporary folder where ``cache_dir`` cannot be made on this worker)."""
    token = FILE_CACHE.set(Path(cache_dir) if cache_dir else None)
    tmp_root = None
    if cache_dir:
        try:
            tmp_root = Path(cache_dir) / "tmp"
            tmp_root.mkdir(parents=True, exist_ok=True)
        except OSError:
            tmp_root = None
    try:
        return execute_run(exp, params, seed, index, tmp_root)
    finally:
        FILE_CACHE.reset(token)


@dataclasses.dataclass
class StudyResult:
    """Outcome of :func:`run_study`: the spec, the records ``{(cell, seed index): record}``,
    the per-run rows, the comparisons, the per-cell rows, the counts of tasks run and
    skipped, and the output folder."""

    spec: StudySpec
    records: dict
    runs: list
    comparisons: list
    cells: list
    n_run: int
    n_skipped: int
    out_dir: Path
    elapsed_s: float
    tuning: dict | None = None           # {filter: tuning.Choice} of a tuned study

    @property
    def failed(self) -> list[dict]:
        """Per-run rows (cell, seed, filter) that failed or diverged."""
        return [r for r in self.runs if r["status"] != "ok"]


def check_study_counts(runs, workers, scheduler, names: dict | None = None) -> None:
    """Seeds per cell (an integer >= 1, or None: the spec's), local workers (an integer >= 0
    or None) and a scheduler address, which takes no worker count: the rule of ``sdr-di
    study`` and ``sdr_di.study``.

    ``names``: how the message names ``runs`` and ``workers`` (the CLI's flags).

    Raises
    ------
    StudyError
        A count out of range or of the wrong type, or workers with a scheduler.
    """
    n = (names or {}).get
    for key, v, low in (("runs", runs, 1), ("workers", workers, 0)):
        if v is not None and (isinstance(v, bool) or not isinstance(v, int) or v < low):
            raise StudyError(f"{n(key, key)} must be an integer >= {low}, got {v!r}")
    if scheduler is not None and workers is not None:
        raise StudyError(f"{n('workers', 'workers')} applies to the local cluster only")


def _record_path(runs_dir: Path, c: int, i: int) -> Path:
    return runs_dir / f"{c}_{i}.json"


def _same_study(out: Path, spec: StudySpec) -> bool:
    try:
        return read_json(out / "study.json").get("hash") == spec.hash
    except (OSError, ValueError, AttributeError):
        return False


def _keep_unchanged_runs(spec: StudySpec, runs_dir: Path) -> None:
    """Replace another study's runs by ``spec``'s: keep the finished runs whose cell run key
    ``spec`` still has (renamed to their cell's index in ``spec`` and marked with its hash),
    remove the rest (module notes)."""
    wanted = {spec.run_key(c): c for c in range(len(spec.cells))}
    old_dir = runs_dir.with_name(runs_dir.name + ".old")
    shutil.rmtree(old_dir, ignore_errors=True)
    runs_dir.rename(old_dir)
    ensure_output_dir(runs_dir)
    for path in sorted(old_dir.glob("*.json")):
        try:
            rec = read_json(path)
        except (OSError, ValueError):
            continue
        if not isinstance(rec, dict) or rec.get("lost"):
            continue
        c, i = wanted.get(str(rec.get("run_key"))), rec.get("seed_index")
        if c is None or not isinstance(i, int):
            continue
        files = old_dir / path.stem
        if files.is_dir():
            files.rename(runs_dir / f"{c}_{i}")
        rec.update(cell=spec.cells[c].name, cell_index=c, spec_hash=spec.hash)
        write_json(_record_path(runs_dir, c, i), rec)
    shutil.rmtree(old_dir)


def _check_folder(spec: StudySpec, out: Path, force: bool) -> None:
    meta_path = out / "study.json"
    if not meta_path.is_file():
        if (out / "runs").exists() and not force:
            raise StudyError(f"output folder {out} holds runs of something that is not a "
                             "study; choose another --out or pass --force")
        return
    try:
        meta = read_json(meta_path)
        old, tuned_from = meta.get("hash"), meta.get("tuned_from")
    except (OSError, ValueError, AttributeError):
        old = tuned_from = None
    if spec.hash not in (old, tuned_from) and not force:
        raise StudyError(f"output folder {out} holds study {old} (a different spec than "
                         f"{spec.hash}); choose another --out or pass --force to replace it")


def run_study(spec: StudySpec, out_dir: str | Path, *, runs: int | None = None,
              scheduler: str | None = None, workers: int | None = None, force: bool = False,
              on_record: Callable[[dict], None] | None = None,
              render: bool = True) -> StudyResult:
    """Run (or resume) a study and write its outputs (module notes).

    Parameters
    ----------
    spec : StudySpec
        :func:`~.spec.load_study`.
    out_dir : path
        Output folder.
    runs : int, optional
        Seeds per cell (default the spec's ``runs``).
    scheduler : str, optional
        Dask scheduler address; default a local cluster of ``workers`` processes.
    workers : int, optional
        Local worker processes (default the number of cores); ``0`` runs every task in this
        process, without Dask.
    force : bool
        Replace a different study's runs in ``out_dir``.
    on_record : callable, optional
        Called with each record as it arrives.
    render : bool
        Write ``report.html``.

    Raises
    ------
    StudyError
        Bad ``runs``/``workers``, or ``out_dir`` holds a different study (without ``force``).
    CampaignError
        Scheduler unreachable.
    """
    if spec.tuning is not None:          # train, choose, then evaluate (.tuning)
        from .tuning import run_tuned_study

        return run_tuned_study(spec, out_dir, runs=runs, scheduler=scheduler, workers=workers,
                               force=force, on_record=on_record, render=render)
    t0 = time.perf_counter()
    runs = spec.runs if runs is None else runs
    check_study_counts(runs, workers, scheduler, {"runs": "--runs", "workers": "--workers"})
    check_study_size(f"study {spec.name}", len(spec.cells), runs, force)
    out = Path(out_dir)
    _check_folder(spec, out, force)
    exp = get_experiment(spec.experiment)
    ensure_output_dir(out)
    runs_dir = out / "runs"
    if force and runs_dir.exists() and not _same_study(out, spec):
        _keep_unchanged_runs(spec, runs_dir)
    ensure_output_dir(runs_dir)
    cache = out / "cache"
    seeds = [run_seed(spec.base_seed, i) for i in range(runs)]

    records: dict[tuple[int, int], dict] = {}
    todo: list[Task] = []
    where: dict[str, tuple[int, int]] = {}
    for i, seed in enumerate(seeds):
        for c, cell in enumerate(spec.cells):
            path = _record_path(runs_dir, c, i)
            if path.is_file():
                try:
                    rec = read_json(path)
                except (OSError, ValueError):
                    rec = None
                if isinstance(rec, dict) and rec.get("spec_hash") == spec.hash \
                        and rec.get("run_key") == spec.run_key(c) and not rec.get("lost"):
                    records[(c, i)] = rec
                    continue
            name = f"study-{c}-{i}"
            todo.append(Task(name, i * len(spec.cells) + c, seed, execute_cell_run,
                             (exp, cell.params, seed, i * len(spec.cells) + c, str(cache))))
            where[name] = (c, i)
    n_skipped = len(records)
    left = {i: sum(1 for t in todo if where[t.name][1] == i) for i in range(runs)}
    summary = spec_summary(spec)
    write_json(out / "study.json", {**summary, "status": "running", "runs": runs,
                                    "seeds": seeds})

    def done(task: Task, rec: dict) -> None:
        c, i = where[task.name]
        rec.update(cell=spec.cells[c].name, cell_index=c, seed_index=i, spec_hash=spec.hash,
                   run_key=spec.run_key(c))
        write_run_record(runs_dir, rec, files_dir=runs_dir / f"{c}_{i}",
                         json_path=_record_path(runs_dir, c, i))
        rec.pop("files", None)
        records[(c, i)] = rec
        left[i] -= 1
        if left[i] == 0:                 # the seed's last task: its files go
            for p in cache.glob(f"s{seeds[i]}-*"):
                shutil.rmtree(p, ignore_errors=True) if p.is_dir() else p.unlink(True)
        if on_record is not None:
            on_record(rec)

    address = "in-process"
    try:
        if todo and workers == 0 and scheduler is None:
            run_tasks_here(todo, done)
        elif todo:
            with _client(scheduler, workers, 0) as client:
                address = client.scheduler.address
                with _quiet_on_sigint():
                    run_tasks(client, todo, done)
    except BaseException as exc:
        status = "interrupted" if isinstance(exc, KeyboardInterrupt) else "crashed"
        write_json(out / "study.json", {**summary, "status": status, "runs": runs,
                                        "seeds": seeds, "error": f"{type(exc).__name__}: {exc}",
                                        "n_records": len(records)})
        raise
    shutil.rmtree(cache, ignore_errors=True)
    res = summarize_study(spec, records, runs, out)
    res.n_run, res.n_skipped = len(todo), n_skipped
    res.elapsed_s = time.perf_counter() - t0
    write_json(out / "study.json", {**summary, "status": "done", "runs": runs, "seeds": seeds,
                                    "scheduler": address, "n_run": len(todo),
                                    "n_skipped": n_skipped, "elapsed_s": res.elapsed_s,
                                    "n_failed_runs": len(res.failed)})
    if render:
        from .study_report import render_study_report

        render_study_report(out)
    return res


#: The files a study writes in its folder, by the label ``sdr-di study`` prints.
STUDY_FILES = (("runs", "runs.csv"), ("cells", "cells.csv"), ("comparisons", "comparisons.csv"),
               ("tuning", "tuning.csv"), ("plot", "paired_ratios.png"), ("study", "study.json"),
               ("report", "report.html"))


def study_outputs(out: str | Path) -> dict[str, Path]:
    """The files of :data:`STUDY_FILES` that the study folder ``out`` holds, by label (the
    runs' own records are under ``runs/``)."""
    out = Path(out)
    return {label: out / name for label, name in STUDY_FILES if (out / name).is_file()}


def _run_rows(spec: StudySpec, records: dict, runs: int) -> list[dict]:
    rows = []
    for c, cell in enumerate(spec.cells):
        mode = str(cell.params.get("modes", "deep"))
        for i in range(runs):
            rec = records.get((c, i), {})
            figs = restore_floats(rec.get("figures", {})) if rec.get("status") == "ok" else {}
            for f in spec.filters:
                entry = cell.entries.get(f, f)              # a tuned study: the chosen one
                lab = entry_label(entry, mode)
                row: dict = {"cell": cell.name, "seed_index": i, "seed": rec.get("seed"),
                             "filter": f, "entry": entry}
                if rec.get("status") != "ok":
                    row.update(status="failed", error=rec.get("error", "no record"))
                elif f"{lab}.error" in figs:
                    row.update(status="failed", error=figs[f"{lab}.error"])
                elif figs.get(f"{lab}.completed", 1) != 1:      # experiments without the
                    row.update(status="diverged", error="non-finite errors")  # flag: RMSE
                else:
                    row.update(status="ok", error="")
                for q, (stem, unit) in QUANTITY_KEYS.items():
                    v = figs.get(f"{lab}.{stem}_rmse", math.nan)
                    v = float(v) if isinstance(v, (int, float)) else math.nan
                    if row["status"] != "ok" or not math.isfinite(v):
                        if row["status"] == "ok":
                            row.update(status="diverged", error=f"{q} RMSE not finite")
                        v = math.nan
                    row[f"{q}_rmse_{unit.replace('/', 'p')}"] = v
                row["handover_s"] = figs.get(f"{lab}.handover_s", math.nan)
                row["elapsed_s"] = rec.get("elapsed_s", math.nan)
                for k in CONSISTENCY_KEYS:       # NIS per block, NEES per quantity
                    v = figs.get(f"{lab}.{k}", math.nan)
                    row[k] = float(v) if isinstance(v, (int, float)) and \
                        row["status"] == "ok" else math.nan
                v = figs.get(f"{lab}.nis_dof", math.nan)     # one NIS block's size
                row["nis_dof"] = float(v) if isinstance(v, (int, float)) else math.nan
                rows.append(row)
    for row in rows:                     # a diverged quantity makes the whole run a loss
        if row["status"] != "ok":
            for q, (_, unit) in QUANTITY_KEYS.items():
                row[f"{q}_rmse_{unit.replace('/', 'p')}"] = math.nan
    return rows


def _col(q: str) -> str:
    return f"{q}_rmse_{QUANTITY_KEYS[q][1].replace('/', 'p')}"


def summarize_study(spec: StudySpec, records: dict, runs: int, out: Path) -> StudyResult:
    """Per-run rows, paired comparisons (Holm over the family) and per-cell rows; writes
    ``runs.csv``, ``comparisons.csv`` and ``cells.csv`` into ``out``."""
    rows = _run_rows(spec, records, runs)
    vals: dict = {}
    for r in rows:
        for q in QUANTITY_KEYS:
            vals.setdefault((r["cell"], r["filter"], q), [math.nan] * runs)[r["seed_index"]] = \
                r[_col(q)]
    pairs = [(cell.name, f, spec.baseline) for cell in spec.cells for f in spec.filters
             if f != spec.baseline]
    for cl in spec.claims:
        for cell in spec.cells:
            if (cl.cells is None or cell.name in cl.cells) and \
                    (cell.name, cl.filter, cl.against) not in pairs:
                pairs.append((cell.name, cl.filter, cl.against))
    m = max(1, len(pairs) * len(QUANTITY_KEYS))
    level = 1.0 - spec.alpha / m
    comps: list[Comparison] = [compare_pair(cn, f, a, q, vals[(cn, f, q)], vals[(cn, a, q)],
                                            level)
                               for cn, f, a in pairs for q in QUANTITY_KEYS]
    t_p = [c.log_p if spec.interval == "log_ratio" else c.d_p for c in comps]
    for c, th, sh in zip(comps, holm(t_p), holm([c.sign_p for c in comps])):
        c.t_p_holm, c.sign_p_holm = float(th), float(sh)
    by = {(c.cell, c.filter, c.against, c.quantity): c for c in comps}

    factor_keys = list(dict.fromkeys(k for cell in spec.cells for k in cell.factors))
    cell_rows = []
    for cell in spec.cells:
        means = {}
        for f in spec.filters:
            for q in QUANTITY_KEYS:
                x = np.asarray(vals[(cell.name, f, q)], float)
                means[(f, q)] = float(np.mean(x[np.isfinite(x)])) if np.isfinite(x).any() \
                    else math.nan
        for f in spec.filters:
            n_ok = sum(1 for r in rows if r["cell"] == cell.name and r["filter"] == f
                       and r["status"] == "ok")
            row: dict = {"cell": cell.name, **{k: cell.factors.get(k, "") for k in factor_keys},
                         "filter": f, "n_runs": runs,
                         "n_ok": n_ok, "n_failed": runs - n_ok}
            for q, (stem, unit) in QUANTITY_KEYS.items():
                x = np.asarray(vals[(cell.name, f, q)], float)
                fin = x[np.isfinite(x)]
                u = unit.replace("/", "p")
                row[f"{q}_rmse_{u}"] = means[(f, q)]
                row[f"{q}_rmse_sd"] = float(np.std(fin, ddof=1)) if fin.size > 1 else math.nan
                best = min((means[(g, q)] for g in spec.filters
                            if math.isfinite(means[(g, q)])), default=math.nan)
                row[f"{q}_best"] = int(math.isfinite(means[(f, q)]) and means[(f, q)] == best)
                pair = by.get((cell.name, f, spec.baseline, q))
                row[f"d_{q}_{u}"] = pair.d_mean if pair else math.nan
                row[f"d_{q}_ci_low"] = pair.d_ci_low if pair else math.nan
                row[f"d_{q}_ci_high"] = pair.d_ci_high if pair else math.nan
                row[f"{q}_ratio"] = pair.ratio if pair else math.nan
                row[f"{q}_ratio_ci_low"] = ratio_of_log(pair.log_ci_low) if pair else math.nan
                row[f"{q}_ratio_ci_high"] = ratio_of_log(pair.log_ci_high) if pair else math.nan
                row[f"{q}_wins"] = pair.wins if pair else ""
                row[f"{q}_sign_p"] = pair.sign_p if pair else math.nan
                row[f"{q}_sign_p_holm"] = pair.sign_p_holm if pair else math.nan
                row[f"{q}_t_p_holm"] = pair.t_p_holm if pair else math.nan
            for j, cl in enumerate(spec.claims, 1):
                verdict = ""
                if f == cl.filter and (cl.cells is None or cell.name in cl.cells):
                    verdict = claim_verdict([by[(cell.name, cl.filter, cl.against, q)]
                                             for q in cl.quantities], cl.min_wins,
                                            cl.max_sign_p, cl.interval_excludes_zero,
                                            spec.interval)
                row[f"claim{j}"] = verdict
            for k in CONSISTENCY_KEYS:           # mean over the cell's ok runs
                x = np.array([r[k] for r in rows if r["cell"] == cell.name
                              and r["filter"] == f], float)
                row[k] = float(np.mean(x[np.isfinite(x)])) if np.isfinite(x).any() \
                    else math.nan
            row.update(ensemble_consistency(      # ANEES, ANIS with their chi-square band
                [r for r in rows if r["cell"] == cell.name and r["filter"] == f]))
            cell_rows.append(row)
    write_table(out, "runs", rows)
    write_table(out, "comparisons", [
        {**{k: v for k, v in dataclasses.asdict(c).items()}, "ratio": c.ratio} for c in comps])
    write_table(out, "cells", cell_rows)
    return StudyResult(spec=spec, records=records, runs=rows, comparisons=comps,
                       cells=cell_rows, n_run=0, n_skipped=0, out_dir=out, elapsed_s=0.0)
