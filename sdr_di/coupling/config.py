"""Settings of the integrated receiver in any coupling mode: :class:`IntegrationConfig`.

The reasons for the defaults are the notes of :mod:`sdr_di.integration.receiver`. This module
is in :mod:`sdr_di.coupling`, below both the integration loop and deep mode's measurement
source (:mod:`~sdr_di.deep.vector_tracking`), which both read the settings. The one builder
from a filter entry and assumptions is
:func:`sdr_di.integration.settings.build_integration_config`.
"""

from __future__ import annotations

import dataclasses
import math

from ..errors import OptionsError
from ..ins.imu import ImuErrorModel
from ..oscillator import CLOCK_PRESETS, OscillatorSpec

__all__ = ["DEEP_MEASUREMENTS", "MODES", "NCO_LATENCIES", "RESET_FUSION_HZ", "SCALAR_EPOCH_S",
           "IntegrationConfig", "imu_samples_per_interval", "is_nco_latency"]

#: Coupling modes of :class:`IntegratedReceiver` (receiver notes).
MODES = ("deep", "loose", "tight")
#: Deep mode's NCO latencies [filter intervals] (:attr:`IntegrationConfig.nco_latency`).
NCO_LATENCIES = (0, 1)
#: Deep mode's measurement architectures (:attr:`IntegrationConfig.deep_measurements`,
#: docs/deep.md, *Measurement architectures*): paper 004's cascaded pre-filters, pre-filters
#: with an information reset every interval, and the discriminator outputs themselves.
DEEP_MEASUREMENTS = ("prefilter", "reset", "discriminator")
#: Default fusion rate of the ``reset`` architecture [Hz] (:attr:`IntegrationConfig.
#: fusion_rate_hz`).
RESET_FUSION_HZ = 5.0


def is_nco_latency(v) -> bool:
    """Whether ``v`` is an NCO latency (:data:`NCO_LATENCIES`; a bool is not): the one test
    of the configuration, the API and the experiments' parameters."""
    return not isinstance(v, bool) and v in NCO_LATENCIES


#: Interval of the scalar start-up's output epochs (the hand-over rule runs on them) [s].
SCALAR_EPOCH_S = 0.1


@dataclasses.dataclass
class IntegrationConfig:
    """Settings of the receiver in any coupling mode (receiver notes give the reasons for the
    defaults).

    Attributes
    ----------
    mode : str
        ``"deep"`` (the filter closes the tracking loops), ``"loose"`` (WLS fixes) or
        ``"tight"`` (pseudoranges and rates): :data:`MODES`.
    gnss_rate_hz : float
        Measurement rate of loose and tight [Hz] (receiver notes): 10 Hz divided by a whole
        number, at most the filter rate; unused in deep mode.
    filter : str
        Integration filter (registry name, :data:`sdr_di.filters.FILTER_NAMES`).
    filter_rate_hz : float
        Integration-filter and NCO-command rate [Hz]; must divide the IMU rate.
    output_rate_hz : float
        Solution rows [Hz] (paper 004: 5 Hz).
    align : str
        ``"truth"`` or ``"gnss"`` (receiver notes).
    handover_wait_s : float
        Seconds after the first fix to wait for every tracked channel before handing over
        with at least 4.
    cn0_min_dbhz, cn0_hysteresis_db, cn0_window_ms, fast_margin_db, loss_margin_db, nis_p_min
        Channel management (receiver notes): C/N0 gate [dB-Hz] and its hysteresis [dB], C/N0
        window [ms], the thresholds of the 60 ms and 120 ms tests below the gate [dB], and
        the pre-filter NIS test's false-alarm probability.
    coherent_ms : int
        Longest coherent pre-filter block [ms] (receiver notes); blocks never cross a data
        bit, so D1 channels use at most 20 ms and D2 channels 2 ms. 1 = one update per
        code epoch.
    imu : ImuErrorModel
        IMU spec for ``Q`` and ``P0`` (random walks, biases; default paper 004 Table 4).
    bias_time_s : float
        Time for the bias random walk to reach the spec [s].
    clock : str or OscillatorSpec
        Receiver oscillator the clock states' process noise assumes (paper 004 eq 4): a
        preset of :data:`~sdr_di.oscillator.CLOCK_PRESETS` (``"tcxo"``, the default,
        ``"ocxo"``, ``"ideal"``; Brown & Hwang) or an ``OscillatorSpec``; its flicker term
        is mapped into the two-state model (:func:`clock_model`).
    noise_policy, sigma_range_m, sigma_rate_mps
        The filter's ``R``: ``"cn0"`` (pre-filter variances, from C/N0) or ``"fixed"``
        (these sigmas [m, m/s] on every range and range rate).
    p0_vel_mps, p0_pos_m : tuple or None
        ``P0`` sigmas (E, N, U) [m/s, m]; None: 0.1 m/s and the fix's position sigma (at
        least 1 m). A given position sigma is floored by the fix's.
    p0_clock : tuple or None
        ``(clock bias [m], clock drift [m/s])`` sigmas of ``P0`` (None for either: the
        fix's 1.5x position sigma and 0.1 m/s).
    init_att_err_deg, init_vel_err_mps, init_pos_err_m : tuple
        Errors injected into the INS at the alignment (E, N, U): attitude as a rotation
        vector (computed = exp(-[phi x]) true; U = heading) [deg], velocity [m/s],
        position [m] (docs/assumptions.md).
    assumptions : dict or None
        Record of the assumptions applied (:func:`~sdr_di.integration.assumptions.
        apply_to_deep`), written into the run's summary.
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
        the loop switches the model on when they are decoded (receiver notes). Default 0:
        hand over at once; the rows before the take-up are flagged (``iono`` column of the
        solution file), so a file whose assistance has no ionosphere lines gives up to 30 s
        more solution instead of none.
    nco_latency : int
        Deep mode: filter intervals between an update and the NCO commands that first use
        it, beyond the next (receiver notes, *NCOs one interval ahead*). 0 (default): the
        update at the end of interval ``k`` steers interval ``k + 1``. 1: it steers
        ``k + 2``, as in a receiver whose correlators run on while the filter updates; the
        correlation of ``k + 1`` then overlaps the update of ``k`` on a second core.
    deep_measurements : str
        Deep mode: what each channel hands the integration filter (:data:`DEEP_MEASUREMENTS`;
        docs/deep.md, *Measurement architectures*). ``"prefilter"`` (default): paper 004's
        cascaded pre-filters (:class:`~sdr_di.deep.prefilter.PreFilterBank`);
        ``"reset"``: the same pre-filters restarted from an uninformative prior every
        interval, so each output holds only that interval's information
        (:class:`~sdr_di.deep.prefilter.ResetPreFilterBank`); ``"discriminator"``: the
        interval's code and frequency discriminator outputs, no pre-filter state
        (:class:`~sdr_di.deep.discriminators.DiscriminatorBank`).
    fusion_rate_hz : float or None
        Deep mode, ``deep_measurements = "reset"``: rate [Hz] of the integration filter's
        updates with the pre-filters' outputs, each followed by their information reset;
        the filter rate divided by a whole number (the NCOs and the INS keep the filter
        rate). None (default): 5 Hz for ``reset`` (:data:`RESET_FUSION_HZ`: Carlson's local
        filters run faster than the fusion, and 200 ms of carrier phase per output make its
        frequency 10 times more precise than 20 ms; docs/deep.md), every interval for the
        other architectures (the only value they accept).
    """

    filter: str = "ekf"
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
    clock: str | OscillatorSpec = "tcxo"
    noise_policy: str = "cn0"
    sigma_range_m: float | None = None
    sigma_rate_mps: float | None = None
    p0_vel_mps: tuple | None = None
    p0_pos_m: tuple | None = None
    p0_clock: tuple | None = None
    init_att_err_deg: tuple = (0.0, 0.0, 0.0)
    init_vel_err_mps: tuple = (0.0, 0.0, 0.0)
    init_pos_err_m: tuple = (0.0, 0.0, 0.0)
    assumptions: dict | None = None
    prefilter: dict = dataclasses.field(default_factory=dict)
    filter_options: dict = dataclasses.field(default_factory=dict)
    p0_att_deg: tuple = (0.05, 0.05, 0.1)
    chunk_ms: int = 200
    coherent_ms: int = 20
    iono_wait_s: float = 0.0
    mode: str = "deep"
    gnss_rate_hz: float = 5.0
    nco_latency: int = 0
    deep_measurements: str = "prefilter"
    fusion_rate_hz: float | None = None

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ValueError(f"mode must be one of {', '.join(MODES)}, got {self.mode!r}")
        g = self.gnss_rate_hz
        m = 1.0 / (SCALAR_EPOCH_S * g) if isinstance(g, (int, float)) and g > 0 else math.nan
        if not (math.isfinite(m) and m >= 1.0 - 1e-9 and abs(m - round(m)) < 1e-9):
            raise ValueError(f"gnss_rate_hz must be 10 Hz divided by a whole number (10, 5, "
                             f"2.5, 2, 1, ...), got {g!r}")
        if not isinstance(self.clock, OscillatorSpec) and self.clock not in CLOCK_PRESETS:
            raise ValueError(f"clock must be one of {', '.join(CLOCK_PRESETS)}, got "
                             f"{self.clock!r}")
        if self.noise_policy not in ("cn0", "fixed") or (self.noise_policy == "fixed" and not (
                self.sigma_range_m and self.sigma_rate_mps)):
            raise ValueError(f"noise_policy must be 'cn0' or 'fixed' (with sigma_range_m and "
                             f"sigma_rate_mps > 0), got {self.noise_policy!r}")
        if self.align not in ("truth", "gnss"):
            raise ValueError(f"align must be 'truth' or 'gnss', got {self.align!r}")
        for name in ("filter_rate_hz", "output_rate_hz"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be > 0, got {v!r}")
        v = self.iono_wait_s
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
            raise ValueError(f"iono_wait_s must be >= 0, got {v!r}")
        if not is_nco_latency(self.nco_latency):
            raise ValueError(f"nco_latency must be 0 or 1 (filter intervals), got "
                             f"{self.nco_latency!r}")
        if self.mode != "deep" and self.nco_latency:
            raise ValueError(f"nco_latency applies to deep mode only (the {self.mode} loop "
                             "commands no NCOs)")
        if self.deep_measurements not in DEEP_MEASUREMENTS:
            raise ValueError(f"deep_measurements must be one of {', '.join(DEEP_MEASUREMENTS)}, "
                             f"got {self.deep_measurements!r}")
        if self.mode != "deep" and self.deep_measurements != "prefilter":
            raise ValueError(f"deep_measurements applies to deep mode only (the {self.mode} "
                             "loop takes the scalar receiver's measurements)")
        self._check_fusion_rate()
        if self.mode != "deep" and self.gnss_rate_hz > self.filter_rate_hz + 1e-9:
            raise ValueError(f"gnss_rate_hz {self.gnss_rate_hz:g} must not exceed the filter "
                             f"rate {self.filter_rate_hz:g} Hz")

    def _check_fusion_rate(self) -> None:
        v = self.fusion_rate_hz
        if v is None:
            if self.mode == "deep" and self.deep_measurements == "reset" and self.nco_latency:
                raise ValueError("deep_measurements 'reset' with nco_latency 1: give "
                                 "fusion_rate_hz equal to the filter rate (fusions less often "
                                 "than every interval need nco_latency 0)")
            return
        if self.mode != "deep":
            raise ValueError(f"fusion_rate_hz applies to deep mode only, not {self.mode}")
        m = self.filter_rate_hz / v if isinstance(v, (int, float)) and not isinstance(
            v, bool) and math.isfinite(v) and v > 0 else math.nan
        if not (math.isfinite(m) and m >= 1.0 - 1e-9 and abs(m - round(m)) < 1e-9):
            raise ValueError(f"fusion_rate_hz must be the filter rate "
                             f"{self.filter_rate_hz:g} Hz divided by a whole number, got {v!r}")
        if round(m) > 1 and self.deep_measurements != "reset":
            raise ValueError(f"fusion_rate_hz below the filter rate needs deep_measurements "
                             f"'reset' (the {self.deep_measurements} outputs are fused every "
                             "interval)")
        if round(m) > 1 and self.nco_latency:
            raise ValueError("fusion_rate_hz below the filter rate needs nco_latency 0")

    @property
    def fusion_intervals(self) -> int:
        """Filter intervals per fusion of the channels' measurements (deep mode;
        :attr:`fusion_rate_hz`)."""
        if self.mode != "deep":
            return 1
        v = self.fusion_rate_hz
        if v is None:
            if self.deep_measurements != "reset":
                return 1
            v = RESET_FUSION_HZ
        return max(1, round(self.filter_rate_hz / v))

    @property
    def gnss_every(self) -> int:
        """Scalar output epochs (0.1 s) per loose/tight measurement epoch."""
        return max(1, round(1.0 / (SCALAR_EPOCH_S * self.gnss_rate_hz)))


def imu_samples_per_interval(imu_rate_hz: float, filter_rate_hz: float,
                             name: str = "filter rate", where: str = "") -> int:
    """IMU samples per integration-filter interval: the filter rate must divide the IMU rate
    (the INS is propagated over whole IMU samples between two updates).

    Parameters
    ----------
    imu_rate_hz, filter_rate_hz : float
        IMU sample rate and integration-filter rate [Hz].
    name : str
        How the message names the filter rate (``--filter-rate``, ``filter_rate_hz``).
    where : str
        The IMU file, named in the message.

    Raises
    ------
    OptionsError
        ``imu_rate_hz / filter_rate_hz`` is not a whole number >= 1.
    """
    n_per = imu_rate_hz / filter_rate_hz
    if abs(n_per - round(n_per)) > 1e-9 or round(n_per) < 1:
        of = f" of {where}" if where else ""
        raise OptionsError(f"{name} {filter_rate_hz:g} Hz must divide the IMU rate "
                           f"{imu_rate_hz:g} Hz{of}")
    return round(n_per)
