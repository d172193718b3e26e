"""Tracking-loop discriminators and loop filters (scalar code and carrier loops).

Sign conventions (as :mod:`~sdr_di.receiver.correlator`)
--------------------------------------------------------
* Carrier: the prompt after wipe-off is ``P ~ a exp(j 2 pi (phi_signal - phi_nco))``; the
  *phase error* ``e_phi = phi_signal - phi_nco`` [cycles] is positive when the signal leads,
  and the NCO frequency must then increase. The *frequency error* ``e_f`` [Hz] is the rate
  of change of ``e_phi``.
* Code: ``e_code = theta_signal - theta_replica`` [chips], positive when the replica lags
  (early correlator stronger than late); the code NCO rate must then increase.

Discriminators (module functions, plain Python floats: they run once per channel per update)
--------------------------------------------------------------------------------------------
:func:`costas_atan`
    ``atan(Q / I) / 2 pi`` [cycles], two-quadrant: insensitive to the sign of the data/NH
    symbol, linear over +-1/4 cycle.
:func:`fll_atan`
    ``atan(cross / dot) / (2 pi dt)`` [Hz] of two successive prompts, also two-quadrant
    (bit-sign insensitive); range +-1 / (4 dt) (+-250 Hz at 1 ms).
:func:`dll_nelp`
    Normalized early-minus-late envelope ``(1 - d) (|E| - |L|) / (|E| + |L|)`` [chips] for
    early/late replicas at ``+-d`` chips: exactly ``e_code`` for the ideal triangular
    correlation when ``|e_code| < d``, independent of the signal amplitude.

Loop filters (state in physical units, so the update interval may change on the fly)
-----------------------------------------------------------------------------------
:class:`CarrierLoop`
    Third-order PLL with second-order FLL assist (Ward/Kaplan, *Understanding GPS*, 2nd ed.,
    fig. 5.24): analog prototype ``F_pll(s) = b3 w0p + a3 w0p^2 / s + w0p^3 / s^2`` with
    ``a3 = 1.1``, ``b3 = 2.4``, ``w0p = B_pll / 0.7845``; FLL ``F_fll(s) = a2 w0f + w0f^2 / s``
    with ``a2 = sqrt 2``, ``w0f = B_fll / 0.53``. Both act on shared frequency-rate and
    frequency integrators (rectangular integration with the actual update interval ``T``).
    ``B = 0`` switches a part off (pure FLL, pure PLL). Usable while ``B_pll T`` stays below
    about 0.2.
:class:`CodeLoop`
    First-order (default) or second-order DLL with carrier aiding: the code rate is
    ``f_chip (1 + f_D / f_carrier) + F_dll(e_code)``, ``w0 = 4 B_dll`` (first order) or
    ``w0 = B_dll / 0.53`` (second order, ``a2 = sqrt 2``).

Defaults used by the scalar receiver are in :class:`~sdr_di.receiver.tracking.TrackingConfig`.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "CarrierLoop",
    "CodeLoop",
    "costas_atan",
    "dll_code_noise_chips",
    "dll_nelp",
    "fll_atan",
    "fll_natural_frequency",
    "pll_doppler_noise_hz",
    "pll_rate_dynamic_error",
    "pll_natural_frequency",
]

_TWO_PI = 2.0 * math.pi
#: Third-order PLL coefficients (Kaplan table 5.6): B_L = 0.7845 w0.
PLL3_A3, PLL3_B3, PLL3_BW = 1.1, 2.4, 0.7845
#: Second-order loop coefficients: B_L = 0.53 w0.
LOOP2_A2, LOOP2_BW = math.sqrt(2.0), 0.53


def costas_atan(i: float, q: float) -> float:
    """Costas (two-quadrant arctangent) phase discriminator [cycles], in [-1/4, 1/4].

    Parameters
    ----------
    i, q : float
        In-phase and quadrature prompt (coherent sum).
    """
    if i == 0.0:
        return 0.0 if q == 0.0 else math.copysign(0.25, q)
    return math.atan(q / i) / _TWO_PI


def fll_atan(i1: float, q1: float, i2: float, q2: float, dt: float) -> float:
    """Bit-insensitive frequency discriminator [Hz] of two successive prompts.

    ``atan(cross / dot) / (2 pi dt)`` with ``cross = I1 Q2 - Q1 I2``, ``dot = I1 I2 + Q1 Q2``:
    the phase advance of prompt 2 over prompt 1 modulo a half cycle.

    Parameters
    ----------
    i1, q1 : float
        Earlier prompt.
    i2, q2 : float
        Later prompt.
    dt : float
        Time between the prompts' centres [s].
    """
    cross = i1 * q2 - q1 * i2
    dot = i1 * i2 + q1 * q2
    if dot == 0.0:
        return 0.0 if cross == 0.0 else math.copysign(0.25 / dt, cross)
    return math.atan(cross / dot) / (_TWO_PI * dt)


def dll_nelp(e_abs: float, l_abs: float, spacing_chips: float) -> float:
    """Normalized early-minus-late envelope code discriminator [chips].

    Parameters
    ----------
    e_abs, l_abs : float
        Magnitudes of the early and late correlators (replicas at +d and -d chips).
    spacing_chips : float
        d [chips] (early-late separation 2 d).
    """
    s = e_abs + l_abs
    if s <= 0.0:
        return 0.0
    return (1.0 - spacing_chips) * (e_abs - l_abs) / s


def pll_natural_frequency(bandwidth_hz: float) -> float:
    """``w0`` [rad/s] of the third-order PLL for a noise bandwidth [Hz]."""
    return bandwidth_hz / PLL3_BW


def fll_natural_frequency(bandwidth_hz: float) -> float:
    """``w0`` [rad/s] of the second-order FLL for a noise bandwidth [Hz]."""
    return bandwidth_hz / LOOP2_BW


class CarrierLoop:
    """Third-order PLL with second-order FLL assist (module notes).

    Parameters
    ----------
    pll_bw_hz : float
        PLL noise bandwidth [Hz] (0: no phase feedback).
    fll_bw_hz : float
        FLL noise bandwidth [Hz] (0: no frequency feedback).
    freq_hz : float
        Initial NCO frequency (Doppler) [Hz].
    rate_hz_s : float, optional
        Initial frequency rate [Hz/s].

    Attributes
    ----------
    freq_hz : float
        NCO frequency commanded for the next interval [Hz] (filter output).
    vel_hz : float
        Frequency integrator [Hz].
    acc_hz_s : float
        Frequency-rate integrator [Hz/s].
    """

    __slots__ = ("_w0f", "_w0p", "acc_hz_s", "fll_bw_hz", "freq_hz", "pll_bw_hz", "vel_hz")

    def __init__(self, pll_bw_hz: float, fll_bw_hz: float, freq_hz: float,
                 rate_hz_s: float = 0.0):
        self.vel_hz = float(freq_hz)
        self.acc_hz_s = float(rate_hz_s)
        self.freq_hz = float(freq_hz)
        self.set_bandwidths(pll_bw_hz, fll_bw_hz)

    def set_bandwidths(self, pll_bw_hz: float, fll_bw_hz: float) -> None:
        """Change the noise bandwidths [Hz] keeping the integrators (bumpless)."""
        if pll_bw_hz < 0 or fll_bw_hz < 0:
            raise ValueError("loop bandwidths must be >= 0")
        self.pll_bw_hz = float(pll_bw_hz)
        self.fll_bw_hz = float(fll_bw_hz)
        self._w0p = pll_natural_frequency(self.pll_bw_hz)
        self._w0f = fll_natural_frequency(self.fll_bw_hz)

    def reset(self, freq_hz: float, rate_hz_s: float = 0.0) -> None:
        """Restart the integrators at a frequency [Hz] and rate [Hz/s]."""
        self.vel_hz = float(freq_hz)
        self.acc_hz_s = float(rate_hz_s)
        self.freq_hz = float(freq_hz)

    def update(self, phase_err_cycles: float, freq_err_hz: float, dt: float) -> float:
        """One loop update.

        Parameters
        ----------
        phase_err_cycles : float
            PLL discriminator output [cycles] (ignored when the PLL bandwidth is 0).
        freq_err_hz : float
            FLL discriminator output [Hz] (ignored when the FLL bandwidth is 0).
        dt : float
            Update interval [s] (the coherent integration time).

        Returns
        -------
        float
            New NCO frequency [Hz].
        """
        w0p = self._w0p
        w0f = self._w0f
        ep = phase_err_cycles if w0p > 0.0 else 0.0
        ef = freq_err_hz if w0f > 0.0 else 0.0
        self.acc_hz_s += dt * (w0p * w0p * w0p * ep + w0f * w0f * ef)
        self.vel_hz += dt * (self.acc_hz_s + PLL3_A3 * w0p * w0p * ep + LOOP2_A2 * w0f * ef)
        self.freq_hz = self.vel_hz + PLL3_B3 * w0p * ep
        return self.freq_hz


class CodeLoop:
    """Carrier-aided DLL loop filter (module notes).

    Parameters
    ----------
    bw_hz : float
        DLL noise bandwidth [Hz].
    order : {1, 2}, optional
        Loop order. Default 1 (carrier aiding removes the dynamics).

    Attributes
    ----------
    rate_corr_cps : float
        Code-rate correction commanded for the next interval [chips/s].
    """

    __slots__ = ("_int", "_w0", "bw_hz", "order", "rate_corr_cps")

    def __init__(self, bw_hz: float, order: int = 1):
        if order not in (1, 2):
            raise ValueError(f"DLL order must be 1 or 2, got {order}")
        self.order = int(order)
        self._int = 0.0
        self.rate_corr_cps = 0.0
        self.set_bandwidth(bw_hz)

    def set_bandwidth(self, bw_hz: float) -> None:
        """Change the noise bandwidth [Hz] keeping the integrator."""
        if bw_hz < 0:
            raise ValueError("DLL bandwidth must be >= 0")
        self.bw_hz = float(bw_hz)
        self._w0 = 4.0 * self.bw_hz if self.order == 1 else self.bw_hz / LOOP2_BW

    def reset(self) -> None:
        """Zero the correction and the integrator."""
        self._int = 0.0
        self.rate_corr_cps = 0.0

    def update(self, code_err_chips: float, dt: float) -> float:
        """One update from the discriminator output [chips]; returns the rate correction
        [chips/s]."""
        w0 = self._w0
        if self.order == 1:
            self.rate_corr_cps = w0 * code_err_chips
        else:
            self._int += dt * w0 * w0 * code_err_chips
            self.rate_corr_cps = self._int + LOOP2_A2 * w0 * code_err_chips
        return self.rate_corr_cps


def pll_doppler_noise_hz(cn0_dbhz: float, coherent_s: float, pll_bw_hz: float) -> float:
    """Standard deviation [Hz] of :attr:`CarrierLoop.vel_hz` (the Doppler the receiver
    reports) from thermal noise alone, for a locked pure PLL on a static signal.

    The discriminator noise is the Costas atan's,
    ``sigma_phi^2 = (1 + 1 / (2 T C/N0)) / (2 T C/N0)`` [rad^2] per update of coherent time
    ``T``, white; it drives the closed loop exactly as :meth:`CarrierLoop.update` does (the
    discriminator sees the NCO phase averaged over the interval, the NCO runs at the
    commanded frequency), and the steady-state variance of the frequency integrator is the
    solution of the discrete Lyapunov equation of that linear loop.

    Parameters
    ----------
    cn0_dbhz : float
        Carrier-to-noise density ratio [dB-Hz].
    coherent_s : float
        Coherent integration time = update interval ``T`` [s].
    pll_bw_hz : float
        PLL noise bandwidth [Hz] (> 0, ``B T`` below about 0.2).

    Returns
    -------
    float
        [Hz] (multiply by the wavelength for the pseudorange-rate noise [m/s]).
    """
    from scipy.linalg import solve_discrete_lyapunov  # here: scipy costs start-up time


    if not (pll_bw_hz > 0.0 and coherent_s > 0.0 and math.isfinite(cn0_dbhz)):
        raise ValueError("pll_doppler_noise_hz needs pll_bw_hz > 0, coherent_s > 0 and a "
                         "finite C/N0")
    t = float(coherent_s)
    snr = 2.0 * t * 10.0 ** (cn0_dbhz / 10.0)
    var_cycles = (1.0 + 1.0 / snr) / snr / _TWO_PI ** 2
    w0 = pll_natural_frequency(pll_bw_hz)
    # state [NCO phase error sign-flipped (cycles), acc, vel, commanded freq]; true phase 0:
    # e = -(ph + f T / 2) + n
    e_x = np.array([-1.0, 0.0, 0.0, -0.5 * t])
    ph = np.array([1.0, 0.0, 0.0, t])                              # ph' = ph + f T
    acc = np.array([0.0, 1.0, 0.0, 0.0]) + t * w0 ** 3 * e_x       # acc' = acc + T w0^3 e
    vel = np.array([0.0, 0.0, 1.0, 0.0]) + t * (acc + PLL3_A3 * w0 ** 2 * e_x)
    f = vel + PLL3_B3 * w0 * e_x                                   # f' = vel' + b3 w0 e
    a = np.vstack([ph, acc, vel, f])
    # noise input (e = n), through the same three lines
    b_acc = t * w0 ** 3
    b_vel = t * (b_acc + PLL3_A3 * w0 ** 2)
    b = np.array([0.0, b_acc, b_vel, b_vel + PLL3_B3 * w0])
    if np.max(np.abs(np.linalg.eigvals(a))) >= 1.0:
        raise ValueError(f"unstable loop: B T = {pll_bw_hz * t:g}")
    p = solve_discrete_lyapunov(a, np.outer(b, b) * var_cycles)
    return float(math.sqrt(p[2, 2]))


def dll_code_noise_chips(cn0_dbhz: float, coherent_s: float, dll_bw_hz: float,
                         spacing_chips: float = 0.5) -> float:
    """Standard deviation [chips] of the code tracking error of the carrier-aided
    first-order DLL (:class:`CodeLoop`, order 1) from thermal noise alone.

    The normalized early-minus-late envelope (:func:`dll_nelp`, early/late at +-d chips)
    has, per update of coherent time ``T``, the white noise

        sigma_d^2 = d / (2 T C/N0) (1 + 1 / (T C/N0))             [chips^2]

    (near linear for ``T C/N0`` above a few); the loop corrects ``w0 T`` of each output
    (``w0 = 4 B_L``), so the error ``tau' = (1 - w0 T) tau - w0 T n`` has the steady-state
    variance

        sigma_tau^2 = w0 T sigma_d^2 / (2 - w0 T)  ~  2 B_L T sigma_d^2 = B_L d / C/N0

    Parameters
    ----------
    cn0_dbhz : float
        Carrier-to-noise density ratio [dB-Hz].
    coherent_s : float
        Coherent integration time = update interval ``T`` [s].
    dll_bw_hz : float
        DLL noise bandwidth [Hz] (> 0, ``4 B_L T < 2``).
    spacing_chips : float
        Early/late offset ``d`` [chips].

    Returns
    -------
    float
        [chips] (multiply by ``c / f_code`` for the pseudorange noise [m]). The error is
        correlated over about ``1 / (4 B_L)`` [s].
    """
    k = 4.0 * float(dll_bw_hz) * float(coherent_s)
    if not (0.0 < k < 2.0 and math.isfinite(cn0_dbhz)):
        raise ValueError("dll_code_noise_chips needs 0 < 4 B_L T < 2 and a finite C/N0")
    snr = float(coherent_s) * 10.0 ** (cn0_dbhz / 10.0)
    var_d = spacing_chips / (2.0 * snr) * (1.0 + 1.0 / snr)
    return math.sqrt(k * var_d / (2.0 - k))


def pll_rate_dynamic_error(pll_bw_hz: float) -> float:
    """Dynamic error of the Doppler a scalar channel reports (its 3rd-order loop's frequency
    integrator ``vel_hz``, carried to the observation's sample with the loop's rate):
    ``f_reported ~ f(t) - k f''(t)``, returns ``k = b3 / w0^2`` [s^2].

    Under a constant frequency acceleration ``f''`` [Hz/s^2] the loop settles at the phase
    error ``f'' / w0^3`` [cycles]; its proportional path ``b3 w0`` adds that to the NCO
    frequency, so it is missing from ``vel_hz``. 6.6e-3 s^2 at 15 Hz (1.5 cm/s at a
    line-of-sight jerk of 2.5 m/s^3, the default scenario's circling); measured against the
    generator's truth Doppler (seed 0, 2.5 MHz, 40 dB-Hz): 6.1e-3 and 6.9e-3 s^2.

    Parameters
    ----------
    pll_bw_hz : float
        PLL noise bandwidth [Hz] (> 0).
    """
    if not pll_bw_hz > 0:
        raise ValueError(f"pll_rate_dynamic_error needs pll_bw_hz > 0, got {pll_bw_hz!r}")
    w0 = pll_natural_frequency(pll_bw_hz)
    return PLL3_B3 / (w0 * w0)
