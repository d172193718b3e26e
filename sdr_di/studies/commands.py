"""CLI handlers: ``sdr-di campaign``, ``sdr-di robustness``, ``sdr-di report`` (``sdr-di study``
is the CLI's own, :mod:`sdr_di.cli`: it calls the public API, which this package must not
import).

:func:`add_parsers` adds the four sub-commands to the ``sdr-di`` sub-parser set; each sets
``func`` to its handler, which returns the exit status (0: all runs completed; 1: some runs
failed, their errors printed) and raises :class:`~sdr_di.errors.SdrDiError` subclasses for
bad input (printed by the CLI on one line, exit status 2).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..errors import CampaignError

__all__ = ["add_parsers", "cmd_campaign", "cmd_report", "cmd_robustness"]


#: Dask worker preload (script text) of a local campaign: the worker processes ignore SIGINT.
#: Ctrl-C in a terminal goes to the whole process group; only the sdr-di process should act
#: on it (record the campaign as interrupted, close the cluster, print one line), not every
#: worker with its own KeyboardInterrupt traceback and the nanny's error log.
WORKERS_IGNORE_SIGINT = "import signal; signal.signal(signal.SIGINT, signal.SIG_IGN)"


def _default_out(kind: str, experiment: str) -> Path:
    from ..scenario import REPO_ROOT

    return REPO_ROOT / "signals" / "out" / f"{kind}_{experiment}"


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("experiment", help="experiment name (noise-mismatch, ...)")
    p.add_argument("--out", type=Path, default=None,
                   help="output folder (default: signals/out/<command>_<experiment>)")
    p.add_argument("--seed", type=int, default=0, metavar="S",
                   help="seed (campaign: base seed of the runs' seeds; default 0)")
    p.add_argument("--duration", type=float, default=None, metavar="S",
                   help="run length [s] (the experiment's duration_s parameter)")
    p.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                   help="set an experiment parameter (repeatable), e.g. case=r, "
                   "filters=ekf,ff-aukf")
    p.add_argument("--scheduler", default=None, metavar="ADDR",
                   help="Dask scheduler address (tcp://host:8786); default: local processes")
    p.add_argument("--no-report", action="store_true", help="do not write report.html")


def add_parsers(subparsers) -> None:
    """Add ``campaign``, ``robustness`` and ``report`` to an argparse sub-parser set."""
    p = subparsers.add_parser(
        "campaign", help="repeat an experiment with independent seeds on Dask and aggregate",
        description="Run an experiment RUNS times with independent seeds in parallel (a local "
        "Dask cluster of worker processes, or the cluster of --scheduler), write each run as "
        "it completes (runs/<i>.json), then mean/std/min/max of every figure, the "
        "experiment's tables and plots and report.html.")
    _common(p)
    p.add_argument("--runs", type=int, required=True, metavar="N", help="number of runs")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="local worker processes (default: number of cores)")
    p.add_argument("--force", action="store_true",
                   help="replace the runs of an earlier campaign in --out")
    p.set_defaults(func=cmd_campaign)

    p = subparsers.add_parser(
        "robustness", help="one run of an experiment, with its table, plots and report",
        description="Run an experiment once (seed --seed) and write its figures, tables, "
        "time series, plots and report.html.")
    _common(p)
    p.set_defaults(func=cmd_robustness)

    p = subparsers.add_parser(
        "report", help="render report.html for a campaign, robustness, study or run "
        "output folder",
        description="Write DIR/report.html: one self-contained page with every table "
        "(inline) and plot (embedded PNG) of the folder. On an sdr-di run or lc folder it "
        "draws the run's figures from its files when they are missing (no rerun): errors "
        "per axis with the filter's 3-sigma, NIS against its band, the consistency table, "
        "trajectory, C/N0 and lock per channel, sky plot, fix status (docs/report.md).")
    p.add_argument("dir", type=Path, help="output folder of sdr-di campaign / robustness / "
                   "study, or of one sdr-di run or lc")
    p.set_defaults(func=cmd_report)


def _params(args: argparse.Namespace):
    """Experiment, its parameters and the output folder, all checked before any work.

    A ``scenario`` parameter is read and validated here, so that a bad scenario file is a
    bad input (exit 2), not a failed run.
    """
    import math

    from ..io.atomic import check_output_dir
    from ..experiments.registry import get_experiment, parse_params

    exp = get_experiment(args.experiment)
    overrides = {}
    if args.duration is not None:
        if not (math.isfinite(args.duration) and args.duration > 0):
            raise CampaignError(f"--duration must be a finite number > 0, got "
                                f"{args.duration:g}")
        overrides["duration_s"] = float(args.duration)
    params = parse_params(exp, args.param, overrides)
    if params.get("scenario") is not None:
        _check_scenario(exp.name, params["scenario"])
    check_output_dir(args.out or _default_out(args.command, exp.name))
    return exp, params


def _check_scenario(experiment: str, path) -> None:
    """Read and validate the ``scenario`` parameter (scenario tables plus an optional ``[lc]``
    table, which the loosely coupled experiments read)."""
    from ..errors import ScenarioError
    from ..integration.loose import load_lc_scenario

    if not str(path).strip():
        raise ScenarioError(f"{experiment}: --param scenario= needs a scenario file")
    load_lc_scenario(Path(str(path)))


def cmd_campaign(args: argparse.Namespace) -> int:
    """Handler of ``sdr-di campaign``."""
    from .campaign import run_campaign

    exp, params = _params(args)
    if args.seed < 0:
        raise CampaignError(f"--seed must be >= 0, got {args.seed}")
    out = args.out or _default_out("campaign", exp.name)

    def show(rec: dict) -> None:
        state = "ok" if rec["status"] == "ok" else f"FAILED: {rec.get('error')}"
        print(f"  run {rec['index']:4d} seed {rec['seed']:10d}  {state}", flush=True)

    import dask

    preload = [*dask.config.get("distributed.worker.preload", []), WORKERS_IGNORE_SIGINT]
    with dask.config.set({"distributed.worker.preload": preload}):
        res = run_campaign(exp, params, args.runs, base_seed=args.seed,
                           scheduler=args.scheduler, workers=args.workers, out_dir=out,
                           overwrite=args.force, on_record=show)
    print(f"{res.n_ok}/{len(res.records)} runs completed in {res.elapsed_s:.1f} s on "
          f"{res.scheduler}")
    for r in res.failed:
        print(f"  failed: run {r['index']} (seed {r['seed']}): {r.get('error')}",
              file=sys.stderr)
    if res.n_ok == 0:
        raise CampaignError(f"campaign {exp.name}: all {len(res.records)} runs failed "
                            f"(first: {res.records[0].get('error')}); records in {out}/runs")
    print(f"aggregate {out / 'aggregate.md'}")
    if not args.no_report:
        print(f"report    {_render(out)}")
    return 1 if res.failed else 0


def cmd_robustness(args: argparse.Namespace) -> int:
    """Handler of ``sdr-di robustness``."""
    from .single_run import run_experiment

    exp, params = _params(args)
    out = args.out or _default_out("robustness", exp.name)
    res = run_experiment(exp, params, args.seed, out_dir=out, scheduler=args.scheduler)
    if not res.ok:
        print(f"{exp.name}: run failed: {res.record.get('error')}", file=sys.stderr)
    else:
        figs = res.record["figures"]
        width = max(len(k) for k in figs) if figs else 0
        for k, v in figs.items():
            print(f"{k:{width}s} {v:.6g}" if isinstance(v, float) else f"{k:{width}s} {v}")
    print(f"output    {out}")
    if not args.no_report:
        print(f"report    {_render(out)}")
    return 0 if res.ok else 1


class StudyProgress:
    """``sdr-di study``'s progress: one tqdm bar over the (cell, seed) runs, a failed run
    written above it in one line (issue 49 item 21: a line per finished run, no bar).
    A context manager (closes the bar); called with each run record. The bar appears with
    the first record: a study refused before any run prints its one line alone."""

    def __init__(self, total: int, file=None) -> None:
        self.total, self.file, self.failed = total, file or sys.stderr, 0
        self._bar = None

    @property
    def bar(self):
        """The tqdm bar (made on first use)."""
        if self._bar is None:
            from tqdm import tqdm

            self._bar = tqdm(total=self.total, unit="run", desc="study", file=self.file,
                             dynamic_ncols=True)
        return self._bar

    def __call__(self, rec: dict) -> None:
        if rec["status"] != "ok":
            self.failed += 1
            self.bar.write(f"  {rec['cell']}  seed {rec['seed_index']}: FAILED: "
                           f"{rec.get('error')}", file=sys.stderr)
            self.bar.set_postfix_str(f"{self.failed} failed", refresh=False)
        self.bar.update(1)

    def __enter__(self) -> StudyProgress:
        return self

    def __exit__(self, *exc) -> None:
        if self._bar is not None:
            self._bar.close()


def cmd_report(args: argparse.Namespace) -> int:
    """Handler of ``sdr-di report`` on a campaign, robustness or study folder (a run's
    folder: :func:`sdr_di.cli` hands it to :mod:`sdr_di.report`, the layer above)."""
    print(_render(args.dir))
    return 0


def _render(folder: Path) -> Path:
    """:func:`~sdr_di.studies.campaign_report.render_report`, each warning (a run record it could
    not read) printed as one line ``sdr-di: warning: ...`` on stderr."""
    import warnings

    from .campaign_report import ReportWarning, render_report

    if (Path(folder) / "study.json").is_file():
        from .study_report import render_study_report

        return render_study_report(folder)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ReportWarning)
        path = render_report(folder)
    for w in caught:
        if issubclass(w.category, ReportWarning):
            print(f"sdr-di: warning: {w.message}", file=sys.stderr)
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return path
