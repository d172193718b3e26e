"""What the integration filter believes (``--assume FILE.toml``, a scenario's ``[assume]``),
kept apart from the truth the files were generated with (DESIGN section 7; docs/assumptions.md).

An assumptions file has up to five tables, each optional; what is absent keeps the
consumer's own default (``IntegrationConfig`` for ``run``, ``[lc]``/``LcSettings`` for ``lc``)::

    [imu]                  # filter Q and P0 of the IMU states
    grade = "mems"         # a grade of sdr_di.ins.grades (its 1-sigma values); the terms
                           # below override
    accel_bias_mg, gyro_bias_deg_h, accel_random_walk_mps_sqrth, gyro_random_walk_deg_sqrth
    bias_time_s = 3600     # time for the bias random walk to reach the spec
    accel_scale_factor_ppm, gyro_scale_factor_ppm       # P0 of the scale-factor states
    accel_bias_instability_mg, gyro_bias_instability_deg_h, accel_bias_tau_s,
    gyro_bias_tau_s        # the Gauss-Markov biases (error_states=gm)

    [oscillator]           # filter Q of the clock states (sdr_di.oscillator)
    preset = "tcxo"        # ideal, tcxo, ocxo; h0, h_1 (h_-1), h_2 (h_-2) override

    [measurement_noise]    # the filter's R
    policy = "cn0"         # "cn0": as measured (deep: pre-filter variances from C/N0;
                           # lc: the GNSS receiver's nominal variances), or "fixed":
    sigma_range_m, sigma_rate_mps                      # fixed R of deep (and tight)
    sigma_pos_h_m, sigma_pos_v_m, sigma_vel_mps        # fixed R of lc

    [initial_covariance]   # P0 sigmas; E, N, U
    att_deg = [.., .., ..], vel_mps = [...], pos_m = [...], clock_bias_m, clock_drift_mps

    [initial_errors]       # injected into the INS at the alignment; E, N, U
    att_deg = [0, 0, 20]   # rotation vector (computed = exp(-[phi x]) true): U = heading
    vel_mps = [...], pos_m = [...]

Which keys change the filter's ``Q``: ``[imu]`` (random walks; bias specs with
``bias_time_s``) and ``[oscillator]``. ``P0``: ``[initial_covariance]``, and ``[imu]`` bias
specs. ``R``: ``[measurement_noise]``. The scale factors reach ``P0`` (and the small
``Q``) of the scale-factor states, and the in-run instabilities and correlation times the
Gauss-Markov biases, only with the filter option ``error_states`` (``sf``, ``gm``;
docs/filters.md); the 17-state filter does not use them. Misalignment and gyro
g-sensitivity have no filter state: refused, as is an oscillator's g-sensitivity.

Precedence (lowest to highest): the consumer's defaults; ``[lc]`` keys (lc only); the
scenario's ``[assume]`` table (lc and the experiments); ``--assume FILE`` (replaces the
scenario's ``[assume]`` as a whole: one source of belief per run); command-line options
that scale or name something (``--q-scale``, ``--r-scale`` multiply the assumed Q and R;
``--filter`` names the filter, which the assumptions never do). Assumptions never enter the
generated files, their sidecar or the scenario hash (:meth:`~sdr_di.scenario.schema.
Scenario.hash` covers the scenario without ``[assume]``).

API for callers (``run``, ``lc``, the experiments): :func:`load_assumptions`,
:func:`parse_assumptions`, :func:`apply_to_lc`, :func:`apply_to_deep` (any dataclass with
the :class:`~sdr_di.integration.receiver.IntegrationConfig` assumption fields), and
:meth:`Assumptions.record` for a run's summary.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import AssumptionsError
from ..ins.imu import ImuErrorModel
from ..oscillator import OscillatorSpec, oscillator_from_table
from ..ins.grades import IMU_GRADES

__all__ = [
    "ASSUME_TABLES",
    "Assumptions",
    "FixedNoiseSource",
    "apply_to_deep",
    "apply_to_lc",
    "deep_beliefs",
    "load_assumptions",
    "parse_assumptions",
    "resolve_assumptions",
    "sidecar_truth",
    "truth_record",
]

#: Tables of an assumptions file and their keys.
ASSUME_TABLES: dict[str, tuple[str, ...]] = {
    "imu": ("grade", "accel_bias_mg", "gyro_bias_deg_h", "accel_random_walk_mps_sqrth",
            "gyro_random_walk_deg_sqrth", "bias_time_s", "accel_scale_factor_ppm",
            "gyro_scale_factor_ppm", "accel_bias_instability_mg",
            "gyro_bias_instability_deg_h", "accel_bias_tau_s", "gyro_bias_tau_s"),
    "oscillator": ("preset", "h0", "h_1", "h_2"),
    "measurement_noise": ("policy", "sigma_range_m", "sigma_rate_mps", "sigma_pos_h_m",
                          "sigma_pos_v_m", "sigma_vel_mps"),
    "initial_covariance": ("att_deg", "vel_mps", "pos_m", "clock_bias_m", "clock_drift_mps"),
    "initial_errors": ("att_deg", "vel_mps", "pos_m"),
}
_WHY_REFUSED = {
    "g_sensitivity_per_g": "the filter has no g-sensitivity state (truth only: the scenario's "
                           "[oscillator])",
    **{key: "the filter has no state for it, with any error_states (truth only: the "
            "scenario's [imu])"
       for key in ("accel_misalignment_mrad", "gyro_misalignment_mrad",
                   "gyro_g_sensitivity_deg_h_per_g")},
}


@dataclasses.dataclass(frozen=True)
class Assumptions:
    """A parsed assumptions mapping; None = not given (the consumer's default stays).

    Attributes
    ----------
    source : str
        Where it came from (file name, or ``"<scenario> [assume]"``).
    imu : ImuErrorModel or None
        IMU spec for ``Q`` and ``P0`` (scale factors, instabilities and correlation times
        used with the filter option ``error_states`` only).
    bias_time_s : float or None
    oscillator : OscillatorSpec or None
    noise_policy : str or None
        ``"cn0"`` or ``"fixed"``.
    sigmas : dict
        Fixed-``R`` sigmas given (``sigma_range_m`` ... ``sigma_vel_mps``) [m, m/s].
    p0 : dict
        ``att_deg``, ``vel_mps``, ``pos_m`` (3-tuples, E, N, U), ``clock_bias_m``,
        ``clock_drift_mps`` given.
    init_errors : dict
        ``att_deg``, ``vel_mps``, ``pos_m`` (3-tuples, E, N, U) given.
    raw : dict
        The mapping as given (for the summary).
    """

    source: str = ""
    imu: ImuErrorModel | None = None
    bias_time_s: float | None = None
    oscillator: OscillatorSpec | None = None
    noise_policy: str | None = None
    sigmas: dict = dataclasses.field(default_factory=dict)
    p0: dict = dataclasses.field(default_factory=dict)
    init_errors: dict = dataclasses.field(default_factory=dict)
    raw: dict = dataclasses.field(default_factory=dict)

    @property
    def changes_q(self) -> bool:
        """Whether these assumptions change the filter's process noise ``Q``."""
        return self.imu is not None or self.bias_time_s is not None or (
            self.oscillator is not None)

    def record(self) -> dict:
        """Summary entry: the source and the mapping as given."""
        return {"source": self.source, **self.raw}


def _num(v: Any, where: str, *, lo: float = 0.0, open_: bool = False) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise AssumptionsError(f"{where}: expected a finite number, got {v!r}")
    if v < lo or (open_ and v == lo):
        raise AssumptionsError(f"{where}: must be {'>' if open_ else '>='} {lo:g}, got {v:g}")
    return float(v)


def _vec3(v: Any, where: str, *, nonneg: bool = False) -> tuple[float, float, float]:
    if (not isinstance(v, list) or len(v) != 3 or not all(
            isinstance(a, (int, float)) and not isinstance(a, bool) and math.isfinite(a)
            for a in v)):
        raise AssumptionsError(f"{where}: expected 3 finite numbers (E, N, U), got {v!r}")
    if nonneg and min(v) < 0:
        raise AssumptionsError(f"{where}: standard deviations must be >= 0, got {v!r}")
    return (float(v[0]), float(v[1]), float(v[2]))


def _table(raw: Mapping, name: str, where: str) -> dict:
    t = raw[name]
    w = f"{where} [{name}]"
    if not isinstance(t, Mapping):
        raise AssumptionsError(f"{w}: expected a table")
    for key in t:
        if key in _WHY_REFUSED:
            raise AssumptionsError(f"{w}.{key}: not an assumption ({_WHY_REFUSED[key]})")
        if key not in ASSUME_TABLES[name]:
            raise AssumptionsError(f"{w}: unknown key {key!r}; valid: "
                                   f"{', '.join(ASSUME_TABLES[name])}")
    return dict(t)


def parse_assumptions(raw: Mapping[str, Any], source: str = "assumptions") -> Assumptions:
    """Validate an assumptions mapping (module notes).

    Raises
    ------
    AssumptionsError
        An unknown table, key or preset, a negative sigma or h-parameter, a refused key (scale
        factor, g-sensitivity), a fixed policy without its sigmas; one line naming the key.
    """
    if not isinstance(raw, Mapping):
        raise AssumptionsError(f"{source}: expected TOML tables")
    extra = sorted(set(raw) - set(ASSUME_TABLES))
    if extra:
        raise AssumptionsError(f"{source}: unknown table(s) {', '.join(map(repr, extra))}; "
                               f"valid: {', '.join(ASSUME_TABLES)}")
    kw: dict[str, Any] = {"source": source, "raw": _plain(raw)}
    if "imu" in raw:
        t = _table(raw, "imu", source)
        w = f"{source} [imu]"
        grade = t.get("grade", "mems")
        if grade not in IMU_GRADES:
            raise AssumptionsError(f"{w}.grade: unknown IMU grade {grade!r}; valid: "
                                   f"{', '.join(IMU_GRADES)}")
        # the grade's 1-sigma values (ImuErrorModel fields) with the file's terms over them
        fields = {"accel_bias_mg": "accel_bias_mg", "gyro_bias_deg_h": "gyro_bias_deg_h",
                  "accel_random_walk_mps_sqrth": "accel_random_walk",
                  "gyro_random_walk_deg_sqrth": "gyro_random_walk",
                  **{k: k for k in ("accel_scale_factor_ppm", "gyro_scale_factor_ppm",
                                    "accel_bias_instability_mg",
                                    "gyro_bias_instability_deg_h")}}
        vals: dict[str, Any] = {field: _num(t[key], f"{w}.{key}")
                                for key, field in fields.items() if key in t}
        vals.update({key: _num(t[key], f"{w}.{key}", open_=True)
                     for key in ("accel_bias_tau_s", "gyro_bias_tau_s") if key in t})
        kw["imu"] = dataclasses.replace(IMU_GRADES[grade], **vals)
        if "bias_time_s" in t:
            kw["bias_time_s"] = _num(t["bias_time_s"], f"{w}.bias_time_s", open_=True)
    if "oscillator" in raw:
        t = raw["oscillator"]
        if isinstance(t, Mapping) and "g_sensitivity_per_g" in t:
            raise AssumptionsError(f"{source} [oscillator].g_sensitivity_per_g: not an "
                                   f"assumption ({_WHY_REFUSED['g_sensitivity_per_g']})")
        kw["oscillator"] = oscillator_from_table(t, f"{source} [oscillator]", AssumptionsError,
                                                 allow_g=False)
    if "measurement_noise" in raw:
        t = _table(raw, "measurement_noise", source)
        w = f"{source} [measurement_noise]"
        policy = t.pop("policy", "cn0")
        if policy not in ("cn0", "fixed"):
            raise AssumptionsError(f"{w}.policy: {policy!r} is not 'cn0' or 'fixed'")
        sig = {k: _num(v, f"{w}.{k}", open_=True) for k, v in t.items()}
        if policy == "cn0" and sig:
            raise AssumptionsError(f"{w}: {', '.join(sorted(sig))} given with policy 'cn0' "
                                   "(the sigmas are for policy = 'fixed')")
        if policy == "fixed" and not sig:
            raise AssumptionsError(f"{w}: policy 'fixed' needs sigma_range_m and "
                                   "sigma_rate_mps (deep) or sigma_pos_h_m, sigma_pos_v_m, "
                                   "sigma_vel_mps (lc)")
        kw["noise_policy"] = policy
        kw["sigmas"] = sig
    if "initial_covariance" in raw:
        t = _table(raw, "initial_covariance", source)
        w = f"{source} [initial_covariance]"
        p0 = {}
        for k, v in t.items():
            p0[k] = (_vec3(v, f"{w}.{k}", nonneg=True) if k in ("att_deg", "vel_mps", "pos_m")
                     else _num(v, f"{w}.{k}"))
        kw["p0"] = p0
    if "initial_errors" in raw:
        t = _table(raw, "initial_errors", source)
        w = f"{source} [initial_errors]"
        errs = {k: _vec3(v, f"{w}.{k}") for k, v in t.items()}
        if "att_deg" in errs and math.sqrt(sum(a * a for a in errs["att_deg"])) >= 180.0:
            raise AssumptionsError(f"{w}.att_deg: a rotation of {errs['att_deg']!r} deg is "
                                   "not below 180 deg")
        kw["init_errors"] = errs
    return Assumptions(**kw)


def _plain(raw: Mapping) -> dict:
    return {k: (_plain(v) if isinstance(v, Mapping) else v) for k, v in raw.items()}


def load_assumptions(path: str | Path) -> Assumptions:
    """Read and validate an assumptions TOML file (``--assume``).

    Raises
    ------
    AssumptionsError
        Unreadable file, not TOML, or a bad table/key (:func:`parse_assumptions`).
    """
    from ..paths import read_toml

    path = Path(path)
    raw = read_toml(path, "assumptions", AssumptionsError)
    return parse_assumptions(raw, str(path))


# ------------------------------------------------------------------------------------------

def _fixed_sigmas(a, need: tuple[str, ...], where: str, what: str, needs: str
                  ) -> tuple[float, ...]:
    """The ``need`` sigmas of a ``policy = "fixed"`` noise table, in order; a sigma the
    command has no measurement for, or a missing one, is one error naming the key."""
    bad = sorted(set(a.sigmas) - set(need))
    if bad:
        raise AssumptionsError(f"{where} [measurement_noise].{bad[0]}: not {what}: "
                               f"{', '.join(need)})")
    miss = [k for k in need if k not in a.sigmas]
    if miss:
        raise AssumptionsError(f"{where} [measurement_noise]: {needs} {', '.join(miss)}")
    return tuple(a.sigmas[k] for k in need)

def apply_to_lc(settings, a: Assumptions):
    """``LcSettings`` with the assumptions applied over its ``[lc]`` values (module notes).

    The filter's IMU spec (``imu_model`` of :func:`~sdr_di.integration.loose.run_loose`) is
    returned beside it: ``(settings, imu or None)``.

    Raises
    ------
    AssumptionsError
        A fixed measurement-noise policy without the lc sigmas, or a deep-only key
        (``sigma_range_m``, ``sigma_rate_mps``; the lc filter has no clock measurement, so an
        ``[oscillator]`` assumption changes nothing there and is refused too).
    """
    where = a.source
    if a.oscillator is not None:
        raise AssumptionsError(f"{where} [oscillator]: lc has no clock measurement (its "
                               "clock states are unobserved); remove the table for lc")
    kw: dict[str, Any] = {}
    if a.bias_time_s is not None:
        kw["bias_time_s"] = a.bias_time_s
    if a.noise_policy == "fixed":
        kw["assumed_r_sigmas"] = _fixed_sigmas(
            a, ("sigma_pos_h_m", "sigma_pos_v_m", "sigma_vel_mps"), where,
            "an lc measurement (lc sigmas", "policy 'fixed' for lc needs")
    elif a.noise_policy == "cn0":
        kw["assumed_r_sigmas"] = None
    arcmin = 60.0
    e = a.init_errors
    if "att_deg" in e:
        kw["init_att_err_arcmin"] = tuple(v * arcmin for v in e["att_deg"])
    if "vel_mps" in e:
        kw["init_vel_err_mps"] = e["vel_mps"]
    if "pos_m" in e:
        kw["init_pos_err_m"] = e["pos_m"]
    p = a.p0
    for k in ("clock_bias_m", "clock_drift_mps"):
        if k in p:
            raise AssumptionsError(f"{where} [initial_covariance].{k}: lc has no clock "
                                   "measurement; remove the key for lc")
    if "att_deg" in p:
        kw["p0_sigma_att_arcmin"] = tuple(v * arcmin for v in p["att_deg"])
    if "vel_mps" in p:
        kw["p0_sigma_vel_mps"] = p["vel_mps"]
    if "pos_m" in p:
        kw["p0_sigma_pos_m"] = p["pos_m"]
    return dataclasses.replace(settings, **kw), a.imu


def apply_to_deep(cfg, a: Assumptions):
    """A copy of an ``IntegrationConfig`` (or any dataclass with its assumption fields: ``imu``,
    ``bias_time_s``, ``clock``, ``noise_policy``, ``sigma_range_m``, ``sigma_rate_mps``,
    ``p0_att_deg``, ``p0_vel_mps``, ``p0_pos_m``, ``p0_clock``, ``init_att_err_deg``,
    ``init_vel_err_mps``, ``init_pos_err_m``, ``assumptions``) with ``a`` applied.

    Without an ``[initial_covariance]`` attitude (velocity, position) the ``P0`` sigma of an
    injected initial error is at least that error, so an assumed large heading error is also
    a believed one (give ``att_deg`` to make the filter over-confident on purpose).

    Raises
    ------
    AssumptionsError
        A fixed policy without ``sigma_range_m`` and ``sigma_rate_mps``, or an lc-only sigma.
    """
    where = a.source
    kw: dict[str, Any] = {"assumptions": a.record()}
    if a.imu is not None:
        kw["imu"] = a.imu
    if a.bias_time_s is not None:
        kw["bias_time_s"] = a.bias_time_s
    if a.oscillator is not None:
        kw["clock"] = a.oscillator
    if a.noise_policy is not None:
        kw["noise_policy"] = a.noise_policy
    if a.noise_policy == "fixed" and getattr(cfg, "mode", "deep") == "loose":
        raise AssumptionsError(f"{where} [measurement_noise].policy: 'fixed' is for deep and "
                               "tight (ranges and rates); loose mode uses its fixes' "
                               "covariance")
    if a.noise_policy == "fixed":
        kw["sigma_range_m"], kw["sigma_rate_mps"] = _fixed_sigmas(
            a, ("sigma_range_m", "sigma_rate_mps"), where,
            "a deep/tight measurement (their sigmas", "policy 'fixed' needs")
    e, p = a.init_errors, a.p0
    for key, field in (("att_deg", "init_att_err_deg"), ("vel_mps", "init_vel_err_mps"),
                       ("pos_m", "init_pos_err_m")):
        if key in e:
            kw[field] = e[key]
    if "att_deg" in p:
        kw["p0_att_deg"] = p["att_deg"]
    elif "att_deg" in e:
        kw["p0_att_deg"] = tuple(np.maximum(np.abs(e["att_deg"]), cfg.p0_att_deg))
    if "vel_mps" in p:
        kw["p0_vel_mps"] = p["vel_mps"]
    elif "vel_mps" in e:
        kw["p0_vel_mps"] = tuple(np.maximum(np.abs(e["vel_mps"]), 0.1))
    if "pos_m" in p:
        kw["p0_pos_m"] = p["pos_m"]
    elif "pos_m" in e:
        kw["p0_pos_m"] = tuple(np.abs(e["pos_m"]))  # floored by the fix's sigma
    if "clock_bias_m" in p or "clock_drift_mps" in p:
        kw["p0_clock"] = (p.get("clock_bias_m"), p.get("clock_drift_mps"))
    return dataclasses.replace(cfg, **kw)


class FixedNoiseSource:
    """A measurement source whose ``R`` is replaced by fixed sigmas (``[measurement_noise]
    policy = "fixed"``): ``sigma_range_m`` on the first half of ``z`` (ranges) and
    ``sigma_rate_mps`` on the second (range rates). Everything else is the wrapped source's.
    """

    def __init__(self, source, sigma_range_m: float, sigma_rate_mps: float) -> None:
        self._source = source
        self._sig = (float(sigma_range_m), float(sigma_rate_mps))

    def __getattr__(self, name: str):
        if name == "_source":          # not set yet (unpickling): nothing to delegate to
            raise AttributeError(name)
        return getattr(self._source, name)

    def measure(self, loop, iv):
        return self._fixed(self._source.measure(loop, iv))

    def measure_launched(self, loop, iv):
        return self._fixed(self._source.measure_launched(loop, iv))

    def _fixed(self, m):
        if m is not None and m.z is not None and m.z.size:
            n = m.z.size // 2
            m.R = np.diag(np.r_[[self._sig[0] ** 2] * n, [self._sig[1] ** 2] * n])
        return m


def resolve_assumptions(scenario, path: str | Path | None = None) -> Assumptions | None:
    """The assumptions of a run: the file ``path`` (``--assume``) when given, else the
    scenario's ``[assume]`` table, else None (module notes: the file replaces the table)."""
    if path is not None:
        return load_assumptions(path)
    table = getattr(scenario, "assume", None)
    if table is None:
        return None
    return parse_assumptions(table, f"{scenario.source or 'scenario'} [assume]")


def truth_record(scenario) -> dict:
    """Summary entry of the truth a run was made against: the scenario's name, hash, seed,
    IMU spec, receiver clock and oscillator (never the ``[assume]`` table)."""
    osc = scenario.oscillator
    return {"scenario": scenario.name, "hash": scenario.hash, "seed": scenario.seed,
            "imu": scenario.imu.as_dict(),
            "receiver_clock": dataclasses.asdict(scenario.clock),
            "oscillator": None if osc is None else osc.as_dict()}


def deep_beliefs(cfg) -> dict:
    """Summary entry of what an ``IntegrationConfig``'s filter believed (after
    :func:`apply_to_deep`): IMU spec, bias time, oscillator (with the two-state coefficients
    its ``Q`` uses), measurement-noise policy, ``P0`` sigmas, initial errors and the mapping given."""
    from ..ins.error_model import ClockModel
    from ..oscillator import CLOCK_PRESETS

    osc = CLOCK_PRESETS[cfg.clock] if isinstance(cfg.clock, str) else cfg.clock
    cm = ClockModel.from_oscillator(osc)
    return {
        "imu": cfg.imu.as_dict(), "bias_time_s": cfg.bias_time_s,
        "oscillator": {**osc.as_dict(), "filter_h0": cm.h0, "filter_h_2": cm.h_2},
        "measurement_noise": {"policy": cfg.noise_policy, "sigma_range_m": cfg.sigma_range_m,
                              "sigma_rate_mps": cfg.sigma_rate_mps},
        "initial_covariance": {"att_deg": list(cfg.p0_att_deg),
                               "vel_mps": None if cfg.p0_vel_mps is None else list(
                                   cfg.p0_vel_mps),
                               "pos_m": None if cfg.p0_pos_m is None else list(cfg.p0_pos_m),
                               "clock": None if cfg.p0_clock is None else list(cfg.p0_clock)},
        "initial_errors": {"att_deg": list(cfg.init_att_err_deg),
                           "vel_mps": list(cfg.init_vel_err_mps),
                           "pos_m": list(cfg.init_pos_err_m)},
        "given": cfg.assumptions,
    }


def sidecar_truth(meta: Mapping | None) -> dict | None:
    """Summary entry of the truth of a generated file set, from its sidecar: scenario (name,
    hash, seed), receiver clock, oscillator, IMU spec (None for a file without a sidecar)."""
    if not meta:
        return None
    return {k: meta.get(k) for k in ("scenario", "receiver_clock", "oscillator", "imu")}
