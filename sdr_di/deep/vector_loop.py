"""Deep (INS-aided vector tracking) receiver: scalar start-up, hand-over, federated loop.

Paper 004 Fig. 1, federated architecture. Data flow of :meth:`DeepReceiver.run`::

    scalar start-up (ScalarReceiver: acquisition, loops, NH/bit/frame sync, decoding, WLS PVT)
        --hand-over-->  for every interval [k0, k1) of T = 1 / filter_rate_hz:
    INS (200 Hz IMU) propagated over the interval  -> predicted P, Pc at k0 and k1
    (corrected INS position, clock states, orbits at transmit time, atmosphere: nco.py)
    -> code/carrier NCO commands of every handed-over channel -> correlators (numba, every
    1 ms code epoch of every channel in one kernel call) -> NH wipe-off -> pre-filters
    (prefilter.py) -> z = [c/f_code dtau_i, c/f_carr df_i] of the channels in the measurement
    vector (eq 7-9), R from the pre-filter covariances (eq 34) -> integration filter (any
    name of the filter family, 17 states, eq 1-12) predict + update -> closed-loop feedback to
    the INS (attitude, velocity, position, IMU biases) and the clock, error state reset ->
    the pre-filters shifted by the correction's projection on each channel (their NCOs move
    by it in the next interval).

Code: :meth:`DeepReceiver._vector_loop` hands over and runs the mode-independent
:class:`~sdr_di.integration.loop.IntegrationLoop` (INS propagation, filter predict/update,
closed-loop feedback, solution rows); :class:`VectorTracking` is deep mode's measurement
source in it (NCO commands, correlation, pre-filters and channel management, the NCO and
pre-filter share of the feedback, navigation data taken up). A loose or tight mode is
another measurement source, without the NCO feedback.

Decisions
---------
* **Filter rate** default 50 Hz (T = 20 ms): one D1 data bit, four 200 Hz IMU samples, the
  rate at which the NCO commands are refreshed from the corrected INS. Faster costs filter
  time without new information (the pre-filters already average the 1 ms epochs); slower
  lets the INS error (MEMS: 4 mg) grow between NCO corrections: at 10 Hz an uncorrected
  0.04 m/s^2 gives 2 mm of code and 0.017 Hz of carrier error, still small, so 10-50 Hz all
  work; ``--filter-rate`` sets it.
* **Hand-over** (from scalar tracking) once a valid WLS fix with velocity exists and every
  channel in ``TRACK`` has its transmit time and an ephemeris (decoded, or from the
  assistance navigation file, as paper 004 feeds its ephemerides to the receiver); after
  ``handover_wait_s`` without that, at least 4 such channels suffice. The clock bias/drift
  come from the fix; each channel's pre-filter starts from the scalar loop's code phase and
  Doppler relative to the INS prediction.
* **INS initial alignment**: ``align="truth"``: from the first record of the reference (the
  scenario's initial state, paper 004 Table 3) at the IMU start, then coasting on the IMU
  until the hand-over, where position and velocity are replaced by the WLS fix;
  ``align="gnss"``: at the hand-over from the fix velocity and the IMU (:func:`gnss_alignment`:
  heading along the velocity, tilt from the specific force with the turn's centripetal
  acceleration; the vehicle must move).
* **Time**: IMU sample ``i`` (BDT epoch in its header) is IF sample
  ``round((t_i + sow_imu0 - sow_if0) fs)``: the IMU is taken as time-stamped in the receiver
  clock's scale (exact for generated files, whose receiver clock defaults to BDT).
* **Coherent pre-filter blocks**: the pre-filters are fed sums of the 1 ms epochs over
  blocks that end at data-bit edges (known from the satellite-clock millisecond: D1 20 ms,
  NH wiped off; D2 2 ms) and at interval ends, at most ``coherent_ms``. A 20 ms block at
  25 dB-Hz has an SNR of 8 dB, where the arctangent and the envelope discriminators are
  near linear; a 1 ms epoch has -5 dB, where their gain collapses and the carrier estimate
  drifts off (tested in ``test_prefilter_coherent_blocks_track_a_weak_signal``). The price
  is the phase ambiguity: consecutive 20 ms blocks alias the frequency at 25 Hz, so a
  restarted pre-filter takes its frequency prior from the integration filter (below), not
  from a wide default.
* **Channel management**: C/N0 comes from bit-synchronous prompt sums
  (:class:`~sdr_di.deep.bit_power.BitPower`, known-noise estimator, ``cn0_window_ms`` =
  200 ms). A channel joins the measurement vector when that C/N0 is at least
  ``cn0_min_dbhz`` (20 dB-Hz) and stays while it is no more than ``cn0_hysteresis_db``
  (2 dB) below that, while its last 60 ms of bit sums read at least
  ``cn0_min_dbhz - fast_margin_db`` (17 dB-Hz: noise alone passes this test with
  probability 0.06, a 23 dB-Hz signal fails it on 2 % of the intervals, and such an
  interval is left out) and while its pre-filter's NIS passes a chi-square test at
  ``nis_p_min`` (1e-4: one false exclusion per channel every 3 min at 50 Hz). When the last
  120 ms also read below ``cn0_min_dbhz - loss_margin_db`` (14 dB-Hz) the channel is lost:
  its C/N0 window is emptied, so it rejoins only on a whole window of fresh bit sums, not
  on one still full of signal from before a blockage.
  Its NCOs stay driven by the INS, and its pre-filter restarts every interval while lost
  (frequency prior: the integration filter's rate uncertainty on that line of sight, at
  least 0.5 Hz), so it rejoins as soon as the signal is back, without an acquisition
  search. These thresholds were set on the ``weak-signal`` experiment (docs/experiments.md).
* **Navigation data** in force is decided by :class:`~sdr_di.receiver.navdata.
  NavDataInForce` (decoded data as it arrives, RINEX assistance before it). The hand-over
  waits up to ``iono_wait_s`` after the first fix for Klobuchar coefficients, then goes
  ahead with a :class:`~sdr_di.receiver.navdata.NavDataWarning`. After it, every channel
  keeps decoding its message (:mod:`~sdr_di.deep.navdecode`); a new ephemeris or
  ionosphere model is taken up at the end of the interval in which it was decoded
  (:func:`_take_up_model_change`: the state moves by the least-squares projection of the
  range-model step, the pre-filters by the rest; reasons in docs/deep.md).
* **Process noise** from the IMU spec (random walks; bias random walk reaching the spec in
  ``bias_time_s``), default paper 004 Table 4 (MEMS); clock: TCXO (:class:`ClockModel`).
"""

from __future__ import annotations

import dataclasses
import math
import time
import warnings
from collections.abc import Callable

import numba
import numpy as np

from ..constants import C_LIGHT, CHIP_RATE_B3I, CODE_LENGTH_B3I, LAMBDA_B3I
from ..errors import ImuDataError, SdrDiError
from ..filters import make_filter
from ..frames import ecef_to_llh, llh_to_ecef, radii_of_curvature
from ..ins.error_model import ClockModel, InsErrorModel, process_noise
from ..ins.imu import ImuErrorModel
from ..ins.mechanization import StrapdownINS
from ..integration.loop import IntegrationLoop, Interval, Measurements
from ..integration.measurements import RangeRateMeasurementModel
from ..integration.metrics import summarize
from ..receiver._numba_correlate_bits import correlate_epl_bits, mean_power
from ..receiver.correlator import (
    CODE_PAD,
    bit_windows,
    carrier_rotation,
    kernel_tasks,
    padded_replicas,
    reduce_code_phase,
)
from ..receiver.ifreader import IfSource
from ..receiver.navdata import NavDataInForce, NavDataWarning
from ..receiver.observables import ReceiverTime
from ..receiver.pvt import PvtEngine
from ..receiver.scalar import ScalarReceiver
from ..receiver.threads import KernelThreads
from ..receiver.tracking import ChannelState
from ..signal.codes import NH20, b3i_code
from ..signal.navmsg import klobuchar_of_subframe
from .bit_power import BitPower
from .navdecode import ChannelNavDecoder
from .nco import nco_commands, predict_ranges
from .prefilter import PreFilterBank

__all__ = ["DeepConfig", "DeepReceiver", "DeepResult", "HandoverError"]

_CLOCKS = {"tcxo": ClockModel(h0=2e-19, h_2=2e-20), "ocxo": ClockModel(h0=8e-20, h_2=4e-23)}
_FAST_MS = 60        # bit sums of the fast test (interval left out) [ms]
_LOSS_MS = 120       # bit sums of the loss test [ms]
_CN0_MIN_MS = 40     # bit sums before the loop's own C/N0 replaces the scalar loop's [ms]
_SIGMA_F_MIN = 0.5   # floor of a restarted pre-filter's frequency sigma [Hz]


class HandoverError(SdrDiError):
    """The scalar start-up never reached a state the vector loop can take over."""


@dataclasses.dataclass
class DeepConfig:
    """Settings of the deep receiver (module notes give the reasons for the defaults).

    Attributes
    ----------
    filter : str
        Integration filter (registry name, :data:`sdr_di.filters.FILTER_NAMES`).
    filter_rate_hz : float
        Integration-filter and NCO-command rate [Hz]; must divide the IMU rate.
    output_rate_hz : float
        Solution rows [Hz] (paper 004: 5 Hz).
    align : str
        ``"truth"`` or ``"gnss"`` (module notes).
    handover_wait_s : float
        Seconds after the first fix to wait for every tracked channel before handing over
        with at least 4.
    cn0_min_dbhz, cn0_hysteresis_db, cn0_window_ms, fast_margin_db, loss_margin_db, nis_p_min
        Channel management (module notes): C/N0 gate [dB-Hz] and its hysteresis [dB], C/N0
        window [ms], the thresholds of the 60 ms and 120 ms tests below the gate [dB], and
        the pre-filter NIS test's false-alarm probability.
    coherent_ms : int
        Longest coherent pre-filter block [ms] (module notes); blocks never cross a data
        bit, so D1 channels use at most 20 ms and D2 channels 2 ms. 1 = one update per
        code epoch.
    imu : ImuErrorModel
        IMU spec for ``Q`` and ``P0`` (random walks, biases; default paper 004 Table 4).
    bias_time_s : float
        Time for the bias random walk to reach the spec [s].
    clock : str
        Receiver oscillator model of the clock states' process noise (paper 004 eq 4):
        ``"tcxo"`` (h0 = 2e-19 s, h-2 = 2e-20 1/s, the default) or ``"ocxo"`` (8e-20, 4e-23)
        (Allan-variance coefficients of Brown & Hwang).
    prefilter : dict
        Keyword arguments of :class:`~sdr_di.deep.prefilter.PreFilterBank`.
    filter_options : dict
        Options of :func:`~sdr_di.filters.make_filter` (e.g. ``window`` of ``ff-aukf``).
    p0_att_deg : tuple
        Initial attitude sigmas (E, N, U) [deg] for ``align="truth"`` (``"gnss"`` uses
        (3, 3, 5) deg: the no-sideslip, coordinated-turn assumptions).
    chunk_ms : int
        Samples read per refill [ms].
    iono_wait_s : float
        Seconds after the first fix the hand-over waits for ionosphere coefficients (from the
        assistance file or the signal) before it goes ahead without them, with a warning;
        the loop switches the model on when they are decoded (module notes).
    """

    filter: str = "ff-aukf"
    filter_rate_hz: float = 50.0
    output_rate_hz: float = 5.0
    align: str = "truth"
    handover_wait_s: float = 6.0
    cn0_min_dbhz: float = 20.0
    cn0_window_ms: int = 200
    fast_margin_db: float = 3.0
    loss_margin_db: float = 6.0
    cn0_hysteresis_db: float = 2.0
    nis_p_min: float = 1e-4
    imu: ImuErrorModel = dataclasses.field(default_factory=ImuErrorModel)
    bias_time_s: float = 3600.0
    clock: str = "tcxo"
    prefilter: dict = dataclasses.field(default_factory=dict)
    filter_options: dict = dataclasses.field(default_factory=dict)
    p0_att_deg: tuple = (0.05, 0.05, 0.1)
    chunk_ms: int = 200
    coherent_ms: int = 20
    iono_wait_s: float = 30.0

    def __post_init__(self) -> None:
        if self.clock not in _CLOCKS:
            raise ValueError(f"clock must be one of {', '.join(_CLOCKS)}, got {self.clock!r}")
        if self.align not in ("truth", "gnss"):
            raise ValueError(f"align must be 'truth' or 'gnss', got {self.align!r}")
        for name in ("filter_rate_hz", "output_rate_hz"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be > 0, got {v!r}")
        v = self.iono_wait_s
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
            raise ValueError(f"iono_wait_s must be >= 0, got {v!r}")


@dataclasses.dataclass
class DeepResult:
    """Output of a deep run (solution rows at the output rate, after feedback).

    Attributes
    ----------
    t : (n,) seconds since the IF file start (receiver clock)
    week, sow : BDT of each row (receiver time minus clock bias)
    llh : (n, 3) rad, rad, m;  v_n : (n, 3) ENU m/s;  att : (n, 3) pitch, roll, yaw [rad]
    clock_bias_m, clock_drift_mps : (n,)
    n_used : (n,) channels in the measurement vector
    att_err, vel_err, pos_err : (n, 3) errors vs the reference [deg, m/s, m ENU] (NaN
        without a reference)
    prns : handed-over PRNs;  used : (n, n_ch) bool, channel in the measurement vector
    cn0_dbhz : (n, n_ch)
    nis : (n,) integration-filter normalized innovation squared per measurement, averaged
        over the filter epochs since the previous row (about 1 when ``R`` is consistent)
    handover_s : time of the hand-over [s since file start]
    filter_name : str;  adaptation_s : float (time in the adaptive rule, if any)
    profile : dict (seconds per stage: scalar, read, nco, correlate, prefilter, filter, ins)
    nav_change : (n,) int, navigation data taken up since the previous row: 0 none, bit 1
        an ephemeris, bit 2 the ionosphere model
    navigation : dict, the navigation data in force over the run (summary ``navigation``
        entry, docs/deep.md)
    """

    t: np.ndarray
    week: int
    sow: np.ndarray
    llh: np.ndarray
    v_n: np.ndarray
    att: np.ndarray
    clock_bias_m: np.ndarray
    clock_drift_mps: np.ndarray
    n_used: np.ndarray
    att_err: np.ndarray
    vel_err: np.ndarray
    pos_err: np.ndarray
    prns: tuple
    used: np.ndarray
    cn0_dbhz: np.ndarray
    nis: np.ndarray
    handover_s: float
    filter_name: str
    adaptation_s: float
    profile: dict
    nav_change: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0, int))
    navigation: dict = dataclasses.field(default_factory=dict)

    def metrics(self, t0: float | None = None, t1: float | None = None) -> dict:
        """RMSE / max of the attitude [deg], velocity [m/s], position [m] error norms."""
        return summarize(self.t, self.att_err, self.vel_err, self.pos_err, t0, t1)


@dataclasses.dataclass
class _Chan:
    """Vector-loop state of one handed-over channel."""

    prn: int
    idx: int
    is_d1: bool
    eph: object
    next_start: int          # first sample of the next code epoch
    epoch: int               # its number (ms since S0)
    phase: float             # carrier NCO phase at next_start [cycles]
    power: BitPower          # recent bit sums of the prompts (C/N0, loss test)
    bit_ms: int = 20         # data bit [ms]: D1 20, D2 2
    cn0_dbhz: float = math.nan
    used: bool = True
    f_scalar: float = 0.0    # scalar loop Doppler at the hand-over [Hz]
    rejoining: bool = False  # lost: waits for a whole window of fresh prompts
    fast_fail: int = 0       # last tests: 0 pass, 1 fast test failed, 2 loss test too
    nav: ChannelNavDecoder | None = None   # navigation message after the hand-over


def _imu_offset_s(source: IfSource, imu) -> float:
    """IF-relative time of IMU ``t = 0`` [s]; checks the time tags."""
    if source.start_week is None or source.start_sow is None:
        if imu.week is not None:
            raise ImuDataError("IMU file has a BDT time tag but the IF file has none: give "
                               "--start-week/--start-sow for the IF file")
        return 0.0
    if imu.week is None or imu.sow is None:
        raise ImuDataError("IMU file has no BDT time tag (bdt_week_t0/bdt_sow_t0): cannot "
                           "align it with the IF file")
    return (imu.week - source.start_week) * 604800.0 + (imu.sow - source.start_sow)


def gnss_alignment(v_n, f_b, w_ib_b, g: float = 9.80) -> np.ndarray:
    """Body-to-ENU rotation from the GNSS velocity and the IMU at one instant (TRIAD).

    Assumes no sideslip (the velocity lies along the body Front axis) and a turn about the
    specific-force axis: the horizontal centripetal acceleration is ``omega x v`` with
    ``omega`` the gyro rate about the measured specific force, so the specific force in ENU
    is ``f_n = omega_up x v_n + (0, 0, g)``. TRIAD then pairs ``f_n`` with the measured
    ``f_b`` (primary: tilt, including the bank of a coordinated turn) and ``v_n`` with the
    Front axis (secondary: heading); ``omega_up`` is re-evaluated about the estimated Up axis
    (4 passes).

    Parameters
    ----------
    v_n : (3,) ENU velocity [m/s]; f_b : (3,) specific force [m/s^2] and w_ib_b : (3,)
        angular rate [rad/s], body Right-Front-Up, averaged around the instant.
    """
    v = np.asarray(v_n, float)
    fb = np.asarray(f_b, float)
    wb = np.asarray(w_ib_b, float)

    def frame(a, b):
        t1 = a / np.linalg.norm(a)
        t2 = np.cross(a, b)
        t2 /= np.linalg.norm(t2)
        return np.column_stack([t1, t2, np.cross(t1, t2)])

    up_b = fb / max(np.linalg.norm(fb), 1e-9)     # first guess of the Up axis in the body
    body = frame(fb, np.array([0.0, 1.0, 0.0]))
    for _ in range(4):                             # turn rate about the estimated Up axis
        w_up = float(np.dot(wb, up_b))
        C = frame(np.array([-w_up * v[1], w_up * v[0], g]), v) @ body.T
        up_b = C.T @ np.array([0.0, 0.0, 1.0])
    return C


class DeepReceiver:
    """INS-aided vector-tracking receiver (module notes).

    Parameters
    ----------
    config : DeepConfig, optional
    scalar : ScalarReceiver, optional
        Start-up receiver (default ``ScalarReceiver(log=False)``).
    """

    def __init__(self, config: DeepConfig | None = None, scalar: ScalarReceiver | None = None):
        self.config = config or DeepConfig()
        self.scalar = scalar or ScalarReceiver(log=False)
        self.profile: dict = {}

    # ------------------------------------------------------------------------------------
    def run(self, source: IfSource, imu, *, prns=None, nav=None, truth=None,
            progress: Callable[[float, int, int], None] | None = None,
            duration_s: float | None = None) -> DeepResult:
        """Run the deep receiver over ``source`` with the IMU record ``imu``.

        Parameters
        ----------
        source : IfSource
            IF samples (with a start time tag for generated files).
        imu : ImuData
            IMU record with its BDT epoch; must cover the IF file.
        prns : iterable of int, optional
            PRNs to search (default all 63).
        nav : NavData, optional
            Assistance navigation data (ephemerides and ionosphere before they are decoded).
        truth : Truth, optional
            Reference: needed for ``align="truth"``; gives the error columns when on the
            IMU time grid.
        progress : callable, optional
            ``progress(seconds_processed, n_channels, n_used)`` about once per second.
        duration_s : float, optional
            Stop after this many seconds of the file.

        Raises
        ------
        ImuDataError
            IMU time tags missing or inconsistent, IMU span not covering the IF file.
        FilterError
            Unknown filter name or option, non-positive-definite ``P0``.
        HandoverError
            No satellite found or no hand-over state reached.
        """
        cfg = self.config
        t_all = time.perf_counter()
        fs = source.sampling_rate_hz
        stop = source.n_samples if duration_s is None else min(
            source.n_samples, round(duration_s * fs))
        # ---- IMU / IF time consistency
        off = _imu_offset_s(source, imu)
        if_end = stop / fs
        dt_imu = 1.0 / imu.rate_hz
        if imu.t[0] + off > dt_imu + 1e-6 or imu.t[-1] + off < if_end - dt_imu - 1e-6:
            raise ImuDataError(
                f"IMU record spans {imu.t[0] + off:.3f}..{imu.t[-1] + off:.3f} s of the IF "
                f"file, which needs 0..{if_end:.3f} s (IMU/IF start times inconsistent or IMU "
                "file too short)")
        n_per = imu.rate_hz / cfg.filter_rate_hz
        if abs(n_per - round(n_per)) > 1e-9 or round(n_per) < 1:
            raise ValueError(f"filter rate {cfg.filter_rate_hz} Hz must divide the IMU rate "
                             f"{imu.rate_hz} Hz")
        n_per = round(n_per)
        # filter name check before the (long) start-up
        make_filter(cfg.filter, InsErrorModel(), RangeRateMeasurementModel(), np.zeros(17),
                    np.eye(17), np.eye(17), None, dt=1.0 / cfg.filter_rate_hz,
                    **cfg.filter_options)
        if cfg.align == "truth" and truth is None:
            raise ImuDataError("align='truth' needs the reference (truth) file; use "
                               "align='gnss' without one")

        # ---- scalar start-up until hand-over
        rx = self.scalar
        rt = None
        if source.start_week is not None and source.start_sow is not None:
            rt = ReceiverTime.from_sample_zero(fs, source.start_week, source.start_sow)
        engine = PvtEngine(fs, {}, None, rx_time=rt)
        navdata = NavDataInForce(nav)
        engine.navdata = navdata
        hand: dict = {}

        def on_epoch(sample, obs, ephs):
            if not obs:            # nothing tracked at this epoch: no fix, keep going
                return False
            navdata.offer_decoded(ephs, rx.klobuchar, sample / fs)
            if navdata.iono_source != "broadcast":
                _offer_subframe_klobuchar(rx, navdata, sample / fs)
            engine.ephemerides, engine.iono = navdata, navdata.klobuchar
            sol = engine.process(obs)
            if not sol.valid or not sol.velocity_valid:
                return False
            hand.setdefault("first_fix", sample)
            trk = [o for o in obs if o.state == ChannelState.TRACK.name]
            ok = [o for o in trk if o.time_valid and o.code_lock
                  and navdata.has(o.prn, sol.week, sol.sow)]
            since_fix = (sample - hand["first_fix"]) / fs
            waited = since_fix >= cfg.handover_wait_s
            if navdata.klobuchar is None and since_fix < cfg.iono_wait_s:
                return False       # wait for the ionosphere coefficients (module notes)
            if len(ok) >= 4 and (len(ok) == len(trk) or waited):
                if navdata.klobuchar is None:
                    warnings.warn(
                        f"deep: hand-over at {sample / fs:.1f} s without ionosphere "
                        f"coefficients ({navdata.assistance_iono_label} in the assistance "
                        f"data, none decoded after {since_fix:.1f} s): no ionosphere model "
                        "until subframe 1 is decoded", NavDataWarning, stacklevel=3)
                hand.update(sample=sample, sol=sol, prns=[o.prn for o in ok])
                return True
            return False

        t0 = time.perf_counter()
        rx.run(source, prns=prns, on_epoch=on_epoch, epoch_interval_s=0.1, stop_sample=stop)
        t_scalar = time.perf_counter() - t0
        if "sample" not in hand:
            found = [c.prn for c in rx.channels.values() if c.n_acquisitions > 0]
            raise HandoverError(
                f"{source.path}: no hand-over to the vector loop: " +
                ("no satellite found" if not found else
                 f"tracked {', '.join(f'C{p:02d}' for p in found)} but never 4 with time, "
                 "ephemeris and a valid fix"))
        return self._vector_loop(source, imu, off, n_per, stop, rx, engine, navdata,
                                 hand, truth, progress, t_scalar, t_all)

    # ------------------------------------------------------------------------------------
    def _vector_loop(self, source, imu, off, n_per, stop, rx, engine, navdata,
                     hand, truth, progress, t_scalar, t_all) -> DeepResult:
        """Hand-over from the scalar start-up and the vector loop to the end of the file.

        Hand-over: channels (:meth:`_handover_channels`), INS alignment (:meth:`_align_ins`),
        clock from the fix, integration filter (:meth:`_make_filter`), pre-filters from the
        scalar loops (:meth:`VectorTracking.start`). Then the mode-independent
        :class:`~sdr_di.integration.loop.IntegrationLoop` runs with
        :class:`VectorTracking` as its measurement source.
        """
        cfg = self.config
        fs = source.sampling_rate_hz
        sol = hand["sol"]
        k_h = int(hand["sample"])
        clock = _SampleClock.of(engine.builder.rx_time, fs)
        chans = self._handover_channels(rx, navdata, hand, clock)
        # ---- IMU grid: the loop starts on the first IMU sample after the hand-over
        dt_imu = 1.0 / imu.rate_hz
        t_if = imu.t + off                     # IF-relative time of each IMU sample
        i_h = int(np.searchsorted(t_if, max(k_h, max(c.next_start for c in chans)) / fs))
        i_h = max(i_h, 1)
        T = n_per * dt_imu
        k_grid0 = round(t_if[i_h] * fs)
        ins, llh_fix, att_sig = self._align_ins(imu, truth, sol, t_if, i_h, k_h / fs)
        clk_b = float(sol.clock_bias_m) + float(sol.clock_drift_mps) * (t_if[i_h] - k_h / fs)
        clk_d = float(sol.clock_drift_mps)
        kf, process, meas = self._make_filter(T, sol, llh_fix, att_sig)

        prof = {"scalar": t_scalar, "read": 0.0, "nco": 0.0, "correlate": 0.0,
                "prefilter": 0.0, "filter": 0.0, "ins": 0.0, "output": 0.0}
        tracking = VectorTracking(cfg, source, chans, navdata, clock, stop, prof,
                                  handover=(k_h / fs, sol.week, sol.sow),
                                  spacing_chips=self.scalar.config.spacing_chips)
        tracking.start(rx, ins, clk_b, k_grid0)
        n1 = round(fs * 1e-3)
        loop = IntegrationLoop(
            imu=imu, t_if=t_if, i_start=i_h, k_start=k_grid0, n_per=n_per, fs=fs, stop=stop,
            margin=2 * n1 + 16, ins=ins, clock_bias_m=clk_b, clock_drift_mps=clk_d, kf=kf,
            process=process, meas=meas, sow_of_sample=clock.sow,
            output_every=max(1, round(cfg.filter_rate_hz / cfg.output_rate_hz)), truth=truth,
            progress=progress, profile=prof)
        adapt0 = kf.adaptation_time_s
        try:
            loop.run(tracking)
        finally:
            tracking.close()
        k0 = loop.k0
        prof["total"] = time.perf_counter() - t_all
        prof["processed_s"] = k0 / fs
        prof["deep_s"] = (k0 - k_grid0) / fs
        prof["loop"] = sum(prof[k] for k in ("read", "nco", "correlate", "prefilter", "filter",
                                             "ins", "output"))
        prof["realtime_factor"] = prof["processed_s"] / prof["total"] if prof["total"] else 0.0
        self.profile = prof

        n_ch = len(chans)
        col = loop.columns(n_ch)
        return DeepResult(
            t=col["t"], week=clock.week, sow=col["sow"], llh=col["llh"], v_n=col["v"],
            att=col["att"], clock_bias_m=col["b"], clock_drift_mps=col["d"], n_used=col["n"],
            att_err=col["ae"], vel_err=col["ve"], pos_err=col["pe"],
            prns=tuple(c.prn for c in chans), used=col["used"], cn0_dbhz=col["cn0"],
            nis=col["nis"], handover_s=k_grid0 / fs, filter_name=kf.name,
            adaptation_s=kf.adaptation_time_s - adapt0, profile=prof,
            nav_change=col["nav"], navigation=tracking.nav_log.summary(k0 / fs))

    # ------------------------------------------------------------------------------------
    def _handover_channels(self, rx: ScalarReceiver, navdata: NavDataInForce, hand: dict,
                           clock: _SampleClock) -> list[_Chan]:
        """Vector-loop state of every handed-over channel, from its scalar channel: next
        code epoch (sample and number on the satellite clock), carrier phase, C/N0, the
        ephemeris in force at the fix and the navigation decoder with its subframe in
        progress."""
        cfg = self.config
        sol = hand["sol"]
        S0 = clock.S0
        chans: list[_Chan] = []
        for i, prn in enumerate(hand["prns"]):
            c = rx.channels[prn]
            s = int(c.next_start)
            o = c.observation_at(s)
            eph = navdata.select(prn, sol.week, sol.sow)
            e = round((o.t_tx_sow - S0) * 1000.0)
            bit_ms = 20 if c.is_d1 else 2
            chans.append(_Chan(prn=prn, idx=i, is_d1=c.is_d1, eph=eph, next_start=s, epoch=e,
                               phase=float(c.phi),
                               power=BitPower(max(cfg.cn0_window_ms // bit_ms, 2)),
                               bit_ms=bit_ms, cn0_dbhz=float(c.cn0_dbhz),
                               nav=_handover_decoder(c, e, round(S0 * 1000.0))))
        return chans

    def _align_ins(self, imu, truth, sol, t_if: np.ndarray, i_h: int, t_fix_s: float):
        """INS at IMU sample ``i_h`` (module notes, *INS initial alignment*).

        Position and velocity are the WLS fix moved to ``t_if[i_h]``; attitude from the
        reference (``align="truth"``, INS coasting on the IMU from the reference's first
        record) or from the fix velocity and the IMU (``"gnss"``, :func:`gnss_alignment`).

        Returns
        -------
        ins : StrapdownINS
        llh_fix : (3,) the fix position at ``t_if[i_h]`` [rad, rad, m]
        att_sig : (3,) initial attitude sigmas (E, N, U) [rad]
        """
        cfg = self.config
        dt_imu = 1.0 / imu.rate_hz
        r_fix = sol.r_e + sol.v_e * (t_if[i_h] - t_fix_s)
        llh_fix = ecef_to_llh(r_fix)
        if cfg.align == "truth":
            ins = StrapdownINS(truth.llh[0], truth.v_n[0], C_b_n=truth.C_b_n[0],
                               t=float(imu.t[0]))
            ins.set_previous_increments(imu.f_b[0], imu.w_ib_b[0], dt_imu)
            for i in range(1, i_h + 1):
                ins.step(imu.f_b[i], imu.w_ib_b[i], float(imu.t[i] - imu.t[i - 1]))
            ins.llh = np.array(llh_fix, float)
            ins.v_n = np.array(sol.v_n, float)
            att_sig = np.radians(np.asarray(cfg.p0_att_deg, float))
        else:
            v = np.asarray(sol.v_n, float)
            sp = math.hypot(v[0], v[1])
            if sp < 2.0:
                raise HandoverError(f"align='gnss' needs a moving receiver at the hand-over "
                                    f"(horizontal speed {sp:.2f} m/s < 2 m/s)")
            lo, hi = max(i_h - 10, 0), min(i_h + 11, len(imu.t))
            C0 = gnss_alignment(v, imu.f_b[lo:hi].mean(axis=0), imu.w_ib_b[lo:hi].mean(axis=0))
            ins = StrapdownINS(llh_fix, v, C_b_n=C0, t=float(imu.t[i_h]))
            ins.set_previous_increments(imu.f_b[i_h], imu.w_ib_b[i_h], dt_imu)
            att_sig = np.radians([3.0, 3.0, 5.0])
        return ins, llh_fix, att_sig

    def _make_filter(self, T: float, sol, llh_fix, att_sig):
        """Integration filter of the configured name over interval ``T`` [s].

        ``Q`` from the IMU spec and the clock model (:func:`~sdr_di.ins.error_model.
        process_noise`); ``P0``: the attitude sigmas ``att_sig``, 0.1 m/s, the fix's
        position sigma (at least 1 m; 1.5x for height and clock bias), the bias specs and
        0.1 m/s of clock drift.

        Returns
        -------
        kf, process (InsErrorModel), meas (RangeRateMeasurementModel, the filter's)
        """
        cfg = self.config
        gb, ab = cfg.imu.gyro_bias_si, cfg.imu.accel_bias_si
        Q0 = process_noise(T, gyro_random_walk_si=cfg.imu.gyro_random_walk_si,
                           accel_random_walk_si=cfg.imu.accel_random_walk_si,
                           gyro_bias_si=gb, accel_bias_si=ab, bias_time_s=cfg.bias_time_s,
                           clock=_CLOCKS[cfg.clock])
        lat0, h0 = float(llh_fix[0]), float(llh_fix[2])
        R_M, R_N = (float(r) for r in radii_of_curvature(lat0))
        cov = np.asarray(sol.cov, float)
        s_pos = math.sqrt(max(np.trace(cov[:3, :3]) / 3.0, 0.25)) if np.all(
            np.isfinite(cov[:3, :3])) else 2.0
        s_pos = max(s_pos, 1.0)
        p0 = np.r_[att_sig ** 2, [0.1 ** 2] * 3,
                   (s_pos / (R_M + h0)) ** 2, (s_pos / ((R_N + h0) * math.cos(lat0))) ** 2,
                   (1.5 * s_pos) ** 2, [gb ** 2] * 3, [ab ** 2] * 3, (1.5 * s_pos) ** 2,
                   0.1 ** 2]
        process = InsErrorModel(_CLOCKS[cfg.clock])
        meas = RangeRateMeasurementModel()
        kf = make_filter(cfg.filter, process, meas, np.zeros(17), np.diag(p0), Q0, None, dt=T,
                         **cfg.filter_options)
        return kf, process, meas


@dataclasses.dataclass(frozen=True)
class _SampleClock:
    """Receiver time of IF samples: ``sow(k) = S0 + t_rel(k)`` [s of BDT week ``week``].

    ``S0`` is the whole second before the receiver time of the reference sample ``k0`` (kept
    apart so that ``t_rel``, a few hundred seconds, keeps its sub-nanosecond resolution).
    """

    week: int
    S0: float
    base_rel: float
    k0: float
    fs: float

    @classmethod
    def of(cls, rt: ReceiverTime, fs: float) -> _SampleClock:
        S0 = math.floor(rt.sow0) - 1.0
        return cls(week=int(rt.week0), S0=S0, base_rel=rt.sow0 - S0, k0=rt.k0, fs=fs)

    def t_rel(self, k) -> float:
        """Receiver time of sample ``k`` minus ``S0`` [s]."""
        return self.base_rel + (k - self.k0) / self.fs

    def sow(self, k) -> float:
        """Receiver time of sample ``k`` [s of week]."""
        return self.S0 + self.t_rel(k)


@dataclasses.dataclass
class _EpochRows:
    """Correlator rows of one interval, all channels (one row per code epoch)."""

    reps: list               # rows of each channel
    starts: np.ndarray       # first sample of each epoch
    nsamp: np.ndarray        # samples of each epoch
    theta: np.ndarray        # code NCO phase at the start [chips]
    phi: np.ndarray          # carrier NCO phase at the start [cycles]
    dphi: np.ndarray         # carrier NCO frequency [cycles/sample]
    nh: np.ndarray           # NH20 sign (D1) or 1
    epoch: np.ndarray        # epoch number (ms since S0 on the satellite clock)
    dchip: np.ndarray        # code NCO rate of each channel [chips/sample]


class VectorTracking:
    """Deep mode's measurement source of the :class:`~sdr_di.integration.loop.
    IntegrationLoop`: the vector tracking loop of every handed-over channel.

    One interval, :meth:`measure`::

        command_ncos       predicted ranges at k1 from the propagated INS and clock, code and
                           carrier NCO commands, correlator rows of every channel's epochs
        load_samples       the IF samples the rows need (False: the file ends)
        correlate          E/P/L of every epoch of every channel (one numba kernel call), NH
                           wiped off
        prefilter          per channel: C/N0 tests and navigation decoding
                           (:meth:`_test_channel`), pre-filter, measurement-vector gate
                           (:meth:`_usable`) -> z, R (eq 7-9, 34)

    then :meth:`feed_back` (NCO ranges and pre-filters moved by the filter's correction,
    lost or inconsistent pre-filters restarted) and :meth:`take_up_navigation_data`.

    Parameters
    ----------
    cfg : DeepConfig
    source : IfSource
    chans : list of _Chan
        Handed-over channels (:meth:`DeepReceiver._handover_channels`).
    navdata : NavDataInForce
    clock : _SampleClock
    stop : int
        IF sample at which the data ends.
    profile : dict
        Seconds per stage (``nco``, ``read``, ``correlate``, ``prefilter``; the navigation
        take-up is charged to ``ins`` with the feedback).
    handover : (t_s, week, sow)
        Hand-over time [s since file start] and BDT of the fix.
    spacing_chips : float
        Early-late spacing of the scalar receiver's correlators [chips].
    """

    def __init__(self, cfg: DeepConfig, source: IfSource, chans: list, navdata: NavDataInForce,
                 clock: _SampleClock, stop: int, profile: dict, *, handover: tuple,
                 spacing_chips: float) -> None:
        self.cfg, self.source, self.chans, self.clock = cfg, source, chans, clock
        self.fs = source.sampling_rate_hz
        self.stop, self.profile = stop, profile
        self.n_channels = len(chans)
        self.iono = navdata.klobuchar
        self.ephs = [c.eph for c in chans]
        self.nav_log = _NavLog(navdata, chans, self.iono, *handover)
        self.pre = PreFilterBank(self.n_channels, spacing_chips, source.carrier_hz,
                                 **cfg.prefilter)
        self.bits = bit_windows(np.stack([padded_replicas(np.asarray(b3i_code(c.prn)))[0]
                                          for c in chans]))
        self.chan_idx = np.arange(self.n_channels, dtype=np.int64)
        self.kthreads = KernelThreads()
        self.threads_before = numba.get_num_threads()
        self.meas_all = RangeRateMeasurementModel()     # every channel: the feedback's H
        # sample buffer
        self.x_buf = np.empty(0, dtype=np.int8)
        self.n_comp = 2
        self.buf0 = self.buf1 = 0
        self.npow = 1.0
        self.chunk = max(4 * round(self.fs * 1e-3), round(cfg.chunk_ms * 1e-3 * self.fs))
        # NCO state: predicted ranges at k0 after the feedback, last carrier NCO step
        self.P_k0 = self.Pc_k0 = self.tau_prev = None
        self.dp_prev = None
        self._first = True
        self._pred = self._P1 = self._Pc1 = None

    # ------------------------------------------------------------------------------------
    def start(self, rx: ScalarReceiver, ins, clock_bias_m: float, k_start: int) -> None:
        """Predicted ranges at the loop's first sample ``k_start`` and every pre-filter from
        its scalar loop: code offset of the scalar loop from the INS prediction, 3 Hz
        frequency sigma (its Doppler is taken against the first NCO command)."""
        clock, ephs, iono, pre = self.clock, self.ephs, self.iono, self.pre
        week = clock.week
        r0 = llh_to_ecef(*ins.llh)
        pred0 = predict_ranges(ephs, week, [clock.sow(k_start)], [r0], [clock_bias_m], iono)
        self.P_k0, self.Pc_k0 = pred0.P[:, 0].copy(), pred0.Pc[:, 0].copy()
        for c in self.chans:
            sc = rx.channels[c.prn]
            s = c.next_start
            pr = predict_ranges([c.eph], week, [clock.sow(s)], [r0], [clock_bias_m], iono)
            chips_deep = CHIP_RATE_B3I * (clock.t_rel(s) - pr.P[0, 0] / C_LIGHT)
            dtau = c.epoch * CODE_LENGTH_B3I + float(sc.theta) - chips_deep
            pre.reset(c.idx, dtau=dtau, df=0.0, sigma_tau=0.1, sigma_phi=0.3, sigma_f=3.0)
            c.f_scalar = float(sc.fd)
        self.tau_prev = pred0.tau

    def close(self) -> None:
        """Give numba back the thread count it had before the loop."""
        numba.set_num_threads(self.threads_before)

    # ------------------------------------------------------------------------------------
    def measure(self, loop: IntegrationLoop, iv: Interval) -> Measurements | None:
        """NCO commands, correlation and pre-filters of interval ``iv`` (class notes)."""
        rows = self.command_ncos(iv)
        if not self.load_samples(rows):
            return None
        E, P, L = self.correlate(rows)
        return self.prefilter(iv, rows, E, P, L)

    def command_ncos(self, iv: Interval) -> _EpochRows:
        """Code and carrier NCO commands over ``[k0, k1)`` and the correlator rows.

        Ranges at ``k1`` are predicted from the propagated INS and clock (``iv.nav1``,
        ``iv.clock_bias_m``; :func:`~sdr_di.deep.nco.predict_ranges`); at ``k0`` they are the
        previous interval's, moved by its feedback (``pred_new = pred_old - H x``). On the
        first interval each pre-filter's frequency starts at the scalar loop's Doppler minus
        the INS prediction.
        """
        tb = time.perf_counter()
        clock, fs, k0, k1 = self.clock, self.fs, iv.k0, iv.k1
        r_b = llh_to_ecef(*iv.nav1.llh)
        pred = predict_ranges(self.ephs, clock.week, [clock.sow(k1)], [r_b],
                              [iv.clock_bias_m], self.iono, tau0=self.tau_prev, passes=1)
        self.tau_prev = pred.tau
        P1, Pc1 = pred.P[:, 0], pred.Pc[:, 0]
        cmd = nco_commands(self.P_k0, self.Pc_k0, P1, Pc1, k0, k1, fs, clock.t_rel(k0),
                           clock.t_rel(k1), self.source.carrier_hz)
        dchip = cmd.code_rate_cps / fs
        if self._first:
            for c in self.chans:
                # initial frequency error: scalar loop Doppler minus the INS prediction
                self.pre.x[c.idx, 2] = c.f_scalar - float(cmd.doppler_hz[c.idx])
            self._first = False
        dp1 = (self.source.if_hz + cmd.doppler_hz) / fs
        if self.dp_prev is None:
            self.dp_prev = dp1
        dp_prev = self.dp_prev
        parts = [_epoch_rows(c, float(cmd.chips0[c.idx]), float(dchip[c.idx]),
                             float(dp_prev[c.idx]), float(dp1[c.idx]), k0, k1)
                 for c in self.chans]
        self.dp_prev = dp1
        self._pred, self._P1, self._Pc1 = pred, P1, Pc1
        rows = _EpochRows(reps=[len(p[0]) for p in parts],
                          starts=np.concatenate([p[0] for p in parts]),
                          nsamp=np.concatenate([p[1] for p in parts]),
                          theta=np.concatenate([p[2] for p in parts]),
                          phi=np.concatenate([p[3] for p in parts]),
                          dphi=np.concatenate([p[4] for p in parts]),
                          nh=np.concatenate([p[5] for p in parts]),
                          epoch=np.concatenate([p[6] for p in parts]), dchip=dchip)
        self.profile["nco"] += time.perf_counter() - tb
        return rows

    def load_samples(self, rows: _EpochRows) -> bool:
        """Read the stored IF samples the rows need (a chunk at a time); False when they run
        past the end of the data."""
        tc = time.perf_counter()
        need0 = int(rows.starts.min())
        need1 = int((rows.starts + rows.nsamp).max())
        if need1 > self.stop:
            return False
        if need0 < self.buf0 or need1 > self.buf1:
            n_read = min(max(self.chunk, need1 - need0), self.stop - need0)
            self.x_buf, self.n_comp = self.source.read_stored(need0, n_read)
            self.buf0, self.buf1 = need0, need0 + n_read
            self.npow = mean_power(self.x_buf, self.n_comp)
        self.profile["read"] += time.perf_counter() - tc
        return True

    def correlate(self, rows: _EpochRows):
        """Early, prompt, late of every epoch of every channel: one call of the receiver's
        kernel on the stored samples (bit-window replicas, one rotation row per epoch), NH
        code wiped off. Returns ``(E, P, L)`` complex (n_rows,)."""
        td = time.perf_counter()
        n_rows = rows.starts.size
        nsamp = rows.nsamp
        tab_idx = np.repeat(self.chan_idx, rows.reps)
        rot_re, rot_im = carrier_rotation(rows.dphi)
        th = reduce_code_phase(rows.theta, CODE_LENGTH_B3I)
        threads = self.kthreads.pick()
        n_sub = kernel_tasks(n_rows, int(nsamp.max()), threads)
        out = np.empty((n_rows, 3, 2))
        correlate_epl_bits(self.x_buf, self.n_comp, self.bits, tab_idx, CODE_PAD,
                           CODE_LENGTH_B3I, rows.starts - self.buf0, nsamp, th,
                           np.repeat(rows.dchip, rows.reps), rows.phi, rows.dphi, rot_re,
                           rot_im, np.arange(n_rows, dtype=np.int64), self.pre.spacing, n_sub,
                           out)
        self.kthreads.record(threads, (time.perf_counter() - td) / float(nsamp.sum()))
        epl = out.view(np.complex128)[..., 0]
        E = epl[:, 0] * rows.nh
        P = epl[:, 1] * rows.nh
        L = epl[:, 2] * rows.nh
        self.profile["correlate"] += time.perf_counter() - td
        return E, P, L

    def prefilter(self, iv: Interval, rows: _EpochRows, E, P, L) -> Measurements:
        """Per channel: C/N0 tests and navigation decoding, pre-filter over its epochs
        (coherent blocks, module notes), and the measurement-vector gate; ``z`` =
        ``[c/f_code dtau_i, lambda df_i]`` and ``R`` from the pre-filter variances of the
        channels in the vector (paper 004 eq 7-9, 34)."""
        te = time.perf_counter()
        cfg, pre, fs = self.cfg, self.pre, self.fs
        ns, ep_all = rows.nsamp, rows.epoch
        z_rho, z_rate, r_rho, r_rate, use = [], [], [], [], []
        a = 0
        for c, cnt in zip(self.chans, rows.reps):
            i = c.idx
            sl = slice(a, a + cnt)
            a += cnt
            if cnt:
                pp = P[sl]
                self._test_channel(c, pp, ns[sl], ep_all[sl], iv.k1 / fs)
                cn0_lin = 10.0 ** (c.cn0_dbhz / 10.0) if math.isfinite(c.cn0_dbhz) else 100.0
                pre.process(i, E[sl], pp, L[sl], ns[sl] / fs, cn0_lin,
                            block_start=ep_all[sl] % min(c.bit_ms, cfg.coherent_ms) == 0)
            good = self._usable(c, cnt)
            c.used = good
            use.append(good)
            if good:
                dtau, df, vt, vf = pre.outputs(i)
                z_rho.append(C_LIGHT / CHIP_RATE_B3I * dtau)
                z_rate.append(LAMBDA_B3I * df)
                r_rho.append((C_LIGHT / CHIP_RATE_B3I) ** 2 * vt)
                r_rate.append(LAMBDA_B3I ** 2 * vf)
        use = np.asarray(use, bool)
        z = R = None
        if use.any():
            z = np.r_[z_rho, z_rate]
            R = np.diag(np.r_[r_rho, r_rate])
        m = Measurements(z=z, R=R, geometry=(iv.nav1.llh, self._pred.U[use, 0]), used=use)
        self.profile["prefilter"] += time.perf_counter() - te
        return m

    def _test_channel(self, c: _Chan, prompts, nsamp, epochs, t_s: float) -> None:
        """Channel management on this interval's prompts (module notes): bit sums for the
        C/N0, navigation decoding, the fast test (interval left out), the loss test (channel
        lost, its C/N0 window emptied) and the C/N0 taken up once the window allows."""
        cfg, fs = self.cfg, self.fs
        mon = c.power
        mon.add(prompts, nsamp, epochs % c.bit_ms == 0)
        self.nav_log.demodulate(c, prompts, epochs, t_s)
        if mon.new:
            # tests on the last bit sums: _FAST_MS to leave the interval out,
            # _LOSS_MS to declare the channel lost (module notes)
            fast = mon.cn0_dbhz(self.npow, fs, last=_FAST_MS // c.bit_ms)
            c.fast_fail = 0 if fast >= cfg.cn0_min_dbhz - cfg.fast_margin_db else 1
            if c.fast_fail and not mon.cn0_dbhz(
                    self.npow, fs, last=_LOSS_MS // c.bit_ms) >= \
                    cfg.cn0_min_dbhz - cfg.loss_margin_db:
                c.fast_fail = 2
            if c.fast_fail and c.nav is not None:
                c.nav.interrupt()  # no subframe from bits of a failing interval
            if c.fast_fail >= 2:
                # signal gone: lost, back only on a whole window of fresh bit
                # sums, not on one still full of signal from before a blockage
                mon.clear()
                c.cn0_dbhz = math.nan
                c.rejoining = True
            elif c.fast_fail == 0 and mon.count >= (
                    mon.p.size if c.rejoining else _CN0_MIN_MS // c.bit_ms):
                c.rejoining = False
                c.cn0_dbhz = mon.cn0_dbhz(self.npow, fs)

    def _usable(self, c: _Chan, n_epochs: int) -> bool:
        """Measurement-vector gate of channel ``c`` (module notes): C/N0 at least the gate
        (less the hysteresis while in the vector), epochs this interval, fast test passed,
        pre-filter NIS consistent."""
        cfg = self.cfg
        gate = cfg.cn0_min_dbhz - (cfg.cn0_hysteresis_db if c.used else 0.0)
        return (math.isfinite(c.cn0_dbhz) and c.cn0_dbhz >= gate
                and n_epochs > 0 and c.fast_fail == 0
                and not self.pre.nis_p[c.idx] < cfg.nis_p_min)

    # ------------------------------------------------------------------------------------
    def feed_back(self, loop: IntegrationLoop, iv: Interval, x: np.ndarray) -> None:
        """The correction ``x`` on the NCOs and the pre-filters: ranges at the next ``k0``
        are ``P1 - H x``, each pre-filter shifted by the projection of ``x`` on its line
        of sight (its NCOs move by it), then decorrelated, or restarted from the NCO when
        lost or inconsistent (frequency prior: the filter's rate sigma on that line of
        sight, at least ``_SIGMA_F_MIN``)."""
        n_ch, pre, cfg = self.n_channels, self.pre, self.cfg
        self.meas_all.set_geometry(iv.nav1.llh, self._pred.U[:, 0])
        Hx = self.meas_all.matrix @ x
        self.P_k0 = self._P1 - Hx[:n_ch]
        self.Pc_k0 = self._Pc1 - Hx[:n_ch]
        Hr = self.meas_all.matrix[n_ch:]
        sig_f = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", Hr, loop.kf.P, Hr), 0.0)) / LAMBDA_B3I
        for c in self.chans:
            i = c.idx
            pre.shift(i, CHIP_RATE_B3I / C_LIGHT * Hx[i], Hx[n_ch + i] / LAMBDA_B3I)
            if c.fast_fail >= 2 or pre.nis_p[i] < cfg.nis_p_min:
                # lost, or inconsistent: restart from the NCO (INS) with the integration
                # filter's rate uncertainty as the frequency prior
                pre.reset(i, sigma_phi=1.0, sigma_f=max(float(sig_f[i]), _SIGMA_F_MIN))
            else:
                pre.decorrelate(i)

    def take_up_navigation_data(self, loop: IntegrationLoop, iv: Interval) -> None:
        """Navigation data decoded so far, taken up at the interval's end
        (:func:`_take_up_model_change`): INS position, clock, NCO ranges and pre-filters
        move with the range model."""
        tg = time.perf_counter()
        clock, chans, k1 = self.clock, self.chans, iv.k1
        new_ephs, new_iono = self.nav_log.changes(
            chans, clock.week, clock.sow(k1) - loop.clock_bias_m / C_LIGHT)
        if new_ephs is not None or new_iono is not self.iono:
            step = _take_up_model_change(
                self.ephs, new_ephs or self.ephs, self.iono, new_iono, clock.week,
                clock.sow(k1), loop.ins, loop.clock_bias_m, self.tau_prev,
                np.array([c.used for c in chans]), self.meas_all, loop.kf, self.pre)
            self.P_k0 = self.P_k0 + step.dP - step.Hx_rho
            self.Pc_k0 = self.Pc_k0 + step.dPc - step.Hx_rho
            loop.clock_bias_m = step.clock_bias_m
            self.nav_log.taken_up(k1 / self.fs, chans, new_ephs, self.iono, new_iono, step)
            self.ephs = [c.eph for c in chans]
            self.iono = new_iono
        self.profile["ins"] += time.perf_counter() - tg

    def row(self) -> dict:
        """Channel columns of a solution row: C/N0 [dB-Hz] and the navigation data taken up
        since the previous row (``DeepResult.nav_change``)."""
        out = {"cn0": [c.cn0_dbhz for c in self.chans], "nav": self.nav_log.flag}
        self.nav_log.flag = 0
        return out


def _offer_subframe_klobuchar(rx: ScalarReceiver, navdata: NavDataInForce, t_s: float) -> None:
    """Offer the Klobuchar set of the latest D1 subframe 1 any scalar channel decoded (the
    channels give the coefficients only with a complete ephemeris, up to 18 s later)."""
    for c in rx.channels.values():
        for d in reversed(c.subframes[-5:]):
            k = klobuchar_of_subframe(d)
            if k is not None:
                navdata.offer_klobuchar(k, t_s)
                return


def _handover_decoder(sc, epoch: int, ms0: int) -> ChannelNavDecoder:
    """Navigation decoder of a handed-over channel: the scalar channel ``sc``'s assembler
    and the bits of its subframe in progress (its epoch counter moved to the loop's
    numbering, in which ``sc``'s next epoch is ``epoch``)."""
    dec = ChannelNavDecoder(sc.prn, sc.is_d1, ms0, sc.assembler)
    runs = sc.demodulated_bits()
    if runs:
        e0, bits = runs[-1]
        dec.seed(e0 + epoch - int(sc.epoch), bits)
    return dec


@dataclasses.dataclass
class _ModelStep:
    """A change of the range model taken up at one epoch (:func:`_take_up_model_change`)."""

    dP: np.ndarray          # predicted code range change of every channel [m]
    dPc: np.ndarray         # predicted carrier phase-range change [m]
    Hx_rho: np.ndarray      # range change of the state step [m]
    x: np.ndarray           # state step (17,)
    clock_bias_m: float     # clock bias after the step [m]


def _take_up_model_change(ephs_old, ephs_new, iono_old, iono_new, week: int, sow_nom: float,
                          ins, clock_bias_m: float, tau, used: np.ndarray, meas_all, kf,
                          pre: PreFilterBank) -> _ModelStep:
    """Switch the range model (ephemerides, ionosphere) at a clean epoch (module notes).

    The predicted ranges at the epoch move by ``dP`` (new model minus old, same position and
    clock). A filter that ran on the old model has absorbed that step into its position and
    clock as far as the geometry lets it: its estimate sits at ``x_c``, the least-squares
    solution of ``H_rho x = dP`` over the channels in the measurement vector (position and
    clock columns). The INS and the clock are moved by ``x_c`` (the loop's feedback), the
    pre-filters by what the NCOs then move, ``dP - H x_c`` (which removes the misfit the old
    model left in the innovations), and the position/clock covariance grows by
    ``(x_c / 2)^2`` for the error of that projection (the filter's weights are not equal).
    """
    r = llh_to_ecef(*ins.llh)
    old = predict_ranges(ephs_old, week, [sow_nom], [r], [clock_bias_m], iono_old, tau0=tau)
    new = predict_ranges(ephs_new, week, [sow_nom], [r], [clock_bias_m], iono_new, tau0=tau)
    dP = new.P[:, 0] - old.P[:, 0]
    dPc = new.Pc[:, 0] - old.Pc[:, 0]
    n = dP.size
    meas_all.set_geometry(ins.llh, new.U[:, 0])
    H = meas_all.matrix
    x = np.zeros(17)
    cols = [6, 7, 8, 15]
    if int(np.count_nonzero(used)) >= 4:
        x[cols] = np.linalg.lstsq(H[:n][used][:, cols], dP[used], rcond=None)[0]
        kf.P[cols, cols] += (0.5 * x[cols]) ** 2
    else:
        kf.P[15, 15] += float(np.max(dP ** 2))
    Hx = H @ x
    z3 = np.zeros(3)
    ins.correct(z3, z3, x[6:9], z3, z3)
    for i in range(n):
        pre.shift(i, -CHIP_RATE_B3I / C_LIGHT * (dP[i] - Hx[i]), Hx[n + i] / LAMBDA_B3I)
    return _ModelStep(dP=dP, dPc=dPc, Hx_rho=Hx[:n], x=x, clock_bias_m=clock_bias_m - x[15])


class _NavLog:
    """Navigation data of the vector loop's channels: decoding, changes, history."""

    def __init__(self, navdata: NavDataInForce, chans: list, iono, t_s: float, week: int,
                 sow: float) -> None:
        self.navdata = navdata
        self.flag = 0        # changes since the last output row (DeepResult.nav_change)
        self.ephemerides: dict = {f"C{c.prn:02d}": [] for c in chans}
        self.ionosphere: list = []
        self.steps: list = []
        self._new: list = []
        for c in chans:
            self._eph_entry(t_s, c.prn, c.eph, navdata.select_with_source(c.prn, week, sow)[1])
        self._iono_entry(t_s, iono)

    def demodulate(self, c: _Chan, prompts, epochs, t_s: float) -> None:
        """Feed channel ``c``'s prompts to its decoder; offer what it completes."""
        for eph, klob in c.nav.add(prompts, epochs):
            if eph is not None:
                self.navdata.offer_ephemeris(eph, t_s)
            self.navdata.offer_klobuchar(klob, t_s)

    def changes(self, chans: list, week: int, sow: float):
        """``(new ephemeris list or None, ionosphere in force)`` at BDT (``week``, ``sow``)."""
        self._new = []
        for c in chans:
            try:
                e, src = self.navdata.select_with_source(c.prn, week, sow)
            except SdrDiError:           # nothing valid any more: keep the last one
                e, src = c.eph, None
            self._new.append((e, src))
        changed = any(e is not c.eph and e != c.eph for c, (e, _) in zip(chans, self._new))
        return ([e for e, _ in self._new] if changed else None), self.navdata.klobuchar

    def taken_up(self, t_s: float, chans: list, new_ephs, iono_old, iono_new,
                 step: _ModelStep) -> None:
        """Record the change :func:`_take_up_model_change` just made; set the channels'
        records."""
        if new_ephs is not None:
            self.flag |= 1
            for c, (e, src) in zip(chans, self._new):
                if e is not c.eph and e != c.eph:
                    self._eph_entry(t_s, c.prn, e, src)
                    c.eph = e
        if iono_new is not iono_old:
            self.flag |= 2
            self._iono_entry(t_s, iono_new)
        self.steps.append({"t_s": round(t_s, 3),
                           "max_range_step_m": float(np.max(np.abs(step.dP))),
                           "clock_step_m": float(step.x[15]),
                           "height_step_m": float(step.x[8])})

    def _eph_entry(self, t_s, prn, e, src) -> None:
        self.ephemerides[f"C{prn:02d}"].append(
            {"t_s": round(t_s, 3), "source": src,
             "week": int(e.week), "toe": float(e.toe), "aode": int(e.AODE)})

    def _iono_entry(self, t_s, iono) -> None:
        src = self.navdata.iono_source if iono is not None else None
        self.ionosphere.append({"t_s": round(t_s, 3), "model": "klobuchar" if src else "none",
                                "source": src})

    def summary(self, t_end_s: float) -> dict:
        """``navigation`` entry of the run summary."""
        models = self.navdata.models()
        return {
            "rule": "decoded broadcast data as it arrives (healthy, new data set, toe within "
                    "its age limit), the assistance (RINEX) record on the air before it",
            "ephemerides": self.ephemerides,
            "ionosphere": {**models["ionosphere"], "history": self.ionosphere},
            "troposphere": models["troposphere"],
            "model_steps": self.steps,
            "decoded_conflicts": self.navdata.n_conflicts,
            "decoded_rejected": self.navdata.n_rejected,
            "end_s": round(t_end_s, 3),
        }


def _epoch_rows(c: _Chan, c0: float, dc: float, dp0: float, dp1: float, k0: int, k1: int):
    """Correlator rows of channel ``c``: its code epochs that start in ``[next_start, k1)``.

    The code NCO's chip count is ``c0 + (k - k0) dc`` over the interval; epoch ``e`` ends at
    the first sample where it reaches ``(e + 1) L``. The carrier NCO frequency of each epoch
    [cycles per sample] is ramped linearly in time between ``dp0`` (the previous interval's
    average, placed at its middle ``k0 - N/2``) and ``dp1`` (this interval's average, at
    ``k0 + N/2``), so it follows the Doppler rate of the dynamics (7 m/s^2 in the circling
    phases = 0.6 Hz over a 20 ms interval) while its integral over the interval still equals
    the predicted carrier-phase change; the phase stays continuous. Advances the channel's
    ``next_start``, ``epoch`` and ``phase``.

    Returns ``(starts, n, theta, phi, dphi, nh_sign, epoch)`` arrays (one row per epoch;
    ``epoch`` = ms since S0 on the satellite clock).
    """
    L = CODE_LENGTH_B3I
    s0, e0 = c.next_start, c.epoch
    if s0 >= k1:
        z = np.zeros(0)
        return np.zeros(0, np.int64), np.zeros(0, np.int64), z, z, z, z, np.zeros(0, np.int64)
    # epoch ends: ceil(k0 + ((e + 1) L - c0) / dc) until one reaches k1
    m_max = int((k1 - s0) * dc / L) + 3
    ends = np.ceil(k0 + ((e0 + 1 + np.arange(m_max)) * L - c0) / dc).astype(np.int64)
    starts = np.concatenate(([s0], ends[:-1]))
    ends = np.maximum(ends, starts + 1)
    keep = starts < k1
    starts, ends = starts[keep], ends[keep]
    m = starts.size
    n = ends - starts
    ep = e0 + np.arange(m)
    theta = c0 + (starts - k0) * dc - ep * L
    N = float(k1 - k0)
    dphi = dp0 + (dp1 - dp0) * ((starts + 0.5 * n - k0) / N + 0.5)
    adv = np.cumsum(n * dphi)
    phi = c.phase + np.concatenate(([0.0], adv[:-1]))
    phi -= np.floor(phi)
    end_phase = c.phase + float(adv[-1])
    c.next_start, c.epoch, c.phase = int(ends[-1]), e0 + m, end_phase - math.floor(end_phase)
    nh = NH20[ep % 20].astype(float) if c.is_d1 else np.ones(m)
    return starts, n, theta, phi, dphi, nh, ep
