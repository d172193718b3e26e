"""Jammers and the front-end AGC of the IF generator (issue 15 item 1; ``docs/impairments.md``).

Powers (noise variance 1 per component, as in :mod:`sdr_di.sim.ifgen`): ``N0 = 2 / fs``; a
satellite at the nominal ``cn0_dbhz`` has ``C = 10^(cn0/10) N0``; a jammer of ``J/S`` [dB]
has power ``J = 10^(JS/10) C``. The kernel adds ``a j(t)`` with ``|j| = 1`` on average:
``a = sqrt(J)`` for complex samples, ``sqrt(2 J)`` for real ones (the real part is taken, as
for the satellites).

* **CW**: ``a exp(j (2 pi (f_IF + offset) t + phase))``.
* **Noise**: band-limited complex Gaussian noise of two-sided width ``B`` centred on
  ``f_IF + offset``: white complex Gaussian samples ``w[k]`` at the rate ``R = B`` (counter-
  based, as the thermal noise), interpolated to the sample rate by a Kaiser-windowed sinc
  (:data:`TAPS` taps, beta :data:`KAISER_BETA`, :data:`PHASES` fractional phases), then
  mixed to the offset. Its spectrum is ``|H(f / B)|^2``: flat within 0.2 dB to
  ``|f| < 0.4 B``, -5.8 dB at the band edge, -53 dB at ``0.6 B``; 98.9 % of the power in
  the band (:func:`noise_jammer_psd`).

AGC: the quantizer gain follows a first-order power detector (time constant ``tau``, the
``[agc]`` table) of the expected input power per component,
``P(t) = 1 + sum_s A_s^2 / 2 + sum_q a_q(t)^2 / 2`` (the noise, the nominal satellites and the
jammers on at ``t``): ``P_agc' = (P - P_agc) / tau``, settled at the start, updated per node
interval. The gain is ``target / sqrt(P_agc)`` with the target RMS in LSB (default: the step
that maximizes a uniform quantizer's SNR for Gaussian input, Max 1960). A detector that
averages the measured power over ``tau fs`` samples (250 000 at 10 ms, 25 MHz) fluctuates by
0.3 %: the expected power is used. Without jammers the gain is constant (as before).

Effective C/N0 (sidecar): ``1 / (C/N0)_eff = 1 / (C/N0) + sum_q (J_q / C) kappa_q`` with
``kappa = integral G_s(f) G_j(f) df``, both spectra of unit power, ``G_s`` the B3I BPSK
spectrum ``Tc sinc^2(f Tc)`` as sampled (the generator's chips are unfiltered, so every
alias folds into the sampled band: :func:`b3i_psd` with ``fs``) (Betz, *Engineering
Satellite-Based Navigation and Timing*, 2016, ch. 9: spectral separation coefficient). For a CW jammer ``kappa = G_s(offset)``
is the continuous-spectrum approximation only: the code's spectrum is a line spectrum
(1 kHz spacing), so a CW line between two code lines barely hurts and one on a line hurts
far more; the sidecar marks it ``"kappa_model": "continuous approximation"``.
"""

from __future__ import annotations

import math

import numpy as np

from ..constants import CHIP_RATE_B3I
from ..scenario.impairments import AgcSpec, Interference

#: FIR taps of the noise jammer's interpolator (low-rate samples per output sample).
TAPS = 16
#: Fractional phases of the interpolator table (nearest phase: timing error <= 1/512 of a
#: low-rate sample).
PHASES = 256
#: Kaiser window parameter of the interpolator.
KAISER_BETA = 5.0
#: Kernel codes of the jammer types.
KIND_CODE = {"cw": 0, "noise": 1}


def interpolator_taps() -> np.ndarray:
    """``(PHASES, TAPS)`` float32 table: row ``p`` weighs the ``TAPS`` low-rate samples
    around a point at fractional position ``p / PHASES`` after sample ``TAPS/2 - 1`` of the
    window; normalized so that the output power equals the input power (averaged over
    phases)."""
    phi = np.arange(PHASES)[:, None] / PHASES
    t = np.arange(TAPS)[None, :]
    x = phi + TAPS / 2 - 1 - t  # distance [low-rate samples] from tap t to the point
    win = np.i0(KAISER_BETA * np.sqrt(np.clip(1.0 - (x / (TAPS / 2)) ** 2, 0.0, None)))
    h = np.sinc(x) * win / np.i0(KAISER_BETA)
    h /= math.sqrt(np.mean(np.sum(h * h, axis=1)))
    return h.astype(np.float32)


def noise_jammer_psd(f_hz: np.ndarray, bandwidth_hz: float) -> np.ndarray:
    """Unit-power PSD [1/Hz] of the generated noise jammer at offsets ``f_hz`` from its
    centre: ``|H(f / B)|^2 / B`` of the continuous interpolation kernel."""
    over = 64
    x = np.linspace(-TAPS / 2, TAPS / 2, TAPS * over + 1)
    win = np.i0(KAISER_BETA * np.sqrt(np.clip(1.0 - (x / (TAPS / 2)) ** 2, 0.0, None)))
    h = np.sinc(x) * win
    n = 1 << 18
    spec = np.abs(np.fft.fft(h, n) / over) ** 2
    nu = np.fft.fftfreq(n, 1.0 / over)  # frequency [units of B]
    order = np.argsort(nu)
    nu, spec = nu[order], spec[order]
    spec /= np.trapezoid(spec, nu)
    return np.interp(np.asarray(f_hz) / bandwidth_hz, nu, spec, left=0.0, right=0.0) / bandwidth_hz


def b3i_psd(f_hz: np.ndarray, fs: float | None = None) -> np.ndarray:
    """Unit-power PSD [1/Hz] of the B3I BPSK(10) signal, ``Tc sinc^2(f Tc)``; with ``fs``,
    as sampled at ``fs`` without a filter (the generator's chips are ideal):
    ``sum_n Tc sinc^2((f - n fs) Tc)``, every alias folded in."""
    tc = 1.0 / CHIP_RATE_B3I
    f = np.asarray(f_hz, float)
    if fs is None:
        return tc * np.sinc(f * tc) ** 2
    n_alias = math.ceil(40.0 * CHIP_RATE_B3I / fs) + 1
    out = np.zeros(np.shape(f))
    for n in range(-n_alias, n_alias + 1):
        out += np.sinc((f - n * fs) * tc) ** 2
    return tc * out


def kappa_per_hz(jammer: Interference, fs: float | None = None, if_hz: float = 0.0,
                 complex_baseband: bool = True) -> tuple[float, str]:
    """Spectral separation coefficient ``kappa`` [1/Hz] of a jammer with B3I, and its model
    (``"exact"`` for the noise jammer's generated spectrum, ``"continuous approximation"``
    for CW).

    Without ``fs``: the textbook coefficient with the unsampled B3I spectrum. With ``fs``:
    with the spectrum as sampled (aliases folded in, :func:`b3i_psd`), which is what a
    correlator sees in the generated file: below about twice the chip rate the folded
    signal is denser in the sampled band than ``Tc sinc^2``, and an in-band jammer costs more
    (2 MHz at the centre, 2.5 MHz complex sampling: 6 dB more than the textbook value). Real
    samples add the jammer's image at ``-(2 f_IF + offset)``."""
    def one(offset: float) -> float:
        if jammer.kind == "cw":
            return float(b3i_psd(offset, fs))
        b = jammer.bandwidth_hz
        f = np.linspace(-0.75 * b, 0.75 * b, 20_001)
        return float(np.trapezoid(noise_jammer_psd(f, b) * b3i_psd(f + offset, fs), f))

    k = one(jammer.offset_hz)
    if fs is not None and not complex_baseband:
        k += one(-(2.0 * if_hz + jammer.offset_hz))
    return k, "continuous approximation" if jammer.kind == "cw" else "exact"


def effective_cn0_dbhz(cn0_dbhz: float, nominal_cn0_dbhz: float,
                       jammers: list[tuple[float, float]]) -> float:
    """Effective C/N0 [dB-Hz] of a satellite at ``cn0_dbhz`` under jammers given as
    ``(J/S [dB] relative to the nominal satellite, kappa [1/Hz])``:
    ``1 / (C/N0)_eff = 1 / (C/N0) + sum (J / C) kappa``."""
    inv = 10.0 ** (-cn0_dbhz / 10.0)
    for js_db, kappa in jammers:
        if math.isfinite(js_db):
            inv += 10.0 ** ((js_db + nominal_cn0_dbhz - cn0_dbhz) / 10.0) * kappa
    return 10.0 * math.log10(1.0 / inv)


class JammerPlan:
    """Kernel inputs of a scenario's jammers and AGC.

    Parameters
    ----------
    jammers : tuple of Interference
    agc : AgcSpec or None
        None: the defaults (10 ms, the Max optimum step).
    fs, if_hz : float
        Sample rate and IF [Hz]; ``complex_baseband``: complex samples.
    nominal_cn0_dbhz : float
        The C/N0 J/S refers to.
    base_sigma : float
        Input RMS per component without jammers (noise 1 plus the nominal satellites).
    gain_of_sigma : callable
        Quantizer gain [LSB per unit] for an input RMS (:func:`sdr_di.sim.ifgen
        .quantizer_gain` at the scenario's bits).
    seed : int
        Scenario seed (the noise jammers' keys).
    """

    def __init__(self, jammers: tuple[Interference, ...], agc: AgcSpec | None, fs: float,
                 if_hz: float, complex_baseband: bool, nominal_cn0_dbhz: float,
                 base_sigma: float, gain_of_sigma, seed: int):
        self.jammers = jammers
        self.agc = agc if agc is not None else AgcSpec(0.01, None)
        self.fs = fs
        self.if_hz = if_hz
        self.complex_baseband = complex_baseband
        self.base_sigma = base_sigma
        self.gain_of_sigma = gain_of_sigma
        c_nominal = 10.0 ** (nominal_cn0_dbhz / 10.0) * 2.0 / fs
        self._j_scale = c_nominal * (1.0 if complex_baseband else 2.0)  # a^2 per 10^(JS/10)
        n = len(jammers)
        self.kind = np.array([KIND_CODE[j.kind] for j in jammers], np.int64)
        self.freq = np.array([(if_hz + j.offset_hz) / fs for j in jammers], np.float64)
        self.phase = np.array([j.phase_deg / 360.0 for j in jammers], np.float64)
        self.rate = np.array([j.bandwidth_hz / fs for j in jammers], np.float64)
        keys = np.random.SeedSequence([seed, 0x1A3]).generate_state(max(n, 1), np.uint64)
        self.key = np.asarray(keys[:n], np.uint64)
        self.taps = interpolator_taps()
        self._agc_state: tuple[int, float] | None = None  # (next node, detector power)

    def amplitudes(self, t: np.ndarray) -> np.ndarray:
        """``(n_jam, len(t))`` float32 kernel amplitudes at true times ``t`` (0 when off)."""
        a = np.zeros((len(self.jammers), len(t)), np.float32)
        for q, jam in enumerate(self.jammers):
            js = jam.js_db_at(t)
            on = np.isfinite(js)
            a[q, on] = np.sqrt(self._j_scale * 10.0 ** (js[on] / 10.0))
        return a

    def gains(self, j0: int, amp: np.ndarray, node_dt: float) -> np.ndarray:
        """Per-node quantizer gains (float32) of nodes ``j0 .. j0 + n - 1`` with jammer
        amplitudes ``amp`` (n_jam, n). The detector runs in node order: a call must start at
        node 0 or where the previous call ended (:class:`~sdr_di.sim.ifgen.IfGenerator`
        replays the nodes before a range asked for out of order)."""
        n = amp.shape[1]
        if not len(self.jammers):
            return np.full(n, np.float32(self.gain_of_sigma(self.base_sigma)))
        power = self.base_sigma**2 + np.sum(amp.astype(np.float64) ** 2, axis=0) / 2.0
        if j0 == 0:
            p_agc = power[0]  # settled at the start
        elif self._agc_state is not None and self._agc_state[0] == j0:
            p_agc = self._agc_state[1]
        else:
            raise ValueError(f"AGC: node {j0} asked before the nodes preceding it")
        decay = math.exp(-node_dt / self.agc.time_constant_s)
        out = np.empty(n, np.float64)
        for k in range(n):  # ~1000 nodes per call: a plain loop is fine
            p_agc = power[k] + decay * (p_agc - power[k])
            out[k] = p_agc
        self._agc_state = (j0 + n, p_agc)
        sig = np.sqrt(out)
        if self.agc.target_sigma_lsb is not None:
            return (self.agc.target_sigma_lsb / sig).astype(np.float32)
        return np.array([self.gain_of_sigma(x) for x in sig], np.float32)

    @property
    def agc_node(self) -> int:
        """Node the AGC detector has reached (0: none run)."""
        return 0 if self._agc_state is None else self._agc_state[0]

    def records(self, cn0_per_sat: dict[int, float], nominal_cn0_dbhz: float) -> tuple:
        """Sidecar records: the jammers with their kappa, and each satellite's effective
        C/N0 with every jammer at its highest J/S (``{prn: dB-Hz}``)."""
        jams, worst = [], []
        for jam in self.jammers:
            kappa, model = kappa_per_hz(jam, self.fs, self.if_hz, self.complex_baseband)
            d = jam.as_dict()
            d.update(kappa_per_hz=kappa, kappa_model=model)
            jams.append(d)
            worst.append((max(jam.js_db, jam.js_end_db if jam.js_end_db is not None
                              else -math.inf), kappa))
        eff = {prn: round(effective_cn0_dbhz(c, nominal_cn0_dbhz, worst), 3)
               for prn, c in cn0_per_sat.items()}
        return jams, eff
