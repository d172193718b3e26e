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
  made the filter overconfident (velocity 0.061 m/s, attitude 0.17 deg). The feedback shift
  keeps the carried state the residual error, so the integration filter does not see an old
  error twice.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import gammaincc

from ..constants import C_LIGHT, CHIP_RATE_B3I, F_B3I
from ..ins.imu import ImuErrorModel
from ._numba_prefilter import prefilter_epochs

__all__ = ["PreFilterBank", "ResetPreFilterBank", "coherent_blocks", "discriminator_variances",
           "model_process_noise"]


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


def discriminator_variances(cn0_hz: float, t_epoch: np.ndarray, spacing: float
                            ) -> tuple[np.ndarray, np.ndarray]:
    """``(r_tau [chips^2], r_phi [rad^2])`` per epoch (module notes) at ``cn0_hz`` (linear)."""
    t = np.asarray(t_epoch, float)
    c = max(float(cn0_hz), 1.0)                  # (NaN stays NaN, as np.maximum's)
    if t.ndim == 1 and t.size <= _FEW_BLOCKS and not (t == 0.0).any():
        # the loop's blocks (one or two per interval): the same IEEE operations on Python
        # floats, without a dozen numpy calls on one-element arrays (bit for bit, tested)
        snr = [c * v for v in t.tolist()]
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

    def decorrelate(self, i: int, frequency: bool | None = None) -> None:
        """Reset the code (and, if ``frequency``, default ``reset_frequency``, the frequency)
        variances and their cross terms to the priors."""
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
        early, prompt, late, t = coherent_blocks(early, prompt, late, t, block_start)
        r_tau, r_phi = discriminator_variances(cn0_hz, t, self.spacing)
        # the channel's rows of x, P, C are contiguous views: updated in place
        nis = prefilter_epochs(self.x[i], self.P[i], np.ascontiguousarray(early, np.complex128),
                               np.ascontiguousarray(prompt, np.complex128),
                               np.ascontiguousarray(late, np.complex128), t, self.spacing,
                               self.beta, r_tau, r_phi, self.q_tau, self.q_phi, self.s_f,
                               self.C[i], 0.0, self.q_phi_model, self.s_f_model)
        self._set_nis(i, nis, t.size)

    def _set_nis(self, i: int, nis: float, blocks: int) -> None:
        """NIS per measurement and its chi-square tail probability (2 per block)."""
        self.nis[i] = nis / (2.0 * blocks)
        self.nis_p[i] = float(gammaincc(blocks, 0.5 * nis))  # chi-square sf, 2 per block

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
    "reset"``; docs/deep.md, *Measurement architectures*; Carlson 1990's federated filter
    with its local filters' information zeroed after each fusion).

    The same 3-state filter and measurement model as :class:`PreFilterBank`, but after each
    fusion (below) the filter restarts from an uninformative prior on all three states (code,
    phase and frequency): :meth:`decorrelate` and :meth:`reset` set ``P = C =
    diag(sigma_tau_reset^2, sigma_phi_reset^2, sigma_f_reset^2)``. The state is kept only as
    the point about which the discriminators are linearized (and the phase innovation is
    reduced modulo pi); its weight is ``r / sigma_reset^2`` (below 1 % of the frequency
    information at 25 dB-Hz with the defaults). So each output holds only the information of
    the blocks since the last fusion, and the errors of consecutive outputs are independent:
    the integration filter, which absorbed the previous output, does not count it again. The phase is reset too: a
    carried phase would make consecutive frequency outputs share the phase noise of the
    block between them (a lag-1 correlation of about -0.5).

    The reset comes after every fusion, that is every update of the integration filter with
    these outputs: every ``fusion_intervals`` filter intervals
    (``IntegrationConfig.fusion_rate_hz``, default 5 Hz for this architecture: Carlson's
    local filters run faster than the master's fusion). Between fusions the bank keeps
    filtering the intervals' blocks, so a 200 ms window's frequency comes from 200 ms of
    carrier phase. With a fusion every interval, the frequency comes from the phases of at
    least two blocks of it (the vector loop then cuts blocks of at most half an interval,
    :func:`~sdr_di.deep.architectures.block_ms`). The design noise is the noise model's
    (``s_f = s_f_model``, ``q_tau = q_phi = 0``; the model's phase noise, zero by default,
    enters ``C`` only), so ``P`` and ``C`` agree: the filter is the weighted least-squares
    fit of the interval's blocks under the model.

    Parameters
    ----------
    n, spacing, carrier_hz
        As :class:`PreFilterBank`.
    sigma_tau_reset, sigma_phi_reset, sigma_f_reset : float
        Prior standard deviations of every interval: code [chips] (default 1), phase [rad]
        (default 100) and frequency [Hz] (default 100).
    s_f_model, q_phi_model : float or None
        The noise model (:class:`PreFilterBank`).
    """

    def __init__(self, n: int, spacing: float = 0.5, carrier_hz: float = F_B3I, *,
                 sigma_tau_reset: float = 1.0, sigma_phi_reset: float = 100.0,
                 sigma_f_reset: float = 100.0, s_f_model: float | None = None,
                 q_phi_model: float | None = None):
        self.sigma_reset = (float(sigma_tau_reset), float(sigma_phi_reset),
                            float(sigma_f_reset))
        self.unfitted = np.full(int(n), 3, np.int64)   # states not yet fitted since a reset
        super().__init__(n, spacing, carrier_hz, s_f_model=s_f_model, q_phi_model=q_phi_model,
                         sigma_tau0=self.sigma_reset[0], sigma_f0=self.sigma_reset[2],
                         q_tau=0.0)
        self.s_f = self.s_f_model
        self.q_phi = 0.0

    def reset(self, i: int, dtau: float = 0.0, dphi: float = 0.0, df: float = 0.0,
              sigma_tau: float | None = None, sigma_phi: float = 1.0,
              sigma_f: float | None = None) -> None:
        """Set channel ``i``'s state (the linearization point); the covariance is always
        the uninformative prior (the sigmas given are not used: no prior information is
        handed on)."""
        self.x[i] = (dtau, dphi, df)
        self._uninformed(i)

    def decorrelate(self, i: int, frequency: bool | None = None) -> None:
        """Information reset: the uninformative prior on every state, the state kept as
        the linearization point."""
        self._uninformed(i)

    def _uninformed(self, i: int) -> None:
        st, sp, sf = self.sigma_reset
        self.P[i] = np.diag([st * st, sp * sp, sf * sf])
        self.C[i] = self.P[i]
        self.unfitted[i] = 3

    def _set_nis(self, i: int, nis: float, blocks: int) -> None:
        """NIS per degree of freedom: ``2 m`` for ``m`` blocks less the three states
        fitted from the uninformative prior (on the first blocks after a reset); no test
        without a degree of freedom."""
        fitted = min(int(self.unfitted[i]), 2 * blocks)
        self.unfitted[i] -= fitted
        dof = 2 * blocks - fitted
        if dof <= 0:
            self.nis[i] = math.nan
            self.nis_p[i] = 1.0
            return
        self.nis[i] = nis / dof
        self.nis_p[i] = float(gammaincc(0.5 * dof, 0.5 * nis))
