"""Shared pieces of the deep-receiver experiments (``count-change``, ``outage``, ``weak-signal``).

Each run builds its scenario from a base scenario (default ``signals/default.toml``, the
paper-004 scenario) plus an outage/attenuation schedule (``[[outage]]`` entries of the
scenario schema), generates the IF, IMU and truth files once into a private temporary folder
(never into the run's output folder: the IF file is large and would travel back with the
result), and runs every receiver variant on those same files.

The receivers search only the simulated PRNs (read from the generated sidecar), so start-up
time is spent on tracking, not on searching 63 codes; the deep receiver gets the ephemeris
file as assistance, as ``sdr-di run --mode deep`` does.
"""

from __future__ import annotations

import contextvars
import dataclasses
import fcntl
import hashlib
import json
import math
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ExperimentError, ScenarioError
from ..receiver.scalar import ScalarReceiver
from ..scenario import DEFAULT_SCENARIO, Scenario, load_scenario, parse_scenario
from .filter_figures import QUANTITIES

__all__ = [
    "FILE_CACHE",
    "CountingScalarReceiver",
    "DeepRun",
    "Inputs",
    "base_scenario",
    "check_number",
    "file_keys",
    "generated_inputs",
    "has_mean",
    "nested_assumptions",
    "parse_assume",
    "parse_list",
    "ranked_prns",
    "record_run",
    "run_deep_variant",
    "segment_metrics",
    "with_outages",
    "with_truth",
]



def has_mean(st: Any) -> bool:
    """True for a numeric figure's statistics (``aggregate`` gives text figures as
    ``{"value": ...}``)."""
    return isinstance(st, dict) and "mean" in st


def parse_list(name: str, text: Any, kind: type = float) -> list:
    """``"7,6,5"`` -> ``[7, 6, 5]`` (``kind`` int or float); ExperimentError when malformed."""
    try:
        vals = [kind(v) for v in str(text).replace(" ", "").split(",") if v != ""]
    except ValueError:
        raise ExperimentError(f"{name}={text!r}: expected a comma list of "
                              f"{'integers' if kind is int else 'numbers'}") from None
    if not vals or not all(math.isfinite(v) for v in vals):
        raise ExperimentError(f"{name}={text!r}: expected a non-empty comma list of finite "
                              "values")
    return vals


def check_number(exp: str, params: dict, key: str, *, lo: float = 0.0, allow_none: bool = False,
                 lo_open: bool = True) -> None:
    """Reject a non-number (or one not above/at ``lo``) in ``params[key]``."""
    v = params[key]
    if v is None and allow_none:
        return
    bad = isinstance(v, (str, bool)) or v is None or not math.isfinite(v)
    if bad or v < lo or (lo_open and v == lo):
        raise ExperimentError(f"{exp}: {key}={v!r}: expected a number {'>' if lo_open else '>='}"
                              f" {lo:g}")


def base_scenario(params: dict, seed: int, duration_s: float) -> Scenario:
    """The experiment's base scenario with seed, duration, sample rate and C/N0 applied,
    then the truth overrides of ``params["truth"]`` (:func:`with_truth`) when given."""
    path = Path(str(params["scenario"])) if params.get("scenario") else DEFAULT_SCENARIO
    sc = load_scenario(path)
    sc = sc.with_overrides(seed=int(seed), duration_s=float(duration_s),
                           sampling_rate_hz=params.get("sampling_rate_hz"),
                           cn0_dbhz=params.get("cn0_dbhz"))
    return with_truth(sc, params.get("truth") or {})


def check_truth(params: dict) -> None:
    """Apply the truth keys of ``params["truth"]`` to the scenario its runs start from, now:
    a study spec's cell with a key or value the scenario schema rejects is refused when the
    spec is read, not by each of its runs (:func:`with_truth`).

    Raises
    ------
    ScenarioError
        Naming the truth key's table and key, with the scenario file in brackets.
    ExperimentError
        A key that is neither ``outage`` nor ``table.key``.
    """
    truth = params.get("truth")
    if not isinstance(truth, dict) or not truth:
        return
    path = Path(str(params["scenario"])) if params.get("scenario") else DEFAULT_SCENARIO
    sc = load_scenario(path)
    try:
        with_truth(sc, truth)
    except ScenarioError as exc:     # the key is the cell's, not the scenario file's
        raise ScenarioError(f"truth {str(exc).removeprefix(f'{sc.source}: ')} (scenario "
                            f"{path})") from None


def with_truth(sc: Scenario, truth: dict) -> Scenario:
    """``sc`` with scenario keys set: ``{"imu.accel_random_walk_mps_sqrth": 0.5}`` sets
    ``[imu] accel_random_walk_mps_sqrth``; ``{"outage": [...]}`` appends ``[[outage]]``
    tables (``docs/scenario.md``). The result is validated as a scenario file is.

    Raises
    ------
    ScenarioError
        A key or value the scenario schema rejects.
    ExperimentError
        A key that is neither ``outage`` nor ``table.key``.
    """
    if not truth:
        return sc
    raw = json.loads(json.dumps(sc.raw, default=str))
    outages = []
    for key, value in truth.items():
        if key == "outage":
            outages = list(value)
            continue
        table, dot, name = str(key).partition(".")
        if not dot or not table or not name or "." in name:
            raise ExperimentError(f"truth key {key!r}: expected 'outage' or 'table.key' of the "
                                  "scenario schema (e.g. imu.accel_random_walk_mps_sqrth)")
        if not isinstance(raw.get(table, {}), dict):
            raise ExperimentError(f"truth key {key!r}: [{table}] is not a table")
        raw.setdefault(table, {})[name] = value
    base = sc.source.parent if sc.source is not None else None
    sc = parse_scenario(raw, source=sc.source, base_dir=base)
    return with_outages(sc, outages) if outages else sc


def nested_assumptions(assume: dict) -> dict:
    """``{"imu.accel_bias_mg": 8}`` -> ``{"imu": {"accel_bias_mg": 8}}``: an experiment's
    flat ``assume`` dict (dotted ``table.key``) as the tables of an assumptions file
    (``docs/assumptions.md``); a value that is already a table is kept as one."""
    out: dict = {}
    for key, value in assume.items():
        table, dot, name = str(key).partition(".")
        if dot:
            out.setdefault(table, {})[name] = value
        else:
            out.setdefault(table, {}).update(value if isinstance(value, dict) else {})
            if not isinstance(value, dict):
                raise ExperimentError(f"assume key {key!r}: expected table.key (e.g. "
                                      "imu.accel_random_walk_mps_sqrth) or a table")
    return out


def parse_assume(assume: dict | None, source: str = "assume"):
    """The filter's assumptions of an experiment's ``assume`` dict (``None`` when empty).

    Raises
    ------
    AssumptionsError
        What :func:`~sdr_di.integration.assumptions.parse_assumptions` rejects.
    """
    if not assume:
        return None
    from ..integration.assumptions import parse_assumptions

    return parse_assumptions(nested_assumptions(assume), source=source)


def with_outages(sc: Scenario, outages: list[dict]) -> Scenario:
    """``sc`` with ``outages`` (``[[outage]]`` tables of ``docs/scenario.md``) appended."""
    raw = json.loads(json.dumps(sc.raw, default=str))
    raw["outage"] = list(raw.get("outage", [])) + [dict(o) for o in outages]
    base = sc.source.parent if sc.source is not None else None
    return parse_scenario(raw, source=sc.source, base_dir=base)


def ranked_prns(sc: Scenario) -> list[int]:
    """The PRNs the generator will simulate, highest elevation at the start first.

    An explicit ``prns`` list keeps its order.
    """
    from ..orbits.rinex_nav import load_nav
    from ..sim.generate import simulate_truth
    from ..sim.geometry import ReceiverPath
    from ..sim.ifgen import select_satellites

    truth = simulate_truth(sc)
    path = ReceiverPath(truth.t, truth.r_e, truth.v_e)
    return [c[0] for c in select_satellites(sc, load_nav(sc.satellites.ephemeris), path, None)]


@dataclasses.dataclass
class Inputs:
    """Generated files of one run, opened."""

    source: Any
    imu: Any
    truth: Any
    nav: Any
    prns: list[int]
    paths: dict
    #: kept starts, by hand-over rule (:func:`run_deep_variant`): deep start-up states at the
    #: hand-over (``DeepStart``) and loose/tight scalar runs (``ScalarRecord``)
    starts: dict = dataclasses.field(default_factory=dict)
    #: the ephemeris file ``nav`` was read from (identifies the assistance data of a start-up
    #: shared between tasks: :func:`shared_start`)
    nav_path: Path | None = None


#: Folder of the generated-file cache of the current task (``None``: generate into a private
#: temporary folder and delete it after the run). Set by a study for its tasks.
FILE_CACHE: contextvars.ContextVar[Path | None] = contextvars.ContextVar("FILE_CACHE",
                                                                        default=None)

#: Scenario tables the files never depend on (the filter's beliefs).
_NOT_GENERATED = ("assume",)
#: Scenario tables the IMU file depends on (the IF file depends on all but ``imu``).
_IMU_TABLES = ("scenario", "time", "start", "motion", "imu")


def _key(raw: dict) -> str:
    canon = json.dumps(raw, sort_keys=True, default=str).encode()
    return hashlib.sha256(canon).hexdigest()[:16]


def file_keys(sc: Scenario) -> tuple[str, str]:
    """Cache keys (hex) of the IF file (with truth and sidecar) and of the IMU file of ``sc``.

    Each is a hash of only the scenario keys its file depends on: the IF file of everything
    but the ``[imu]`` errors (so scenarios that differ in IMU errors share it; the IMU rate
    stays, it samples the truth trajectory), the IMU file of
    the seed, duration, epoch, start state, motion and ``[imu]``; neither of the filter's
    assumptions. The scenario name is left out (it names files, it does not change them).
    """
    raw = {k: v for k, v in sc.raw.items() if k not in _NOT_GENERATED}
    raw = json.loads(json.dumps(raw, default=str))
    raw.get("scenario", {}).pop("name", None)
    raw.setdefault("satellites", {})["ephemeris"] = str(sc.satellites.ephemeris)
    if_raw = {k: v for k, v in raw.items() if k != "imu"}
    # the truth trajectory is sampled at the IMU rate, and the IF follows the truth
    if_raw["imu.rate_hz"] = raw.get("imu", {}).get("rate_hz")
    imu_raw = {k: raw[k] for k in _IMU_TABLES if k in raw}
    return _key(if_raw), _key(imu_raw)


def _cached_files(sc: Scenario, cache: Path) -> dict:
    """The files of ``sc`` from ``cache``, generating what is missing (module notes of
    :data:`FILE_CACHE`). Workers on one host take turns on an IF file (a lock file); each
    generates into a folder of its own, renamed into place when complete."""
    import shutil
    import uuid

    from ..io.imu_files import write_imu
    from ..sim.generate import generate_files, imu_model, simulate_truth

    cache = Path(cache)
    cache.mkdir(parents=True, exist_ok=True)
    k_if, k_imu = file_keys(sc)
    if_dir = cache / f"s{sc.seed}-if-{k_if}"
    imu_path = cache / f"s{sc.seed}-imu-{k_imu}.csv"
    # one generator per file: a worker that finds another generating the same IF file
    # waits for it (an advisory lock beside the file) instead of generating it twice
    with open(cache / f"s{sc.seed}-if-{k_if}.lock", "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not (if_dir / "files.json").is_file():
            tmp = cache / f"tmp-{uuid.uuid4().hex}"
            paths = generate_files(sc, tmp, name="run", progress=False)
            if not imu_path.exists():
                os.replace(paths["imu"], imu_path)
            (tmp / "files.json").write_text(json.dumps({k: Path(v).name
                                                        for k, v in paths.items()}))
            try:
                os.rename(tmp, if_dir)
            except OSError:         # a worker without the lock (other host) came first
                shutil.rmtree(tmp, ignore_errors=True)
    names = json.loads((if_dir / "files.json").read_text())
    paths = {k: if_dir / v for k, v in names.items()}
    if not imu_path.exists():
        # the IMU record of generate_files (same truth, same seed stream), alone
        truth = simulate_truth(sc)
        rng = np.random.default_rng(np.random.SeedSequence([sc.seed, 0x1A0]))
        tmp = cache / f"tmp-{uuid.uuid4().hex}.csv"
        write_imu(tmp, imu_model(sc).apply(truth, rng), week=sc.week, sow=sc.sow)
        os.replace(tmp, imu_path)
    paths["imu"] = imu_path
    return paths


#: Deep start-ups kept between the tasks of this process (:func:`shared_start`): at most
#: this many, the latest.
SHARED_STARTS = 2
_shared: list[tuple[tuple, Any]] = []


def _file_identity(inputs: Inputs) -> tuple | None:
    """What a deep start-up read besides its own key (:class:`~sdr_di.integration.receiver.
    DeepStart`): the IF file and the assistance ephemeris file, by path, size and
    modification time; None when the run's files are not in a :data:`FILE_CACHE` (private
    files, deleted after the run: nothing to share)."""
    if FILE_CACHE.get() is None or inputs.nav_path is None:
        return None
    try:
        return tuple((str(Path(p).resolve()), st.st_size, st.st_mtime_ns)
                     for p in (inputs.paths["if"], inputs.nav_path)
                     for st in (os.stat(p),))
    except (OSError, KeyError):
        return None


def shared_start(inputs: Inputs, rule: tuple) -> Any:
    """A deep start-up made by an earlier task of this process on the same IF and ephemeris
    files with hand-over rule ``rule``, or None.

    The cells of a study that differ only in the IMU (truth IMU errors, the filter's
    assumptions) share their IF file (:func:`file_keys`), and the deep start-up does not
    read the IMU, so consecutive tasks of one seed run it once. On a hit, ``inputs.nav``
    becomes the start-up's navigation data (read from the same file) so that the run takes
    the same object the start-up did; the start-up's own key (samples, PRNs, span, rule)
    is still checked by the receiver."""
    ident = _file_identity(inputs)
    if ident is None:
        return None
    for (k_ident, k_rule), start in reversed(_shared):
        if k_ident == ident and k_rule == rule:
            inputs.nav = start.nav
            return start
    return None


def _keep_shared(inputs: Inputs, rule: tuple, start: Any) -> None:
    ident = _file_identity(inputs)
    if ident is None or SHARED_STARTS < 1:
        return
    kept = [e for e in _shared if e[0] != (ident, rule)]
    _shared[:] = kept[max(len(kept) - (SHARED_STARTS - 1), 0):] + [((ident, rule), start)]


class generated_inputs:
    """Context manager: generate ``sc`` (or take it from the task's :data:`FILE_CACHE`),
    yield :class:`Inputs`; a private temporary folder is deleted on exit."""

    def __init__(self, sc: Scenario):
        self.sc = sc
        self._tmp: tempfile.TemporaryDirectory | None = None

    def __enter__(self) -> Inputs:
        from ..io.imu_files import read_imu, read_truth
        from ..orbits.rinex_nav import load_nav
        from ..receiver.run_scalar import open_source
        from ..sim.generate import generate_files

        cache = FILE_CACHE.get()
        if cache is not None:
            paths = _cached_files(self.sc, cache)
            return self._open(paths, open_source, read_imu, read_truth, load_nav)
        self._tmp = tempfile.TemporaryDirectory(prefix="sdr_di_exp_")
        try:
            paths = generate_files(self.sc, self._tmp.name, progress=False)
            return self._open(paths, open_source, read_imu, read_truth, load_nav)
        except BaseException:
            self._tmp.cleanup()
            raise

    def _open(self, paths, open_source, read_imu, read_truth, load_nav) -> Inputs:
        meta = json.loads(Path(paths["metadata"]).read_text(encoding="utf-8"))
        prns = [int(s["prn"]) for s in meta["satellites"]]
        return Inputs(source=open_source(paths["if"]), imu=read_imu(paths["imu"]),
                      truth=read_truth(paths["truth"])[0],
                      nav=load_nav(self.sc.satellites.ephemeris), prns=prns, paths=paths,
                      nav_path=Path(self.sc.satellites.ephemeris))

    def __exit__(self, *exc) -> None:
        if self._tmp is not None:
            self._tmp.cleanup()


class CountingScalarReceiver(ScalarReceiver):
    """Scalar receiver that records the first sample of every acquisition search it runs.

    The deep receiver is given one of these as its start-up receiver, so an experiment can
    show from the record (not from reading the code) that no acquisition search ran after
    the hand-over.
    """

    def __init__(self, *args, **kw):
        super().__init__(*args, **kw)
        self.acquisition_samples: list[int] = []

    def _acquire(self, source, sample, prns, **over):
        self.acquisition_samples.append(int(sample))
        return super()._acquire(source, sample, prns, **over)


@dataclasses.dataclass
class DeepRun:
    """One deep run: the result (None when it failed), its error and acquisition record."""

    filter: str
    result: Any
    error: str | None
    acq_after_handover: int


#: The experiments' parameters that only deep variants take (:func:`run_deep_variant`
#: leaves them out of loose and tight ones).
DEEP_ONLY = ("nco_latency", "deep_measurements", "fusion_rate_hz")


def run_deep_variant(inputs: Inputs, filter_name: str, *, mode: str = "deep",
                     assume: dict | None = None, **config: Any) -> DeepRun:
    """Run :class:`~sdr_di.integration.receiver.IntegratedReceiver` with ``filter_name`` in
    ``mode`` on ``inputs``.

    ``mode`` (``"loose"``, ``"tight"``, ``"deep"``) is the receiver's coupling
    (``IntegrationConfig.mode``); ``"deep"`` is the configuration's default and is not passed, so
    the call also works with a receiver that predates the modes. ``assume`` is the filter's
    assumptions (an experiment's ``assume`` dict, :func:`parse_assume`), applied to the
    configuration as ``--assume`` is. ``config`` are further
    :class:`~sdr_di.integration.receiver.IntegrationConfig` fields; ``nco_latency``,
    ``deep_measurements`` and ``fusion_rate_hz`` (:data:`DEEP_ONLY`) go to deep
    variants only (loose and tight have no NCOs to command), so one experiment can set them
    for its deep variants beside loose or tight ones.

    Deep mode runs the scalar start-up once per ``inputs`` and hand-over rule: the first
    run keeps its state at the hand-over (``inputs.starts``) and the next ones continue
    from a copy of it, with the same results as their own start-up would give
    (:class:`~sdr_di.integration.receiver.DeepStart`); a study's filters on one file share
    it, and so do the next tasks of this process on the same files (:func:`shared_start`:
    a study's cells that differ only in the IMU). Loose and tight likewise run the scalar
    receiver once (either mode's run serves both: it gets no feedback) and the other
    filters' loops over its recorded epochs
    (:class:`~sdr_di.integration.receiver.ScalarRecord`).

    Exceptions of the package (:class:`~sdr_di.errors.SdrDiError`) and numerical failures
    (``ValueError``, ``FloatingPointError``, ``numpy.linalg.LinAlgError``) are returned as
    ``error`` text, not raised: a filter that fails is a result of the experiment.
    """
    from ..errors import SdrDiError
    from ..integration.settings import build_integration_config
    from ..integration.receiver import IntegratedReceiver, StartMismatchError

    if mode != "deep":
        config["mode"] = mode
        for key in DEEP_ONLY:
            config.pop(key, None)
    scalar = CountingScalarReceiver(log=False)
    try:
        cfg = build_integration_config(filter_name, assume=parse_assume(assume), **config)
        # the start-up (deep) or the whole scalar run (loose and tight: either mode's
        # serves both) is made once per hand-over rule and kept
        rule = (cfg.handover_wait_s, cfg.iono_wait_s) if cfg.mode == "deep" else \
            ("scalar", cfg.handover_wait_s, cfg.iono_wait_s, cfg.gnss_every)
        start = inputs.starts.get(rule)
        shared = None
        if start is None:
            shared = start = shared_start(inputs, rule)

        def run(rx, start):
            return rx.run(inputs.source, inputs.imu, prns=inputs.prns, nav=inputs.nav,
                          truth=inputs.truth, start=start, keep_start=start is None)

        rx = IntegratedReceiver(cfg, scalar=scalar)
        try:
            try:
                res = run(rx, start)
            except StartMismatchError:
                if shared is None:
                    raise
                # another task's start-up on these files, but of another span, PRNs or
                # assistance (refused before any work, the receiver untouched): this run
                # makes its own
                shared = None
                res = run(rx, None)
        finally:          # kept also when this filter fails after the hand-over
            made = rx.deep_start if rx.deep_start is not None else rx.scalar_record
            if made is not None:
                inputs.starts[rule] = made
                _keep_shared(inputs, rule, made)
            elif shared is not None:   # this task's next filters continue from it too
                inputs.starts[rule] = shared
    except (SdrDiError, ValueError, FloatingPointError, np.linalg.LinAlgError) as exc:
        return DeepRun(filter_name, None, f"{type(exc).__name__}: {exc}", -1)
    k_h = round(res.handover_s * inputs.source.sampling_rate_hz)
    # the start-up receiver that ran this run's hand-over (a copy of it when resumed)
    after = sum(1 for s in rx.scalar.acquisition_samples if s >= k_h)
    return DeepRun(filter_name, res, None, after)


def record_run(fig: dict, name: str, dr: DeepRun) -> Any:
    """Figures every deep experiment records for one filter run, into ``fig``.

    ``<name>.completed`` (1 when every error row is finite), and either ``<name>.error``
    (the run failed: returns None) or ``<name>.handover_s`` and
    ``<name>.acq_after_handover`` (returns the
    :class:`~sdr_di.integration.receiver.IntegrationResult`).
    """
    res = dr.result
    if res is None:
        fig[f"{name}.completed"] = 0
        fig[f"{name}.error"] = dr.error
        return None
    finite = bool(res.t.size) and all(
        np.all(np.isfinite(getattr(res, a))) for a in ("att_err", "vel_err", "pos_err"))
    fig[f"{name}.completed"] = int(finite)
    fig[f"{name}.handover_s"] = float(res.handover_s)
    fig[f"{name}.acq_after_handover"] = dr.acq_after_handover
    return res


def consistency_figures(res: Any, t0: float | None, t1: float | None, prefix: str) -> dict:
    """``{prefix}nis_<block>`` and ``{prefix}nees_<q>`` of a result over ``t0 <= t <= t1``:
    the means of its :meth:`~sdr_di.integration.receiver.IntegrationResult.consistency` entry (NaN
    without samples), and ``{prefix}nis_dof``: the degrees of freedom of one NIS sample of a
    block (the median block size over the window; NaN without updates), which a study needs
    for the chi-square band of its ensemble average (:mod:`sdr_di.studies.ensemble`)."""
    from ..integration.consistency import flat

    c = res.consistency(t0, t1)
    out = {f"{prefix}{k}": v for k, v in flat(c).items()}
    nis = [v for k, v in c.items() if k.startswith("nis_") and isinstance(v, dict) and v["n"]]
    out[f"{prefix}nis_dof"] = float(nis[0]["dof"]) if nis else math.nan
    return out


def segment_metrics(res: Any, t0: float | None, t1: float | None, prefix: str) -> dict:
    """``{prefix}{q}_{rmse,max}`` of a result's error norms over ``t0 <= t < t1``."""
    from ..integration.metrics import rmse_max

    t = np.asarray(res.t, float)
    sel = np.ones(t.size, bool)
    if t0 is not None:
        sel &= t >= t0
    if t1 is not None:
        sel &= t < t1
    out = {}
    for q, _ in QUANTITIES:
        e = np.asarray(getattr(res, f"{q[:3]}_err"), float)[sel]
        r, m = rmse_max(e)
        out[f"{prefix}{q}_rmse"] = r
        out[f"{prefix}{q}_max"] = m
    return out
