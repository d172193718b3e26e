#!/usr/bin/env python
"""Time and cross-channel correlation of the deep integration filter's innovations.

Usage::

    python scripts/check_innovation_correlation.py [--seed 1] [--cn0 40] [--duration 30]
                                                   [--filter ekf] [--filter-rates 50 10]
                                                   [--architecture prefilter reset ...]

The default scenario (``signals/default.toml``, 2.5 MHz, every satellite at 40 dB-Hz until
15 s and at ``--cn0`` after; the window of ``scripts/check_consistency.py``, 17 s to the
end) runs in deep mode at each filter rate on the same files (the start-up shared,
:class:`~sdr_di.integration.receiver.DeepStart`). Each filter update with every channel in
the measurement vector gives the normalized innovations ``y_i / sqrt(S_ii)`` of the code and
the rate block, whitened with the block's ``S`` (``L^-1 y``, ``S = L L^T``; ``--diagonal``:
``y_i / sqrt(S_ii)``, which leaves the errors the channels share, such as the clock's,
in every channel), for each deep measurement architecture (``--architecture``; the start-up
shared). Printed per block
(:func:`~sdr_di.experiments.measurement_errors.whiteness_figures`): their mean square per
channel, the mean correlation between channels, the autocorrelation at lags 1, 2, 5, 10 and
25 updates (mean over channels), and the mean square of sums of N consecutive ones per term
for N = 1, 5, 25, 100: equal to the variance of one for white innovations, smaller when the
errors cancel in time (a frequency that is the slope of a tracked phase), larger when they
persist; and issue 45's criterion (``|lag 1| <= 0.15``, sum of 25 within [0.7, 1.4]).
docs/notes/consistency.md uses it to explain deep's velocity NEES.
"""

from __future__ import annotations

import argparse
import itertools

import numpy as np

from sdr_di.experiments._deep import generated_inputs, run_deep_variant, with_outages
from sdr_di.experiments.measurement_errors import meets_criterion, whiteness_figures
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


def normalized(ups: list, sl: slice, diagonal: bool = False) -> np.ndarray:
    """Normalized innovations of one block (updates x channels): ``L^-1 y`` with ``S = L
    L^T`` the block's innovation covariance (white and of unit variance for a consistent
    filter, whatever the channels share: the clock, the INS velocity), or with
    ``diagonal``, ``y_i / sqrt(S_ii)`` (then channels that share an error correlate)."""
    out = []
    for y, S in ups:
        yb, Sb = y[sl], S[sl, sl]
        out.append(yb / np.sqrt(np.diag(Sb)) if diagonal
                   else np.linalg.solve(np.linalg.cholesky(Sb), yb))
    return np.array(out)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--cn0", type=float, default=40.0, help="C/N0 from 15 s [dB-Hz], <= 40")
    p.add_argument("--duration", type=float, default=30.0)
    p.add_argument("--filter", default="ekf")
    p.add_argument("--filter-rates", nargs="+", type=float, default=[50.0])
    p.add_argument("--architecture", nargs="+", default=["prefilter"],
                   help="deep measurement architectures (--deep-measurements)")
    p.add_argument("--diagonal", action="store_true",
                   help="normalize each innovation by its own sigma (sqrt S_ii) instead of "
                   "whitening the block with its S")
    args = p.parse_args(argv)
    sc = load_scenario(DEFAULT_SCENARIO).with_overrides(
        seed=args.seed, duration_s=args.duration, sampling_rate_hz=2.5e6, cn0_dbhz=40.0)
    if args.cn0 < 40.0:
        sc = with_outages(sc, [{"prn": "all", "start_s": 15.0, "end_s": args.duration + 1.0,
                                "attenuation_db": 40.0 - args.cn0}])
    rec: list = []
    record_innovations(rec)
    with generated_inputs(sc) as inp:
        for arch, rate in itertools.product(args.architecture, args.filter_rates):
            rec.clear()
            dr = run_deep_variant(inp, args.filter, filter_rate_hz=rate,
                                  deep_measurements=arch)
            if dr.result is None:
                print(f"{arch}, {rate:g} Hz: {dr.error}")
                continue
            n_ch = len(dr.result.prns)
            ups = [(y, s) for t, y, s in rec if t >= 17.0 and y.size == 2 * n_ch]
            print(f"seed {args.seed}, {args.cn0:g} dB-Hz, {args.filter}, {arch} at {rate:g} "
                  f"Hz: {len(ups)} updates with all {n_ch} channels")
            for name, sl in (("code", slice(0, n_ch)), ("rate", slice(n_ch, 2 * n_ch))):
                f = whiteness_figures(normalized(ups, sl, args.diagonal))
                print(f"  {name}: mean square per channel {np.round(f['var'], 2)}, "
                      f"cross-channel corr {f['cross_corr']:+.3f}, criterion "
                      f"{'met' if meets_criterion(f) else 'not met'}")
                print("    autocorr " + "  ".join(f"lag {k[3:]} {f[k]:+.3f}" for k in f
                                                  if k.startswith("lag")))
                print("    mean square of sums of N, per term " + "  ".join(
                    f"N={k[3:]} {f[k]:.3f}" for k in f if k.startswith("sum")))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
