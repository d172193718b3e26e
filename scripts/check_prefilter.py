#!/usr/bin/env python
"""Monte Carlo check of deep mode's channel measurements, open loop (issues 25 and 45).

Usage::

    python scripts/check_prefilter.py [--architecture prefilter reset discriminator]
        [--cn0 45 40 35 30] [--channels 100] [--fusions 300] [--seed 1]

Independent channels of each measurement architecture
(:func:`~sdr_di.deep.architectures.make_measurement_bank`) are fed simulated correlator sums
of 1 ms epochs with known errors, fused and steered as the vector loop does, without an
integration filter (:func:`~sdr_di.experiments.measurement_errors.simulate_open_loop`, whose
notes give the model). For each C/N0, the code and the rate block:

* ``stated/MC``: the mean stated variance over the Monte Carlo variance of the output
  errors (1 for a consistent noise model);
* ``lag 1``, ``lag 2``: the autocorrelation of consecutive normalized errors;
* ``sum 25``, ``sum 100``: the mean square of sums of 25 and 100 consecutive normalized
  errors, per term (1 for white unit errors);
* ``ok``: issue 45's criterion for the default architecture (``|lag 1| <= 0.15`` and
  ``sum 25`` within [0.7, 1.4]).
"""

from __future__ import annotations

import argparse

from sdr_di.experiments.measurement_errors import (meets_criterion, simulate_open_loop,
                                                   whiteness_figures)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--architecture", nargs="+",
                    default=["prefilter", "reset", "discriminator"])
    ap.add_argument("--cn0", type=float, nargs="+", default=[45.0, 40.0, 35.0, 30.0])
    ap.add_argument("--channels", type=int, default=100)
    ap.add_argument("--fusions", type=int, default=300)
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args(argv)
    print("architecture   C/N0  block  stated/MC   lag 1   lag 2  sum 25  sum 100  ok")
    for arch in a.architecture:
        for cn0 in a.cn0:
            r = simulate_open_loop(arch, cn0, channels=a.channels, fusions=a.fusions,
                                   seed=a.seed)
            for name, e in (("code", r.code), ("rate", r.rate)):
                f = whiteness_figures(e)
                print(f"{arch:13s} {cn0:5.1f}  {name:5s}  {r.stated_over_mc[name]:9.2f}  "
                      f"{f['lag1']:+6.3f}  {f['lag2']:+6.3f}  {f.get('sum25', float('nan')):6.3f}"
                      f"  {f.get('sum100', float('nan')):7.3f}  "
                      f"{'yes' if meets_criterion(f) else 'no'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
