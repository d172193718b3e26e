"""Options of the commands: one frozen object per command that owns every rule between its
options (:class:`RunOptions`, :class:`GenerateOptions`, :class:`StudyOptions`).

The CLI parses its arguments into these objects and calls the API (:mod:`sdr_di.api`) with
them; the API's keyword functions build the same objects. So both doors apply the same rules,
in the same order, and raise the same errors: only the names in the messages differ, the CLI's
flags (``--pll-bw``) where the API says its arguments (``pll_bw_hz``): the ``names`` mapping.

=============================  ==============================================================
rule                           where
=============================  ==============================================================
options of another mode        :meth:`RunOptions.__post_init__` (:data:`INTEGRATED_ONLY`; deep
                               only: ``nco_latency``, ``deep_measurements``, ``fusion_rate_hz``)
numbers in range               :meth:`RunOptions.__post_init__`
PLL stability limit            :meth:`RunOptions.tracking_config`
                               (:func:`~sdr_di.receiver.tracking.pll_stability_problem`)
file description, IF file      :class:`IfFileOptions` (``run`` and ``acquire``)
visible-satellite assistance   :meth:`RunOptions.search_assistance`
companion files (scalar)       :meth:`RunOptions.scalar_companions`
filter entry, ``--assume``     :meth:`RunOptions.integration_config`
                               (:func:`~sdr_di.integration.settings.build_integration_config`)
filter rate divides IMU rate   :meth:`RunOptions.check_integrated_inputs`
scenario overrides             :meth:`GenerateOptions.scenario_config`
seeds per cell, workers        :meth:`StudyOptions.__post_init__`
                               (:func:`~sdr_di.studies.study.check_study_counts`)
=============================  ==============================================================

A new option of ``run`` is one field here (with its default, which is "not given"), one
argument of :func:`sdr_di.run`, one flag in ``cli.py``, and its rule in one method.

Importing this module loads only the standard library (``import sdr_di`` stays light); the
checks that need the receiver import it when they run.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any, NoReturn

from .errors import OptionsError

__all__ = ["INTEGRATED_ONLY", "RUN_MODES", "GenerateOptions", "IfFileOptions", "RunOptions",
           "StudyOptions", "check_approx_pos"]

#: Receiver modes of ``run`` (``--mode``).
RUN_MODES = ("scalar", "deep", "loose", "tight")
#: Options of the integrated modes (deep, loose, tight) that scalar mode refuses. Scalar mode
#: takes ``truth``, ``ephemeris``, ``assist`` and ``duration_s`` as the others do.
INTEGRATED_ONLY = ("filter", "imu", "filter_rate_hz", "align", "assume", "iono_wait_s")
#: Largest BDT week of a start-time hint (BDT week 0 began 2006-01-01; week 9999 is in 2197).
MAX_BDT_WEEK = 9999

PathLike = str | Path


def _path(v) -> Path | None:
    return None if v is None else Path(v)


def check_approx_pos(lat_deg: float, lon_deg: float, h_m: float) -> str | None:
    """What is wrong with an approximate receiver position, or None.

    Parameters
    ----------
    lat_deg, lon_deg : float
        Geodetic latitude and longitude [deg].
    h_m : float
        Height above the ellipsoid [m].
    """
    ok = all(math.isfinite(v) for v in (lat_deg, lon_deg, h_m))
    if ok and abs(lat_deg) <= 90.0 and abs(lon_deg) <= 360.0 and -1e3 <= h_m <= 1e5:
        return None
    return "position out of range"


@dataclasses.dataclass(frozen=True)
class IfFileOptions:
    """An IF file and the options that describe a file sdr-di did not write (``run`` and
    ``acquire``: ``--fs``, ``--if``, ``--format``, ``--rfch``, ``--inverted``,
    ``--start-week``, ``--start-sow``, ``--ignore-sidecar``, ``--no-format-check``).

    Construction checks the values and that the file (or its sidecar, or a SigMF
    ``X.sigmf-meta``) exists; :meth:`open_source` reads its description.
    The attributes are :func:`sdr_di.run`'s arguments of the same names.
    """

    if_file: Path
    sampling_rate_hz: float | None = None
    if_hz: float | None = None
    sample_format: str | None = None
    rfch: int | None = None
    inverted: bool = False
    start_week: int | None = None
    start_sow: float | None = None
    ignore_sidecar: bool = False
    check_format: bool = True
    names: Mapping[str, str] = dataclasses.field(default_factory=dict, compare=False,
                                                 repr=False)

    def __post_init__(self) -> None:
        from .constants import SECONDS_PER_WEEK as week_s

        object.__setattr__(self, "if_file", Path(self.if_file))
        n = self.name
        fs, sow = self.sampling_rate_hz, self.start_sow
        if fs is not None and not (math.isfinite(fs) and fs > 0):
            raise OptionsError(f"{n('sampling_rate_hz')} must be a finite number > 0, got "
                               f"{fs:g}")
        if self.if_hz is not None and not math.isfinite(self.if_hz):
            raise OptionsError(f"{n('if_hz')} must be a finite number [Hz], got "
                               f"{self.if_hz:g}")
        if self.start_week is not None and not 0 <= self.start_week <= MAX_BDT_WEEK:
            raise OptionsError(f"{n('start_week')} must be a BDT week 0..{MAX_BDT_WEEK}, got "
                               f"{self.start_week}")
        if sow is not None and not (math.isfinite(sow) and 0 <= sow < week_s):
            raise OptionsError(f"{n('start_sow')} must be BDT seconds of week in [0, "
                               f"{week_s:g}), got {sow:g}")
        path = self.if_file
        if path.is_dir():
            raise OptionsError(f"IF file {path}: is a folder")
        if not path.exists() and (path.suffix == ".json"
                                  or not path.with_suffix(".json").exists()):
            from .io.sigmf_files import sigmf_meta_path

            if sigmf_meta_path(path) is None:  # a SigMF base name X needs only X.sigmf-meta
                raise OptionsError(f"IF file {path}: no such file")

    def name(self, key: str) -> str:
        """How messages name option ``key`` (the CLI's flag, else the argument name)."""
        return self.names.get(key, key)

    def open_source(self):
        """The IF source of :attr:`if_file` (its sidecar, tag, SigMF or the file options).

        Raises
        ------
        SampleFormatError
            Missing or inconsistent sidecar, bad file options; bytes that do not look like
            the declared format (unless ``check_format`` is off).
        """
        from .errors import FormatCheckError
        from .receiver.run_scalar import open_source

        try:
            return open_source(self.if_file, sampling_rate_hz=self.sampling_rate_hz,
                               if_hz=self.if_hz, sample_format=self.sample_format,
                               spectrum_inverted=self.inverted, start_week=self.start_week,
                               start_sow=self.start_sow, rfch=self.rfch,
                               ignore_sidecar=self.ignore_sidecar,
                               check_format=self.check_format)
        except FormatCheckError as exc:  # the CLI names its own switch
            if "check_format" not in self.names:
                raise
            raise FormatCheckError(exc.finding, f"{self.names['check_format']} reads it "
                                   "anyway") from None


@dataclasses.dataclass(frozen=True)
class RunOptions:
    """Every option of a receiver run (``sdr-di run``, :func:`sdr_di.run`), checked.

    Construction checks everything that needs no file (a bad value raises
    :class:`~sdr_di.errors.OptionsError` at once); the methods apply the rules that need the
    IF source or the filter. The attributes are :func:`sdr_di.run`'s arguments (its
    docstring gives units and the CLI flag of each); ``None`` means "not given, the default".

    Attributes
    ----------
    if_file : Path
        IF samples (or their sidecar, or a SigMF recording).
    mode : str
        One of :data:`RUN_MODES`.
    prns : tuple of int or None
        PRNs to search (parsed: ``"C21"`` and ``21`` are 21).
    names : mapping of str to str
        How messages name an option (the CLI: its flags); an option not in it is named by its
        attribute name.
    """

    if_file: Path
    mode: str = "scalar"
    out: Path | None = None
    prns: tuple[int | str, ...] | None = None
    rate_hz: float = 5.0
    cold: bool = False
    pll_bw_hz: float | None = None
    approx_pos: tuple[float, float, float] | None = None
    filter: str | None = None
    imu: Path | None = None
    truth: Path | None = None
    ephemeris: Path | None = None
    assist: bool = True
    filter_rate_hz: float | None = None
    align: str | None = None
    duration_s: float | None = None
    gnss_rate_hz: float | None = None
    iono_wait_s: float | None = None
    assume: Path | None = None
    nco_latency: int | None = None
    deep_measurements: str | None = None
    fusion_rate_hz: float | None = None
    # a file sdr-di did not write
    sampling_rate_hz: float | None = None
    if_hz: float | None = None
    sample_format: str | None = None
    rfch: int | None = None
    inverted: bool = False
    start_week: int | None = None
    start_sow: float | None = None
    ignore_sidecar: bool = False
    check_format: bool = True
    progress: bool = False
    names: Mapping[str, str] = dataclasses.field(default_factory=dict, compare=False,
                                                 repr=False)

    def __post_init__(self) -> None:
        for key in ("if_file", "out", "imu", "truth", "ephemeris", "assume"):
            object.__setattr__(self, key, _path(getattr(self, key)))
        if self.prns is not None:   # each once, a repeat with one warning (issue 49 item 9)
            from .constants import parse_prns

            object.__setattr__(self, "prns", tuple(parse_prns(self.prns,
                                                               self.names.get("prns", "prns"))))
        if self.approx_pos is not None:
            object.__setattr__(self, "approx_pos", tuple(float(v) for v in self.approx_pos))
        self._check_modes()
        self._check_numbers()
        self.tracking_config()
        self.file_options       # noqa: B018  (its construction checks the file options)

    def name(self, key: str) -> str:
        """How messages name option ``key`` (the CLI's flag, else the argument name)."""
        return self.names.get(key, key)

    def _fail(self, message: str) -> NoReturn:
        raise OptionsError(message)

    def _check_modes(self) -> None:
        n = self.name
        if self.mode not in RUN_MODES:
            self._fail(f"{n('mode')} must be one of {', '.join(RUN_MODES)}, got {self.mode!r}")
        given = [n(k) for k in INTEGRATED_ONLY if getattr(self, k) is not None]
        if self.mode == "scalar" and given:
            self._fail(f"{', '.join(given)}: only with {n('mode')} deep, loose or tight")
        if self.gnss_rate_hz is not None and self.mode not in ("loose", "tight"):
            self._fail(f"{n('gnss_rate_hz')}: only with {n('mode')} loose or tight")
        for key in ("deep_measurements", "fusion_rate_hz"):
            if getattr(self, key) is not None and self.mode != "deep":
                self._fail(f"{n(key)}: only with {n('mode')} deep")
        if self.nco_latency is not None:
            if self.mode != "deep":
                self._fail(f"{n('nco_latency')}: only with {n('mode')} deep")
            from .coupling.config import is_nco_latency

            if not is_nco_latency(self.nco_latency):
                self._fail(f"{n('nco_latency')} must be 0 or 1 (filter intervals), got "
                           f"{self.nco_latency!r}")
        if self.approx_pos is not None:
            if self.mode != "scalar" or self.ephemeris is None:
                self._fail(f"{n('approx_pos')}: only in scalar mode, with {n('ephemeris')}")
            if len(self.approx_pos) != 3 or check_approx_pos(*self.approx_pos):
                self._fail(f"{n('approx_pos')}: position out of range: {self.approx_pos!r} "
                           "(latitude, longitude [deg], height [m])")

    def _check_numbers(self) -> None:
        for key in ("rate_hz", "filter_rate_hz", "duration_s", "gnss_rate_hz", "pll_bw_hz"):
            v = getattr(self, key)
            if v is not None and not (math.isfinite(v) and v > 0):
                self._fail(f"{self.name(key)} must be a finite number > 0, got {v:g}")
        v = self.iono_wait_s
        if v is not None and not (math.isfinite(v) and v >= 0):
            self._fail(f"{self.name('iono_wait_s')} must be a finite number >= 0, got {v:g}")

    # ---- rules that need more than the options -----------------------------------------------
    @property
    def out_dir(self) -> Path:
        """The output folder: ``out``, else ``<stem>_run/`` beside the IF file."""
        return self.out if self.out is not None else \
            self.if_file.with_name(self.if_file.stem + "_run")

    def tracking_config(self):
        """The scalar loops' settings (``pll_bw_hz``), or None for the defaults.

        Raises
        ------
        OptionsError
            A PLL bandwidth beyond the loop's stability limit for the longest coherent time.
        """
        if self.pll_bw_hz is None:
            return None
        from .receiver.tracking import TrackingConfig, pll_stability_problem

        d = TrackingConfig()
        problem = pll_stability_problem(self.pll_bw_hz, d.max_coherent_s,
                                        self.name("pll_bw_hz"))
        if problem is not None:
            self._fail(problem)
        return dataclasses.replace(d, track_pll_bw_hz=self.pll_bw_hz)

    @property
    def file_options(self) -> IfFileOptions:
        """The IF file and the options that describe it (checked at construction)."""
        return IfFileOptions(
            if_file=self.if_file, sampling_rate_hz=self.sampling_rate_hz, if_hz=self.if_hz,
            sample_format=self.sample_format, rfch=self.rfch, inverted=self.inverted,
            start_week=self.start_week, start_sow=self.start_sow,
            ignore_sidecar=self.ignore_sidecar, check_format=self.check_format,
            names=self.names)

    def open_source(self):
        """The IF source (:meth:`IfFileOptions.open_source`)."""
        return self.file_options.open_source()

    def search_assistance(self, source) -> bool | dict[int, float]:
        """Acquisition assistance of the start: the sidecar's satellites (True), a cold search
        (False, ``cold``), or with ``approx_pos`` the satellites visible from it at the file's
        start and their Dopplers (:func:`~sdr_di.receiver.prediction.visible_satellites`).

        Raises
        ------
        OptionsError
            ``approx_pos`` without the file's start time, or no satellite visible.
        """
        if self.approx_pos is None:
            return not self.cold
        from .frames import llh_to_ecef
        from .orbits.rinex_nav import load_nav
        from .receiver.prediction import visible_satellites

        n = self.name
        if source.start_week is None or source.start_sow is None:
            self._fail(f"{n('ephemeris')}/{n('approx_pos')} need the file's start time: a "
                       f"sidecar, or {n('start_week')} and {n('start_sow')}")
        lat, lon, h = self.approx_pos
        assert self.ephemeris is not None      # construction: approx_pos needs ephemeris
        vis = visible_satellites(load_nav(self.ephemeris), source.start_week, source.start_sow,
                                 llh_to_ecef(math.radians(lat), math.radians(lon), h))
        if not vis:
            self._fail(f"{self.ephemeris}: no satellite above 5 deg at the file's start from "
                       f"{lat:g}, {lon:g}, {h:g} m")
        return vis

    def scalar_companions(self, source) -> tuple[Path | None, Path | None]:
        """Scalar mode's assistance navigation file (``ephemeris``, else the sidecar's
        ``ephemeris_file``; None with ``assist`` off) and reference file (``truth``, else the
        sidecar's ``truth_file``), as the integrated modes find them.

        Raises
        ------
        FileSetError
            The sidecar's reference file is not the one it was written with.
        """
        from .io.sidecar import companion_files

        comp = companion_files(source, skip=("imu",) + (("truth",) if self.truth else ()))
        nav = None if not self.assist else (self.ephemeris or comp["ephemeris"])
        return nav, (self.truth or comp["truth"])

    def integration_config(self):
        """The integrated receiver's settings: the filter entry, the given fields and the
        assumptions file (:func:`~sdr_di.integration.settings.build_integration_config`).

        Raises
        ------
        FilterError, OptionsError, AssumptionsError
            See :func:`~sdr_di.integration.settings.build_integration_config`.
        """
        from .integration.settings import build_integration_config

        fields = {"gnss_rate_hz": self.gnss_rate_hz, "filter_rate_hz": self.filter_rate_hz,
                  "align": self.align, "iono_wait_s": self.iono_wait_s,
                  "nco_latency": self.nco_latency, "deep_measurements": self.deep_measurements,
                  "fusion_rate_hz": self.fusion_rate_hz}
        return build_integration_config(
            self.filter or "ekf", assume=self.assume, mode=self.mode,
            output_rate_hz=self.rate_hz, **{k: v for k, v in fields.items() if v is not None})

    def check_integrated_inputs(self, source, cfg) -> None:
        """Before the start-up: the filter built on the models of its layout (a plugin's import and
        interface), and a given filter rate that divides the IMU file's rate.

        Raises
        ------
        FilterError
            The filter cannot be built.
        OptionsError
            The filter rate does not divide the IMU rate.
        """
        from .integration.filter_setup import check_filter

        check_filter(cfg)
        if self.filter_rate_hz is None:
            return
        from .coupling.config import imu_samples_per_interval
        from .io.imu_files import read_imu
        from .io.sidecar import companion_files

        imu_path = self.imu or companion_files(source, skip=("truth",))["imu"]
        if imu_path is not None:
            imu_samples_per_interval(read_imu(imu_path).rate_hz, cfg.filter_rate_hz,
                                     self.name("filter_rate_hz"), str(imu_path))


#: Scenario override key -> the :class:`GenerateOptions` attribute that sets it.
_OVERRIDE_OPTION = {"duration_s": "duration_s", "seed": "seed",
                    "sampling_rate_hz": "sampling_rate_hz", "if_hz": "if_hz",
                    "sample_format": "sample_format", "kind": "sample_format",
                    "quantization_bits": "bits", "cn0_dbhz": "cn0_dbhz",
                    "ephemeris": "ephemeris", "prns": "prns"}


@dataclasses.dataclass(frozen=True)
class GenerateOptions:
    """Every option of ``sdr-di generate`` / :func:`sdr_di.generate` (its docstring gives
    units and flags). The rules are the scenario's: an option overrides a scenario key, and a
    bad value is reported under the option's name (:meth:`scenario_config`)."""

    out: Path | None = None
    scenario: Path | None = None
    name: str | None = None
    duration_s: float | None = None
    seed: int | None = None
    sampling_rate_hz: float | None = None
    if_hz: float | None = None
    sample_format: str | None = None
    bits: int | None = None
    cn0_dbhz: float | None = None
    ephemeris: Path | None = None
    prns: tuple[str | int, ...] | None = None
    progress: bool = False
    sigmf: bool = False
    names: Mapping[str, str] = dataclasses.field(default_factory=dict, compare=False,
                                                 repr=False)

    def __post_init__(self) -> None:
        for key in ("out", "scenario", "ephemeris"):
            object.__setattr__(self, key, _path(getattr(self, key)))
        if self.prns is not None:
            object.__setattr__(self, "prns", tuple(str(p) for p in self.prns))

    @property
    def out_dir(self) -> Path:
        """Output folder: ``out``, else ``signals/out`` of the repository."""
        from .scenario import REPO_ROOT

        return REPO_ROOT / "signals" / "out" if self.out is None else self.out

    def scenario_config(self):
        """The scenario file (default paper 004's) with the options as overrides.

        Raises
        ------
        ScenarioError, UnknownPrnError
            Bad scenario file or override (named as the option was given).
        SampleFormatError
            Unknown sample format.
        """
        from .errors import ScenarioError, UnknownPrnError
        from .scenario import DEFAULT_SCENARIO, load_scenario
        from .scenario.schema import with_flag_names

        sc = load_scenario(self.scenario or DEFAULT_SCENARIO)
        kind, sample_format = None, self.sample_format
        if sample_format is not None:
            from .io.sample_formats import get_format

            fmt = get_format(sample_format)
            kind = "complex" if fmt.is_complex else "real"
            sample_format = fmt.name
        prns = self.prns
        if prns is not None:   # a repeated PRN: one warning naming the option (bad ones below)
            from .constants import parse_prn, parse_prns

            try:
                for p in prns:
                    parse_prn(p)
            except UnknownPrnError:
                pass
            else:
                prns = tuple(f"C{p:02d}" for p in parse_prns(prns, self.names.get("prns",
                                                                                  "prns")))
        over = dict(duration_s=self.duration_s, seed=self.seed,
                    sampling_rate_hz=self.sampling_rate_hz, if_hz=self.if_hz,
                    sample_format=sample_format, kind=kind, quantization_bits=self.bits,
                    cn0_dbhz=self.cn0_dbhz, ephemeris=self.ephemeris,
                    prns=None if prns is None else list(prns))
        try:
            return sc.with_overrides(**over)
        except (ScenarioError, UnknownPrnError) as exc:  # the option's name, not the key
            raise with_flag_names(exc, sc, {k: self.names.get(_OVERRIDE_OPTION[k],
                                                              _OVERRIDE_OPTION[k])
                                            for k, v in over.items() if v is not None}) \
                from None


@dataclasses.dataclass(frozen=True)
class StudyOptions:
    """Every option of ``sdr-di study`` / :func:`sdr_di.study` (its docstring gives their
    meaning). Construction checks the seeds per cell and the workers; :meth:`load_spec` reads
    and checks the specification.

    Attributes
    ----------
    spec : path, mapping or StudySpec
        The specification (a TOML file, its content as a mapping, or a parsed spec).
    out : Path
        Output folder.
    """

    spec: Any
    out: Path
    runs: int | None = None
    scheduler: str | None = None
    workers: int | None = None
    force: bool = False
    report: bool = True
    names: Mapping[str, str] = dataclasses.field(default_factory=dict, compare=False,
                                                 repr=False)

    def __post_init__(self) -> None:
        from .studies.study import check_study_counts

        object.__setattr__(self, "out", Path(self.out))
        check_study_counts(self.runs, self.workers, self.scheduler, dict(self.names))

    def load_spec(self):
        """The parsed :class:`~sdr_di.studies.spec.StudySpec`.

        Raises
        ------
        StudyError
            Missing or malformed specification.
        """
        from .studies.spec import StudySpec, load_study, parse_study

        if isinstance(self.spec, StudySpec):
            return self.spec
        if isinstance(self.spec, Mapping):
            return parse_study(dict(self.spec), force=self.force)
        return load_study(self.spec, force=self.force)
