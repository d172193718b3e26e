"""Per-channel pre-filters of the federated deep integration (paper 004 Fig. 1, refs [6], [13]).

Each tracked channel has a small Kalman filter fed by the early/prompt/late sums of coherent
blocks of 1 ms code epochs (NH code wiped off on D1 satellites; the vector loop ends the
blocks at data-bit edges, so an epoch below is one such block of duration ``T``). Its state
is the tracking error of the INS-commanded NCOs, *signal minus replica*::

    x = [dtau (chips), dphi (rad), df (Hz)]     at the start of an epoch

Measurements of epoch ``j`` (duration ``T``), linear in the state at its start (epoch
averages)::

    z_tau = (1 - d) (|E| - |L|) / (|E| + |L|)  = dtau + (beta T / 2) df + v_tau
    z_phi = atan(Q_P / I_P)                    = dphi + (pi T) df     + v_phi   (mod pi)

``d`` the early/late offset [chips], ``beta = f_code / f_carr`` [chips per cycle]. The
two-quadrant arctangent and the innovation reduced modulo pi make the filter insensitive to
data-bit (and NH) sign changes, so it needs no bit synchronization: bit transitions never
break it. Discriminator noise variances from the channel's C/N0 (linear, Hz) and ``T``::

    r_tau = d / (2 C/N0 T) (1 + 1 / (C/N0 T))          (normalized early-minus-late envelope)
    r_phi = 1 / (2 C/N0 T) (1 + 1 / (2 C/N0 T))         (arctangent, with squaring loss)

Dynamics from one epoch start to the next: ``dtau += beta T df`` (carrier-aided code),
``dphi += 2 pi T df``, ``df`` a random walk of PSD ``s_f`` [Hz^2/s] (the INS velocity-error
drift and the clock frequency noise the NCO commands cannot predict), plus small
``q_tau``, ``q_phi`` per epoch.

Noise model: what the output variances mean
-------------------------------------------
The filter above is a *design*: ``s_f`` (4 Hz^2/s) and ``q_phi`` set its bandwidth so that
it follows what the INS-driven NCOs miss, and its covariance ``P`` is the error covariance
only if the tracking errors really were a random walk of that PSD. They are not: with the
NCOs commanded from the INS and clock every interval, and the filter's corrections moved
into the state (:meth:`PreFilterBank.shift`), what is left per channel is the line-of-sight
velocity error the accelerometer noise adds, ``s_f_model = VRW^2 / lambda^2`` (about 1e-5
Hz^2/s for the default MEMS IMU; :func:`model_process_noise`). ``P[2, 2]`` then overstated
the frequency error variance 4.5-6.3 times (45-30 dB-Hz, ``scripts/check_prefilter.py``),
which is the 5.5 times too large rate ``R`` the deep filters' innovations showed.

So the outputs state the error covariance ``C`` of the *same* estimates under the noise
model (the covariance analysis of a suboptimal filter: the filter's own gain ``K``, the
model's noise)::

    C <- (I - K H) C (I - K H)^T + K R K^T                 (update, Joseph form)
    C <- F C F^T + diag(0, q_phi_model T, s_f_model T)     (propagation)

with ``R = diag(r_tau, r_phi)`` and ``H``, ``F`` above. ``C`` starts equal to ``P`` (the
priors of :meth:`PreFilterBank.reset` are real priors), is not touched by ``shift``
(the NCOs and the state move together, the error does not) nor by ``decorrelate`` (which
only resets the design code variance, to keep the code gain high). The oscillator's noise is
not in the model: it is common to every channel and is the integration filter's clock
process noise, which a diagonal ``R`` could not carry. Checked by Monte Carlo
(``scripts/check_prefilter.py``, 200 channels x 200 intervals of 20 ms blocks, errors
against the simulated truth): stated / true variance 0.99-1.08 (code) and 0.93
(frequency) at 45, 40, 35 and 30 dB-Hz, where ``P`` gave 1.00-1.35 and 6.3-4.5.

Interaction with the vector loop (:mod:`sdr_di.integration.receiver`):

* **outputs** at the integration-filter rate: ``dtau``, ``df`` and their variances (``C``),
  turned into the measurements of paper 004 eq 8-9, ``drho = (c / f_code) dtau`` and
  ``drho_dot = (c / f_carr) df`` (``df`` in Hz is ``delta_omega / 2 pi``), with ``R_k`` from
  the covariances (eq 34);
* **corrections**: after the integration filter's feedback the NCO commands of the next
  interval move by the correction's projection on the channel, ``(f_code / c) (H x)_rho``
  chips and ``(f_carr / c) (H x)_rho_dot`` Hz; :meth:`PreFilterBank.shift` removes them from
  the state so it stays the error relative to the new NCOs;
* **decorrelation**: the code variance is reset to its prior (``sigma_tau0``) at the start of
  every interval, so successive code outputs are (nearly) independent measurements of the
  integration filter, as a federated filter's local filters should be. The carrier states
  (phase, frequency) keep their covariance (``reset_frequency=False``, the default): the
  frequency then comes from the continuously tracked carrier phase rather than from the
  phase slope inside one 20 ms interval, 4x more precise. Measured (with 1 ms updates, before
  the coherent blocks, and with the 0.45 m ephemeris bias then present) on a 26 s
  default-scenario file (2.5 MHz, ``ekf``, 13.8 s of vector loop): velocity RMSE
  0.0092 m/s with the carrier states kept, 0.036 m/s with the frequency reset too
  (attitude 0.036 vs 0.043 deg, position 0.45 m both); keeping the code covariance as well
  made the filter overconfident (velocity 0.061 m/s, attitude 0.17 deg).

What the cascade costs. The feedback shift moves the carried state and the truth together,
so the carried state's *estimation error* stays in it, and :meth:`PreFilterBank.decorrelate`
resets a variance, not the state: every output re-uses the pre-filter's prior, which the
integration filter already absorbed from the previous output. The integration filter counts
old information again, and consecutive outputs have correlated errors (rate lag-1
autocorrelation +0.13 at 40 dB-Hz, +0.44 at 30; sums of 25 consecutive normalized rate errors
0.27 and 0.51 per term where white errors give 1: ``scripts/check_prefilter.py``), which no
white ``R`` describes. :class:`ResetPreFilterBank` (``deep_measurements = "reset"``) hands
over only a window's information; docs/deep.md, *Measurement architectures*.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import gammaincc

from ..constants import C_LIGHT, CHIP_RATE_B3I, F_B3I
from ..ins.imu import ImuErrorModel
from ._numba_prefilter import prefilter_channels, prefilter_epochs

__all__ = ["PreFilterBank", "ResetPreFilterBank", "coherent_blocks", "coherent_blocks_of_channels",
           "discriminator_variances", "model_process_noise", "nis_test"]


def model_process_noise(imu: ImuErrorModel | None, carrier_hz: float = F_B3I
                        ) -> tuple[float, float]:
    """``(s_f_model [Hz^2/s], q_phi_model [rad^2/s])``: the per-channel tracking-error
    dynamics the INS-driven NCO commands cannot predict (module notes, *Noise model*).

    ``s_f_model = VRW^2 / lambda^2``: the assumed accelerometer's velocity random walk
    [m/s/sqrt(s)] on the line of sight, in Hz. ``q_phi_model = 0``. The oscillator's noise is
    common to every channel and is the integration filter's clock states' process noise,
    not a per-channel error (a diagonal ``R`` could not carry it). ``imu=None``: a perfect
    IMU.
    """
    lam = C_LIGHT / float(carrier_hz)
    s_f = 0.0 if imu is None else (imu.accel_random_walk_si / lam) ** 2
    return s_f, 0.0


#: Blocks up to which :func:`discriminator_variances` works on Python floats.
_FEW_BLOCKS = 4


def nis_test(nis: float, dof: int) -> tuple[float, float]:
    """``(nis / dof, P)``: the NIS per degree of freedom and the chi-square tail probability
    of ``nis`` with ``dof`` degrees of freedom (small: a false lock or a slip); ``(nan,
    1.0)`` without a degree of freedom."""
    if dof <= 0:
        return math.nan, 1.0
    return nis / dof, float(gammaincc(0.5 * dof, 0.5 * nis))


def coherent_blocks(early, prompt, late, t_epoch: np.ndarray, block_start=None):
    """Correlator sums and durations of the coherent blocks of one channel's epochs.

    ``block_start`` (bool per epoch, or None: every epoch its own block) marks the epochs
    that start a block; the first epoch always does. Returns ``(early, prompt, late, t)``
    summed over each block (the inputs themselves when every epoch starts one).
    """
    t = t_epoch
    if block_start is not None:
        b = np.asarray(block_start, bool).copy()
        b[0] = True
        idx = b.nonzero()[0]
        if idx.size < t.size:
            early, prompt, late = (np.add.reduceat(np.asarray(a), idx)
                                   for a in (early, prompt, late))
            t = np.add.reduceat(t, idx)
    return early, prompt, late, t


def coherent_blocks_of_channels(early, prompt, late, t_epoch: np.ndarray, block_start,
                                counts):
    """:func:`coherent_blocks` of several channels' epochs at once (one call per array, not
    per channel): the epochs of channel ``k`` are the next ``counts[k]`` of the arrays, its
    first epoch starts a block. Returns ``(early, prompt, late, t, bounds)``: channel ``k``'s
    blocks are ``[bounds[k]:bounds[k + 1]]`` of the arrays, equal to :func:`coherent_blocks`
    of its epochs alone (``np.add.reduceat`` sums each block by itself)."""
    offs = np.zeros(len(counts) + 1, np.int64)
    np.cumsum(counts, out=offs[1:])
    b = np.asarray(block_start, bool).copy()
    b[offs[:-1][offs[:-1] < offs[1:]]] = True
    idx = b.nonzero()[0]
    if idx.size < b.size:
        early, prompt, late, t_epoch = (np.add.reduceat(np.asarray(a), idx)
                                        for a in (early, prompt, late, t_epoch))
    return early, prompt, late, t_epoch, np.searchsorted(idx, offs).tolist()


def discriminator_variances(cn0_hz: float, t_epoch: np.ndarray, spacing: float
                            ) -> tuple[np.ndarray, np.ndarray]:
    """``(r_tau [chips^2], r_phi [rad^2])`` per epoch (module notes) at ``cn0_hz`` (linear)."""
    t = np.asarray(t_epoch, float)
    c = max(float(cn0_hz), 1.0)                  # (NaN stays NaN, as np.maximum's)
    tl = t.tolist() if t.ndim == 1 and t.size <= _FEW_BLOCKS else None
    if tl is not None and 0.0 not in tl:        # (as (t == 0.0).any(): -0.0 too, NaN not)
        # the loop's blocks (one or two per interval): the same IEEE operations on Python
        # floats, without a dozen numpy calls on one-element arrays (bit for bit, tested)
        snr = [c * v for v in tl]
        return (np.array([spacing / (2.0 * s) * (1.0 + 1.0 / s) for s in snr]),
                np.array([1.0 / (2.0 * s) * (1.0 + 1.0 / (2.0 * s)) for s in snr]))
    snr = c * t
    r_tau = spacing / (2.0 * snr) * (1.0 + 1.0 / snr)
    r_phi = 1.0 / (2.0 * snr) * (1.0 + 1.0 / (2.0 * snr))
    return r_tau, r_phi


class PreFilterBank:
    """Pre-filters of ``n`` channels (module notes).

    Parameters
    ----------
    n : int
        Channels.
    spacing : float
        Early/late offset d [chips].
    carrier_hz : float
        Carrier frequency [Hz] (for ``beta``).
    s_f : float
        Design frequency random-walk PSD [Hz^2/s] (sets the gain, module notes). Default 4
        (0.2 Hz, i.e. 5 cm/s, of unpredicted drift in 10 ms).
    sigma_tau0, sigma_f0 : float
        Prior standard deviations of the code [chips] and frequency [Hz] errors set at every
        interval start when the state is reset (decorrelation). Defaults 0.2 chip, 5 Hz.
    reset_code, reset_frequency : bool
        Which variances :meth:`decorrelate` resets (module notes). Defaults True, False.
    q_tau, q_phi : float
        Design process noise per epoch [chips^2], [rad^2].
    s_f_model, q_phi_model : float or None
        The noise model's frequency random-walk PSD [Hz^2/s] and phase random-walk PSD
        [rad^2/s] behind the stated variances (module notes, *Noise model*); None: those of
        the default MEMS IMU (:func:`model_process_noise`).

    Attributes
    ----------
    x : ndarray (n, 3)
        States ``[dtau, dphi, df]``.
    P : ndarray (n, 3, 3)
        Design covariances (they set the gains).
    C : ndarray (n, 3, 3)
        Error covariances under the noise model (the stated output variances).
    nis : ndarray (n,)
        Normalized innovation squared of the last interval, per measurement (two per
        block).
    nis_p : ndarray (n,)
        Probability of a NIS at least that large for a consistent filter (chi-square with
        two degrees of freedom per block): small values flag a false lock or a slip.
    """

    def __init__(self, n: int, spacing: float = 0.5, carrier_hz: float = F_B3I, *,
                 s_f: float = 4.0, sigma_tau0: float = 0.2, sigma_f0: float = 5.0,
                 q_tau: float = 1e-8, q_phi: float = 1e-4, reset_code: bool = True,
                 reset_frequency: bool = False, s_f_model: float | None = None,
                 q_phi_model: float | None = None):
        self.n = int(n)
        self.spacing = float(spacing)
        self.beta = CHIP_RATE_B3I / float(carrier_hz)
        self.s_f = float(s_f)
        self.sigma_tau0 = float(sigma_tau0)
        self.sigma_f0 = float(sigma_f0)
        self.q_tau = float(q_tau)
        self.q_phi = float(q_phi)
        self.reset_code = bool(reset_code)
        self.reset_frequency = bool(reset_frequency)
        s_m, q_m = model_process_noise(ImuErrorModel(), carrier_hz)
        self.s_f_model = s_m if s_f_model is None else float(s_f_model)
        self.q_phi_model = q_m if q_phi_model is None else float(q_phi_model)
        self.x = np.zeros((self.n, 3))
        self.P = np.zeros((self.n, 3, 3))
        self.C = np.zeros((self.n, 3, 3))
        self.nis = np.full(self.n, math.nan)
        self.nis_p = np.full(self.n, math.nan)
        for i in range(self.n):
            self.reset(i)

    def reset(self, i: int, dtau: float = 0.0, dphi: float = 0.0, df: float = 0.0,
              sigma_tau: float | None = None, sigma_phi: float = 1.0,
              sigma_f: float | None = None) -> None:
        """Set channel ``i``'s state and a diagonal covariance (defaults: the priors)."""
        st = self.sigma_tau0 if sigma_tau is None else float(sigma_tau)
        sf = self.sigma_f0 if sigma_f is None else float(sigma_f)
        self.x[i] = (dtau, dphi, df)
        self.P[i] = np.diag([st * st, float(sigma_phi) ** 2, sf * sf])
        self.C[i] = self.P[i]

    def shift(self, i: int, d_tau_chips: float, d_f_hz: float) -> None:
        """The channel's NCOs moved by ``d_tau`` chips and ``d_f`` Hz: keep the state the
        error relative to them."""
        self.x[i, 0] -= d_tau_chips
        self.x[i, 2] -= d_f_hz

    #: Whether :meth:`decorrelate` uses the integration filter's sigmas (``prior``).
    takes_prior = False

    def decorrelate(self, i: int, frequency: bool | None = None,
                    prior: tuple[float, float] | None = None) -> None:
        """Reset the code (and, if ``frequency``, default ``reset_frequency``, the frequency)
        variances and their cross terms to the priors (``prior``, the integration filter's
        sigmas, is not used: :class:`ResetPreFilterBank` takes it)."""
        P = self.P[i]
        freq = self.reset_frequency if frequency is None else bool(frequency)
        for k, on, sig in ((0, self.reset_code, self.sigma_tau0),
                           (2, freq, self.sigma_f0)):
            if on:
                P[k, :] = 0.0
                P[:, k] = 0.0
                P[k, k] = sig * sig

    def process(self, i: int, early, prompt, late, t_epoch, cn0_hz: float,
                block_start=None) -> None:
        """Run channel ``i`` over its epochs of the interval (NH already wiped off).

        ``block_start`` (bool per epoch, optional): epochs that start a coherent block; the
        correlator sums of each block (from one start to the next, the first epoch always
        starting one) are added before the discriminators, one filter update per block.
        """
        t = np.ascontiguousarray(t_epoch, dtype=np.float64)
        if t.size == 0:
            return
        self.process_blocks(i, *coherent_blocks(early, prompt, late, t, block_start), cn0_hz)

    def process_blocks(self, i: int, early, prompt, late, t, cn0_hz: float) -> None:
        """:meth:`process` of channel ``i``'s coherent blocks (at least one; their sums and
        durations ``t`` [s], :func:`coherent_blocks`)."""
        t = np.ascontiguousarray(t, dtype=np.float64)
        r_tau, r_phi = discriminator_variances(cn0_hz, t, self.spacing)
        # the channel's rows of x, P, C are contiguous views: updated in place
        nis = prefilter_epochs(self.x[i], self.P[i], np.ascontiguousarray(early, np.complex128),
                               np.ascontiguousarray(prompt, np.complex128),
                               np.ascontiguousarray(late, np.complex128), t, self.spacing,
                               self.beta, r_tau, r_phi, self.q_tau, self.q_phi, self.s_f,
                               self.C[i], 0.0, self.q_phi_model, self.s_f_model)
        self._after_blocks(i, nis, t)

    def _after_blocks(self, i: int, nis: float, t: np.ndarray) -> None:
        """After the update over blocks of durations ``t`` [s]: NIS per measurement and its
        chi-square tail probability (2 per block)."""
        self.nis[i], self.nis_p[i] = nis_test(nis, 2 * t.size)

    def process_channels(self, ch0: int, counts: np.ndarray, bounds, early, prompt, late,
                         t, cn0_hz) -> None:
        """:meth:`process_blocks` of channels ``ch0, ch0 + 1, ...`` in one kernel call
        (:func:`~sdr_di.deep._numba_prefilter.prefilter_channels`; the same values): channel
        ``k`` of the pass has ``counts[k]`` epochs (none: left alone) and the blocks
        ``[bounds[k], bounds[k + 1])`` of ``early, prompt, late, t``; ``cn0_hz`` its C/N0
        (linear)."""
        counts = np.asarray(counts, np.int64)
        bounds = np.asarray(bounds, np.int64)
        t = np.ascontiguousarray(t, dtype=np.float64)
        nis = np.empty(counts.size)
        prefilter_channels(int(ch0), counts, bounds,
                           np.ascontiguousarray(early, np.complex128),
                           np.ascontiguousarray(prompt, np.complex128),
                           np.ascontiguousarray(late, np.complex128), t,
                           np.asarray(cn0_hz, np.float64), self.spacing, self.beta, self.x,
                           self.P, self.C, self.q_tau, self.q_phi, self.s_f,
                           self.q_phi_model, self.s_f_model, nis)
        self._after_channels(int(ch0), counts, bounds, nis, t)

    def _after_channels(self, ch0: int, counts: np.ndarray, bounds: np.ndarray,
                        nis: np.ndarray, t: np.ndarray) -> None:
        """:meth:`_after_blocks` of the channels of :meth:`process_channels` (those with
        epochs), as arrays: the same values (:func:`nis_test` is element-wise)."""
        k = counts.nonzero()[0]
        if k.size == 0:
            return
        dof = 2 * (bounds[k + 1] - bounds[k])
        self.nis[ch0 + k] = nis[k] / dof
        self.nis_p[ch0 + k] = gammaincc(0.5 * dof, 0.5 * nis[k])

    def set_frequency(self, i: int, df_hz: float) -> None:
        """Channel ``i``'s frequency error estimate [Hz] (the loop's first interval: the
        scalar loop's Doppler minus the INS prediction)."""
        self.x[i, 2] = df_hz

    def outputs(self, i: int) -> tuple[float, float, float, float]:
        """``(dtau [chips], df [Hz], var_tau [chips^2], var_f [Hz^2])`` of channel ``i``: the
        estimates and their error variances under the noise model (``C``, module notes)."""
        return (float(self.x[i, 0]), float(self.x[i, 2]), float(self.C[i, 0, 0]),
                float(self.C[i, 2, 2]))


class ResetPreFilterBank(PreFilterBank):
    """Pre-filters with an information reset after every fusion (``deep_measurements =
    "reset"``; docs/deep.md, *Measurement architectures*; Carlson 1990's federated filter,
    whose local filters' information is zeroed after each fusion).

    The same 3-state filter and measurement model as :class:`PreFilterBank`. After every
    fusion (an update of the integration filter with these outputs, every
    ``fusion_intervals`` filter intervals: ``IntegrationConfig.fusion_rate_hz``, default
    5 Hz for this architecture, as Carlson's local filters run faster than the master's
    fusion) each filter restarts from a prior ``(x0, P0)``: its state moved by the feedback
    (the NCOs steered by the integration filter), with the integration filter's own
    uncertainty of the channel's range and rate as code and frequency sigmas (the ``prior``
    of :meth:`decorrelate`; without one, the wide ``sigma_*_reset``) and an uninformative
    phase. The prior keeps the window's first phase innovations inside the arctangent's
    +-pi/2 (a 200 ms window at 30 dB-Hz slipped half cycles from a wide prior), and is then
    taken out again: the output is the window's **equivalent measurement** (its information
    increment), with the prior propagated over the window by the same model
    (``x_bar = F x0``, ``P_bar = F P0 F^T + Q``)::

        Y = C^-1 - P_bar^-1,   R_eq = Y^-1,   z_eq = R_eq (C^-1 x - P_bar^-1 x_bar)

    of which the code and frequency entries and variances are handed on. For a linear
    model ``z_eq`` is the weighted least-squares estimate from the window's blocks alone, so
    the errors of consecutive outputs are independent: the integration filter, which
    absorbed the previous output, does not count it again, and the prior's information
    (which came from the integration filter) is not returned to it. The phase is never
    carried from one window to the next: a carried phase would make consecutive frequency
    outputs share the phase noise of the blocks between them (a lag-1 correlation of about
    -0.5).

    Between fusions the bank keeps filtering the intervals' blocks, so a 200 ms window's
    frequency comes from 200 ms of carrier phase. With a fusion every interval the
    frequency comes from the phases of at least two blocks of it (the vector loop then cuts
    blocks of at most half an interval, :func:`~sdr_di.deep.architectures.block_ms`). The
    design noise is the noise model's (``s_f = s_f_model``, ``q_tau = q_phi = 0``; the
    model's phase noise, zero by default, enters ``C`` and ``P_bar`` only), so ``P`` and
    ``C`` agree.

    Parameters
    ----------
    n, spacing, carrier_hz
        As :class:`PreFilterBank`.
    sigma_tau_reset, sigma_phi_reset, sigma_f_reset : float
        Prior standard deviations when no prior is given: code [chips] (default 1),
        frequency [Hz] (default 100); the phase's [rad] always (default 100).
    s_f_model, q_phi_model : float or None
        The noise model (:class:`PreFilterBank`).

    Attributes
    ----------
    x_bar, P_bar : ndarray (n, 3), (n, 3, 3)
        The window's prior propagated to the last block's end.
    takes_prior : bool
        True: :meth:`decorrelate` uses the integration filter's sigmas (``prior``).
    """

    takes_prior = True

    def __init__(self, n: int, spacing: float = 0.5, carrier_hz: float = F_B3I, *,
                 sigma_tau_reset: float = 1.0, sigma_phi_reset: float = 100.0,
                 sigma_f_reset: float = 100.0, s_f_model: float | None = None,
                 q_phi_model: float | None = None):
        self.sigma_reset = (float(sigma_tau_reset), float(sigma_phi_reset),
                            float(sigma_f_reset))
        self.unfitted = np.full(int(n), 3, np.int64)   # prior-free states not yet fitted
        self.x_bar = np.zeros((int(n), 3))
        self.P_bar = np.zeros((int(n), 3, 3))
        super().__init__(n, spacing, carrier_hz, s_f_model=s_f_model, q_phi_model=q_phi_model,
                         sigma_tau0=self.sigma_reset[0], sigma_f0=self.sigma_reset[2],
                         q_tau=0.0)
        self.s_f = self.s_f_model
        self.q_phi = 0.0

    def reset(self, i: int, dtau: float = 0.0, dphi: float = 0.0, df: float = 0.0,
              sigma_tau: float | None = None, sigma_phi: float = 1.0,
              sigma_f: float | None = None) -> None:
        """Restart channel ``i`` at ``(dtau, dphi, df)`` with code and frequency sigmas
        ``sigma_tau``, ``sigma_f`` (default the wide ``sigma_*_reset``) and an
        uninformative phase (``sigma_phi`` is not used); the output is again only what the
        blocks from here on add (class notes)."""
        self.x[i] = (dtau, dphi, df)
        self._restart(i, sigma_tau, sigma_f)

    def decorrelate(self, i: int, frequency: bool | None = None,
                    prior: tuple[float, float] | None = None) -> None:
        """Information reset after a fusion: the state kept (it is the error relative to
        the NCOs the integration filter steers), the prior ``(sigma_tau [chips], sigma_f
        [Hz])`` (the integration filter's uncertainty of the channel's range and rate;
        None: the wide ``sigma_*_reset``) and an uninformative phase."""
        self._restart(i, *(prior if prior is not None else (None, None)))

    def _restart(self, i: int, sigma_tau: float | None, sigma_f: float | None) -> None:
        st = self.sigma_reset[0] if sigma_tau is None else float(sigma_tau)
        sf = self.sigma_reset[2] if sigma_f is None else float(sigma_f)
        sp = self.sigma_reset[1]
        self.P[i] = np.diag([st * st, sp * sp, sf * sf])
        self.C[i] = self.P[i]
        self.x_bar[i] = self.x[i]
        self.P_bar[i] = self.P[i]
        # the states that have no prior information (fitted from the first blocks): the
        # phase, and code and frequency when no prior was given
        self.unfitted[i] = 1 + (sigma_tau is None) + (sigma_f is None)

    def shift(self, i: int, d_tau_chips: float, d_f_hz: float) -> None:
        """The NCOs moved: the state and the window's prior move with them."""
        super().shift(i, d_tau_chips, d_f_hz)
        self.x_bar[i, 0] -= d_tau_chips
        self.x_bar[i, 2] -= d_f_hz

    def _after_blocks(self, i: int, nis: float, t: np.ndarray) -> None:
        """The window's prior propagated over the blocks of durations ``t`` [s] with the noise
        model (``P_bar <- F P_bar F^T + diag(0, q_phi_m T, s_f_m T)``, as ``C``), and the NIS
        per degree of freedom: ``2 m`` for ``m`` blocks less the states fitted without prior
        information on the first blocks after a restart (no test without a degree of
        freedom)."""
        xb, Pb = self.x_bar[i], self.P_bar[i]
        for T in t.tolist():
            F = np.array([[1.0, 0.0, self.beta * T], [0.0, 1.0, 2.0 * math.pi * T],
                          [0.0, 0.0, 1.0]])
            xb[:] = F @ xb
            Pb[:] = F @ Pb @ F.T
            Pb[1, 1] += self.q_phi_model * T
            Pb[2, 2] += self.s_f_model * T
        fitted = min(int(self.unfitted[i]), 2 * t.size)
        self.unfitted[i] -= fitted
        self.nis[i], self.nis_p[i] = nis_test(nis, 2 * t.size - fitted)

    def _after_channels(self, ch0: int, counts: np.ndarray, bounds: np.ndarray,
                        nis: np.ndarray, t: np.ndarray) -> None:
        """:meth:`_after_blocks` of each channel of :meth:`~PreFilterBank.process_channels`
        with epochs (the window's prior is propagated channel by channel)."""
        for k in counts.nonzero()[0].tolist():
            self._after_blocks(ch0 + k, float(nis[k]), t[bounds[k]:bounds[k + 1]])

    def outputs(self, i: int) -> tuple[float, float, float, float]:
        """``(dtau [chips], df [Hz], var_tau [chips^2], var_f [Hz^2])``: the window's
        equivalent measurement (class notes); the wide prior's variances when the window
        holds no information."""
        try:
            Y_post = np.linalg.inv(self.C[i])
            Y_prior = np.linalg.inv(self.P_bar[i])
            Y = Y_post - Y_prior
            R_eq = np.linalg.inv(Y)
        except np.linalg.LinAlgError:
            R_eq = None
        if R_eq is None or not (R_eq[0, 0] > 0.0 and R_eq[2, 2] > 0.0):
            return (float(self.x[i, 0]), float(self.x[i, 2]), self.sigma_reset[0] ** 2,
                    self.sigma_reset[2] ** 2)
        z = R_eq @ (Y_post @ self.x[i] - Y_prior @ self.x_bar[i])
        return float(z[0]), float(z[2]), float(R_eq[0, 0]), float(R_eq[2, 2])
