"""Whiteness of deep mode's channel measurements, open loop (issue 45 item 2).

Independent channels of a measurement bank (:func:`~sdr_di.deep.architectures.
make_measurement_bank`: ``prefilter``, ``reset`` or ``discriminator``) are fed simulated
correlator sums of 1 ms code epochs with known errors, interval after interval, as the vector
loop feeds them, but without an integration filter (no NCO corrections: the truth stays where
it drifts). Per channel and epoch::

    tau  code error [chips], constant plus beta f t (carrier-aided code)
    phi  carrier phase error [rad], + 2 pi f t
    f    frequency error [Hz]: N(0, 0.5 Hz) at the start, then a random walk of the noise
         model's PSD (the assumed MEMS accelerometer's velocity random walk on the line of
         sight, ``model_process_noise``) at every interval end
    E, P, L = b sqrt(2 C/N0 T) exp(j phi) R(tau - d, tau, tau + d) + unit complex noise
         (triangle correlation R, data bit b of 20 ms whose edges fall ``bit_offset_ms``
         into each 20 ms interval, so that an interval holds two blocks)

At each fusion (every interval, or every ``fusion_intervals`` for ``reset``), the bank's
outputs minus the truth at the interval's end, divided by the stated sigma, are the
normalized errors of the code (``dtau``) and the rate (``df``). Then the NCOs move by
``feedback`` (default half) of the outputs, the truth and the bank (``shift``) with them, as
an integration filter's corrections move them in the vector loop: without it the code error
would drift with the frequency error (``beta f``, 0.24 chip a minute at 0.5 Hz) to where the
normalized discriminator's gain is below one at low block SNR, a bias the closed loop never
sees. Then the bank is decorrelated
(the integration filter's fusion; ``prefilter``: its code variance reset, ``reset``: the
window's prior, ``discriminator``: nothing).

:func:`whiteness_figures` gives their lag autocorrelations and the variance of sums of ``N``
consecutive errors per term (1 for white unit errors; smaller when consecutive errors cancel,
as the slopes of one tracked phase do; larger when they persist): the criterion of the
default architecture (:func:`meets_criterion`, issue 45 item 2: ``|lag 1| <= 0.15`` and the
per-term variance of sums of 25 within [0.7, 1.4], code and rate, at 40 and 30 dB-Hz).
``scripts/check_prefilter.py --architecture`` prints them.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..constants import CHIP_RATE_B3I, F_B3I
from ..deep.architectures import block_ms, make_measurement_bank
from ..ins.imu import ImuErrorModel

__all__ = ["CRITERION", "OpenLoopErrors", "meets_criterion", "simulate_open_loop",
           "whiteness_figures"]

#: The default architecture's criterion (issue 45 item 2): largest ``|lag 1|`` and the
#: range of the per-term variance of sums of 25 normalized errors.
CRITERION = {"lag1_max": 0.15, "sum25": (0.7, 1.4)}

_EPOCH_S = 1e-3
_SIGMA_F_START = 0.5      # initial frequency error sigma [Hz]
_SIGMA_TAU_START = 0.01   # code error sigma [chips]: the closed loop's (0.3 m, module notes)


@dataclasses.dataclass
class OpenLoopErrors:
    """Normalized output errors of an open-loop run (module notes).

    Attributes
    ----------
    code, rate : ndarray (fusions, channels)
        ``(output - truth) / stated sigma`` of the code and the frequency (rate).
    stated_over_mc : dict
        ``{"code", "rate"}``: mean stated variance over the Monte Carlo variance.
    design_over_mc : dict
        The same for a pre-filter's design covariance ``P`` (what the cascade stated before
        issue 25; empty for the discriminators).
    """

    code: np.ndarray
    rate: np.ndarray
    stated_over_mc: dict
    design_over_mc: dict = dataclasses.field(default_factory=dict)


def simulate_open_loop(architecture: str, cn0_dbhz: float, *, channels: int = 100,
                       fusions: int = 300, seed: int = 1, fusion_intervals: int | None = None,
                       interval_s: float = 0.02, bit_offset_ms: int = 7, burn_in: int = 20,
                       spacing: float = 0.5, prior: tuple[float, float] | None = (0.05, 0.5),
                       feedback: float = 0.5) -> OpenLoopErrors:
    """Normalized output errors of ``channels`` independent channels (module notes).

    Parameters
    ----------
    architecture : str
        ``"prefilter"``, ``"reset"`` or ``"discriminator"``.
    cn0_dbhz : float
        C/N0 of every channel [dB-Hz] (also the C/N0 the bank is told).
    channels, fusions : int
        Channels, and fusions kept after the burn-in.
    seed : int
    fusion_intervals : int, optional
        Intervals per fusion; default that of the receiver's default configuration for the
        architecture (``reset``: 10 at 50 Hz; the others 1).
    interval_s : float
        Filter interval [s] (a whole number of ms).
    bit_offset_ms : int
        Where the data-bit edges fall in each interval [ms].
    burn_in : int
        Fusions left out at the start.
    spacing : float
        Early/late offset d [chips].
    prior : (float, float) or None
        Code [chips] and frequency [Hz] sigmas handed to ``decorrelate`` after a fusion
        (the integration filter's; ``reset`` takes them as its window's prior, the others
        ignore them). Default (0.05 chip, 0.5 Hz): the vector loop's floors are 0.01 chip
        and 0.5 Hz, and an integration filter knows the range better than 0.05 chip.
    feedback : float
        Share of each fused output by which the NCOs are moved (module notes).
    """
    from ..coupling.config import IntegrationConfig

    rate_hz = 1.0 / interval_s
    if fusion_intervals is None:
        fusion_intervals = IntegrationConfig(deep_measurements=architecture,
                                             filter_rate_hz=rate_hz).fusion_intervals
    rng = np.random.default_rng(seed)
    imu = ImuErrorModel()
    bank = make_measurement_bank(architecture, channels, spacing, F_B3I, imu)
    blk = block_ms(architecture, 20, rate_hz, fusion_intervals)
    n = channels
    beta = CHIP_RATE_B3I / F_B3I
    cn0 = 10.0 ** (cn0_dbhz / 10.0)
    amp = math.sqrt(2.0 * cn0 * _EPOCH_S)
    m = round(interval_s / _EPOCH_S)
    tau = rng.normal(0.0, _SIGMA_TAU_START, n)
    phi = rng.normal(0.0, 0.3, n)
    f = rng.normal(0.0, _SIGMA_F_START, n)
    for i in range(n):
        bank.reset(i, sigma_phi=0.3, sigma_f=_SIGMA_F_START)
    s_f_model = getattr(bank, "s_f_model", None)
    if s_f_model is None:
        from ..deep.prefilter import model_process_noise

        s_f_model = model_process_noise(imu, F_B3I)[0]
    sig_walk = math.sqrt(s_f_model * interval_s)
    t_ep = np.full(m, _EPOCH_S)
    bits = rng.choice([-1.0, 1.0], n)
    code: list = []
    rate: list = []
    design_P = getattr(bank, "P", None)
    design: list | None = None if design_P is None else []
    epoch = (20 - bit_offset_ms) % 20      # satellite-clock ms: bits start at multiples of 20
    total = (fusions + burn_in) * fusion_intervals
    for k in range(total):
        ep = np.arange(epoch, epoch + m)
        tc = (np.arange(m) + 0.5) * _EPOCH_S                  # epoch centres in the interval
        new_bit = ep % 20 == 0
        sign = np.empty((m, n))
        for j in range(m):
            if new_bit[j]:
                bits = rng.choice([-1.0, 1.0], n)
            sign[j] = bits
        tau_c = tau[None, :] + beta * f[None, :] * tc[:, None]
        ph = sign * amp * np.exp(1j * (phi[None, :] + 2.0 * math.pi * f[None, :] * tc[:, None]))
        epl = [ph * np.maximum(1.0 - np.abs(tau_c - off), 0.0)
               + rng.normal(size=(m, n)) + 1j * rng.normal(size=(m, n))
               for off in (spacing, 0.0, -spacing)]
        tau = tau + beta * interval_s * f
        phi = phi + 2.0 * math.pi * interval_s * f
        starts = ep % min(20, blk) == 0
        for i in range(n):
            bank.process(i, epl[0][:, i], epl[1][:, i], epl[2][:, i], t_ep, cn0,
                         block_start=starts)
        epoch += m
        if (k + 1) % fusion_intervals == 0:
            keep = (k + 1) // fusion_intervals > burn_in
            for i in range(n):
                dtau, df, vt, vf = bank.outputs(i)
                if keep:
                    code.append((dtau - tau[i], vt))
                    rate.append((df - f[i], vf))
                    if design is not None:
                        design.append((design_P[i, 0, 0], design_P[i, 2, 2]))
                # the NCOs steered by part of the output (the integration filter's feedback):
                # the truth and the bank move together
                d_tau, d_f = feedback * dtau, feedback * df
                tau[i] -= d_tau
                f[i] -= d_f
                bank.shift(i, d_tau, d_f)
                bank.decorrelate(i, prior=prior)
        f = f + sig_walk * rng.normal(size=n)   # the drift after the interval's end
    e_c, v_c = (np.array(a).reshape(-1, n) for a in zip(*code))
    e_r, v_r = (np.array(a).reshape(-1, n) for a in zip(*rate))
    d_over = {}
    if design:
        d_c, d_r = np.array(design).T
        d_over = {"code": float(d_c.mean() / np.mean(e_c ** 2)),
                  "rate": float(d_r.mean() / np.mean(e_r ** 2))}
    return OpenLoopErrors(code=e_c / np.sqrt(v_c), rate=e_r / np.sqrt(v_r),
                          stated_over_mc={"code": float(v_c.mean() / np.mean(e_c ** 2)),
                                          "rate": float(v_r.mean() / np.mean(e_r ** 2))},
                          design_over_mc=d_over)


def whiteness_figures(yn: np.ndarray, lags=(1, 2, 5, 10, 25), sums=(1, 5, 25, 100)) -> dict:
    """Figures of normalized errors ``yn`` (times x channels): ``var`` per channel (mean
    square), ``cross_corr`` (mean correlation between channels), ``lag{k}`` (autocorrelation
    at lag ``k``, mean over channels) and ``sum{N}`` (mean square of sums of ``N``
    consecutive errors per term, mean over channels; about zero-mean errors, so a bias
    counts, and without the ``1 - 1/k`` shrinkage of a variance about the mean of ``k``
    sums; left out when fewer than two sums per channel)."""
    yn = np.asarray(yn, float)
    n_t, n_ch = yn.shape
    out: dict = {"var": (yn ** 2).mean(0)}
    if n_ch > 1:
        c = np.corrcoef(yn.T)[~np.eye(n_ch, dtype=bool)]
        out["cross_corr"] = float(c.mean())
    for lag in lags:
        if n_t > lag + 2:
            out[f"lag{lag}"] = float(np.mean([np.corrcoef(yn[:-lag, i], yn[lag:, i])[0, 1]
                                              for i in range(n_ch)]))
    for n in sums:
        k = (n_t // n) * n
        if k >= 2 * n:
            out[f"sum{n}"] = float((np.square(yn[:k].reshape(-1, n, n_ch).sum(1)).mean(0)
                                    / n).mean())
    return out


def meets_criterion(fig: dict) -> bool:
    """Whether :func:`whiteness_figures` meet :data:`CRITERION` (``|lag 1| <= 0.15`` and the
    per-term variance of sums of 25 within [0.7, 1.4])."""
    lo, hi = CRITERION["sum25"]
    return (abs(fig.get("lag1", math.inf)) <= CRITERION["lag1_max"]
            and lo <= fig.get("sum25", math.nan) <= hi)
