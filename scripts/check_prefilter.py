#!/usr/bin/env python
"""Monte Carlo check of the deep pre-filter's stated output variances (issue 25 item 2).

Usage::

    python scripts/check_prefilter.py [--cn0 45 40 35 30] [--channels 200]
        [--intervals 250] [--seed 1]

Independent channels of :class:`~sdr_di.deep.prefilter.PreFilterBank` (default settings)
are fed simulated correlator sums of 20 ms coherent blocks (one per 20 ms interval, as the
vector loop's D1 channels get when the interval is bit-aligned) with known errors: code
offset, carrier phase and a frequency error that is a random walk of the noise model's PSD
(``s_f_model``, the assumed MEMS accelerometer's velocity random walk on the line of
sight). After every interval the bank's :meth:`~sdr_di.deep.prefilter.PreFilterBank.
decorrelate` runs, as in the vector loop. After a burn-in of 50 intervals, for each C/N0:

* ``var_tau``, ``var_f``: the MC variance of the output errors (``dtau`` minus truth
  [chips^2], ``df`` minus truth [Hz^2]) over channels and intervals;
* ``stated``: the mean of what :meth:`~sdr_di.deep.prefilter.PreFilterBank.outputs`
  states (the ``R`` of paper 004 eq 34, before the ``c / f`` scaling);
* ``design``: the mean of the design covariance ``P`` (what the outputs stated before this
  check: its frequency variance was about 5.5 times the true one at 40 dB-Hz);
* the ratio stated / MC (1 for a consistent model).

The block's correlator sums follow the pre-filter's own measurement model (triangle
correlation, unit complex noise per component, amplitude ``sqrt(2 C/N0 T)``), so this
checks the covariance propagation, not the discriminators' linearization.
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from sdr_di.constants import CHIP_RATE_B3I, F_B3I
from sdr_di.deep.prefilter import PreFilterBank

T_BLOCK = 0.02       # coherent block = filter interval [s]
BURN_IN = 50         # intervals left out before the statistics
SIGMA_F_START = 0.5  # initial frequency error sigma [Hz]
SIGMA_TAU_START = 0.05  # initial code error sigma [chips] (inside the linear range)


def monte_carlo(cn0_dbhz: float, channels: int = 200, intervals: int = 250, seed: int = 1,
                spacing: float = 0.5) -> dict:
    """Output errors of ``channels`` pre-filters over ``intervals`` 20 ms intervals at
    ``cn0_dbhz`` (module notes). Returns MC variances, stated and design variances
    (chips^2, Hz^2), after the burn-in."""
    rng = np.random.default_rng(seed)
    cn0 = 10.0 ** (cn0_dbhz / 10.0)
    beta = CHIP_RATE_B3I / F_B3I
    bank = PreFilterBank(channels, spacing)
    amp = math.sqrt(2.0 * cn0 * T_BLOCK)
    n = channels
    # truth at the block start, drawn from the prior of a pre-filter the vector loop
    # restarts (frequency sigma 0.5 Hz: 20 ms phase steps alias the frequency at 25 Hz),
    # the code well inside the discriminator's linear range (+-0.5 chip)
    tau = rng.normal(0.0, SIGMA_TAU_START, n)
    phi = rng.normal(0.0, 0.3, n)
    f = rng.normal(0.0, SIGMA_F_START, n)
    for i in range(n):
        bank.reset(i, sigma_phi=0.3, sigma_f=SIGMA_F_START)
    sig_walk = math.sqrt(bank.s_f_model * T_BLOCK)
    e_tau, e_f, s_tau, s_f, d_tau, d_f = ([] for _ in range(6))
    t = np.full(1, T_BLOCK)
    for k in range(intervals):
        sign = rng.choice([-1.0, 1.0], n)                     # data bit
        tau_avg = tau + 0.5 * beta * T_BLOCK * f
        ph = sign * amp * np.exp(1j * (phi + math.pi * T_BLOCK * f))
        epl = [ph * np.maximum(1.0 - np.abs(tau_avg - off), 0.0)
               + rng.normal(size=n) + 1j * rng.normal(size=n)
               for off in (spacing, 0.0, -spacing)]
        tau = tau + beta * T_BLOCK * f
        phi = phi + 2.0 * math.pi * T_BLOCK * f
        f = f + sig_walk * rng.normal(size=n)
        for i in range(n):
            bank.process(i, epl[0][i:i + 1], epl[1][i:i + 1], epl[2][i:i + 1], t, cn0)
            if k >= BURN_IN:
                dtau, df, vt, vf = bank.outputs(i)
                e_tau.append(dtau - tau[i])
                e_f.append(df - f[i])
                s_tau.append(vt)
                s_f.append(vf)
                d_tau.append(bank.P[i, 0, 0])
                d_f.append(bank.P[i, 2, 2])
            bank.decorrelate(i)
    return {"cn0_dbhz": cn0_dbhz,
            "var_tau": float(np.mean(np.square(e_tau))), "var_f": float(np.mean(np.square(e_f))),
            "stated_tau": float(np.mean(s_tau)), "stated_f": float(np.mean(s_f)),
            "design_tau": float(np.mean(d_tau)), "design_f": float(np.mean(d_f))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cn0", type=float, nargs="+", default=[45.0, 40.0, 35.0, 30.0])
    ap.add_argument("--channels", type=int, default=200)
    ap.add_argument("--intervals", type=int, default=250)
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    print("C/N0   MC var_tau  stated/MC  design/MC |  MC var_f   stated/MC  design/MC")
    print("dB-Hz  [chip^2]                          |  [Hz^2]")
    for cn0 in a.cn0:
        r = monte_carlo(cn0, a.channels, a.intervals, a.seed)
        print(f"{cn0:5.1f}  {r['var_tau']:.3e}  {r['stated_tau'] / r['var_tau']:9.2f}  "
              f"{r['design_tau'] / r['var_tau']:9.2f} |  {r['var_f']:.3e}  "
              f"{r['stated_f'] / r['var_f']:9.2f}  {r['design_f'] / r['var_f']:9.2f}")


if __name__ == "__main__":
    main()
