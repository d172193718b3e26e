"""``sdr-di run --mode deep|loose|tight``: IF file + IMU file -> receiver -> solution files.

The mode is ``IntegrationConfig.mode`` (:mod:`~sdr_di.integration.receiver`): deep, or
loose / tight on the scalar receiver's own fixes / observables (docs/coupling.md); every
mode writes the same files under its own name (``MODE`` below: ``deep``, ``loose`` or ``tight``).

Companion files default to the ones the IF file's sidecar names (``imu_file``,
``truth_file``, ``ephemeris_file``, relative to the sidecar): the IMU record (required), the
reference trajectory (for ``align="truth"`` and the error columns) and the RINEX navigation
file used as assistance data (ephemerides and ionosphere before they are decoded; the
decoded records take precedence; ``assist=False`` uses decoded messages only).

Outputs in ``out_dir`` (``STEM`` = IF file name without extension), written under temporary
names and renamed when complete:

``STEM_MODE.csv``          one row per output epoch (``docs/deep.md``); ``nav_change``
                           marks the rows where the loop took up navigation data since
                           the previous row: 1 an ephemeris, 2 the ionosphere model, 3 both;
                           the clock columns hold the filter's clock states (loose: the
                           latest WLS fix's clock, docs/coupling.md)
``STEM_MODE_summary.json`` mode, filter, hand-over time, channels, error metrics vs the
                           reference, ``consistency`` (NIS per measurement block and NEES
                           per quantity over the metrics' window, expected value 1, with
                           a band: :mod:`~sdr_di.integration.consistency`),
                           time shares of the loop stages, ``navigation`` (per satellite
                           the ephemeris source and toe over time, the ionosphere and
                           troposphere models and their sources), ``warnings``,
                           ``truth`` (from the sidecar: scenario, receiver clock,
                           oscillator, IMU spec) and ``assumptions`` (what the filter
                           believed: :func:`~sdr_di.integration.assumptions.deep_beliefs`)
``STEM_MODE_channels.csv`` one row per output epoch: ``t_s`` and, per channel ``Cxx``,
                           ``cn0_Cxx`` [dB-Hz] and ``used_Cxx`` (1: in the measurement
                           vector / fix at the row, 0: not); deep and tight also
                           ``innov_<block>_Cxx`` (blocks of NIS_BLOCKS): the normalized
                           innovation ``y_i / sqrt(S_ii)`` of the channel's measurements
                           at the row's last update
``STEM_MODE_nis.csv``      one row per filter update: ``t_s``, the NIS per degree of
                           freedom of each measurement block (``nis_<block>``,
                           :data:`~sdr_di.integration.consistency.NIS_BLOCKS`) and
                           ``dof``, the block size (the per-update samples the summary's
                           ``consistency`` averages; ``sdr-di report`` draws them)

Warnings of the run (:class:`~sdr_di.receiver.navdata.NavDataWarning`: no ionosphere model
at the hand-over) are printed as one ``sdr-di: warning: ...`` line each on stderr and kept
in the summary.
"""

from __future__ import annotations

import dataclasses
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from ..errors import ImuDataError
from ..integration.assumptions import deep_beliefs, sidecar_truth
from ..ins.truth import Truth
from ..integration.consistency import NIS_BLOCKS, SD_COLUMNS
from ..io.atomic import atomic_open, ensure_output_dir
from ..io.json_values import json_safe
from ..io.sidecar import companion_files
from ..receiver.ifreader import IfSource
from ..receiver.navdata import NavDataWarning
from ..receiver.run_scalar import search_assistance
from ..receiver.scalar import ScalarReceiver
from ..receiver.tracking import TrackingConfig
from .receiver import IntegrationConfig, IntegratedReceiver, IntegrationResult, check_imu_span

#: The filter whose runs keep the plain names ``STEM_MODE.csv`` (:func:`solution_names`).
DEFAULT_FILTER = IntegrationConfig.filter

__all__ = ["SOLUTION_COLUMNS", "IntegratedRunSummary", "companion_files", "run_integrated",
           "write_channel_series", "write_nis_series", "write_solution_csv"]

SOLUTION_COLUMNS = (
    "t_s", "bdt_week", "bdt_sow", "lat_deg", "lon_deg", "h_m", "v_e", "v_n", "v_u",
    "pitch_deg", "roll_deg", "yaw_deg", "clock_bias_m", "clock_drift_mps", "n_used",
    "att_err_e_deg", "att_err_n_deg", "att_err_u_deg", "vel_err_e", "vel_err_n", "vel_err_u",
    "pos_err_e_m", "pos_err_n_m", "pos_err_u_m", "iono", "nav_change", *SD_COLUMNS,
)


@dataclasses.dataclass
class IntegratedRunSummary:
    """What an integrated run (deep, loose or tight) produced."""

    files: dict
    result: IntegrationResult
    metrics: dict
    wall_s: float
    #: first row with an ionosphere model after rows without one (None: every row had it)
    iono_from_s: float | None = None
    #: ``metrics`` over the rows from ``iono_from_s`` on (None when it is None)
    metrics_after_iono: dict | None = None
    #: why ``metrics`` are null (:func:`metrics_note`; None when they are not)
    metrics_note: str | None = None


def iono_in_force(res: IntegrationResult) -> np.ndarray:
    """``(n,)`` 1 where an ionosphere model (Klobuchar) was in force at the row, 0 where the
    run had none yet (handed over before subframe 1 was decoded, ``iono_wait_s``): from the
    summary's ionosphere history (deep: ``navigation.ionosphere.history``; loose and tight:
    ``navigation.ionosphere``), the entry in force at each row's time."""
    ion = res.navigation.get("ionosphere") if isinstance(res.navigation, dict) else None
    hist = ion.get("history", []) if isinstance(ion, dict) else ion or []
    if not hist:
        return np.ones(res.t.size)        # no record: nothing to flag
    t_h = np.array([h["t_s"] for h in hist], float)
    on = np.array([h.get("model") == "klobuchar" for h in hist], float)
    # an entry is written at the row that takes it up (t_s rounded to the ms)
    k = np.searchsorted(t_h, np.asarray(res.t, float) + 1e-3, side="right") - 1
    return on[np.clip(k, 0, None)]


def iono_take_up_s(res: IntegrationResult) -> float | None:
    """Time [s] of the first row with an ionosphere model after rows without one, None when
    every row had it (or none had)."""
    on = iono_in_force(res)
    if on.size == 0 or on[0] == 1.0 or not on.any():
        return None
    return float(res.t[int(np.argmax(on))])


def write_solution_csv(path: Path, res: IntegrationResult) -> Path:
    """Write the solution rows (atomic)."""
    data = np.column_stack([
        res.t, np.full(res.t.size, res.week), res.sow, np.degrees(res.llh[:, :2]),
        res.llh[:, 2], res.v_n, np.degrees(res.att), res.clock_bias_m, res.clock_drift_mps,
        res.n_used, res.att_err, res.vel_err, res.pos_err, iono_in_force(res),
        res.nav_change if res.nav_change.size == res.t.size else np.zeros(res.t.size),
        res.sd if res.sd.shape[0] == res.t.size else np.full((res.t.size, 9), np.nan)]) \
        if res.t.size else np.zeros(
        (0, len(SOLUTION_COLUMNS)))
    label = (res.filter_used or {}).get("spec", res.filter_name)  # name:options as run
    with atomic_open(path, "w") as fh:
        # the measurement architecture is named when it is not paper 004's cascade (whose
        # files keep their earlier header)
        arch = res.deep_measurements
        arch = "" if arch in (None, "prefilter") else f", measurements {arch}"
        fh.write(f"# sdr-di {res.mode} solution, filter {label}{arch}, hand-over at "
                 f"{res.handover_s:.3f} s, channels {' '.join(f'C{p:02d}' for p in res.prns)}\n")
        fh.write(",".join(SOLUTION_COLUMNS) + "\n")
        np.savetxt(fh, data, delimiter=",", fmt="%.12g")
    return path


def write_channel_series(path: Path, res: IntegrationResult) -> Path:
    """Write ``STEM_MODE_channels.csv``: per output row, each channel's C/N0 [dB-Hz] and
    whether it was in the measurement vector (atomic)."""
    n, n_ch = res.t.size, len(res.prns)
    cn0 = res.cn0_dbhz if res.cn0_dbhz.shape == (n, n_ch) else np.full((n, n_ch), np.nan)
    used = res.used if res.used.shape == (n, n_ch) else np.zeros((n, n_ch), bool)
    names = [f"C{int(p):02d}" for p in res.prns]
    cols = ["t_s", *(f"cn0_{c}" for c in names), *(f"used_{c}" for c in names)]
    data = [res.t, cn0, used.astype(float)]
    innov = np.asarray(res.innov, float)
    if innov.shape == (n, 2 * n_ch) and np.isfinite(innov).any():
        cols += [f"innov_{b}_{c}" for b in NIS_BLOCKS[res.mode] for c in names]
        data.append(innov)
    with atomic_open(path, "w") as fh:
        fh.write(f"# sdr-di {res.mode} channels: C/N0 [dB-Hz], used (1 in the measurement "
                 "vector) and, deep and tight, the normalized innovation y_i/sqrt(S_ii) of each "
                 "measurement at the row's last update, per channel and output row\n")
        fh.write(",".join(cols) + "\n")
        np.savetxt(fh, np.column_stack(data).reshape(n, -1), delimiter=",", fmt="%.10g")
    return path


def write_nis_series(path: Path, res: IntegrationResult) -> Path:
    """Write ``STEM_MODE_nis.csv``: per filter update, the NIS per degree of freedom of each
    measurement block and the block size (atomic)."""
    up = res.updates or {}
    t = np.asarray(up.get("t", np.zeros(0)), float)
    nis = np.asarray(up.get("nis", np.zeros((0, 2))), float).reshape(-1, 2)
    dof = np.asarray(up.get("dof", np.zeros(0)), float)
    blocks = NIS_BLOCKS.get(res.mode, ("a", "b"))
    with atomic_open(path, "w") as fh:
        fh.write(f"# sdr-di {res.mode} NIS per degree of freedom of each measurement block "
                 "at each filter update; dof = block size\n")
        fh.write(",".join(["t_s", *(f"nis_{b}" for b in blocks), "dof"]) + "\n")
        np.savetxt(fh, np.column_stack([t, nis, dof]).reshape(t.size, 4), delimiter=",",
                   fmt="%.10g")
    return path


def _progress_stage(mode: str, n_channels: int, n_used: int | None) -> str:
    """What the run is doing, for its progress bar."""
    if n_used is None:
        return f"scalar start-up, {n_channels} tracked"
    if mode == "deep":
        return f"{n_used}/{n_channels} in the vector"
    if mode == "loose":
        return f"WLS fixes of {n_channels} satellites into the filter"
    return f"ranges and rates of {n_used} satellites into the filter"


class ReferenceGridWarning(UserWarning):
    """The reference file's rate differs from the IMU's: taken at the IMU's times."""


def reference_on_imu_grid(truth, imu, truth_path) -> Truth:
    """The reference at the IMU's sample times, on which the loop writes its error columns
    (issue 49 item 7: a 50 Hz IMU beside a 200 Hz reference gave every error column NaN and
    null metrics, in silence). The same grid: as is. A reference holding every IMU time: its
    rows at those times (with one warning when its rate differs). Otherwise refused.

    Raises
    ------
    ImuDataError
        Some IMU time is not a sample of the reference.
    """
    if len(truth.t) == len(imu.t) and np.allclose(truth.t, imu.t, atol=1e-6):
        return truth
    on = truth.at_times(imu.t)
    if on is None:
        raise ImuDataError(
            f"reference {truth_path} ({truth.rate_hz:g} Hz) does not hold the IMU's sample "
            f"times ({imu.rate_hz:g} Hz, {imu.t[0]:g}..{imu.t[-1]:g} s): the error columns "
            "need the reference at every IMU time (a reference at a multiple of the IMU "
            "rate, covering its span)")
    if abs(imu.rate_hz - truth.rate_hz) > 1e-9 * truth.rate_hz:  # same rate, other span: quiet
        warnings.warn(f"IMU at {imu.rate_hz:g} Hz, reference {truth_path} at "
                      f"{truth.rate_hz:g} Hz: the errors are taken at the IMU's times",
                      ReferenceGridWarning, stacklevel=3)
    return on


def metrics_note(metrics: dict, truth_path) -> str | None:
    """Why a run's error metrics are null (None when they are not): no reference, or no
    row after the hand-over with a finite error."""
    if metrics.get("n") and metrics.get("pos_m_rmse") == metrics.get("pos_m_rmse"):
        return None
    if truth_path is None:
        return "no reference file (--truth, or the sidecar's truth_file): no errors computed"
    if not metrics.get("n"):
        return "no solution row after the hand-over: no errors computed"
    return (f"the reference {truth_path} gave no finite error on the {metrics['n']} rows "
            "after the hand-over")


def solution_names(out_dir: Path, stem: str, cfg: IntegrationConfig) -> dict[str, Path]:
    """The files of an integrated run: ``STEM_MODE.csv``, ``STEM_MODE_summary.json``,
    ``STEM_MODE_channels.csv`` and ``STEM_MODE_nis.csv`` with the default filter,
    ``STEM_MODE_FILTER...`` with any other, so that runs of two filters into one folder
    never share a file (issue 49 item 13)."""
    from ..paths import file_safe

    tag = cfg.mode if cfg.filter == DEFAULT_FILTER else f"{cfg.mode}_{file_safe(cfg.filter)}"
    return {"solution": out_dir / f"{stem}_{tag}.csv",
            "summary": out_dir / f"{stem}_{tag}_summary.json",
            "channels": out_dir / f"{stem}_{tag}_channels.csv",
            "nis": out_dir / f"{stem}_{tag}_nis.csv"}


def run_integrated(source: IfSource, out_dir: str | Path, *,
                   config: IntegrationConfig | None = None,
                   imu_path: str | Path | None = None, truth_path: str | Path | None = None,
                   nav_path: str | Path | None = None, assist: bool = True, prns=None,
                   stem: str | None = None, progress: bool = True,
                   duration_s: float | None = None,
                   search: bool | dict[int, float | None] = True,
                   tracking: TrackingConfig | None = None) -> IntegratedRunSummary:
    """Run the integrated receiver (deep, loose or tight: ``config.mode``) over ``source``
    and write the solution files (module notes).

    ``search`` is the start-up's acquisition assistance, the same rule as scalar mode's
    (:func:`~sdr_di.receiver.run_scalar.search_assistance`: True, the sidecar's list around
    its Dopplers; False, a cold search of ``prns``, default all 63). ``tracking``: the
    start-up scalar receiver's loop settings (default :class:`~sdr_di.receiver.tracking.
    TrackingConfig`; ``sdr-di run --pll-bw``), which also track loose's and tight's
    channels to the end.

    Raises
    ------
    ImuDataError
        No IMU file, bad IMU/truth file, time span or time tags inconsistent with the IF.
    FilterError
        Unknown filter name or option.
    HandoverError
        No satellite found / no hand-over from scalar tracking.
    OutputError
        Outputs cannot be written.
    """
    from ..io.imu_files import read_imu, read_truth
    from ..orbits.rinex_nav import load_nav

    cfg = config or IntegrationConfig()
    comp = companion_files(source, skip=tuple(k for k, p in (("imu", imu_path),
                                                              ("truth", truth_path))
                                              if p is not None))
    imu_path = Path(imu_path) if imu_path is not None else comp["imu"]
    if imu_path is None:
        raise ImuDataError(f"{source.path}: {cfg.mode} mode needs an IMU file (--imu); the "
                           "sidecar names none")
    truth_path = Path(truth_path) if truth_path is not None else comp["truth"]
    if cfg.align == "truth" and truth_path is None:
        raise ImuDataError("align 'truth' needs a reference file (--truth); use --align gnss "
                           "without one")
    imu = read_imu(imu_path)
    truth = read_truth(truth_path)[0] if truth_path is not None else None
    if truth is not None:
        truth = reference_on_imu_grid(truth, imu, truth_path)
    nav = None
    if assist:
        nav_path = Path(nav_path) if nav_path is not None else comp["ephemeris"]
        if nav_path is not None:
            nav = load_nav(nav_path)
    fs = source.sampling_rate_hz
    check_imu_span(source, imu, source.n_samples if duration_s is None else min(
        source.n_samples, round(duration_s * fs)))            # before any output or work
    from ..paths import check_outputs

    files = solution_names(Path(out_dir), stem or source.path.stem, cfg)
    check_outputs(files.values())
    out_dir = ensure_output_dir(out_dir)
    bar = None
    t_wall = time.perf_counter()
    cb = None
    if progress:
        from tqdm import tqdm

        from ..kernel_cache import first_use_note

        total = source.duration_s if duration_s is None else min(source.duration_s,
                                                                  duration_s)
        bar = tqdm(total=round(total, 2), unit="s",
                   desc=f"run {cfg.mode} {cfg.filter}",
                   bar_format="{l_bar}{bar}| {n:.1f}/{total:.1f} s [{elapsed}<{remaining}"
                              "{postfix}]", postfix="; ".join(filter(None, [
                                  "scalar start-up: acquisition", first_use_note()])))

        shown = {"stage": None}

        def cb(done, n_ch, n_used):
            # A new stage is drawn at once; other reports follow tqdm's refresh interval.
            rt = done / max(time.perf_counter() - t_wall, 1e-9)
            stage = _progress_stage(cfg.mode, n_ch, n_used)
            bar.set_postfix_str(f"x{rt:.2f} real time, {stage}", refresh=False)
            bar.update(round(done - bar.n, 3))
            if stage != shown["stage"]:
                shown["stage"] = stage
                bar.refresh()

    try:
        rx = IntegratedReceiver(cfg, scalar=None if tracking is None
                          else ScalarReceiver(config=tracking, log=False))
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", NavDataWarning)
            res = rx.run(source, imu, prns=prns, nav=nav, truth=truth, progress=cb,
                         duration_s=duration_s,
                         assist=search_assistance(source, prns, search))
        if bar is not None:     # the run is done (its last report is up to 1 s before the end)
            bar.update(bar.total - bar.n)
    finally:
        if bar is not None:
            bar.close()
    notes = []
    for w in caught:
        if issubclass(w.category, NavDataWarning):
            notes.append(str(w.message))
            print(f"sdr-di: warning: {w.message}", file=sys.stderr)
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    wall = time.perf_counter() - t_wall
    metrics = res.metrics()
    note = metrics_note(metrics, truth_path)
    if note is not None and truth_path is not None:   # a reference given, no errors: say why
        warnings.warn(f"metrics are null: {note}", ReferenceGridWarning, stacklevel=2)
    t_iono = iono_take_up_s(res)
    m_iono = None if t_iono is None else res.metrics(t0=t_iono)
    write_solution_csv(files["solution"], res)
    write_channel_series(files["channels"], res)
    write_nis_series(files["nis"], res)
    summary = {
        "mode": res.mode, "filter": res.filter_name, "handover_s": res.handover_s,
        "nco_latency": cfg.nco_latency if res.mode == "deep" else None,
        "deep_measurements": cfg.deep_measurements if res.mode == "deep" else None,
        "fusion_rate_hz": (cfg.filter_rate_hz / cfg.fusion_intervals if res.mode == "deep"
                           else None),
        "prns": list(res.prns), "rows": int(res.t.size),
        "channels_always_used": bool(res.used.all()) if res.used.size else False,
        "used_fraction": res.used.mean(axis=0) if res.used.size else [],
        "metrics": metrics,
        "metrics_note": note,
        "consistency": res.consistency(),
        "iono_from_s": t_iono,
        "metrics_after_iono": m_iono,
        "adaptation_s": res.adaptation_s,
        "profile": res.profile,
        "wall_s": wall,
        "navigation": res.navigation,
        "warnings": notes,
        "truth": sidecar_truth(getattr(source, "meta", None)),
        "assumptions": {**deep_beliefs(cfg), "filter": res.filter_used},
    }
    with atomic_open(files["summary"], "w") as fh:   # NaN and inf as null (io.json_values)
        json.dump(json_safe(summary), fh, indent=2)
        fh.write("\n")
    return IntegratedRunSummary(files=files, result=res, metrics=metrics, wall_s=wall,
                                iono_from_s=t_iono, metrics_after_iono=m_iono,
                                metrics_note=note)
