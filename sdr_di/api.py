"""The public Python API: :func:`generate`, :func:`run` and :func:`study`.

Each function mirrors one ``sdr-di`` command, option for option (the CLI's ``--duration``
is ``duration_s=``, ``--fs`` is ``sampling_rate_hz=``, and so on; the parameter lists say
which). Its arguments become that command's options object (:mod:`sdr_di.options`:
:class:`RunOptions`, :class:`GenerateOptions`, :class:`StudyOptions`), which owns every rule
between them; :func:`run_with`, :func:`generate_with` and :func:`study_with` take such an
object, and the CLI calls them. So a run from Python writes the same files, and a bad input
raises the same error (an :class:`~sdr_di.errors.SdrDiError`), as the same run from the
shell; only the messages name the argument (``pll_bw_hz``) where the CLI names its flag
(``--pll-bw``). Everything else in the package is internal and may move between releases.

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

from .options import RUN_MODES, GenerateOptions, RunOptions, StudyOptions

if TYPE_CHECKING:
    from .studies.spec import StudySpec
    from .studies.study import StudyResult

__all__ = ["RUN_MODES", "GenerateOptions", "GeneratedFiles", "RunOptions", "RunResult",
           "StudyOptions", "generate", "generate_with", "run", "run_with", "study",
           "study_with"]

F = TypeVar("F", bound=Callable)


def _guarded(func: F) -> F:
    """Run ``func`` inside :func:`sdr_di.paths.command_scope` (no output of the call may
    be one of its inputs); the module is imported on the first call, not with ``sdr_di``."""

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        from .paths import command_scope

        with command_scope():
            return func(*args, **kwargs)

    return wrapper  # type: ignore[return-value]



Mode = Literal["scalar", "deep", "loose", "tight"]
PathLike = str | Path


def _path(p: PathLike | None) -> Path | None:
    return None if p is None else Path(p)


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
        Scalar: ``n_epochs``, ``n_fixes``, ``processed_s``, ``first_fix_s`` [s since file
        start; NaN without a fix] and, with a reference file and a fix, the errors of the
        ``n`` fixes it covers (``vel_mps_rmse``, ``vel_mps_max`` [m/s], ``pos_m_rmse``, ``pos_m_max`` [m]).
        Integrated modes: the error
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
        :class:`~sdr_di.integration.run_integrated.IntegratedRunSummary`, whose ``result`` holds
        the solution arrays); internal, may change between releases.
    inputs : dict of str to Path
        Input files by label: ``if``; in scalar mode the ``ephemeris`` (assistance) and
        ``truth`` (reference) files it used, given or the sidecar's; in the integrated modes
        the ``imu``, ``truth`` and ``ephemeris`` given (the others are the sidecar's, named
        in the run's summary).
    """

    mode: str
    out_dir: Path
    files: dict[str, Path]
    metrics: dict[str, Any]
    processed_s: float
    wall_s: float
    details: Any = dataclasses.field(repr=False, default=None)
    inputs: dict[str, Path] = dataclasses.field(default_factory=dict)


@_guarded
def generate(out: PathLike | None = None, *, scenario: PathLike | None = None,
             name: str | None = None, duration_s: float | None = None,
             seed: int | None = None, sampling_rate_hz: float | None = None,
             if_hz: float | None = None, sample_format: str | None = None,
             bits: int | None = None, cn0_dbhz: float | None = None,
             ephemeris: PathLike | None = None, prns: Sequence[str | int] | None = None,
             progress: bool = False, sigmf: bool = False) -> GeneratedFiles:
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
        RINEX 3 or 4 navigation file (``--ephemeris``).
    prns : sequence of str or int, optional
        Satellites instead of the automatic selection, ``"C21"`` or ``21`` (``--prn``).
    progress : bool
        Show a progress bar (the CLI's default; here off).
    sigmf : bool
        Also write the SigMF pair ``NAME.sigmf-meta`` and ``NAME.sigmf-data`` (the IF
        samples, hard-linked to ``NAME.bin``) (``--sigmf``).

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
    return generate_with(GenerateOptions(
        out=_path(out), scenario=_path(scenario), name=name, duration_s=duration_s, seed=seed,
        sampling_rate_hz=sampling_rate_hz, if_hz=if_hz, sample_format=sample_format,
        bits=bits, cn0_dbhz=cn0_dbhz, ephemeris=_path(ephemeris),
        prns=None if prns is None else tuple(prns), progress=progress, sigmf=sigmf))


@_guarded
def generate_with(options: GenerateOptions) -> GeneratedFiles:
    """:func:`generate` with its options as one object (what ``sdr-di generate`` calls).

    Parameters
    ----------
    options : GenerateOptions
        :class:`~sdr_di.options.GenerateOptions`.

    Returns
    -------
    GeneratedFiles
    """
    from .sim.generate import generate_files

    sc = options.scenario_config()
    files = generate_files(sc, options.out_dir, name=options.name, progress=options.progress,
                           sigmf=options.sigmf)
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
        deep_measurements: Literal["prefilter", "reset", "discriminator"] | None = None,
        fusion_rate_hz: float | None = None, sampling_rate_hz: float | None = None, if_hz: float | None = None,
        sample_format: str | None = None, rfch: int | None = None, inverted: bool = False,
        start_week: int | None = None, start_sow: float | None = None,
        ignore_sidecar: bool = False, check_format: bool = True,
        progress: bool = False) -> RunResult:
    """Run the receiver on an IF file in any mode (``sdr-di run``).

    The arguments become a :class:`~sdr_di.options.RunOptions`, which applies every rule
    between them, then :func:`run_with` runs it: ``sdr-di run`` does the same, so both give
    the same files and the same errors.

    Parameters
    ----------
    if_file : path
        IF samples (or their ``.json`` sidecar, or a SigMF ``X.sigmf-meta``/``-data``).
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
        Tracking PLL noise bandwidth once locked [Hz] (``--pll-bw``; default 15; at most
        25 Hz with the 10 ms D1 coherent time). Any mode (deep's start-up).
    approx_pos : (lat_deg, lon_deg, h_m), optional
        Scalar mode with ``ephemeris``: search the satellites visible from this position
        [deg, deg, m] around their predicted Doppler (``--approx-pos``).
    truth : path, optional
        Reference file (``--truth``; default the sidecar's): the errors in ``metrics``.
    ephemeris : path, optional
        RINEX navigation file used as assistance data (``--ephemeris``; default the
        sidecar's), any mode.
    assist : bool
        False: decoded ephemerides and ionosphere only (``--no-assist``), any mode.
    duration_s : float, optional
        Process only the first seconds of the file [s] (``--duration``), any mode.

    Other Parameters
    ----------------
    filter : str, optional
        Integration filter entry ``NAME[:OPT=VALUE...]`` (``--filter``; default ``ekf``):
        a built-in, registered or entry-point name, or an import path
        ``package.module:Name``; e.g. ``"ekf:q_scale=4"``, ``"ff-aukf:q_states=nominal"``.
        Integrated modes only, as are ``imu``, ``filter_rate_hz``, ``align``,
        ``iono_wait_s`` and ``assume``.
    imu : path, optional
        IMU file (``--imu``; default the sidecar's).
    filter_rate_hz : float, optional
        Integration filter and NCO rate [Hz] (``--filter-rate``; default 50); must divide
        the IMU rate.
    align : {"truth", "gnss"}, optional
        INS initial alignment (``--align``; default ``truth``).
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
    deep_measurements : {"prefilter", "reset", "discriminator"}, optional
        Deep only: what each channel hands the integration filter: paper 004's cascaded
        pre-filters (default), pre-filters restarted from an uninformative prior at each
        fusion, or the interval's discriminator outputs (``--deep-measurements``;
        docs/deep.md).
    fusion_rate_hz : float, optional
        Deep with ``deep_measurements="reset"``: rate of the filter's updates with the
        pre-filters' outputs [Hz], the filter rate divided by a whole number
        (``--fusion-rate``; default 5).
    sampling_rate_hz, if_hz : float, optional
        A file sdr-di did not write: sampling rate and intermediate frequency [Hz] (``--fs``,
        ``--if``).
    sample_format : str, optional
        Its sample format (``--format``; docs/formats.md).
    rfch : int, optional
        RF channel (1-based) of a multi-channel PocketSDR file (``--rfch``).
    inverted : bool
        Spectrum inverted (``--inverted``).
    start_week, start_sow : optional
        Start-time hint: BDT week and seconds of week [s] of sample 0 (``--start-week``,
        ``--start-sow``).
    ignore_sidecar : bool
        Read the file with the options above alone, even where a sidecar says otherwise
        (``--ignore-sidecar``).
    check_format : bool
        False: read the file even where its bytes do not look like the declared format
        (``--no-format-check``).
    progress : bool
        Show a progress bar (the CLI's default; here off).

    Returns
    -------
    RunResult

    Raises
    ------
    OptionsError
        A bad mode, options that do not fit together or out of range (a ``ValueError``).
    SampleFormatError
        Missing or inconsistent sidecar, bad file options.
    FilterError
        Unknown filter, bad filter option, a plugin that does not import.
    ImuDataError, HandoverError
        Integrated modes: bad IMU/reference files, no hand-over.
    """
    return run_with(RunOptions(
        if_file=Path(if_file), mode=mode, out=_path(out),
        prns=None if prns is None else tuple(prns), rate_hz=rate_hz, cold=cold,
        pll_bw_hz=pll_bw_hz, approx_pos=approx_pos, filter=filter, imu=_path(imu),
        truth=_path(truth), ephemeris=_path(ephemeris), assist=assist,
        filter_rate_hz=filter_rate_hz, align=align, duration_s=duration_s,
        gnss_rate_hz=gnss_rate_hz, iono_wait_s=iono_wait_s, assume=_path(assume),
        nco_latency=nco_latency, deep_measurements=deep_measurements,
        fusion_rate_hz=fusion_rate_hz, sampling_rate_hz=sampling_rate_hz, if_hz=if_hz,
        sample_format=sample_format, rfch=rfch, inverted=inverted, start_week=start_week,
        start_sow=start_sow, ignore_sidecar=ignore_sidecar, check_format=check_format,
        progress=progress))


@_guarded
def run_with(options: RunOptions) -> RunResult:
    """:func:`run` with its options as one object (what ``sdr-di run`` calls).

    Everything that can be checked before the run is checked first: the options
    (construction), the IF file, the output folder, the assistance and, in the integrated
    modes, the filter and its rate against the IMU rate. The output folder is created only
    then, and removed again if the run fails before writing into it.

    Parameters
    ----------
    options : RunOptions
        :class:`~sdr_di.options.RunOptions`.

    Returns
    -------
    RunResult
    """
    from .io.atomic import check_output_dir, output_dir_removed_on_failure

    opts = options
    source = opts.open_source()
    out_dir = check_output_dir(opts.out_dir)
    if opts.mode == "scalar":
        assist = opts.search_assistance(source)
        nav_path, truth_path = opts.scalar_companions(source)
        with output_dir_removed_on_failure(out_dir):
            return _run_scalar(opts, source, out_dir, assist, nav_path, truth_path)
    cfg = opts.integration_config()
    opts.check_integrated_inputs(source, cfg)
    with output_dir_removed_on_failure(out_dir):
        return _run_integrated(opts, source, out_dir, cfg)


def _run_scalar(opts: RunOptions, source, out_dir: Path, assist, nav_path: Path | None,
                truth_path: Path | None) -> RunResult:
    """Scalar mode: :func:`~sdr_di.receiver.run_scalar.run_scalar`, with the errors against
    the reference when there is one."""
    from .orbits.rinex_nav import load_nav
    from .receiver.run_scalar import run_scalar
    from .receiver.scalar import ScalarReceiver

    tracking = opts.tracking_config()
    res = run_scalar(source, out_dir, prns=opts.prns, rate_hz=opts.rate_hz,
                     progress=opts.progress, assist=assist,
                     receiver=None if tracking is None
                     else ScalarReceiver(config=tracking, log=False),
                     nav=None if nav_path is None else load_nav(nav_path),
                     duration_s=opts.duration_s)
    metrics: dict[str, Any] = {"n_epochs": res.n_epochs, "n_fixes": res.n_fixes,
                               "processed_s": res.processed_s, "first_fix_s": res.first_fix_s}
    if truth_path is not None and res.n_fixes:
        from .receiver.accuracy import solution_vs_truth

        m = solution_vs_truth(res.files["pvt"], truth_path)
        metrics.update(n=m["n_fixes"], vel_mps_rmse=m["vel_rmse_mps"], vel_mps_max=m["vel_max_mps"],
                       pos_m_rmse=m["pos_rmse_m"], pos_m_max=m["pos_max_m"])
    inputs = {"if": source.path, "ephemeris": nav_path, "truth": truth_path}
    return RunResult(mode="scalar", out_dir=out_dir, files=dict(res.files), metrics=metrics,
                     processed_s=res.processed_s, wall_s=res.wall_s, details=res,
                     inputs={k: Path(v) for k, v in inputs.items() if v is not None})


def _run_integrated(opts: RunOptions, source, out_dir: Path, cfg) -> RunResult:
    """Deep, loose or tight: :func:`~sdr_di.integration.run_integrated.run_integrated`."""
    from .integration.run_integrated import run_integrated

    res = run_integrated(source, out_dir, config=cfg, imu_path=opts.imu, truth_path=opts.truth,
                   nav_path=opts.ephemeris, assist=opts.assist, prns=opts.prns,
                   progress=opts.progress, duration_s=opts.duration_s, search=not opts.cold,
                   tracking=opts.tracking_config())
    r = res.result
    given = {"if": source.path, "imu": opts.imu, "truth": opts.truth,
             "ephemeris": opts.ephemeris}
    return RunResult(mode=opts.mode, out_dir=out_dir, files=dict(res.files),
                     metrics={**res.metrics, "handover_s": r.handover_s},
                     processed_s=float(r.profile.get("processed_s", math.nan)),
                     wall_s=res.wall_s, details=res,
                     inputs={k: Path(v) for k, v in given.items() if v is not None})


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
    return study_with(StudyOptions(spec=spec, out=Path(out), runs=runs, scheduler=scheduler,
                                   workers=workers, force=force, report=report),
                      on_record=on_record)


@_guarded
def study_with(options: StudyOptions,
               on_record: Callable[[dict], None] | None = None) -> StudyResult:
    """:func:`study` with its options as one object (what ``sdr-di study`` calls).

    Parameters
    ----------
    options : StudyOptions
        :class:`~sdr_di.options.StudyOptions`.
    on_record : callable, optional
        Called with each run record as it arrives.

    Returns
    -------
    StudyResult
    """
    from .io.atomic import check_output_dir
    from .studies.study import run_study

    parsed = options.load_spec()
    out_dir = check_output_dir(options.out)
    return run_study(parsed, out_dir, runs=options.runs, scheduler=options.scheduler,
                     workers=options.workers, force=options.force, on_record=on_record,
                     render=options.report)
