#!/usr/bin/env python
"""Scalar receiver acceptance at full rate: generate (or reuse) a default-scenario file,
run ``sdr-di run --mode scalar`` on it and print the accuracy against truth.

Usage::

    python scripts/check_scalar.py [--duration 40] [--out signals/out/check] [--fs 25e6]
        [--if 0] [--format iq_int8] [--bits 4] [--reuse]

Prints acquisition/tracking/decoding per channel, position and velocity RMSE after the first
fix, and the receiver's real-time factor and time split.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

from sdr_di.cli import main as cli
from sdr_di.receiver.accuracy import solution_vs_truth
from sdr_di.receiver.run_scalar import open_source, run_scalar
from sdr_di.receiver.scalar import ScalarReceiver
from sdr_di.scenario import REPO_ROOT


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", default="40")
    ap.add_argument("--out", type=Path, default=REPO_ROOT / "signals" / "out" / "check")
    ap.add_argument("--fs", default="25e6")
    ap.add_argument("--if", dest="if_hz", default="0")
    ap.add_argument("--format", default="iq_int8")
    ap.add_argument("--bits", default="4")
    ap.add_argument("--reuse", action="store_true", help="reuse an existing file")
    a = ap.parse_args()
    d = a.out
    if not (a.reuse and (d / "default.json").exists()):
        t0 = time.perf_counter()
        rc = cli(["generate", "--no-progress", "--duration", a.duration, "--out", str(d),
                  "--fs", a.fs, "--if", a.if_hz, "--format", a.format, "--bits", a.bits])
        if rc:
            raise SystemExit(rc)
        print(f"generated {a.duration} s in {time.perf_counter() - t0:.1f} s")
    meta = json.loads((d / "default.json").read_text())
    prns = [s["prn"] for s in meta["satellites"]]
    rx = ScalarReceiver(log=False)
    res = run_scalar(open_source(d / "default.bin"), d / "run", prns=prns, progress=False,
                     receiver=rx)
    acc = solution_vs_truth(res.files["pvt"], d / "default_truth.csv")
    print(f"machine: {os.cpu_count()} cores; file {meta['sampling_rate_hz'] / 1e6:g} MHz "
          f"{meta['sample_format']} {meta['quantization_bits']}-bit, {meta['duration_s']:.0f} s")
    truth = {s["prn"]: s for s in meta["satellites"]}
    acq = {r.prn: r for r in rx.acquisition_results}
    for row in res.channels:
        t, r = truth[row["prn"]], acq[row["prn"]]
        dcode = (r.code_phase_chips - t["code_phase_chips"] + 5115) % 10230 - 5115
        print(f"  C{row['prn']:02d} {row['state']:6s} acq dDoppler {r.doppler_hz - t['doppler_hz']:+7.1f} Hz"
              f" dcode {dcode:+.3f} chip  C/N0 {row['cn0_dbhz']}  eph "
              f"{'decoded' if row['ephemeris_decoded'] else '-'}")
    print(f"fixes {acc['n_fixes']}, first at {acc['first_fix_s']:.1f} s; position RMSE "
          f"{acc['pos_rmse_m']:.3f} m (max {acc['pos_max_m']:.3f}); velocity RMSE "
          f"{acc['vel_rmse_mps']:.4f} m/s (max {acc['vel_max_mps']:.4f})")
    p = res.profile
    print(f"receiver: {res.processed_s:.1f} s of data in {res.wall_s:.1f} s "
          f"(x{res.processed_s / res.wall_s:.2f} real time); acquisition {p['acquisition']:.1f} s, "
          f"correlate {p['correlate']:.1f} s, channels {p['channels']:.1f} s, "
          f"read {p['read']:.1f} s, PVT/output {p['callback']:.1f} s")


if __name__ == "__main__":
    main()
