"""The public Python API: :func:`generate`, :func:`run` and :func:`study`.

Each function mirrors one ``sdr-di`` command, option for option (the CLI's ``--duration``
is ``duration_s=``, ``--fs`` is ``sampling_rate_hz=``, and so on; the parameter lists say
which), and calls the internal functions that command calls, so a run from Python writes
the same files as the same run from the shell. Everything else in the package is internal
and may move between releases.

Importing this module (and so ``import sdr_di``) loads nothing but the standard library;
the receiver, the generator and the study machinery are imported on first call.

Examples
--------
>>> import sdr_di
>>> files = sdr_di.generate("signals/out", duration_s=20, sampling_rate_hz=2.5e6)
>>> res = sdr_di.run(files.if_file, mode="deep", filter="ekf")
>>> res.metrics["pos_m_rmse"], res.files["solution"]
>>> st = sdr_di.study("studies/smoke.toml", "out/smoke", runs=2)
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, TypeVar

if TYPE_CHECKING:
    from .studies.spec import StudySpec
    from .studies.study import StudyResult

__all__ = ["GeneratedFiles", "RunResult", "generate", "run", "study"]

F = TypeVar("F", bound=Callable)


def _guarded(func: F) -> F:
    """Run ``func`` inside :func:`sdr_di.io.paths.command_scope` (no output of the call may
    be one of its inputs); the module is imported on the first call, not with ``sdr_di``."""

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        from .io.paths import command_scope

        with command_scope():
            return func(*args, **kwargs)

    return wrapper  # type: ignore[return-value]


#: Receiver modes of :func:`run` (``sdr-di run --mode``).
RUN_MODES = ("scalar", "deep", "loose", "tight")

Mode = Literal["scalar", "deep", "loose", "tight"]
PathLike = str | Path


@dataclasses.dataclass(frozen=True)
class GeneratedFiles:
    """The file set :func:`generate` wrote (one scenario, one seed).

    Attributes
    ----------
    if_file : Path
        IF samples (``NAME.bin``); pass it to :func:`run`.
    imu : Path
        200 Hz IMU record (``NAME_imu.csv``).
    truth : Path
        200 Hz reference trajectory (``NAME_truth.csv``).
    metadata : Path
        Sidecar (``NAME.json``): sample format, start time, satellites, the files above.
    sigmf_data, sigmf_meta : Path or None
        The SigMF pair (``NAME.sigmf-data``, ``NAME.sigmf-meta``) with ``sigmf=True``.
    """

    if_file: Path
    imu: Path
    truth: Path
    metadata: Path
    sigmf_data: Path | None = None
    sigmf_meta: Path | None = None

    @property
    def files(self) -> dict[str, Path]:
        """The paths by the labels ``sdr-di generate`` prints (``if``, ``imu``, ``truth``,
        ``metadata``, and ``sigmf-data``, ``sigmf-meta`` when written): every file."""
        extra = {k: p for k, p in (("sigmf-data", self.sigmf_data),
                                   ("sigmf-meta", self.sigmf_meta)) if p is not None}
        return {"if": self.if_file, "imu": self.imu, "truth": self.truth,
                "metadata": self.metadata, **extra}


@dataclasses.dataclass(frozen=True)
class RunResult:
    """What :func:`run` produced, in any mode.

    Attributes
    ----------
    mode : str
        ``"scalar"``, ``"deep"``, ``"loose"`` or ``"tight"``.
    out_dir : Path
        Output folder.
    files : dict of str to Path
        Output files by label, as ``sdr-di run`` prints them (scalar: ``pvt``, ``nmea``,
        ``channels``, ``summary``, ``rinex_obs``, ``rinex_nav``; integrated modes:
        ``solution``, ``summary``, ``channels``, ``nis``).
    metrics : dict
        Scalar: ``n_epochs``, ``n_fixes``, ``processed_s``. Integrated modes: the error
        figures vs the reference after the hand-over (``att_deg_rmse``, ``att_deg_max``
        [deg], ``vel_mps_rmse``, ``vel_mps_max`` [m/s], ``pos_m_rmse``, ``pos_m_max`` [m],
        ``n`` rows; NaN without a reference) plus ``handover_s`` [s since file start].
    processed_s : float
        Seconds of IF processed.
    wall_s : float
        Wall-clock time of the run [s].
    details : object
        The internal record the run returned
        (:class:`~sdr_di.receiver.run_scalar.RunSummary` or
        :class:`~sdr_di.integration.run_integrated.DeepRunSummary`, whose ``result`` holds
        the solution arrays); internal, may change between releases.
    """

    mode: str
    out_dir: Path
    files: dict[str, Path]
    metrics: dict[str, Any]
    processed_s: float
    wall_s: float
    details: Any = dataclasses.field(repr=False, default=None)


#: Scenario override key -> the argument of :func:`generate` that sets it; an override's bad
#: value is reported under this name (the CLI passes its flags instead, ``_names``).
_GENERATE_ARGUMENTS = {"duration_s": "duration_s", "seed": "seed",
                       "sampling_rate_hz": "sampling_rate_hz", "if_hz": "if_hz",
                       "sample_format": "sample_format", "kind": "sample_format",
                       "quantization_bits": "bits", "cn0_dbhz": "cn0_dbhz",
                       "ephemeris": "ephemeris", "prns": "prns"}


@_guarded
def generate(out: PathLike | None = None, *, scenario: PathLike | None = None,
             name: str | None = None, duration_s: float | None = None,
             seed: int | None = None, sampling_rate_hz: float | None = None,
             if_hz: float | None = None, sample_format: str | None = None,
             bits: int | None = None, cn0_dbhz: float | None = None,
             ephemeris: PathLike | None = None, prns: Sequence[str | int] | None = None,
             progress: bool = False, sigmf: bool = False,
             _names: dict[str, str] | None = None) -> GeneratedFiles:
    """Generate B3I IF samples, 200 Hz IMU data, truth and a sidecar (``sdr-di generate``).

    Parameters
    ----------
    out : path, optional
        Output folder (``--out``; default ``signals/out`` of the repository).
    scenario : path, optional
        Scenario TOML (``--scenario``; default ``signals/default.toml``, paper 004's).
    name : str, optional
        Base name of the files (``--name``; default the scenario's name).
    duration_s : float, optional
        Duration [s] (``--duration``).
    seed : int, optional
        Random seed (``--seed``).
    sampling_rate_hz : float, optional
        Sampling rate [Hz] (``--fs``; the scenario's default is 25 MHz: 2.5 MHz makes files
        ten times smaller and still tracks).
    if_hz : float, optional
        Intermediate frequency [Hz] (``--if``).
    sample_format : str, optional
        ``iq_int8``, ``real_int8``, ``iq_int16``, ``real_int16``, ``iq_int4`` (``--format``).
    bits : int, optional
        Quantization bits (``--bits``).
    cn0_dbhz : float, optional
        C/N0 of every satellite [dB-Hz] (``--cn0``).
    ephemeris : path, optional
        RINEX 3 navigation file (``--ephemeris``).
    prns : sequence of str or int, optional
        Satellites instead of the automatic selection, ``"C21"`` or ``21`` (``--prn``).
    progress : bool
        Show a progress bar (the CLI's default; here off).

    Returns
    -------
    GeneratedFiles

    Raises
    ------
    ScenarioError
        Bad scenario file or override.
    SampleFormatError
        Unknown sample format.
    OutputError
        The files cannot be written (nothing is left under the final names).
    """
    from .errors import ScenarioError, UnknownPrnError
    from .scenario import DEFAULT_SCENARIO, REPO_ROOT, load_scenario
    from .scenario.schema import with_flag_names
    from .sim.generate import generate_files

    sc = load_scenario(scenario or DEFAULT_SCENARIO)
    kind = None
    if sample_format is not None:
        from .io.sample_formats import get_format

        fmt = get_format(sample_format)
        kind = "complex" if fmt.is_complex else "real"
        sample_format = fmt.name
    names = _GENERATE_ARGUMENTS if _names is None else _names
    if prns is not None:   # a repeated PRN: one warning naming the flag (the bad ones: below)
        from .constants import parse_prn, parse_prns

        try:
            for p in prns:
                parse_prn(p)
        except UnknownPrnError:
            pass
        else:
            prns = [f"C{p:02d}" for p in parse_prns(prns, names["prns"])]
    over = dict(
        duration_s=duration_s, seed=seed, sampling_rate_hz=sampling_rate_hz, if_hz=if_hz,
        sample_format=sample_format, kind=kind, quantization_bits=bits, cn0_dbhz=cn0_dbhz,
        ephemeris=ephemeris, prns=None if prns is None else [str(p) for p in prns])
    try:
        sc = sc.with_overrides(**over)
    except (ScenarioError, UnknownPrnError) as exc:  # name the argument given, not the key
        raise with_flag_names(exc, sc, {k: names[k] for k, v in over.items()
                                        if v is not None}) from None
    files = generate_files(sc, REPO_ROOT / "signals" / "out" if out is None else Path(out),
                           name=name, progress=progress, sigmf=sigmf)
    return GeneratedFiles(if_file=files["if"], imu=files["imu"], truth=files["truth"],
                          metadata=files["metadata"], sigmf_data=files.get("sigmf-data"),
                          sigmf_meta=files.get("sigmf-meta"))


@_guarded
def run(if_file: PathLike, *, mode: Mode = "scalar", out: PathLike | None = None,
        prns: Sequence[str | int] | None = None, rate_hz: float = 5.0, cold: bool = False,
        pll_bw_hz: float | None = None,
        approx_pos: tuple[float, float, float] | None = None,
        filter: str | None = None, imu: PathLike | None = None,
        truth: PathLike | None = None, ephemeris: PathLike | None = None,
        assist: bool = True, filter_rate_hz: float | None = None,
        align: Literal["truth", "gnss"] | None = None, duration_s: float | None = None,
        gnss_rate_hz: float | None = None, iono_wait_s: float | None = None,
        assume: PathLike | None = None, nco_latency: int | None = None,
        sampling_rate_hz: float | None = None, if_hz: float | None = None,
        sample_format: str | None = None, rfch: int | None = None, inverted: bool = False,
        start_week: int | None = None, start_sow: float | None = None,
        progress: bool = False) -> RunResult:
    """Run the receiver on an IF file in any mode (``sdr-di run``).

    Parameters
    ----------
    if_file : path
        IF samples (or their ``.json`` sidecar).
    mode : {"scalar", "deep", "loose", "tight"}
        Scalar tracking loops; deep (INS-aided vector tracking); loose or tight (the scalar
        receiver's WLS fixes, or its pseudoranges and rates, into the integration filter)
        (``--mode``).
    out : path, optional
        Output folder (``--out``; default ``<stem>_run/`` beside the IF file).
    prns : sequence of str or int, optional
        PRNs to search, ``"C21"`` or ``21`` (``--prn``; default all 63).
    rate_hz : float
        Solution output rate [Hz] (``--rate``).
    cold : bool
        Cold start: ignore the sidecar's satellites and Dopplers (``--cold``).
    pll_bw_hz : float, optional
        Tracking PLL noise bandwidth once locked [Hz] (``--pll-bw``; default 15).
    approx_pos : (lat_deg, lon_deg, h_m), optional
        Scalar mode with ``ephemeris``: search the satellites visible from this position
        around their predicted Doppler (``--approx-pos``).

    Other Parameters
    ----------------
    filter : str, optional
        Integration filter (``--filter``; default ``ekf``). Integrated modes only, as
        are the parameters down to ``assume``.
    imu, truth, ephemeris : path, optional
        IMU file, reference file, RINEX assistance file (``--imu``, ``--truth``,
        ``--ephemeris``; default the sidecar's).
    assist : bool
        False: decoded ephemerides and ionosphere only (``--no-assist``).
    filter_rate_hz : float, optional
        Integration filter and NCO rate [Hz] (``--filter-rate``; default 50).
    align : {"truth", "gnss"}, optional
        INS initial alignment (``--align``; default ``truth``).
    duration_s : float, optional
        Process only the first seconds of the file (``--duration``).
    gnss_rate_hz : float, optional
        Loose and tight: GNSS measurement rate [Hz], 10 divided by a whole number
        (``--gnss-rate``; default 5).
    iono_wait_s : float, optional
        Seconds the hand-over waits for ionosphere coefficients (``--iono-wait``).
    assume : path, optional
        What the filter believes (``--assume``, docs/assumptions.md).
    nco_latency : {0, 1}, optional
        Deep only: filter intervals between an update and the NCO commands that first use
        it, beyond the next (``--nco-latency``; default 0; docs/deep.md, *NCOs one interval
        ahead*).
    sampling_rate_hz, if_hz, sample_format, rfch, inverted, start_week, start_sow
        A file sdr-di did not write (``--fs``, ``--if``, ``--format``, ``--rfch``,
        ``--inverted``, ``--start-week``, ``--start-sow``).
    progress : bool
        Show a progress bar (the CLI's default; here off).

    Returns
    -------
    RunResult

    Raises
    ------
    ValueError
        Options that do not fit together or out of range (the CLI's one-line usage errors).
    SampleFormatError
        Missing or inconsistent sidecar, bad file options.
    ImuDataError, FilterError, HandoverError
        Integrated modes: bad IMU/reference files, unknown filter, no hand-over.
    NoSatelliteError
        Scalar mode: no satellite acquired.
    """
    from .constants import parse_prns
    from .io.atomic import check_output_dir, output_dir_removed_on_failure
    from .receiver.run_scalar import open_source

    if mode not in RUN_MODES:
        raise ValueError(f"mode must be one of {', '.join(RUN_MODES)}, got {mode!r}")
    if_file = Path(if_file)
    integrated = {"filter": filter, "imu": imu, "truth": truth, "filter_rate_hz":
                  filter_rate_hz, "align": align, "duration_s": duration_s,
                  "iono_wait_s": iono_wait_s, "assume": assume, "nco_latency": nco_latency}
    given = [k for k, v in integrated.items() if v is not None]
    if ephemeris is not None and not (mode == "scalar" and approx_pos is not None):
        given.append("ephemeris")
    if not assist:
        given.append("assist")
    if mode == "scalar" and given:
        raise ValueError(f"{', '.join(given)}: only with mode deep, loose or tight")
    if gnss_rate_hz is not None and mode not in ("loose", "tight"):
        raise ValueError("gnss_rate_hz: only with mode loose or tight")
    if nco_latency is not None and mode != "deep":
        raise ValueError("nco_latency: only with mode deep")
    from .integration.config import is_nco_latency

    if nco_latency is not None and not is_nco_latency(nco_latency):
        raise ValueError(f"nco_latency must be 0 or 1 (filter intervals), got {nco_latency!r}")
    if approx_pos is not None and (mode != "scalar" or ephemeris is None):
        raise ValueError("approx_pos: only in scalar mode, with ephemeris")
    for key, v in (("rate_hz", rate_hz), ("filter_rate_hz", filter_rate_hz),
                   ("duration_s", duration_s), ("gnss_rate_hz", gnss_rate_hz),
                   ("pll_bw_hz", pll_bw_hz)):
        if v is not None and not (math.isfinite(v) and v > 0):
            raise ValueError(f"{key} must be a finite number > 0, got {v!r}")
    if iono_wait_s is not None and not (math.isfinite(iono_wait_s) and iono_wait_s >= 0):
        raise ValueError(f"iono_wait_s must be a finite number >= 0, got {iono_wait_s!r}")
    tracking = _tracking_config(pll_bw_hz)
    prn_list = None if prns is None else parse_prns(prns, "prns")
    source = open_source(if_file, sampling_rate_hz=sampling_rate_hz, if_hz=if_hz,
                         sample_format=sample_format, spectrum_inverted=inverted,
                         start_week=start_week, start_sow=start_sow, rfch=rfch)
    out_dir = check_output_dir(Path(out) if out is not None
                               else if_file.with_name(if_file.stem + "_run"))
    with output_dir_removed_on_failure(out_dir):   # a failed run leaves no empty folder
        if mode == "scalar":
            return _run_scalar(source, out_dir, prn_list, rate_hz, cold, approx_pos,
                               ephemeris, tracking, progress)
        return _run_integrated(source, out_dir, prn_list, mode, rate_hz, cold, tracking,
                               progress, integrated, ephemeris, assist, gnss_rate_hz)


def _tracking_config(pll_bw_hz: float | None):
    """The scalar loops' settings for ``pll_bw_hz`` (None: the defaults)."""
    if pll_bw_hz is None:
        return None
    from .receiver.tracking import TrackingConfig

    d = TrackingConfig()
    t_max = d.max_coherent_s
    if pll_bw_hz * t_max > 0.25:       # TrackingConfig's stability limit
        raise ValueError(f"pll_bw_hz {pll_bw_hz:g} Hz x {t_max * 1e3:g} ms coherent time = "
                         f"{pll_bw_hz * t_max:g} > 0.25 (unstable loop): at most "
                         f"{0.25 / t_max:g} Hz")
    return dataclasses.replace(d, track_pll_bw_hz=pll_bw_hz)


def _run_scalar(source, out_dir: Path, prns, rate_hz: float, cold: bool, approx_pos,
                ephemeris, tracking, progress: bool) -> RunResult:
    """Scalar mode: :func:`~sdr_di.receiver.run_scalar.run_scalar`, as ``sdr-di run``."""
    from .receiver.run_scalar import run_scalar
    from .receiver.scalar import ScalarReceiver

    assist: bool | dict = not cold
    if approx_pos is not None:
        from .frames import llh_to_ecef
        from .orbits.rinex_nav import load_nav
        from .receiver.prediction import visible_satellites

        if source.start_week is None or source.start_sow is None:
            raise ValueError("ephemeris/approx_pos need the file's start time: a sidecar, or "
                             "start_week and start_sow")
        lat, lon, h = approx_pos
        assist = visible_satellites(load_nav(ephemeris), source.start_week, source.start_sow,
                                    llh_to_ecef(math.radians(lat), math.radians(lon), h))
        if not assist:
            raise ValueError(f"{ephemeris}: no satellite above 5 deg at the file's start "
                             f"from {lat:g}, {lon:g}, {h:g} m")
    res = run_scalar(source, out_dir, prns=prns, rate_hz=rate_hz, progress=progress,
                     assist=assist, receiver=None if tracking is None
                     else ScalarReceiver(config=tracking, log=False))
    return RunResult(mode="scalar", out_dir=out_dir, files=dict(res.files),
                     metrics={"n_epochs": res.n_epochs, "n_fixes": res.n_fixes,
                              "processed_s": res.processed_s},
                     processed_s=res.processed_s, wall_s=res.wall_s, details=res)


def _run_integrated(source, out_dir: Path, prns, mode: str, rate_hz: float, cold: bool,
                    tracking, progress: bool, opt: dict, ephemeris, assist: bool,
                    gnss_rate_hz: float | None) -> RunResult:
    """Deep, loose or tight: :func:`~sdr_di.integration.run_integrated.run_deep`, as
    ``sdr-di run --mode``."""
    from .integration.receiver import IntegrationConfig
    from .integration.run_integrated import run_deep

    kw: dict[str, Any] = {"filter": (opt["filter"] or "ekf").strip().lower(),
                          "output_rate_hz": rate_hz, "mode": mode}
    for key, name in (("gnss_rate_hz", None), ("filter_rate_hz", "filter_rate_hz"),
                      ("align", "align"), ("iono_wait_s", "iono_wait_s"),
                      ("nco_latency", "nco_latency")):
        v = gnss_rate_hz if name is None else opt[name]
        if v is not None:
            kw[key] = v
    cfg = IntegrationConfig(**kw)
    if opt["assume"] is not None:        # over IntegrationConfig's defaults
        from .integration.assumptions import apply_to_deep, load_assumptions

        cfg = apply_to_deep(cfg, load_assumptions(opt["assume"]))
    res = run_deep(source, out_dir, config=cfg, imu_path=opt["imu"], truth_path=opt["truth"],
                   nav_path=ephemeris, assist=assist, prns=prns, progress=progress,
                   duration_s=opt["duration_s"], search=not cold, tracking=tracking)
    r = res.result
    return RunResult(mode=mode, out_dir=out_dir, files=dict(res.files),
                     metrics={**res.metrics, "handover_s": r.handover_s},
                     processed_s=float(r.profile.get("processed_s", math.nan)),
                     wall_s=res.wall_s, details=res)


@_guarded
def study(spec: PathLike | Mapping[str, Any] | StudySpec, out: PathLike, *,
          runs: int | None = None, scheduler: str | None = None, workers: int | None = None,
          force: bool = False, report: bool = True,
          on_record: Callable[[dict], None] | None = None) -> StudyResult:
    """Run (or resume) a study: cells x filters x seeds, paired on the same files, with the
    claims decided by paired statistics (``sdr-di study``).

    Parameters
    ----------
    spec : path, mapping or StudySpec
        A study specification file (TOML, docs/studies.md), the same content as a mapping,
        or a parsed :class:`~sdr_di.studies.spec.StudySpec`.
    out : path
        Output folder (``--out``): ``runs.csv``, ``cells.csv``, ``study.json``,
        ``report.html``; a folder holding the same study is resumed.
    runs : int, optional
        Seeds per cell (``--runs``; default the spec's).
    scheduler : str, optional
        Dask scheduler address (``--scheduler``); default a local cluster.
    workers : int, optional
        Local worker processes (``--workers``; default the cores); 0 runs every task in
        this process, without Dask.
    force : bool
        Replace a different study's runs in ``out`` (``--force``).
    report : bool
        Write ``report.html`` (False: ``--no-report``).
    on_record : callable, optional
        Called with each run record as it arrives.

    Returns
    -------
    StudyResult
        :class:`~sdr_di.studies.study.StudyResult`: per-run rows (``runs``), per-cell rows
        with the claims' verdicts (``cells``), the comparisons, ``failed``, ``out_dir``.

    Raises
    ------
    StudyError
        Bad specification, ``runs`` or ``workers``, or ``out`` holds a different study
        (without ``force``).
    CampaignError
        Scheduler unreachable.
    """
    from .io.atomic import check_output_dir
    from .studies.spec import StudySpec, load_study, parse_study
    from .studies.study import run_study

    if isinstance(spec, StudySpec):
        parsed = spec
    elif isinstance(spec, Mapping):
        parsed = parse_study(dict(spec), force=force)
    else:
        parsed = load_study(spec, force=force)
    out_dir = check_output_dir(Path(out))
    return run_study(parsed, out_dir, runs=runs, scheduler=scheduler, workers=workers,
                     force=force, on_record=on_record, render=report)
