"""Closed-loop loosely coupled INS/GNSS runs (papers 000, 003; DESIGN section 1).

Data flow of :func:`run_loose`::

    IMU (rate f_imu) --> StrapdownINS --(every 1/f_gnss s)--> filter predict (17-state
    nonlinear error model, :class:`~sdr_di.ins.error_model.InsErrorModel`, improved Euler over
    the interval with the INS state at its ends and the compensated IMU average)
    GNSS position/velocity = truth + noise (:class:`~.noise.GnssNoise`, scheduled variance)
    --> z = INS - GNSS (eq 13) --> filter update with the filter's R --> feedback:
    ``ins.correct(phi, dv, dp, eps, nabla)`` (and the scale factors with
    ``error_states=sf``) and every navigation/IMU error state reset to 0 (the clock states,
    unobserved, are kept).

Decisions
---------
* Filter rate = GNSS rate (default 1 Hz, papers 000/003). The IMU rate is the scenario's.
* Filter ``Q`` = ``q_scale`` x :func:`~sdr_di.ins.error_model.process_noise` of the
  scenario's IMU spec (random walks; bias random walk reaching the spec in ``bias_time_s``,
  or none with ``bias_noise = false``: the simulated biases are constants, so that is the
  true ``Q``, the form of paper 000 eq 57); ``q_scale = 16`` reproduces paper 000's wrong
  ``Q``. The clock states are carried (same
  layout as deep mode) but unobserved; their ``Q`` is tiny.
* Filter ``R`` = ``r_scale`` x nominal GNSS variances; the true noise follows the schedule
  (``r_windows``: paper 003's 16 R during 500-700 s). The filter is never told the schedule.
  An assumptions ``[measurement_noise] policy = "fixed"`` replaces the nominal variances by
  its ``sigma_pos_h_m``, ``sigma_pos_v_m``, ``sigma_vel_mps`` (``assumed_r_sigmas``); the
  simulated noise stays the ``[lc]`` one (truth).
* What the filter believes (IMU spec, ``R``, ``P0``, initial errors) can be given apart from
  the truth by an assumptions file (``--assume``) or the scenario's ``[assume]`` table
  (:mod:`~sdr_di.integration.assumptions`; they override the ``[lc]`` keys of the same
  meaning). Without them the filter's IMU spec is the scenario's ``[imu]`` (truth = belief).
* ``P0`` = diag of the squared ``p0_sigma_*`` (default: the initial errors, floored) and of
  the bias specs; a non-positive-definite ``P0`` is rejected by the filter
  (:class:`~sdr_di.errors.FilterError`).
* The INS starts from truth plus the initial errors (attitude error as a rotation vector,
  ``C(computed) = exp(-[phi x]) C(true)``).

Scenario files: the usual scenario tables plus an optional ``[lc]`` table read here (the
scenario schema rejects unknown tables, so ``[lc]`` is removed before validation). Keys (all
optional): ``filter``, ``gnss_rate_hz``, ``sigma_pos_h_m``, ``sigma_pos_v_m``,
``sigma_vel_mps``, ``r_windows = [[t0, t1, factor], ...]``, ``q_scale``, ``r_scale``,
``init_att_err_arcmin`` (3: E, N, U), ``init_vel_err_mps`` (3), ``init_pos_err_m`` (3: E, N, U),
``p0_sigma_att_arcmin``, ``p0_sigma_vel_mps``, ``p0_sigma_pos_m`` (3 each), ``bias_time_s``,
``bias_noise`` (bool), ``imu_draw`` ("gaussian" or "fixed"), and sub-tables
``[lc.options.<filter name>]`` of :func:`~sdr_di.filters.make_filter` options applied only
when that filter runs (e.g. ``[lc.options.ml-q-ukf] mask = [...]``).
"""

from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path

import numpy as np

from ..errors import ImuDataError, ScenarioError
from ..filters import filter_record, make_filter
from ..frames import radii_of_curvature
from ..filters.state import layout_of_options
from ..ins.error_model import NavState, correct_ins, process_noise, rotvec_to_dcm
from ..ins.imu import ImuErrorModel
from ..ins.mechanization import StrapdownINS
from ..scenario.schema import Scenario, parse_scenario
from ..coupling.measurements import LooseMeasurementModel, loose_measurement
from .filter_setup import error_state_model
from .consistency import (SD_COLUMNS, block_nis, consistency_summary, enu_blocks, formal_sd,
                          nees_per_dof)
from .metrics import nav_errors, summarize
from .noise import GnssNoise, NoiseWindow

__all__ = [
    "LcResult",
    "LcSettings",
    "lc_summary",
    "load_lc_scenario",
    "run_loose",
]

ARCMIN = math.radians(1.0 / 60.0)


@dataclasses.dataclass(frozen=True)
class LcSettings:
    """Settings of a loosely coupled run (see the module docstring for the ``[lc]`` keys)."""

    filter: str = "ekf"
    gnss_rate_hz: float = 1.0
    noise: GnssNoise = dataclasses.field(default_factory=GnssNoise)
    q_scale: float = 1.0
    r_scale: float = 1.0
    init_att_err_arcmin: tuple = (3.0, 3.0, 10.0)
    init_vel_err_mps: tuple = (0.3, 0.3, 0.3)
    init_pos_err_m: tuple = (5.0, 5.0, 8.0)
    p0_sigma_att_arcmin: tuple | None = None
    p0_sigma_vel_mps: tuple | None = None
    p0_sigma_pos_m: tuple | None = None
    bias_time_s: float = 3600.0
    bias_noise: bool = True
    imu_draw: str = "gaussian"
    filter_options: dict = dataclasses.field(default_factory=dict)
    options_by_filter: dict = dataclasses.field(default_factory=dict)
    #: Fixed ``R`` sigmas (horizontal, vertical position [m], velocity [m/s]) the filter
    #: assumes; None: the nominal variances of ``noise`` (module notes).
    assumed_r_sigmas: tuple | None = None

    def replace(self, **kw) -> LcSettings:
        return dataclasses.replace(self, **kw)


def _vec3(v, where):
    if (not isinstance(v, list) or len(v) != 3 or not all(
            isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
            for x in v)):
        raise ScenarioError(f"{where}: expected 3 finite numbers, got {v!r}")
    return tuple(float(x) for x in v)


def _parse_lc(table, where: str) -> LcSettings:
    if not isinstance(table, dict):
        raise ScenarioError(f"{where}: [lc] must be a table")
    t = dict(table)
    kw: dict = {}

    def num(key, lo_open=0.0):
        v = t.pop(key)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
                or v <= lo_open:
            raise ScenarioError(f"{where}: [lc].{key}: expected a number > {lo_open:g}, "
                                f"got {v!r}")
        return float(v)

    if "filter" in t:
        v = t.pop("filter")
        if not isinstance(v, str):
            raise ScenarioError(f"{where}: [lc].filter: expected a filter name")
        kw["filter"] = v
    for key in ("gnss_rate_hz", "q_scale", "r_scale", "bias_time_s"):
        if key in t:
            kw[key] = num(key)
    noise_kw = {}
    for key, name in (("sigma_pos_h_m", "sigma_h_m"), ("sigma_pos_v_m", "sigma_v_m"),
                      ("sigma_vel_mps", "sigma_vel_mps")):
        if key in t:
            noise_kw[name] = num(key)
    windows = []
    if "r_windows" in t:
        rw = t.pop("r_windows")
        if not isinstance(rw, list):
            raise ScenarioError(f"{where}: [lc].r_windows: expected [[t0, t1, factor], ...]")
        for i, w in enumerate(rw):
            a, b, c = _vec3(w, f"{where}: [lc].r_windows[{i}]")
            try:
                windows.append(NoiseWindow(a, b, c))
            except ValueError as exc:
                raise ScenarioError(f"{where}: [lc].r_windows[{i}]: {exc}") from None
    kw["noise"] = GnssNoise(windows=tuple(windows), **noise_kw)
    for key in ("init_att_err_arcmin", "init_vel_err_mps", "init_pos_err_m",
                "p0_sigma_att_arcmin", "p0_sigma_vel_mps", "p0_sigma_pos_m"):
        if key in t:
            v = _vec3(t.pop(key), f"{where}: [lc].{key}")
            if key.startswith("p0") and min(v) < 0:
                raise ScenarioError(f"{where}: [lc].{key}: standard deviations must be >= 0")
            kw[key] = v
    if "bias_noise" in t:
        v = t.pop("bias_noise")
        if not isinstance(v, bool):
            raise ScenarioError(f"{where}: [lc].bias_noise: expected true or false, got {v!r}")
        kw["bias_noise"] = v
    if "options" in t:
        from ..filters import FILTER_NAMES

        opts = t.pop("options")
        if not isinstance(opts, dict) or not all(isinstance(v, dict) for v in opts.values()):
            raise ScenarioError(f"{where}: [lc.options]: expected sub-tables "
                                "[lc.options.<filter name>]")
        bad = sorted(k for k in opts if k not in FILTER_NAMES)
        if bad:
            raise ScenarioError(f"{where}: [lc.options]: unknown filter(s) "
                                f"{', '.join(map(repr, bad))}; valid: {', '.join(FILTER_NAMES)}")
        kw["options_by_filter"] = {k: dict(v) for k, v in opts.items()}
    if "imu_draw" in t:
        v = t.pop("imu_draw")
        if v not in ("gaussian", "fixed"):
            raise ScenarioError(f"{where}: [lc].imu_draw: 'gaussian' or 'fixed', got {v!r}")
        kw["imu_draw"] = v
    if t:
        raise ScenarioError(f"{where}: [lc]: unknown key(s) {', '.join(map(repr, sorted(t)))}")
    return LcSettings(**kw)


def load_lc_scenario(path: str | Path) -> tuple[Scenario, LcSettings]:
    """Read a scenario TOML with an optional ``[lc]`` table.

    Raises
    ------
    ScenarioError
        Unreadable file, bad scenario or bad ``[lc]`` key.
    """
    from ..paths import read_toml

    path = Path(path)
    raw = read_toml(path, "scenario", ScenarioError)
    lc = raw.pop("lc", {})
    sc = parse_scenario(raw, source=path, base_dir=path.parent)
    return sc, _parse_lc(lc, str(path))


@dataclasses.dataclass
class LcResult:
    """Time series (one row per filter epoch, after feedback) and settings of a run.

    Attributes
    ----------
    t : (n,) epoch times [s]
    att_err : (n, 3) attitude error [deg] (E, N, U rotation vector)
    vel_err : (n, 3) velocity error [m/s] (ENU)
    pos_err : (n, 3) position error [m] (E, N, U)
    r_diag : (n, 6) the filter's R used at each update (after adaptation)
    r_true : (n, 6) the true noise variances
    q_diag : (n, n_states) the filter's Q used in each predict
    nis : (n,) normalized innovation squared
    filter_name : str
    sd : (n, 9) formal 1-sigma after the feedback, ENU: position [m], velocity [m/s],
        attitude [deg] (:func:`~sdr_di.integration.consistency.formal_sd`)
    nees : (n, 3) NEES per degree of freedom of position, velocity, attitude
    nis_blocks : (n, 2) NIS per degree of freedom of the velocity and position blocks
    elapsed_s : float
        Wall time of the run [s].
    adaptation_time_s : float
        Time spent in the filter's adaptive rule (``filter.rule.adaptation_time_s``) [s];
        NaN for a filter without a rule.
    filter_used : dict or None
        The built filter's record (:func:`~sdr_di.filters.filter_record`), the summary's
        ``assumptions.filter``.
    imu_estimate : dict
        The INS's IMU compensation at the end (``gyro_bias`` [rad/s], ``accel_bias``
        [m/s^2], ``gyro_scale``, ``accel_scale`` [-], each (3,)): the filter's estimates of
        the unit's errors, after the last feedback.
    P_last : (n_states, n_states) ndarray or None
        The filter's covariance after the last feedback (its 1-sigma of those estimates:
        ``sqrt`` of the diagonal at the layout's indices).
    """

    t: np.ndarray
    att_err: np.ndarray
    vel_err: np.ndarray
    pos_err: np.ndarray
    r_diag: np.ndarray
    r_true: np.ndarray
    q_diag: np.ndarray
    nis: np.ndarray
    filter_name: str
    elapsed_s: float = 0.0
    adaptation_time_s: float = math.nan
    filter_used: dict | None = None
    sd: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 9)))
    nees: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 3)))
    nis_blocks: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 2)))
    imu_estimate: dict = dataclasses.field(default_factory=dict)
    P_last: np.ndarray | None = None

    def metrics(self, t0: float | None = None, t1: float | None = None) -> dict:
        """RMSE / max of attitude [deg], velocity [m/s], position [m] (``t0 <= t <= t1``)."""
        return summarize(self.t, self.att_err, self.vel_err, self.pos_err, t0, t1)

    def consistency(self, t0: float | None = None, t1: float | None = None) -> dict:
        """NIS per block (``nis_vel``, ``nis_pos``) and NEES per quantity over the window of
        :meth:`metrics` (:func:`~sdr_di.integration.consistency.consistency_summary`)."""
        return consistency_summary("lc", self.t, self.nis_blocks, np.full(self.t.size, 3),
                                   self.t, self.nees, t0, t1)

    def write_csv(self, path: str | Path) -> Path:
        """Write the error time series (atomic: ``.part`` then rename)."""
        from ..io.atomic import atomic_open

        path = Path(path)
        cols = (["t", "att_e_deg", "att_n_deg", "att_u_deg", "vel_e", "vel_n", "vel_u",
                 "pos_e_m", "pos_n_m", "pos_u_m", "nis"]
                + [f"r{i}" for i in range(6)] + [f"r_true{i}" for i in range(6)]
                + list(SD_COLUMNS))
        sd = self.sd if self.sd.shape[0] == self.t.size else np.full((self.t.size, 9),
                                                                     math.nan)
        data = np.column_stack([self.t, self.att_err, self.vel_err, self.pos_err, self.nis,
                                self.r_diag, self.r_true, sd])
        with atomic_open(path, "w") as fh:
            label = (self.filter_used or {}).get("spec", self.filter_name)
            fh.write(f"# sdr-di lc errors, filter {label}; attitude deg, "
                     "velocity m/s, position m (E, N, U), R variances, formal 1-sigma\n")
            fh.write(",".join(cols) + "\n")
            np.savetxt(fh, data, delimiter=",", fmt="%.10g")
        return path


def min_lc_duration_s(settings: LcSettings) -> float:
    """Shortest run that gives a result [s]: one GNSS interval (``1 / gnss_rate_hz``, 1 s by
    default), the time to the first filter update; a shorter run has no epoch to report."""
    return 1.0 / settings.gnss_rate_hz


#: Longest loosely coupled run [s]: one hour holds about 0.3 GB of 200 Hz truth, IMU and error
#: rows in memory (``lc --duration 1e9`` ran silently, issue 49 item 5). A longer span is a
#: campaign of shorter runs.
MAX_LC_DURATION_S = 3600.0


def check_lc_duration(duration_s: float, settings: LcSettings, what: str) -> None:
    """``duration_s`` of an ``lc`` run (``what``: the option or key that set it) within
    [:func:`min_lc_duration_s`, :data:`MAX_LC_DURATION_S`].

    Raises
    ------
    ScenarioError
    """
    shortest = min_lc_duration_s(settings)
    if not (math.isfinite(duration_s) and duration_s >= shortest):
        raise ScenarioError(f"{what} must be >= {shortest:g} s (one GNSS interval: the "
                            f"first filter update), got {duration_s:g}")
    if duration_s > MAX_LC_DURATION_S:
        raise ScenarioError(f"{what} must be <= {MAX_LC_DURATION_S:g} s (one hour of 200 Hz "
                            f"rows is about 0.3 GB of memory), got {duration_s:g}")


def _check_inputs(truth, imu) -> None:
    if len(imu.t) != len(truth.t) or not np.allclose(imu.t, truth.t, atol=1e-6):
        raise ImuDataError(f"IMU record ({len(imu.t)} samples) and truth ({len(truth.t)} "
                           "samples) are not on the same time grid")
    if len(imu.t) < 2:
        raise ImuDataError("IMU record has fewer than 2 samples")


def run_loose(truth, imu, imu_model: ImuErrorModel, settings: LcSettings, *,
              seed: int = 0, duration_s: float | None = None) -> LcResult:
    """Run the closed-loop loosely coupled filter (module docstring).

    Parameters
    ----------
    truth : Truth
        Reference trajectory at the IMU rate (also the source of the simulated GNSS fixes).
    imu : ImuData
        Measured IMU on the same time grid.
    imu_model : ImuErrorModel
        IMU spec used for ``Q`` and ``P0`` (random walks, bias specs).
    settings : LcSettings
    seed : int
        Seed of the GNSS noise.
    duration_s : float, optional
        Stop after this many seconds.

    Raises
    ------
    FilterError
        Unknown filter name, bad option, non-positive-definite ``P0``.
    ImuDataError
        IMU and truth not on one grid.
    """
    t_start = time.perf_counter()
    _check_inputs(truth, imu)
    s = settings
    dt_imu = float(imu.t[1] - imu.t[0])
    n_per = round(1.0 / (s.gnss_rate_hz * dt_imu))   # whole IMU samples per GNSS epoch
    if n_per < 1:
        raise ImuDataError("GNSS rate above the IMU rate")
    dt_f = n_per * dt_imu
    t_end = imu.t[-1] if duration_s is None else min(imu.t[-1], imu.t[0] + duration_s)

    # ---- filter
    gyro_rw, accel_rw = imu_model.gyro_random_walk_si, imu_model.accel_random_walk_si
    gb, ab = imu_model.gyro_bias_si, imu_model.accel_bias_si
    options = {**s.options_by_filter.get(s.filter.strip().lower(), {}), **s.filter_options}
    layout = layout_of_options(options)
    process, q_terms, p0_extra = error_state_model(imu_model, layout)
    Q_model = process_noise(dt_f, gyro_random_walk_si=gyro_rw, accel_random_walk_si=accel_rw,
                            gyro_bias_si=gb, accel_bias_si=ab,
                            bias_time_s=s.bias_time_s if s.bias_noise else None,
                            with_clock=False, **q_terms)
    # keep Q positive definite on the IMU states even for a perfect IMU
    floor = np.r_[[1e-14] * 3, [1e-10] * 3, [0.0] * 3, [1e-20] * 3, [1e-16] * 3, 0.0, 0.0,
                  [0.0] * (layout.n - 17)]
    Q0 = s.q_scale * (Q_model + np.diag(floor))
    if s.assumed_r_sigmas is None:
        R0 = s.r_scale * s.noise.nominal_diag()
    else:
        sh, sv, svel = s.assumed_r_sigmas
        R0 = s.r_scale * np.array([svel**2] * 3 + [sh**2, sh**2, sv**2])
    lat0, h0 = float(truth.llh[0, 0]), float(truth.llh[0, 2])
    R_M, R_N = (float(r) for r in radii_of_curvature(lat0))
    att0 = np.array(s.init_att_err_arcmin) * ARCMIN
    vel0 = np.array(s.init_vel_err_mps)
    pe, pn, pu = s.init_pos_err_m
    dp0 = np.array([pn / (R_M + h0), pe / ((R_N + h0) * math.cos(lat0)), pu])

    def _sig(given, init, floor_):
        v = np.abs(np.array(init, float)) if given is None else np.array(given, float)
        return np.maximum(v, floor_) if given is None else v

    sa = _sig(s.p0_sigma_att_arcmin, s.init_att_err_arcmin, 1.0) * ARCMIN
    sv = _sig(s.p0_sigma_vel_mps, s.init_vel_err_mps, 0.1)
    sp = _sig(s.p0_sigma_pos_m, s.init_pos_err_m, 1.0)
    p0 = np.r_[sa**2, sv**2, (sp[1] / (R_M + h0))**2, (sp[0] / ((R_N + h0) * math.cos(lat0)))**2,
               sp[2]**2, [max(gb, 1e-7)**2] * 3, [max(ab, 1e-5)**2] * 3, 1.0, 0.01, p0_extra]
    meas = LooseMeasurementModel(truth.llh[0], n_states=layout.n)
    kf = make_filter(s.filter, process, meas, np.zeros(layout.n), np.diag(p0), Q0, R0,
                     dt=dt_f, **options)
    used = filter_record(kf, s.filter, options)

    # ---- INS
    C0 = rotvec_to_dcm(-att0) @ truth.C_b_n[0]
    ins = StrapdownINS(truth.llh[0] + dp0, truth.v_n[0] + vel0, C_b_n=C0, t=float(imu.t[0]))
    ins.set_previous_increments(imu.f_b[0], imu.w_ib_b[0], dt_imu)
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x4C43]))

    rows_t, A, V, P, RD, RT, QD, NIS = [], [], [], [], [], [], [], []
    SD, NEES, NISB = [], [], []
    k = 0
    n = len(imu.t)
    while k + n_per < n and imu.t[k + n_per] <= t_end + 1e-9:
        nav0 = NavState.from_ins(ins)
        fs = imu.f_b[k + 1:k + n_per + 1]
        ws = imu.w_ib_b[k + 1:k + n_per + 1]
        f_mean, w_mean = ins.compensate(fs.mean(axis=0), ws.mean(axis=0))
        ins.step_many(fs, ws, np.diff(imu.t[k:k + n_per + 1]))
        k += n_per
        tk = float(imu.t[k])
        process.set_interval(nav0, NavState.from_ins(ins), f_mean, w_mean)
        kf.predict(dt_f)
        g_llh, g_v = s.noise.sample(tk, truth.llh[k], truth.v_n[k], rng)
        z = loose_measurement(ins.llh, ins.v_n, g_llh, g_v)
        meas.set_epoch(ins.llh)
        kf.update(z)
        assert kf.R_used is not None      # set by every update
        x = kf.x.copy()
        correct_ins(ins, x, layout)
        x_clock = x[layout.clock]
        x = np.zeros_like(x)
        x[layout.clock] = x_clock          # unobserved, never fed back
        kf.x = x
        a, v, p = nav_errors(ins.llh, ins.v_n, ins.C_b_n, truth.llh[k], truth.v_n[k],
                             truth.C_b_n[k])
        rows_t.append(tk)
        A.append(a)
        V.append(v)
        P.append(p)
        RD.append(np.diagonal(kf.R_used).copy())
        RT.append(s.noise.true_diag(tk))
        QD.append(np.diagonal(kf.Q_used).copy())
        NIS.append(kf.nis)
        NISB.append(block_nis(kf.y, kf.S, 2))
        SD.append(formal_sd(kf.P, ins.llh))
        P_att, P_vel, P_pos = enu_blocks(kf.P, ins.llh)
        NEES.append([nees_per_dof(p, P_pos), nees_per_dof(v, P_vel),
                     nees_per_dof(np.radians(a), P_att)])
    return LcResult(t=np.array(rows_t), att_err=np.array(A).reshape(-1, 3),
                    vel_err=np.array(V).reshape(-1, 3), pos_err=np.array(P).reshape(-1, 3),
                    r_diag=np.array(RD).reshape(-1, 6), r_true=np.array(RT).reshape(-1, 6),
                    q_diag=np.array(QD).reshape(-1, layout.n), nis=np.array(NIS),
                    filter_name=kf.name, elapsed_s=time.perf_counter() - t_start,
                    adaptation_time_s=(kf.rule.adaptation_time_s if kf.rule is not None
                                       else math.nan), filter_used=used,
                    sd=np.array(SD).reshape(-1, 9), nees=np.array(NEES).reshape(-1, 3),
                    nis_blocks=np.array(NISB).reshape(-1, 2),
                    imu_estimate={k: getattr(ins, k).copy() for k in (
                        "gyro_bias", "accel_bias", "gyro_scale", "accel_scale")},
                    P_last=kf.P.copy())


def lc_summary(sc: Scenario, settings: LcSettings, filter_imu: ImuErrorModel, assumed,
               res: LcResult, *, seed: int) -> dict:
    """Summary of an ``lc`` run: metrics, the truth (scenario, IMU, GNSS noise) and what the
    filter assumed (its IMU spec, ``R``, ``P0`` sigmas, initial errors, scales, and the
    assumptions mapping given, if any)."""
    from ..io.json_values import json_safe
    from .assumptions import truth_record

    noise = settings.noise
    truth = truth_record(sc)
    truth["seed"] = seed
    truth["gnss_noise"] = {"sigma_pos_h_m": noise.sigma_h_m, "sigma_pos_v_m": noise.sigma_v_m,
                           "sigma_vel_mps": noise.sigma_vel_mps,
                           "windows": [dataclasses.astuple(w) for w in noise.windows]}
    r = settings.assumed_r_sigmas
    beliefs = {
        "imu": filter_imu.as_dict(), "bias_time_s": settings.bias_time_s,
        "bias_noise": settings.bias_noise, "q_scale": settings.q_scale,
        "r_scale": settings.r_scale,
        "measurement_noise": {"policy": "nominal" if r is None else "fixed",
                              **({} if r is None else dict(zip(
                                  ("sigma_pos_h_m", "sigma_pos_v_m", "sigma_vel_mps"), r)))},
        "initial_errors": {"att_arcmin": list(settings.init_att_err_arcmin),
                           "vel_mps": list(settings.init_vel_err_mps),
                           "pos_m": list(settings.init_pos_err_m)},
        "initial_covariance": {"att_arcmin": settings.p0_sigma_att_arcmin,
                               "vel_mps": settings.p0_sigma_vel_mps,
                               "pos_m": settings.p0_sigma_pos_m},
        "given": None if assumed is None else assumed.record(),
        "filter": res.filter_used,
    }
    return {"filter": res.filter_name,
            "metrics": json_safe(res.metrics()),
            "consistency": json_safe(res.consistency()),
            "truth": truth, "assumptions": beliefs}
