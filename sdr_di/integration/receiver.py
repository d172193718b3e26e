"""Deep (INS-aided vector tracking) receiver: scalar start-up, hand-over, federated loop.

Paper 004 Fig. 1, federated architecture. Data flow of :meth:`IntegratedReceiver.run`::

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

Modes (``IntegrationConfig.mode``, ``sdr-di run --mode``): ``"deep"`` (above), ``"loose"`` and
``"tight"`` (docs/coupling.md). All three share the scalar start-up, the hand-over rule and
time, the INS alignment, the filter and its ``Q``/``P0``, and the integration loop; loose and
tight take their measurements from the scalar receiver, which keeps tracking after the
hand-over without any feedback from the filter: its WLS fixes (loose,
:mod:`~sdr_di.integration.loose_fixes`) or its pseudoranges and rates (tight,
:mod:`~sdr_di.integration.tight_ranges`), every ``1 / gnss_rate_hz`` s
(:mod:`~sdr_di.integration.gnss_epochs`). So the three report over the same time window.

Code, in the order of a run (:meth:`IntegratedReceiver.run`): ``_check_inputs`` (IMU span,
filter rate, filter, reference), then either ``_run_from`` (an earlier run's start-up or
scalar run) or the scalar start-up, ``_StartUp`` (the receiver's epoch callback: fixes,
navigation data in force, the hand-over rule ``_hand_over``, for loose and tight the loop
started there and the measurement epochs after it) ending in a typed
:class:`~sdr_di.integration.handover.Handover`; ``_no_handover`` says why there was none;
``_keep_start`` keeps the start for other runs.
:meth:`IntegratedReceiver._vector_loop` hands over and runs the mode-independent
:class:`~sdr_di.integration.loop.IntegrationLoop` (INS propagation, filter predict/update,
closed-loop feedback, solution rows) with deep mode's measurement source,
:class:`~sdr_di.deep.vector_tracking.VectorTracking` (NCO commands, correlation,
pre-filters and channel management, the NCO and pre-filter share of the feedback,
navigation data taken up). :meth:`IntegratedReceiver._start_scalar_coupled_loop` runs the same loop
with the loose or tight source, without the NCO feedback, behind the receiver
(``_CoupledRun``), and ``_finish_scalar_coupled_loop`` collects it.

Decisions
---------
* **Filter rate** default 50 Hz (T = 20 ms): one D1 data bit, four 200 Hz IMU samples, the
  rate at which the NCO commands are refreshed from the corrected INS. Faster costs filter
  time without new information (the pre-filters already average the 1 ms epochs); slower
  lets the INS error (MEMS: 4 mg) grow between NCO corrections: at 10 Hz an uncorrected
  0.04 m/s^2 gives 2 mm of code and 0.017 Hz of carrier error, still small, so 10-50 Hz all
  work; ``--filter-rate`` sets it.
* **NCOs one interval ahead** (``nco_latency = 1``, ``--nco-latency 1``; default 0): the
  update at the end of interval ``k`` steers the NCOs from interval ``k + 2`` instead of
  ``k + 1``, as in a receiver whose correlators run on while its filter updates, so that
  the correlation of ``k + 1`` (on the kernel's worker thread) overlaps the pre-filters,
  update and feedback of ``k`` (on the loop's thread):
  :meth:`~sdr_di.integration.loop.IntegrationLoop.run_ahead`. Nothing is approximated
  beyond that delay: after the update of ``k`` the filter predicts to the end of ``k + 1``
  and that predicted error is fed back there (INS, clock, the ranges the next NCO command
  starts from), and each pre-filter takes the same step after the correlations of
  ``k + 1``, so every measurement refers to the INS the filter's state describes. Paired
  over 6 seeds it changed no error or consistency figure measurably in steady tracking;
  after a 3 s blockage of every satellite one set of 6 seeds did not exclude a velocity
  loss (one seed 16 % worse) and a second set showed none (docs/deep.md, *NCOs one interval
  ahead*). The default stays 0, which also keeps earlier results and studies reproducible.
* **Hand-over** (from scalar tracking) once a valid WLS fix with velocity exists and every
  channel in ``TRACK`` has its transmit time and an ephemeris (decoded, or from the
  assistance navigation file, as paper 004 feeds its ephemerides to the receiver); after
  ``handover_wait_s`` without that, at least 4 such channels suffice. The clock bias/drift
  come from the fix; each channel's pre-filter starts from the scalar loop's code phase and
  Doppler relative to the INS prediction.
* **INS initial alignment**: ``align="truth"``: from the first record of the reference (the
  scenario's initial state, paper 004 Table 3) at the IMU start, then coasting on the IMU
  until the hand-over, where position and velocity are replaced by the WLS fix;
  ``align="gnss"``: at the hand-over from the fix velocity and the IMU (:func:`~.alignment.gnss_alignment`:
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
  (:class:`~sdr_di.deep.bit_power.BitPower`, known-noise estimator, run for every channel
  at once by :class:`~sdr_di.deep.channel_tests.ChannelTests`, ``cn0_window_ms`` =
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
  waits up to ``iono_wait_s`` (default 0: not at all) after the first fix for Klobuchar
  coefficients, then goes ahead with a :class:`~sdr_di.receiver.navdata.NavDataWarning`.
  After it, every channel keeps decoding its message (:mod:`~sdr_di.deep.navdecode`); a new ephemeris or
  ionosphere model is taken up at the end of the interval in which it was decoded
  (:func:`_take_up_model_change`: the state moves by the least-squares projection of the
  range-model step, the pre-filters by the rest; reasons in docs/deep.md).
* **GNSS rate** of loose and tight (``gnss_rate_hz``, default 5 Hz): the scalar receiver's
  output epochs are every 0.1 s in every mode (the hand-over rule is evaluated on them, so
  all modes hand over at the same sample); loose and tight take every ``10 / gnss_rate_hz``-th
  from the hand-over on, so the rate must be 10 Hz divided by a whole number. Scalar
  pseudoranges come from a carrier-aided DLL whose errors are correlated over a fraction
  of a second: fed at 50 Hz as white noise they make the filter overconfident.
* **Process noise** from the IMU spec (random walks; bias random walk reaching the spec in
  ``bias_time_s``), default paper 004 Table 4 (MEMS); clock: TCXO (:class:`~sdr_di.ins.error_model.ClockModel`).
"""

from __future__ import annotations

import copy
import dataclasses
import time
import warnings
from collections.abc import Callable

import numpy as np

from ..deep.vector_tracking import SampleClock, VectorTracking
from ..errors import ImuDataError
from ..filters import filter_record
from ..integration.assumptions import FixedNoiseSource
from ..integration.consistency import consistency_summary
from ..integration.gnss_epochs import GnssEpochRecorder
from ..integration.loop import BackgroundLoop, IntegrationLoop, MeasurementSource
from ..integration.loop_process import LoopChild, LoopProcess, start_loop_behind
from ..integration.loose_fixes import LooseFixSource
from ..coupling.measurements import LooseMeasurementModel, RangeRateMeasurementModel
from ..integration.metrics import summarize
from ..integration.tight_ranges import TightRangeSource
from ..receiver.ifreader import IfSource
from ..receiver.navdata import NavDataInForce, NavDataWarning
from ..receiver.observables import ReceiverTime
from ..receiver.prediction import FixPredictor
from ..receiver.pvt import PvtEngine
from ..receiver.scalar import ScalarReceiver
from ..receiver.tracking import ChannelState
from .alignment import align_ins
from ..coupling.config import MODES, SCALAR_EPOCH_S, IntegrationConfig, imu_samples_per_interval
from ..filters.state import layout_of_options
from .filter_setup import check_filter, make_integration_filter
from .handover import (Handover, HandoverError, handover_channels, handover_span_s,
                       offer_subframe_klobuchar)

__all__ = ["MODES", "DeepStart", "HandoverError", "IntegratedReceiver", "IntegrationConfig",
           "IntegrationResult", "ScalarRecord", "StartMismatchError", "check_imu_span"]


class StartMismatchError(ValueError):
    """A :class:`DeepStart` or :class:`ScalarRecord` given to :meth:`IntegratedReceiver.run`
    was made on other data, with another hand-over rule, assistance data or GNSS rate, or
    for the other kind of mode (deep against loose and tight)."""


@dataclasses.dataclass
class DeepStart:
    """The scalar start-up's state at the deep hand-over, kept to run other filters from it.

    Deep mode's start-up (acquisition, scalar loops, decoding, the fixes up to the
    hand-over) does not depend on the integration filter, its rate or its assumptions: only
    on the IF data, the PRNs searched, the assistance data, the span processed, the
    hand-over rule (``handover_wait_s``, ``iono_wait_s``) and the scalar receiver's tracking
    configuration. A study runs several filters on
    one file; :meth:`IntegratedReceiver.run` with ``keep_start=True`` keeps a copy of the
    state at the hand-over (:attr:`IntegratedReceiver.deep_start`) and ``start=`` continues
    another run from a fresh copy of it, with the same results as a run from sample 0 (the
    start-up is deterministic; tested in ``tests/test_deep.py``). ``key`` holds what
    the start-up depended on; a start given to a run that differs in any of it is refused.

    Attributes
    ----------
    key : tuple
        IF path, samples processed, PRNs, assistance, hand-over rule, the scalar receiver's
        tracking configuration.
    nav : object
        The assistance navigation data the start-up took (compared by identity).
    state : tuple
        ``(scalar receiver, PVT engine, navigation data in force, Handover)``.
    scalar_s : float
        Wall time of the start-up that made it [s].
    """

    key: tuple
    nav: object
    state: tuple
    scalar_s: float
    #: The IF source the state refers to (not copied: :meth:`copy_for` puts the run's own
    #: source in its place).
    source: object

    def copy_for(self, source: IfSource) -> tuple:
        """A fresh deep copy of :attr:`state` in which ``source`` (an IF source on the same
        file) takes the place of :attr:`source`; neither is copied."""
        return copy.deepcopy(self.state, memo={id(self.source): source})


@dataclasses.dataclass
class ScalarRecord:
    """Loose and tight: the scalar receiver's run over the file, kept to run other filters
    and the other of the two modes on it.

    In loose and tight mode no filter output reaches the scalar receiver (no NCO feedback),
    so its run, and the epochs :class:`~sdr_di.integration.gnss_epochs.GnssEpochRecorder`
    keeps of it, depend only on what :class:`DeepStart` lists plus the GNSS rate
    (``gnss_every``), not on the mode, the filter or its assumptions. The integration loop
    reads nothing else of the receiver but its channels and tracking configuration at the
    hand-over and its clock. :meth:`IntegratedReceiver.run` with ``keep_start=True`` keeps
    one (:attr:`IntegratedReceiver.scalar_record`), and ``start=`` runs another loop over
    its epochs instead of the receiver, with the same rows as a run of its own (the epochs
    are never changed once recorded; tested in ``tests/test_coupling.py``).

    Attributes
    ----------
    key : tuple
        As :attr:`DeepStart.key`, then ``gnss_every``.
    nav : object
        The assistance navigation data the run took (compared by identity).
    hand : Handover
        The hand-over (:class:`~sdr_di.integration.handover.Handover`: ``sample``, ``sol``,
        ``prns``, ``next_start``, ``channels``).
    epochs : list of GnssEpoch
        Every recorded epoch (read-only).
    rx_time : ReceiverTime
        The receiver's receive-time scale.
    scalar : ScalarReceiver
        The receiver after its run (its records, e.g. the acquisitions it ran; its
        tracking configuration).
    scalar_s : float
        Wall time of the receiver's run [s].
    """

    key: tuple
    nav: object
    hand: Handover
    epochs: list
    rx_time: object
    scalar: ScalarReceiver
    scalar_s: float

    def recorder(self) -> GnssEpochRecorder:
        """A closed recorder holding the epochs (shared: a recorded epoch never changes)."""
        rec = GnssEpochRecorder(None, None)
        rec.epochs = self.epochs
        rec.close()
        return rec


@dataclasses.dataclass
class IntegrationResult:
    """Output of a run in any mode (solution rows at the output rate, after feedback).

    Attributes
    ----------
    t : (n,) seconds since the IF file start (receiver clock)
    week, sow : BDT of each row (receiver time minus clock bias)
    llh : (n, 3) rad, rad, m;  v_n : (n, 3) ENU m/s;  att : (n, 3) pitch, roll, yaw [rad]
    clock_bias_m, clock_drift_mps : (n,) the filter's clock states (loose: the latest WLS
        fix's clock, :mod:`~sdr_di.integration.loose_fixes`)
    n_used : (n,) channels in the measurement vector (loose, tight: of the latest GNSS
        epoch; loose: the fix's satellites, 0 without a fix)
    mode : str, the coupling mode
    att_err, vel_err, pos_err : (n, 3) errors vs the reference [deg, m/s, m ENU] (NaN
        without a reference)
    prns : handed-over PRNs (loose, tight: then any acquired later);  used : (n, n_ch)
        bool, channel in the measurement vector
    cn0_dbhz : (n, n_ch)
    nis : (n,) integration-filter normalized innovation squared per measurement, averaged
        over the filter epochs since the previous row (about 1 when ``R`` is consistent)
    handover_s : time of the hand-over [s since file start]
    filter_name : str;  adaptation_s : float (time in the adaptive rule, if any)
    filter_used : dict, the built filter's record (:func:`~sdr_di.filters.filter_record`:
        spec, class, options, Q0/P0 diagonals), the summary's ``assumptions.filter``
    profile : dict (seconds per stage: scalar, read, nco, correlate, prefilter, filter, ins)
    nav_change : (n,) int, navigation data taken up since the previous row: 0 none, bit 1
        an ephemeris, bit 2 the ionosphere model
    navigation : dict, the navigation data in force over the run (summary ``navigation``
        entry, docs/deep.md)
    sd : (n, 9) formal 1-sigma of the corrected solution, ENU: position [m], velocity
        [m/s], attitude [deg] (:func:`~sdr_di.integration.consistency.formal_sd`)
    nees : (n, 3) NEES per degree of freedom of position, velocity, attitude (NaN without
        a reference)
    updates : dict, per filter update ``t`` [s], ``nis`` (k, 2) per block, ``dof`` (k,)
        (:attr:`~sdr_di.integration.loop.IntegrationLoop.updates`)
    deep_measurements : str or None, deep mode's measurement architecture
        (``IntegrationConfig.deep_measurements``); None in loose and tight
    innov : (n, 2 n_ch) normalized innovation ``y_i / sqrt(S_ii)`` of each channel's code
        then rate measurement at the row's last update (deep, tight; NaN where not mapped:
        :func:`~sdr_di.integration.loop.channel_innovations`)
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
    mode: str = "deep"
    filter_used: dict | None = None
    sd: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 9)))
    nees: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 3)))
    updates: dict = dataclasses.field(default_factory=dict)
    deep_measurements: str | None = None
    innov: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 0)))

    def metrics(self, t0: float | None = None, t1: float | None = None) -> dict:
        """RMSE / max of the attitude [deg], velocity [m/s], position [m] error norms."""
        return summarize(self.t, self.att_err, self.vel_err, self.pos_err, t0, t1)

    def consistency(self, t0: float | None = None, t1: float | None = None) -> dict:
        """NIS per block and NEES per quantity over ``t0 <= t <= t1``, the window of
        :meth:`metrics` (:func:`~sdr_di.integration.consistency.consistency_summary`)."""
        up = self.updates or {"t": np.zeros(0), "nis": np.zeros((0, 2)), "dof": np.zeros(0)}
        return consistency_summary(self.mode, up["t"], up["nis"], up["dof"], self.t,
                                   self.nees, t0, t1)


def check_imu_span(source: IfSource, imu, stop: int) -> float:
    """IF-relative time of IMU ``t = 0`` [s], once the IMU record is checked to cover IF
    samples ``[0, stop)`` (time tags consistent, record long enough).

    Raises
    ------
    ImuDataError
        Time tags missing or inconsistent, or the record shorter than the IF span.
    """
    off = _imu_offset_s(source, imu)
    if_end = stop / source.sampling_rate_hz
    dt_imu = 1.0 / imu.rate_hz
    if imu.t[0] + off > dt_imu + 1e-6 or imu.t[-1] + off < if_end - dt_imu - 1e-6:
        raise ImuDataError(
            f"IMU record spans {imu.t[0] + off:.3f}..{imu.t[-1] + off:.3f} s of the IF "
            f"file, which needs 0..{if_end:.3f} s (IMU/IF start times inconsistent or IMU "
            "file too short)")
    return off


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


class IntegratedReceiver:
    """INS-aided vector-tracking receiver (module notes).

    Parameters
    ----------
    config : IntegrationConfig, optional
    scalar : ScalarReceiver, optional
        Start-up receiver (default ``ScalarReceiver(log=False)``).
    """

    def __init__(self, config: IntegrationConfig | None = None,
                 scalar: ScalarReceiver | None = None):
        self.config = config or IntegrationConfig()
        self.scalar = scalar or ScalarReceiver(log=False)
        self.profile: dict = {}
        #: the start-up state kept by :meth:`run` with ``keep_start=True``
        self.deep_start: DeepStart | None = None
        #: loose and tight: the scalar run kept by :meth:`run` with ``keep_start=True``
        self.scalar_record: ScalarRecord | None = None

    # ------------------------------------------------------------------------------------
    def run(self, source: IfSource, imu, *, prns=None, nav=None, truth=None,
            progress: Callable[[float, int, int], None] | None = None,
            duration_s: float | None = None,
            assist: dict[int, float | None] | None = None,
            start: DeepStart | ScalarRecord | None = None,
            keep_start: bool = False) -> IntegrationResult:
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
            ``progress(seconds_processed, n_channels, n_used)`` about once per second
            (``n_used`` None during the scalar start-up, before the hand-over).
        duration_s : float, optional
            Stop after this many seconds of the file.
        assist : dict, optional
            ``{prn: Doppler [Hz] or None}``: the start-up's search assistance, as
            :meth:`~sdr_di.receiver.scalar.ScalarReceiver.run` takes it (the sidecar's list
            in ``sdr-di run``, the same search as scalar mode's); None: a cold search of
            ``prns``.
        start : DeepStart or ScalarRecord, optional
            Deep mode: continue from this start-up state (made by an earlier run on the
            same file with ``keep_start=True``) instead of running the start-up. Loose and
            tight: run the loop over the epochs of this scalar run (an earlier loose or
            tight run's, either mode) instead of running the receiver.
        keep_start : bool
            Deep mode: keep a copy of the start-up state at the hand-over in
            :attr:`deep_start` (None when no hand-over was reached). Loose and tight: keep
            the scalar run in :attr:`scalar_record`.

        Raises
        ------
        ImuDataError
            IMU time tags missing or inconsistent, IMU span not covering the IF file.
        FilterError
            Unknown filter name or option, non-positive-definite ``P0``.
        HandoverError
            No satellite found or no hand-over state reached.
        StartMismatchError
            ``start`` from a start-up or scalar run that differs from this run's
            (:attr:`DeepStart.key`, :attr:`ScalarRecord.key`), or of the other kind of mode
            (a ``ValueError``).
        """
        t_all = time.perf_counter()
        stop, off, n_per = self._check_inputs(source, imu, truth, duration_s)
        key = (str(source.path), source.n_samples, stop,
               None if prns is None else tuple(prns),
               None if assist is None else tuple(sorted(assist.items())),
               self.config.handover_wait_s, self.config.iono_wait_s, self.scalar.config)
        self.deep_start, self.scalar_record = None, None        # set by _keep_start
        if start is not None:
            return self._run_from(start, key, nav, source, imu, off, n_per, stop, truth,
                                  progress, t_all)
        # the scalar start-up until the hand-over (deep), or the whole scalar run (loose
        # and tight: the loop runs behind it from the hand-over)
        up = _StartUp(self, source, nav, progress,
                      lambda hand, recorder, engine: self._start_scalar_coupled_loop(
                          source, imu, off, n_per, stop, hand, recorder, truth,
                          self.scalar.config, engine.builder.rx_time, child=up.take_child()))
        t_scalar = up.run(prns, stop, assist)
        if not up.hand.reached:
            raise self._no_handover(source, stop)
        if keep_start:
            self._keep_start(up, key, nav, t_scalar)
        if self.config.mode != "deep":
            assert up.coupled is not None        # started at the hand-over
            return self._finish_scalar_coupled_loop(up.coupled, up.hand.prns,
                                                    up.recorder.epochs, t_scalar, t_all)
        return self._vector_loop(source, imu, off, n_per, stop, self.scalar, up.engine,
                                 up.navdata, up.hand, truth, progress, t_scalar, t_all)

    def _keep_start(self, up: _StartUp, key: tuple, nav, t_scalar: float) -> None:
        """Loose and tight: the scalar run (:attr:`scalar_record`); deep: a copy of the
        start-up's state at the hand-over (:attr:`deep_start`; the vector loop changes the
        objects themselves)."""
        if self.config.mode != "deep":
            self.scalar_record = ScalarRecord(
                key + (self.config.gnss_every,), nav, copy.copy(up.hand), up.recorder.epochs,
                up.engine.builder.rx_time, self.scalar, t_scalar)
            return
        state = (self.scalar, up.engine, up.navdata, up.hand)
        self.deep_start = DeepStart(key, nav, copy.deepcopy(state, memo={
            id(up.source): up.source}), t_scalar, up.source)

    def _check_inputs(self, source: IfSource, imu, truth,
                      duration_s: float | None) -> tuple[int, float, int]:
        """Before the start-up: the IMU span over the samples processed, the filter rate
        against the IMU rate, the filter, the reference for a truth alignment. Returns the
        end sample, the IMU-to-IF time offset [s] and the IMU samples per interval."""
        cfg = self.config
        stop = source.n_samples if duration_s is None else min(
            source.n_samples, round(duration_s * source.sampling_rate_hz))
        off = check_imu_span(source, imu, stop)
        n_per = imu_samples_per_interval(imu.rate_hz, cfg.filter_rate_hz)
        check_filter(cfg)              # filter name check before the (long) start-up
        if cfg.align == "truth" and truth is None:
            raise ImuDataError("align='truth' needs the reference (truth) file; use "
                               "align='gnss' without one")
        return stop, off, n_per

    def _run_from(self, start: DeepStart | ScalarRecord, key: tuple, nav, source, imu, off,
                  n_per, stop, truth, progress, t_all) -> IntegrationResult:
        """A run from an earlier run's start-up (deep) or scalar run (loose and tight)."""
        cfg = self.config
        if isinstance(start, ScalarRecord):
            if cfg.mode == "deep" or start.key != key + (cfg.gnss_every,) \
                    or start.nav is not nav:
                raise StartMismatchError(
                    "start: the scalar run was made on other data, with another hand-over "
                    "rule or GNSS rate (ScalarRecord.key), or the mode is deep")
            return self._replay_scalar_coupled_loop(source, imu, off, n_per, stop, start,
                                                    truth, t_all)
        if cfg.mode != "deep" or start.key != key or start.nav is not nav:
            raise StartMismatchError(
                "start: the start-up state was made on other data or with another "
                "hand-over rule (DeepStart.key), or the mode is not deep")
        t0 = time.perf_counter()
        rx, engine, navdata, hand = start.copy_for(source)
        self.scalar = rx                       # its records are this run's from here
        t_scalar = time.perf_counter() - t0   # this run's own work: the copy
        return self._vector_loop(source, imu, off, n_per, stop, rx, engine, navdata,
                                 hand, truth, progress, t_scalar, t_all)

    def _no_handover(self, source: IfSource, stop: int) -> HandoverError:
        """Why the start-up never handed over: what it found, and whether the file was long
        enough (two D1 subframes for the time of week, plus ``handover_wait_s``)."""
        cfg, fs = self.config, source.sampling_rate_hz
        found = [c.prn for c in self.scalar.channels.values() if c.n_acquisitions > 0]
        usual, longest = handover_span_s(cfg)
        span = stop / fs                       # the start-up runs from sample 0
        need = (f"needs about {usual:.0f} s of file (two D1 subframes: the time of week), "
                f"up to {longest:.0f} s when a channel lacks navigation data")
        short = (f"; the {span:.1f} s processed are too short for the hand-over, which "
                 f"{need}" if span < usual else
                 f"; the {span:.1f} s processed may be too short: the hand-over {need}"
                 if span < longest else "")
        loop = "vector" if cfg.mode == "deep" else cfg.mode
        return HandoverError(
            f"{source.path}: no hand-over to the {loop} loop: " +
            ("no satellite found" if not found else
             f"tracked {', '.join(f'C{p:02d}' for p in found)} but never 4 with time, "
             "ephemeris and a valid fix") + short)

    # ------------------------------------------------------------------------------------
    def _vector_loop(self, source, imu, off, n_per, stop, rx, engine, navdata,
                     hand, truth, progress, t_scalar, t_all) -> IntegrationResult:
        """Hand-over from the scalar start-up and the vector loop to the end of the file.

        Hand-over: channels (:func:`~.handover.handover_channels`), INS alignment
        (:func:`~.alignment.align_ins`), clock from the fix, integration filter
        (:func:`~.filter_setup.make_integration_filter`), pre-filters from the
        scalar loops (:meth:`~sdr_di.deep.vector_tracking.VectorTracking.start`). Then the
        mode-independent
        :class:`~sdr_di.integration.loop.IntegrationLoop` runs with
        :class:`~sdr_di.deep.vector_tracking.VectorTracking` as its measurement source.
        """
        cfg = self.config
        fs = source.sampling_rate_hz
        sol = hand.sol
        assert hand.sample is not None           # a reached hand-over
        k_h = int(hand.sample)
        clock = SampleClock.of(engine.builder.rx_time, fs)
        chans = handover_channels(cfg, rx, navdata, hand, clock)
        # ---- IMU grid: the loop starts on the first IMU sample after the hand-over
        dt_imu = 1.0 / imu.rate_hz
        t_if = imu.t + off                     # IF-relative time of each IMU sample
        i_h = int(np.searchsorted(t_if, max(k_h, max(c.next_start for c in chans)) / fs))
        i_h = max(i_h, 1)
        T = n_per * dt_imu
        k_grid0 = round(t_if[i_h] * fs)
        ins, llh_fix, att_sig = align_ins(cfg, imu, truth, sol, t_if, i_h, k_h / fs)
        clk_b = float(sol.clock_bias_m) + float(sol.clock_drift_mps) * (t_if[i_h] - k_h / fs)
        clk_d = float(sol.clock_drift_mps)
        kf, process, meas = make_integration_filter(cfg, T, sol, llh_fix, att_sig)
        # the summary's record of what the filter uses, read from the built filter
        self.filter_used = filter_record(kf, cfg.filter, cfg.filter_options)

        prof = {"scalar": t_scalar, "read": 0.0, "nco": 0.0, "correlate": 0.0,
                "prefilter": 0.0, "filter": 0.0, "ins": 0.0, "output": 0.0}
        tracking = VectorTracking(cfg, source, chans, navdata, clock, stop, prof,
                                  handover=(k_h / fs, sol.week, sol.sow),
                                  spacing_chips=self.scalar.config.spacing_chips)
        tracking.start(rx, ins, clk_b, k_grid0)
        n1 = round(fs * 1e-3)            # an interval needs its last epochs' samples past k1
        loop = IntegrationLoop(
            imu=imu, t_if=t_if, i_start=i_h, k_start=k_grid0, n_per=n_per, fs=fs, stop=stop,
            margin=2 * n1 + 16, ins=ins, clock_bias_m=clk_b, clock_drift_mps=clk_d, kf=kf,
            process=process, set_geometry=meas.set_geometry, sow_of_sample=clock.sow,
            output_every=max(1, round(cfg.filter_rate_hz / cfg.output_rate_hz)), truth=truth,
            progress=progress, profile=prof)
        adapt0 = kf.adaptation_time_s
        src: MeasurementSource = tracking
        if cfg.noise_policy != "cn0":    # "fixed": the config checked both sigmas are given
            assert cfg.sigma_range_m is not None and cfg.sigma_rate_mps is not None
            src = FixedNoiseSource(tracking, cfg.sigma_range_m, cfg.sigma_rate_mps)
        try:
            (loop.run_ahead if cfg.nco_latency else loop.run)(src)
        finally:
            tracking.close()
        return self._result(loop, clock, tuple(c.prn for c in chans), kf, adapt0, k_grid0,
                            prof, t_all, tracking.nav_log.summary(loop.k0 / fs))

    def _result(self, loop: IntegrationLoop, clock: SampleClock, prns: tuple, kf,
                adapt0: float, k_grid0: int, prof: dict, t_all: float,
                navigation: dict) -> IntegrationResult:
        """The loop's rows and the run's profile as an :class:`IntegrationResult` (every
        mode)."""
        fs = loop.fs
        k0 = loop.k0
        prof["total"] = time.perf_counter() - t_all
        prof["processed_s"] = k0 / fs
        prof["deep_s"] = (k0 - k_grid0) / fs
        prof["loop"] = sum(prof.get(k, 0.0) for k in (
            "read", "nco", "correlate", "prefilter", "measure", "filter", "ins", "output"))
        prof["realtime_factor"] = prof["processed_s"] / prof["total"] if prof["total"] else 0.0
        self.profile = prof
        col = loop.columns(len(prns))
        return IntegrationResult(
            t=col["t"], week=clock.week, sow=col["sow"], llh=col["llh"], v_n=col["v"],
            att=col["att"], clock_bias_m=col["b"], clock_drift_mps=col["d"], n_used=col["n"],
            att_err=col["ae"], vel_err=col["ve"], pos_err=col["pe"],
            prns=prns, used=col["used"], cn0_dbhz=col["cn0"],
            nis=col["nis"], handover_s=k_grid0 / fs, filter_name=kf.name,
            adaptation_s=kf.adaptation_time_s - adapt0, profile=prof,
            nav_change=col["nav"], navigation=navigation, mode=self.config.mode,
            filter_used=getattr(self, "filter_used", None),
            sd=col["sd"], nees=col["nees"], updates=col["updates"], innov=col["innov"],
            deep_measurements=(self.config.deep_measurements if self.config.mode == "deep"
                               else None))

    # ------------------------------------------------------------------------------------
    def _start_scalar_coupled_loop(self, source, imu, off, n_per, stop, hand: Handover,
                                   recorder, truth, tracking_config, rx_time,
                                   behind: bool = True, child=None) -> _CoupledRun:
        """Loose or tight mode: start the loop at the hand-over (module notes).

        Same hand-over grid point, INS alignment, clock and filter as :meth:`_vector_loop`;
        the loop's measurement source is :class:`~sdr_di.integration.loose_fixes.
        LooseFixSource` or :class:`~sdr_di.integration.tight_ranges.TightRangeSource` over
        the epochs the scalar receiver records; the loop runs behind the receiver in a
        child process (:func:`~sdr_di.integration.loop_process.start_loop_behind`; else on
        a second thread; ``child``: the process started for it, else none), with a channel
        column for every channel of the receiver until :meth:`_finish_scalar_coupled_loop`.
        """
        cfg = self.config
        fs = source.sampling_rate_hz
        sol = hand.sol
        assert hand.sample is not None and hand.next_start is not None   # reached, coupled
        k_h = int(hand.sample)
        clock = SampleClock.of(rx_time, fs)
        t_if = imu.t + off
        i_h = max(int(np.searchsorted(t_if, max(k_h, hand.next_start) / fs)), 1)
        T = n_per / imu.rate_hz
        k_grid0 = round(t_if[i_h] * fs)
        ins, llh_fix, att_sig = align_ins(cfg, imu, truth, sol, t_if, i_h, k_h / fs)
        clk_b = float(sol.clock_bias_m) + float(sol.clock_drift_mps) * (t_if[i_h] - k_h / fs)
        clk_d = float(sol.clock_drift_mps)
        loose = cfg.mode == "loose"
        n_states = layout_of_options(cfg.filter_options).n
        model = LooseMeasurementModel(n_states=n_states) if loose else \
            RangeRateMeasurementModel(n_states=n_states)
        kf, process, meas = make_integration_filter(cfg, T, sol, llh_fix, att_sig, model)
        # the summary's record of what the filter uses, read from the built filter
        self.filter_used = filter_record(kf, cfg.filter, cfg.filter_options)
        others = sorted(set(hand.channels) - set(hand.prns))
        prns = tuple(hand.prns) + tuple(others)
        prof = {"scalar": 0.0, "measure": 0.0, "filter": 0.0, "ins": 0.0, "output": 0.0}
        imu_epoch = (clock.week, clock.sow(0) + off)     # BDT of IMU t = 0 (module notes)
        src_cls = LooseFixSource if loose else TightRangeSource
        src = src_cls(recorder, prns, imu.t, imu_epoch, fs, prof,
                      tracking_config=tracking_config, interval_s=1.0 / cfg.gnss_rate_hz)
        n1 = round(fs * 1e-3)            # deep's margin, so that the windows are the same
        loop = IntegrationLoop(
            imu=imu, t_if=t_if, i_start=i_h, k_start=k_grid0, n_per=n_per, fs=fs, stop=stop,
            margin=2 * n1 + 16, ins=ins, clock_bias_m=clk_b, clock_drift_mps=clk_d, kf=kf,
            process=process, set_geometry=meas.set_epoch if loose else meas.set_geometry,
            sow_of_sample=clock.sow,
            output_every=max(1, round(cfg.filter_rate_hz / cfg.output_rate_hz)), truth=truth,
            profile=prof)
        adapt0 = kf.adaptation_time_s
        run_src: MeasurementSource = src
        if not (loose or cfg.noise_policy == "cn0"):  # "fixed": the config checked both sigmas
            assert cfg.sigma_range_m is not None and cfg.sigma_rate_mps is not None
            run_src = FixedNoiseSource(src, cfg.sigma_range_m, cfg.sigma_rate_mps)
        if behind:
            thread = start_loop_behind(loop, run_src, src, recorder, child=child)
        else:              # the epochs are all recorded: the loop runs on a thread at once
            thread = BackgroundLoop(loop, run_src)
        return _CoupledRun(thread=thread, loop=loop, src=src, clock=clock, kf=kf,
                           adapt0=adapt0, k_grid0=k_grid0, prof=prof)

    def _replay_scalar_coupled_loop(self, source, imu, off, n_per, stop, record: ScalarRecord,
                                    truth, t_all) -> IntegrationResult:
        """Loose or tight mode over the epochs of an earlier run (:class:`ScalarRecord`):
        the loop of :meth:`_start_scalar_coupled_loop` without the receiver."""
        t0 = time.perf_counter()
        hand = copy.deepcopy(record.hand)
        self.scalar = record.scalar                # its records are this run's
        recorder = record.recorder()
        run = self._start_scalar_coupled_loop(
            source, imu, off, n_per, stop, hand, recorder, truth, record.scalar.config,
            record.rx_time, behind=False)
        return self._finish_scalar_coupled_loop(run, hand.prns, recorder.epochs,
                                                time.perf_counter() - t0, t_all)

    def _finish_scalar_coupled_loop(self, run: _CoupledRun, handed: list[int], epochs,
                                    t_scalar, t_all) -> IntegrationResult:
        """Loose or tight mode: wait for the loop (:meth:`_start_scalar_coupled_loop`),
        keep the channel columns of the handed-over PRNs and of those the receiver acquired
        later, in that order."""
        t0 = time.perf_counter()
        run.thread.join()
        if isinstance(run.thread, LoopProcess):     # its objects as the loop ended
            th = run.thread
            run.loop, run.src, run.kf, run.prof = (th.loop, th.epoch_source, th.loop.kf,
                                                   th.loop.profile)
        loop, src, prof = run.loop, run.src, run.prof
        prof["scalar"] = t_scalar
        prof["loop_wait"] = time.perf_counter() - t0   # the loop's tail after the receiver
        prof["loop_cpu"] = run.thread.cpu_s             # CPU of the loop's thread
        later = sorted({int(p) for ep in epochs for p in ep.obs.prn} - set(handed))
        prns = tuple(handed) + tuple(later)
        src.keep_columns(prns, loop.rows)
        return self._result(loop, run.clock, prns, run.kf, run.adapt0, run.k_grid0, prof,
                            t_all, src.navigation)


@dataclasses.dataclass
class _CoupledRun:
    """Loose or tight: the integration loop started at the hand-over and running behind the
    scalar receiver (:meth:`IntegratedReceiver._start_scalar_coupled_loop`), with what its
    result needs."""

    thread: LoopProcess | BackgroundLoop
    loop: IntegrationLoop
    src: LooseFixSource | TightRangeSource
    clock: SampleClock
    kf: object
    adapt0: float            # the filter's adaptation time at the start [s]
    k_grid0: int             # IF sample of the loop's first grid point
    prof: dict


class _StartUp:
    """The scalar start-up (every mode): the scalar receiver's run with its epoch callback
    (:meth:`on_epoch`), the fixes (PVT engine), the navigation data in force and the
    hand-over rule (:meth:`_hand_over`; receiver notes). Deep: it ends at the hand-over.
    Loose and tight: the receiver runs on; the loop is started at the hand-over
    (``start_loop``) and every ``gnss_every``-th epoch after it is recorded for it
    (:meth:`_after_handover`).
    """

    def __init__(self, owner: IntegratedReceiver, source: IfSource, nav, progress,
                 start_loop: Callable) -> None:
        self.cfg, self.rx, self.source = owner.config, owner.scalar, source
        self.fs = source.sampling_rate_hz
        rt = None
        if source.start_week is not None and source.start_sow is not None:
            rt = ReceiverTime.from_sample_zero(self.fs, source.start_week, source.start_sow)
        self.engine = PvtEngine(self.fs, {}, None, rx_time=rt)
        self.navdata = NavDataInForce(nav)
        self.engine.navdata = self.navdata
        self.recorder = GnssEpochRecorder(self.engine, self.navdata)
        self.hand = Handover()
        self.progress, self.start_loop = progress, start_loop
        self.n_epoch = 0                 # epochs after the hand-over (loose and tight)
        self.next_progress = 0.0         # file time of the next progress call [s]
        self.child: LoopChild | None = None    # loose and tight: the loop's process
        self.child_started = False
        self.coupled: _CoupledRun | None = None

    def run(self, prns, stop: int, assist) -> float:
        """The scalar receiver over ``[0, stop)``; its wall time [s]."""
        t0 = time.perf_counter()
        try:
            self.rx.run(self.source, prns=prns, on_epoch=self.on_epoch,
                        epoch_interval_s=SCALAR_EPOCH_S, stop_sample=stop, assist=assist)
        except BaseException:
            self.recorder.close()
            if self.coupled is not None:
                self.coupled.thread.abort()
            raise
        finally:
            if self.child is not None:          # no hand-over: not used
                self.child.close()
        self.recorder.close()
        return time.perf_counter() - t0

    def take_child(self):
        """The loop's process for the loop that starts now (None: a thread runs it)."""
        child, self.child = self.child, None
        return child

    def take_up(self, sample: int, ephs) -> None:
        """Navigation data decoded by now into the data in force, and into the fixes."""
        rx, navdata = self.rx, self.navdata
        navdata.offer_decoded(ephs, rx.klobuchar, sample / self.fs)
        if navdata.iono_source != "broadcast":
            offer_subframe_klobuchar(rx, navdata, sample / self.fs)
        self.engine.ephemerides, self.engine.iono = navdata, navdata.klobuchar

    def _report(self, sample: int, n_obs: int, n_used: int | None) -> None:
        if self.progress is not None and sample / self.fs >= self.next_progress:
            self.progress(sample / self.fs, n_obs, n_used)
            self.next_progress = sample / self.fs + 1.0

    def on_epoch(self, sample: int, obs, ephs) -> bool:
        """The scalar receiver's epoch callback: a fix, and the hand-over when its rule is
        met; True ends the scalar run (deep: the vector loop takes over)."""
        if self.cfg.mode != "deep" and not self.child_started:
            # loose/tight: the loop's process, started once acquisition is done, so that
            # its start-up uses the core tracking leaves idle (integration.loop_process)
            self.child, self.child_started = LoopChild.start(), True
        if self.hand.reached:
            return self._after_handover(sample, obs, ephs)
        self._report(sample, len(obs), None)           # start-up: no filter yet
        if not obs:            # nothing tracked at this epoch: no fix, keep going
            return False
        self.take_up(sample, ephs)
        sol = self.engine.process(obs)
        if not sol.valid or not sol.velocity_valid:
            return False
        if self.hand.first_fix is None:
            self.hand.first_fix = sample
        return self._hand_over(sample, obs, sol)

    def _hand_over(self, sample: int, obs, sol) -> bool:
        """The hand-over rule (receiver notes): at least 4 channels with time, code lock and
        ephemeris, every tracked one or ``handover_wait_s`` after the first fix, and the
        ionosphere coefficients or ``iono_wait_s`` spent waiting for them."""
        cfg, fs, navdata, hand = self.cfg, self.fs, self.navdata, self.hand
        trk = [o for o in obs if o.state == ChannelState.TRACK.name]
        ok = [o for o in trk if o.time_valid and o.code_lock
              and navdata.has(o.prn, sol.week, sol.sow)]
        assert hand.first_fix is not None        # on_epoch sets it before
        since_fix = (sample - hand.first_fix) / fs
        waited = since_fix >= cfg.handover_wait_s
        if navdata.klobuchar is None and since_fix < cfg.iono_wait_s:
            return False       # wait for the ionosphere coefficients (module notes)
        if not (len(ok) >= 4 and (len(ok) == len(trk) or waited)):
            return False
        if navdata.klobuchar is None:
            warnings.warn(
                f"deep: hand-over at {sample / fs:.1f} s without ionosphere "
                f"coefficients ({navdata.assistance_iono_label} in the assistance "
                f"data, none decoded after {since_fix:.1f} s): no ionosphere model "
                "until subframe 1 is decoded", NavDataWarning, stacklevel=4)
        hand.sample, hand.sol, hand.prns = sample, sol, [o.prn for o in ok]
        if cfg.mode == "deep":
            return True        # the vector loop takes over from the channels
        # loose/tight: the loop's grid starts where deep's would (the channels' next code
        # epochs); the fix of the hand-over epoch is the first measurement
        hand.next_start = max(int(self.rx.channels[p].next_start) for p in hand.prns)
        hand.channels = sorted(int(p) for p in self.rx.channels)
        self.recorder.record(sample, obs)
        # lost channels are searched around, and timed from, the last fix
        self.rx.predictor = FixPredictor(self.engine, fs, self.source.carrier_hz)
        # the integration loop runs behind the receiver, on a second thread
        self.coupled = self.start_loop(hand, self.recorder, self.engine)
        return False

    def _after_handover(self, sample: int, obs, ephs) -> bool:
        """Loose and tight: the scalar receiver keeps running; every gnss_every-th epoch is
        a measurement epoch (module notes)."""
        self.n_epoch += 1
        self.take_up(sample, ephs)
        if self.n_epoch % self.cfg.gnss_every == 0:
            self.recorder.record(sample, obs)
        self._report(sample, len(obs), len(obs))
        return False
