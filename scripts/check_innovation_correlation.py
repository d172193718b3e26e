#!/usr/bin/env python
"""Time and cross-channel correlation of the deep integration filter's innovations.

Usage::

    python scripts/check_innovation_correlation.py [--seed 1] [--cn0 40] [--duration 30]
                                                   [--filter ekf] [--filter-rates 50 10]

The default scenario (``signals/default.toml``, 2.5 MHz, every satellite at 40 dB-Hz until
15 s and at ``--cn0`` after; the window of ``scripts/check_consistency.py``, 17 s to the
end) runs in deep mode at each filter rate on the same files (the start-up shared,
:class:`~sdr_di.integration.receiver.DeepStart`). Each filter update with every channel in
the measurement vector gives the normalized innovations ``y_i / sqrt(S_ii)`` of the code and
the rate block. Printed per block: their variance per channel, the mean correlation between
channels, the autocorrelation at lags 1, 2, 5, 10 and 25 updates (mean over channels), and
``var(sum of N consecutive) / N`` for N = 1, 5, 25, 100: equal to the variance of one for
white innovations, smaller when the errors cancel in time (a frequency that is the slope of
a tracked phase), larger when they persist. docs/notes/consistency.md uses it to explain
deep's velocity NEES.
"""

from __future__ import annotations

import argparse

import numpy as np

from sdr_di.experiments._deep import generated_inputs, run_deep_variant, with_outages
from sdr_di.integration import loop as loop_module
from sdr_di.scenario import DEFAULT_SCENARIO, load_scenario


def record_innovations(rec: list):
    """Patch :meth:`IntegrationLoop.filter_step` to append ``(t, y, S)`` of every update."""
    step = loop_module.IntegrationLoop.filter_step

    def filter_step(self, iv, m):
        step(self, iv, m)
        if m.z is not None:
            rec.append((iv.k1 / self.fs, self.kf.y.copy(), self.kf.S.copy()))
    loop_module.IntegrationLoop.filter_step = filter_step


def block_figures(yn: np.ndarray) -> dict:
    """Figures of one block's normalized innovations ``yn`` (updates x channels)."""
    n_ch = yn.shape[1]
    c = np.corrcoef(yn.T)[~np.eye(n_ch, dtype=bool)]
    out = {"var": (yn ** 2).mean(0), "cross_corr": float(c.mean())}
    for lag in (1, 2, 5, 10, 25):
        out[f"lag{lag}"] = float(np.mean([np.corrcoef(yn[:-lag, i], yn[lag:, i])[0, 1]
                                          for i in range(n_ch)]))
    for n in (1, 5, 25, 100):
        k = (len(yn) // n) * n
        if k >= 2 * n:
            out[f"sum{n}"] = float((yn[:k].reshape(-1, n, n_ch).sum(1).var(0) / n).mean())
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--cn0", type=float, default=40.0, help="C/N0 from 15 s [dB-Hz], <= 40")
    p.add_argument("--duration", type=float, default=30.0)
    p.add_argument("--filter", default="ekf")
    p.add_argument("--filter-rates", nargs="+", type=float, default=[50.0])
    args = p.parse_args(argv)
    sc = load_scenario(DEFAULT_SCENARIO).with_overrides(
        seed=args.seed, duration_s=args.duration, sampling_rate_hz=2.5e6, cn0_dbhz=40.0)
    if args.cn0 < 40.0:
        sc = with_outages(sc, [{"prn": "all", "start_s": 15.0, "end_s": args.duration + 1.0,
                                "attenuation_db": 40.0 - args.cn0}])
    rec: list = []
    record_innovations(rec)
    with generated_inputs(sc) as inp:
        for rate in args.filter_rates:
            rec.clear()
            dr = run_deep_variant(inp, args.filter, filter_rate_hz=rate)
            if dr.result is None:
                print(f"{rate:g} Hz: {dr.error}")
                continue
            n_ch = len(dr.result.prns)
            ups = [(y, s) for t, y, s in rec if t >= 17.0 and y.size == 2 * n_ch]
            y = np.array([u[0] for u in ups])
            sd = np.sqrt(np.array([np.diag(u[1]) for u in ups]))
            print(f"seed {args.seed}, {args.cn0:g} dB-Hz, {args.filter} at {rate:g} Hz: "
                  f"{len(ups)} updates with all {n_ch} channels")
            for name, sl in (("code", slice(0, n_ch)), ("rate", slice(n_ch, 2 * n_ch))):
                f = block_figures(y[:, sl] / sd[:, sl])
                print(f"  {name}: var per channel {np.round(f['var'], 2)}, cross-channel "
                      f"corr {f['cross_corr']:+.3f}")
                print("    autocorr " + "  ".join(f"lag {k[3:]} {f[k]:+.3f}" for k in f
                                                  if k.startswith("lag")))
                print("    var(sum of N)/N " + "  ".join(f"N={k[3:]} {f[k]:.3f}" for k in f
                                                         if k.startswith("sum")))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
