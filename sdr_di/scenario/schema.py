"""Scenario file schema (TOML) and its validation.

A scenario says *what* to simulate: when and where the vehicle starts, how it moves, which IMU
it carries, which satellites it sees at what C/N0 (and when they are blocked), and how the IF
samples are made. ``docs/scenario.md`` documents every key; ``signals/default.toml`` is the
paper 004 scenario. Every problem is reported as :class:`~sdr_di.errors.ScenarioError` naming
the file, the key and what is wrong.

Units at the user interface: degrees, metres, seconds, Hz, dB-Hz; SI/radians inside.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import hashlib
import json
import math
from pathlib import Path
from typing import Any

from ..constants import parse_prn, parse_prns
from ..errors import ScenarioError, SdrDiError
from ..ins.grades import IMU_GRADES
from ..oscillator import OscillatorSpec, oscillator_from_table
from ..timebase import datetime_to_bdt, utc_to_bdt

#: Motion segment types and their required / optional keys (besides ``type``).
SEGMENT_KEYS: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    "uniform": (("duration_s",), ()),
    "accelerate": (("duration_s", "accel_mps2"), ()),
    "decelerate": (("duration_s", "decel_mps2"), ()),
    "climb": (("duration_s", "vertical_rate_mps"), ()),
    "descend": (("duration_s", "vertical_rate_mps"), ()),
    "turn_left": (("duration_s", "rate_dps"), ()),
    "turn_right": (("duration_s", "rate_dps"), ()),
    "circle": (("duration_s", "direction"), ("rate_dps", "radius_m")),
    "hold": (("duration_s",), ()),
}

#: ``[imu]`` keys of the scenario -> the :class:`~sdr_di.ins.imu.ImuErrorModel` field its
#: grade default comes from (grades: :data:`~sdr_di.ins.grades.IMU_GRADES`).
IMU_KEYS: dict[str, str] = {
    "accel_scale_factor_ppm": "accel_scale_factor_ppm",
    "gyro_scale_factor_ppm": "gyro_scale_factor_ppm",
    "accel_bias_mg": "accel_bias_mg",
    "gyro_bias_deg_h": "gyro_bias_deg_h",
    "accel_random_walk_mps_sqrth": "accel_random_walk",
    "gyro_random_walk_deg_sqrth": "gyro_random_walk",
    "accel_bias_instability_mg": "accel_bias_instability_mg",
    "gyro_bias_instability_deg_h": "gyro_bias_instability_deg_h",
    "accel_bias_tau_s": "accel_bias_tau_s",
    "gyro_bias_tau_s": "gyro_bias_tau_s",
    "accel_misalignment_mrad": "accel_misalignment_mrad",
    "gyro_misalignment_mrad": "gyro_misalignment_mrad",
    "gyro_g_sensitivity_deg_h_per_g": "gyro_g_sensitivity_deg_h_per_g",
}

#: Shortest scenario duration [s]: ten B3I code periods, and two IMU intervals at 200 Hz so
#: that the IMU and truth files hold at least three samples (a scenario whose IMU rate is
#: lower needs two of its intervals). Shorter durations are refused before any work.
MIN_DURATION_S = 0.01

#: Sample formats the generator writes (see :mod:`sdr_di.io.sample_formats`).
SAMPLE_FORMATS = ("iq_int8", "real_int8", "iq_int16", "real_int16", "iq_int4")


@dataclasses.dataclass(frozen=True)
class ImuSpec:
    """IMU grade and error parameters (user units; 1-sigma; :mod:`sdr_di.ins.imu`, grades
    :mod:`sdr_di.ins.grades`)."""

    grade: str
    rate_hz: float
    accel_scale_factor_ppm: float
    gyro_scale_factor_ppm: float
    accel_bias_mg: float
    gyro_bias_deg_h: float
    accel_random_walk_mps_sqrth: float
    gyro_random_walk_deg_sqrth: float
    accel_bias_instability_mg: float = 0.0
    gyro_bias_instability_deg_h: float = 0.0
    accel_bias_tau_s: float = 3600.0
    gyro_bias_tau_s: float = 3600.0
    accel_misalignment_mrad: float = 0.0
    gyro_misalignment_mrad: float = 0.0
    gyro_g_sensitivity_deg_h_per_g: float = 0.0

    #: The fields of paper 004's six terms (and grade, rate): all a legacy spec records.
    LEGACY = ("grade", "rate_hz", "accel_scale_factor_ppm", "gyro_scale_factor_ppm",
              "accel_bias_mg", "gyro_bias_deg_h", "accel_random_walk_mps_sqrth",
              "gyro_random_walk_deg_sqrth")

    @property
    def is_extended(self) -> bool:
        """Whether any term beyond paper 004's six is set (in-run bias, misalignment,
        g-sensitivity)."""
        return any(getattr(self, f.name) != 0 for f in dataclasses.fields(self)
                   if f.name not in self.LEGACY and not f.name.endswith("_tau_s"))

    def as_dict(self) -> dict[str, Any]:
        """The spec for the sidecar and summaries: every field of an extended spec, the
        legacy fields alone otherwise (so a legacy scenario's sidecar is unchanged)."""
        d = dataclasses.asdict(self)
        return d if self.is_extended else {k: d[k] for k in self.LEGACY}


@dataclasses.dataclass(frozen=True)
class Outage:
    """Attenuation window for one PRN (``prn`` None = every satellite).

    ``attenuation_db`` is ``math.inf`` for full blockage. Times are seconds from the start.
    """

    prn: int | None
    start_s: float
    end_s: float
    attenuation_db: float


@dataclasses.dataclass(frozen=True)
class SatelliteSpec:
    """Which satellites are simulated and how strong they are."""

    ephemeris: Path
    prns: tuple[int, ...] | None  # None = automatic selection
    count: int
    elevation_mask_deg: float
    cn0_dbhz: float
    cn0_per_prn: dict[int, float]


@dataclasses.dataclass(frozen=True)
class SignalSpec:
    """How IF samples are produced."""

    sampling_rate_hz: float
    if_hz: float
    complex_baseband: bool
    sample_format: str
    quantization_bits: int
    ionosphere: str
    troposphere: str
    chunk_ms: int


@dataclasses.dataclass(frozen=True)
class AtmosphereSpec:
    """Truth atmosphere (``[atmosphere]``; model and defaults: docs/scenario.md and
    :mod:`sdr_di.sim.atmosphere`). ``truth = "model"``: the delays are the receiver's models
    (broadcast Klobuchar, Saastamoinen standard atmosphere); ``"residuals"``: the truth
    differs from them by the drawn amounts below (1-sigma values)."""

    truth: str = "model"
    #: 1-sigma of the per-satellite-pass scale of the Klobuchar delay, truth = (1 + k) K [-]
    iono_scale_sigma: float = 0.5
    #: stationary 1-sigma [-] and correlation time [s] of the slow variation of that scale
    iono_variation_sigma: float = 0.1
    iono_variation_tau_s: float = 1800.0
    #: 1-sigma of the zenith wet delay's offset from the standard atmosphere's [m]
    zwd_sigma_m: float = 0.05
    #: stationary 1-sigma [m] and correlation time [s] of its slow variation
    zwd_variation_sigma_m: float = 0.01
    zwd_variation_tau_s: float = 3600.0

    @property
    def residuals(self) -> bool:
        """Whether the truth differs from the receiver's models."""
        return self.truth == "residuals"


@dataclasses.dataclass(frozen=True)
class ReceiverClock:
    """Receiver clock: bias [s] at t = 0 and constant drift [s/s]."""

    bias_s: float
    drift_s_s: float


@dataclasses.dataclass(frozen=True)
class Scenario:
    """A validated scenario. Times BDT; angles in radians; start epoch (week, sow)."""

    name: str
    source: Path | None
    week: int
    sow: float
    duration_s: float
    seed: int
    lat: float
    lon: float
    height: float
    v_n: tuple[float, float, float]
    att: tuple[float, float, float]  # pitch, roll, yaw [rad]
    motion: tuple[dict[str, Any], ...]
    imu: ImuSpec
    satellites: SatelliteSpec
    signal: SignalSpec
    outages: tuple[Outage, ...]
    clock: ReceiverClock
    raw: dict[str, Any] = dataclasses.field(repr=False, compare=False)
    #: Truth receiver oscillator (``[oscillator]``); None: the ``[receiver_clock]`` line only.
    oscillator: OscillatorSpec | None = None
    #: The ``[assume]`` table as given (what a filter believes; validated by its consumers,
    #: :func:`sdr_di.integration.assumptions.parse_assumptions`); never part of ``raw``, the
    #: hash or any generated file.
    assume: dict[str, Any] | None = dataclasses.field(default=None, compare=False)
    #: Jammers (``[[interference]]``), multipath replicas (``[[multipath]]``) and the
    #: front-end AGC (``[agc]``; None: its defaults): :mod:`sdr_di.scenario.impairments`.
    interference: tuple = ()
    multipath: tuple = ()
    agc: Any = None
    #: Truth atmosphere (``[atmosphere]``); None: the table is absent (truth = model).
    atmosphere: AtmosphereSpec | None = None

    @property
    def hash(self) -> str:
        """SHA-256 (hex, first 16 characters) of the canonical scenario content."""
        canon = json.dumps(self.raw, sort_keys=True, default=str).encode()
        return hashlib.sha256(canon).hexdigest()[:16]

    def with_overrides(self, **kw: Any) -> "Scenario":
        """Return a copy with CLI overrides applied and re-validated.

        Accepted keys: ``duration_s``, ``seed``, ``sampling_rate_hz``, ``if_hz``,
        ``kind``, ``sample_format``, ``quantization_bits``, ``cn0_dbhz``, ``ephemeris``,
        ``prns``. A relative ``ephemeris`` path is taken relative to the working directory.
        """
        raw = json.loads(json.dumps(self.raw, default=str))
        sec = OVERRIDE_KEYS
        for key, value in kw.items():
            if value is None:
                continue
            if key not in sec:
                raise ScenarioError(f"unknown scenario override {key!r}")
            table, name = sec[key]
            if key == "ephemeris":
                value = str(Path(value).resolve())
            raw.setdefault(table, {})[name] = value
        base = self.source.parent if self.source is not None else Path.cwd()
        return dataclasses.replace(parse_scenario(raw, source=self.source, base_dir=base),
                                   assume=self.assume)


#: Keys of :meth:`Scenario.with_overrides`: ``{key: (table, name)}`` of the scenario file.
OVERRIDE_KEYS: dict[str, tuple[str, str]] = {
    "duration_s": ("scenario", "duration_s"),
    "seed": ("scenario", "seed"),
    "sampling_rate_hz": ("signal", "sampling_rate_hz"),
    "if_hz": ("signal", "if_hz"),
    "kind": ("signal", "kind"),
    "sample_format": ("signal", "sample_format"),
    "quantization_bits": ("signal", "quantization_bits"),
    "cn0_dbhz": ("satellites", "cn0_dbhz"),
    "ephemeris": ("satellites", "ephemeris"),
    "prns": ("satellites", "prns"),
}


def with_flag_names(exc: SdrDiError, scenario: Scenario,
                    flags: dict[str, str]) -> SdrDiError:
    """``exc`` (from :meth:`Scenario.with_overrides`) naming the command-line flag that set
    the value, not the scenario file's key.

    Parameters
    ----------
    exc : ScenarioError or UnknownPrnError
        The error, ``"<scenario file>: [table].key: ..."``.
    scenario : Scenario
        The scenario the overrides were applied to (its file is the message's prefix).
    flags : dict
        ``{override key: flag}`` of the overrides given (``{"if_hz": "--if"}``).

    Returns
    -------
    SdrDiError
        Of ``exc``'s class: ``"--if: must be <= 2.25e+06, got 2e+07"``; ``exc`` itself when
        the key at fault was not set by a flag.
    """
    msg = str(exc)
    prefix = f"{scenario.source}: " if scenario.source is not None else ""
    if "for real sampling" in msg and "sample_format" in flags and "if_hz" not in flags:
        return ScenarioError(f"{flags['sample_format']}: real samples need an IF > 0: give "
                             f"--if (the scenario {scenario.source} has [signal].if_hz = "
                             f"{scenario.raw.get('signal', {}).get('if_hz', 0)})")
    for key, flag in flags.items():
        table, name = OVERRIDE_KEYS[key]
        token = f"[{table}].{name}"
        if token in msg:
            return type(exc)(msg.removeprefix(prefix).replace(token, flag, 1))
    return exc


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a TOML scenario file.

    Raises
    ------
    ScenarioError
        The file is missing, not TOML, or any key is missing, of the wrong type or impossible.
    """
    from ..paths import read_toml

    path = Path(path)
    raw = read_toml(path, "scenario", ScenarioError)
    return parse_scenario(raw, source=path, base_dir=path.parent)


class _Reader:
    """Typed access to one TOML table with errors naming file and key."""

    def __init__(self, table: Any, where: str):
        if not isinstance(table, dict):
            raise ScenarioError(f"{where}: expected a table")
        self.t = table
        self.where = where
        self.used: set[str] = set()

    def _get(self, key: str, default: Any) -> Any:
        self.used.add(key)
        if key not in self.t:
            if default is _REQUIRED:
                raise ScenarioError(f"{self.where}: missing key {key!r}")
            return default
        return self.t[key]

    def num(self, key: str, default: Any = None, *, lo: float | None = None,
            hi: float | None = None, lo_open: bool = False) -> float:
        v = self._get(key, default)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ScenarioError(f"{self.where}.{key}: expected a finite number, got {v!r}")
        v = float(v)
        if lo is not None and (v < lo or (lo_open and v == lo)):
            op = ">" if lo_open else ">="
            raise ScenarioError(f"{self.where}.{key}: must be {op} {lo:g}, got {v:g}")
        if hi is not None and v > hi:
            raise ScenarioError(f"{self.where}.{key}: must be <= {hi:g}, got {v:g}")
        return v

    def int_(self, key: str, default: Any = None, *, lo: int | None = None,
             hi: int | None = None) -> int:
        v = self._get(key, default)
        if isinstance(v, bool) or not isinstance(v, int):
            raise ScenarioError(f"{self.where}.{key}: expected an integer, got {v!r}")
        if (lo is not None and v < lo) or (hi is not None and v > hi):
            raise ScenarioError(f"{self.where}.{key}: must be in [{lo}, {hi}], got {v}")
        return v

    def str_(self, key: str, default: Any = None, choices: tuple[str, ...] | None = None) -> str:
        v = self._get(key, default)
        if not isinstance(v, str):
            raise ScenarioError(f"{self.where}.{key}: expected a string, got {v!r}")
        if choices is not None and v not in choices:
            raise ScenarioError(f"{self.where}.{key}: {v!r} is not one of {', '.join(choices)}")
        return v

    def vec3(self, key: str, default: Any = None) -> tuple[float, float, float]:
        v = self._get(key, default)
        if (not isinstance(v, list) or len(v) != 3
                or not all(isinstance(x, (int, float)) and not isinstance(x, bool)
                           and math.isfinite(x) for x in v)):
            raise ScenarioError(f"{self.where}.{key}: expected 3 finite numbers, got {v!r}")
        return (float(v[0]), float(v[1]), float(v[2]))

    def check_unknown(self) -> None:
        extra = sorted(set(self.t) - self.used)
        if extra:
            raise ScenarioError(f"{self.where}: unknown key(s) {', '.join(map(repr, extra))}")


_REQUIRED = object()


def _parse_prn(value: Any, where: str) -> int:
    """Accept 21, "21" or "C21"; return the PRN number 1..63 (errors name ``where``)."""
    from ..errors import UnknownPrnError

    try:
        return parse_prn(value)
    except UnknownPrnError as exc:
        raise UnknownPrnError(f"{where}: {exc}") from None


def _prn_or_all(r: _Reader, where: str) -> int | None:
    """A table's required ``prn``: a PRN (as :func:`_parse_prn`) or ``"all"`` (None)."""
    p = r._get("prn", _REQUIRED)
    return None if p == "all" else _parse_prn(p, f"{where}.prn")


def _parse_time(value: Any, scale: str, where: str) -> tuple[int, float]:
    if isinstance(value, _dt.datetime):
        t = value.replace(tzinfo=None)
    elif isinstance(value, str):
        try:
            t = _dt.datetime.fromisoformat(value.replace("Z", ""))
        except ValueError:
            raise ScenarioError(f"{where}: {value!r} is not an ISO date-time") from None
    else:
        raise ScenarioError(f"{where}: expected an ISO date-time, got {value!r}")
    try:
        return utc_to_bdt(t) if scale == "UTC" else datetime_to_bdt(t)
    except ValueError as exc:
        raise ScenarioError(f"{where}: {exc}") from None


def _parse_segment(seg: Any, i: int, where: str) -> dict[str, Any]:
    w = f"{where}.motion[{i}]"
    r = _Reader(seg, w)
    kind = r.str_("type", _REQUIRED, tuple(SEGMENT_KEYS))
    required, optional = SEGMENT_KEYS[kind]
    out: dict[str, Any] = {"type": kind}
    for key in required + optional:
        if key == "direction":
            out[key] = r.str_(key, _REQUIRED if key in required else None, ("left", "right"))
        elif key in required:
            out[key] = r.num(key, _REQUIRED)
        elif key in seg:
            out[key] = r.num(key)
    r.check_unknown()
    if out["duration_s"] <= 0:
        raise ScenarioError(f"{w}.duration_s: must be > 0, got {out['duration_s']:g}")
    if kind == "circle" and ("rate_dps" in out) == ("radius_m" in out):
        raise ScenarioError(f"{w}: give exactly one of rate_dps or radius_m")
    for key in ("decel_mps2", "rate_dps", "radius_m"):
        if key in out and out[key] <= 0:
            raise ScenarioError(f"{w}.{key}: must be > 0, got {out[key]:g}")
    return out


def parse_scenario(raw: dict[str, Any], *, source: Path | None = None,
                   base_dir: Path | None = None) -> Scenario:
    """Validate a scenario given as the parsed TOML dictionary.

    Parameters
    ----------
    raw : dict
        Parsed TOML (see ``docs/scenario.md``).
    source : Path, optional
        File the dictionary came from (for messages).
    base_dir : Path, optional
        Directory relative ephemeris paths are resolved against (the scenario's folder).
    """
    where = str(source) if source is not None else "scenario"
    if not isinstance(raw, dict):
        raise ScenarioError(f"{where}: expected TOML tables at the top level")
    known = {"scenario", "time", "start", "motion", "imu", "satellites", "signal", "outage",
             "receiver_clock", "oscillator", "assume", "interference", "multipath", "agc",
             "atmosphere"}
    extra = sorted(set(raw) - known)
    if extra:
        raise ScenarioError(f"{where}: unknown table(s) {', '.join(map(repr, extra))}")
    base_dir = base_dir or Path.cwd()

    sc = _Reader(raw.get("scenario", {}), f"{where}: [scenario]")
    name = sc.str_("name", "unnamed")
    duration = sc.num("duration_s", _REQUIRED, lo=0.0, lo_open=True)
    seed = sc.int_("seed", 0, lo=0)
    sc.check_unknown()

    tm = _Reader(raw.get("time"), f"{where}: [time]") if "time" in raw else None
    if tm is None:
        raise ScenarioError(f"{where}: missing table [time]")
    scale = tm.str_("scale", "BDT", ("BDT", "UTC"))
    week, sow = _parse_time(tm._get("start", _REQUIRED), scale, f"{where}: [time].start")
    tm.check_unknown()

    st = _Reader(raw.get("start", {}), f"{where}: [start]")
    lat = st.num("lat_deg", _REQUIRED, lo=-90.0, hi=90.0)
    lon = st.num("lon_deg", _REQUIRED, lo=-180.0, hi=360.0)
    h = st.num("height_m", 0.0, lo=-500.0, hi=1.0e5)
    v_n = st.vec3("velocity_enu_mps", [0.0, 0.0, 0.0])
    att_deg = st.vec3("attitude_pitch_roll_yaw_deg", [0.0, 0.0, 0.0])
    st.check_unknown()

    motion_raw = raw.get("motion", [])
    if not isinstance(motion_raw, list):
        raise ScenarioError(f"{where}: [[motion]] must be an array of tables")
    motion = tuple(_parse_segment(s, i, where) for i, s in enumerate(motion_raw))
    total = sum(s["duration_s"] for s in motion)
    if motion and total + 1e-9 < duration:
        # The last state is held: that is documented, not an error.
        pass

    im = _Reader(raw.get("imu", {}), f"{where}: [imu]")
    grade = im.str_("grade", "mems", tuple(IMU_GRADES))
    g = IMU_GRADES[grade]
    terms = {key: im.num(key, getattr(g, field), lo=0.0, lo_open=key.endswith("_tau_s"))
             for key, field in IMU_KEYS.items()}
    imu = ImuSpec(grade=grade, rate_hz=im.num("rate_hz", 200.0, lo=1.0, hi=10000.0), **terms)
    im.check_unknown()
    shortest = max(MIN_DURATION_S, 2.0 / imu.rate_hz)
    if duration < shortest:
        raise ScenarioError(
            f"{where}: [scenario].duration_s: must be >= {shortest:g} s (the shortest scenario: "
            f"{MIN_DURATION_S:g} s and two IMU intervals), got {duration:g}")

    sa = _Reader(raw.get("satellites", {}), f"{where}: [satellites]")
    eph = Path(sa.str_("ephemeris", _REQUIRED))
    if not eph.is_absolute():
        eph = (base_dir / eph).resolve()
    sel = sa._get("prns", "auto")
    if sel == "auto":
        prns = None
    elif isinstance(sel, list) and sel:
        for p in sel:
            _parse_prn(p, f"{where}: [satellites].prns")  # the message names the key
        prns = tuple(parse_prns(sel, f"{where}: [satellites].prns"))
    else:
        raise ScenarioError(f"{where}: [satellites].prns: expected \"auto\" or a list of PRNs")
    count = sa.int_("count", len(prns) if prns else 7, lo=1, hi=63)
    mask = sa.num("elevation_mask_deg", 10.0, lo=-5.0, hi=90.0)
    cn0 = sa.num("cn0_dbhz", 40.0, lo=0.0, hi=70.0)
    per = sa._get("cn0_per_prn", {})
    if not isinstance(per, dict):
        raise ScenarioError(f"{where}: [satellites].cn0_per_prn must be a table")
    cn0_per = {}
    for k, v in per.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 <= v <= 70:
            raise ScenarioError(f"{where}: [satellites].cn0_per_prn.{k}: expected 0..70 dB-Hz")
        cn0_per[_parse_prn(k, f"{where}: [satellites].cn0_per_prn")] = float(v)
    sa.check_unknown()
    satellites = SatelliteSpec(eph, prns, count, mask, cn0, cn0_per)

    sg = _Reader(raw.get("signal", {}), f"{where}: [signal]")
    fs = sg.num("sampling_rate_hz", 25.0e6, lo=1.0e6, hi=200.0e6)
    f_if = sg.num("if_hz", 0.0, lo=-fs / 2, hi=fs / 2)
    kind = sg.str_("kind", "complex", ("complex", "real"))
    fmt = sg.str_("sample_format", "iq_int8" if kind == "complex" else "real_int8",
                  SAMPLE_FORMATS)
    bits = sg.int_("quantization_bits", 4, lo=1, hi=16)
    iono = sg.str_("ionosphere", "klobuchar", ("klobuchar", "none"))
    tropo = sg.str_("troposphere", "saastamoinen", ("saastamoinen", "none"))
    chunk_ms = sg.int_("chunk_ms", 200, lo=1, hi=1000)
    sg.check_unknown()
    is_complex = kind == "complex"
    if fmt.startswith("iq") != is_complex:
        raise ScenarioError(
            f"{where}: [signal].sample_format {fmt!r} does not match kind {kind!r}")
    fmt_bits = {"iq_int8": 8, "real_int8": 8, "iq_int16": 16, "real_int16": 16, "iq_int4": 4}
    if bits > fmt_bits[fmt]:
        raise ScenarioError(
            f"{where}: [signal].quantization_bits {bits} does not fit format {fmt!r}")
    if not is_complex and f_if <= 0:
        raise ScenarioError(f"{where}: [signal].if_hz must be > 0 for real sampling")
    signal = SignalSpec(fs, f_if, is_complex, fmt, bits, iono, tropo, chunk_ms)

    outages_raw = raw.get("outage", [])
    if not isinstance(outages_raw, list):
        raise ScenarioError(f"{where}: [[outage]] must be an array of tables")
    outages = []
    for i, o in enumerate(outages_raw):
        w = f"{where}: [[outage]][{i}]"
        r = _Reader(o, w)
        prn = _prn_or_all(r, w)
        t0 = r.num("start_s", _REQUIRED, lo=0.0)
        t1 = r.num("end_s", _REQUIRED, lo=0.0)
        if t1 <= t0:
            raise ScenarioError(f"{w}: end_s ({t1:g}) must be after start_s ({t0:g})")
        blocked = r._get("blockage", False)
        if not isinstance(blocked, bool):
            raise ScenarioError(f"{w}.blockage: expected true or false")
        if blocked:
            if "attenuation_db" in o:
                raise ScenarioError(f"{w}: give blockage = true or attenuation_db, not both")
            att_db = math.inf
        else:
            att_db = r.num("attenuation_db", _REQUIRED, lo=0.0)
        r.check_unknown()
        outages.append(Outage(prn, t0, t1, att_db))

    ck = _Reader(raw.get("receiver_clock", {}), f"{where}: [receiver_clock]")
    clock = ReceiverClock(ck.num("bias_s", 0.0, lo=-1.0, hi=1.0),
                          ck.num("drift_s_s", 0.0, lo=-1e-4, hi=1e-4))
    ck.check_unknown()

    oscillator = None
    if "oscillator" in raw:
        oscillator = oscillator_from_table(raw["oscillator"], f"{where}: [oscillator]",
                                           ScenarioError)
    from .impairments import check_bands, parse_agc, parse_interference, parse_multipath

    jammers = parse_interference(raw.get("interference", []), where)
    check_bands(jammers, fs, f_if, is_complex, where)
    multipath = parse_multipath(raw.get("multipath", []), where)
    agc = parse_agc(raw.get("agc", {}), where)
    atmosphere = _parse_atmosphere(raw["atmosphere"], where) if "atmosphere" in raw else None
    assume = raw.get("assume")
    if assume is not None and not isinstance(assume, dict):
        raise ScenarioError(f"{where}: [assume] must be a table")

    raw_canon = json.loads(json.dumps({k: v for k, v in raw.items() if k != "assume"},
                                      default=str))
    raw_canon.setdefault("satellites", {})["ephemeris"] = str(eph)
    return Scenario(
        name=name, source=source, week=week, sow=sow, duration_s=duration, seed=seed,
        lat=math.radians(lat), lon=math.radians(lon), height=h, v_n=v_n,
        att=tuple(math.radians(a) for a in att_deg),  # type: ignore[arg-type]
        motion=motion, imu=imu, satellites=satellites, signal=signal,
        outages=tuple(outages), clock=clock, raw=raw_canon, oscillator=oscillator,
        assume=assume, interference=jammers, multipath=multipath, agc=agc,
        atmosphere=atmosphere,
    )


def _parse_atmosphere(table: Any, where: str) -> AtmosphereSpec:
    """``[atmosphere]`` (:class:`AtmosphereSpec`; every key optional)."""
    r = _Reader(table, f"{where}: [atmosphere]")
    d = AtmosphereSpec()
    kw: dict[str, Any] = {"truth": r.str_("truth", d.truth, ("model", "residuals"))}
    for f in dataclasses.fields(AtmosphereSpec):
        if f.name != "truth":
            kw[f.name] = r.num(f.name, getattr(d, f.name), lo=0.0,
                               lo_open=f.name.endswith("_tau_s"))
    r.check_unknown()
    return AtmosphereSpec(**kw)
