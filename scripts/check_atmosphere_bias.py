#!/usr/bin/env python
"""How much of a run's position error the truth's atmosphere residuals explain.

Usage::

    python scripts/check_atmosphere_bias.py SIDECAR SOLUTION_CSV [--skip 5]

``SIDECAR``: the generated file's JSON sidecar, with ``[atmosphere] truth = "residuals"``
(``atmosphere_truth`` in it). ``SOLUTION_CSV``: a loose, tight or deep solution of that file
(``sdr-di run F --mode deep``; the ``pos_err_*`` and ``pos_sd_*`` columns).

The truth's residuals (:mod:`sdr_di.sim.atmosphere`: each satellite's Klobuchar delay scaled
by ``k_s + g_s(t)``, the wet delay's offset mapped by elevation) are range errors that no
filter of this project models. Drawn again here from the sidecar's seed and model (checked
against the sidecar's recorded draws), averaged over the scored span and projected through
the start's line-of-sight geometry by unweighted least squares with a clock column, they
predict a constant position bias (ENU, metres). The script prints it beside the run's mean
ENU error, the error's spread about that mean and the filter's mean 1-sigma: where the bias
is the error, the position NEES is about ``(bias / sigma)^2`` whatever the filter.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def fmt(v) -> str:
    """Three values [m] as a table row."""
    return "  ".join(f"{x:+7.3f}" for x in v)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("sidecar")
    p.add_argument("solution")
    p.add_argument("--skip", type=float, default=5.0,
                   help="seconds after the solution's first row left out [s]")
    args = p.parse_args(argv)

    from sdr_di.io.imu_files import read_truth
    from sdr_di.orbits.atmosphere import iono_delay_b3i_m
    from sdr_di.orbits.ephemeris import Klobuchar
    from sdr_di.scenario.schema import AtmosphereSpec
    from sdr_di.sim.atmosphere import AtmosphereTruth

    side = json.loads(Path(args.sidecar).read_text())
    rec = side.get("atmosphere_truth")
    if not rec or rec.get("truth") != "residuals":
        raise SystemExit("the sidecar's truth atmosphere is the receiver's model: no residuals")
    sats = side["satellites"]
    prns = [s["prn"] for s in sats]
    truth_file = Path(args.sidecar).with_name(Path(side["truth_file"]).name)
    llh0 = read_truth(truth_file)[0].llh[0]          # lat, lon [rad], h [m] at t = 0
    atm = AtmosphereTruth(AtmosphereSpec(truth="residuals", **rec["model"]), prns,
                          side["duration_s"], side["scenario"]["seed"], float(llh0[2]))
    drawn = {f"C{p:02d}": k for p, k in atm.iono_scale.items()}
    if any(abs(drawn[k] - v) > 1e-12 for k, v in rec["iono_scale"].items()):
        raise SystemExit("the draws do not match the sidecar's (another seed or model)")

    sol = np.genfromtxt(args.solution, delimiter=",", names=True, skip_header=1)
    t = sol["t_s"]
    keep = t >= t[0] + args.skip
    kl = side["klobuchar"]
    iono = Klobuchar(alpha=tuple(kl["alpha"]), beta=tuple(kl["beta"]))
    lat, lon = float(llh0[0]), float(llh0[1])
    rows, dr = [], []
    for s in sats:
        el, az = np.radians(s["elevation_deg"]), np.radians(s["azimuth_deg"])
        ts = t[keep]
        delay = float(iono_delay_b3i_m(iono, lat, lon, el, az, side["start"]["sow"]
                                       + ts.mean()))
        r = float(np.mean((atm.iono_factor(s["prn"], ts) - 1.0) * delay
                          + atm.tropo_residual_m(ts, el)))
        rows.append(np.r_[-np.cos(el) * np.sin(az), -np.cos(el) * np.cos(az), -np.sin(el),
                          1.0])
        dr.append(r)
        print(f"C{s['prn']:02d}  el {s['elevation_deg']:5.1f} deg  Klobuchar {delay:5.2f} m"
              f"  residual {r:+6.2f} m")
    bias = np.linalg.lstsq(np.array(rows), np.array(dr), rcond=None)[0]
    err = np.array([sol[f"pos_err_{c}_m"][keep] for c in "enu"])
    sd = np.array([sol[f"pos_sd_{c}_m"][keep] for c in "enu"])
    print(f"ENU [m]                      {'e':>7s}  {'n':>7s}  {'u':>7s}")
    print(f"residuals projected (LS):    {fmt(bias[:3])}   (clock {bias[3]:+.2f} m)")
    print(f"run's mean error:            {fmt(err.mean(axis=1))}")
    print(f"run's error about its mean:  {fmt(err.std(axis=1))}   (sd over {keep.sum()} rows)")
    print(f"filter's mean 1-sigma:       {fmt(sd.mean(axis=1))}")
    nees = np.mean(np.sum((err / sd) ** 2, axis=0)) / 3.0
    print(f"position NEES per dof {nees:.0f}; with the projected bias taken out "
          f"{np.mean(np.sum(((err - bias[:3, None]) / sd) ** 2, axis=0)) / 3.0:.1f}")


if __name__ == "__main__":
    main()
