"""The code discriminator's error from the code's alignment with the sample grid.

The generator's chips are ideal (no front-end filter), so below about twice the chip rate
each sample sees one chip, and which chip transitions fall between a sample and its early
and late replicas depends on where the code sits against the sample grid. The noise-free
early-minus-late discriminator (``receiver.loops.dll_nelp``, +-0.5 chip) at zero tracking
error therefore reads an error that depends on that alignment. Where ``fs / 1000`` is a
whole number (2.5, 4, 5, 25 MHz: *commensurate* sampling) the grid is the same in every
code period, so the error changes only as fast as the code phase drifts: a MEO or IGSO
satellite's code moves several chips a second and its error averages out within a
pre-filter interval, a GEO's moves about a quarter of a chip a second (the receiver's own
motion) and its error stays for tens of seconds, a range bias. Where ``fs / 1000`` is not a
whole number (2.5003 MHz) the grid slides by a fraction of a sample every period and the
error averages out for every satellite.

Prints, per sampling rate and PRN: the standard deviation of the 1 ms error over
alignments, and that of its mean over ``--interval`` ms for a code drifting at ``--drift``
chips/s (GEO-like) and 16 chips/s (MEO-like), in metres.

Usage: ``python scripts/check_sampling_alignment.py [--fs 2.5e6 2.5003e6 ...]``
"""

from __future__ import annotations

import argparse

import numpy as np

from sdr_di.constants import C_LIGHT
from sdr_di.receiver.loops import dll_nelp
from sdr_di.signal.codes import b3i_code

CHIP_RATE = 10.23e6
CODE_LENGTH = 10230
CHIP_M = C_LIGHT / CHIP_RATE


def discriminator_errors(prn: int, fs: float, start_chips: float, drift_cps: float,
                         n_ms: int, spacing: float = 0.5) -> np.ndarray:
    """Noise-free 1 ms early-minus-late errors [chips] of ``n_ms`` consecutive periods.

    The replica equals the signal (zero tracking error); the code starts at
    ``start_chips`` at sample 0 and its phase moves ``drift_cps`` chips/s beyond the
    nominal chip rate.
    """
    code = b3i_code(prn).astype(np.float64)
    rate = CHIP_RATE + drift_cps
    out = np.empty(n_ms)
    n = int(round(fs * 1e-3))
    for m in range(n_ms):
        k0 = int(np.ceil(m * CODE_LENGTH / rate * fs))      # first sample of period m
        t = (k0 + np.arange(n)) / fs
        ph = start_chips + t * rate
        s = code[np.floor(ph).astype(np.int64) % CODE_LENGTH]
        e = code[np.floor(ph + spacing).astype(np.int64) % CODE_LENGTH] @ s
        late = code[np.floor(ph - spacing).astype(np.int64) % CODE_LENGTH] @ s
        out[m] = dll_nelp(abs(e), abs(late), spacing)
    return out


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fs", type=float, nargs="+", default=[2.5e6, 2.5003e6, 4e6, 5e6])
    ap.add_argument("--prn", type=int, nargs="+", default=[5, 27, 32])
    ap.add_argument("--drift", type=float, default=0.25, help="GEO-like drift [chips/s]")
    ap.add_argument("--interval", type=int, default=200, help="averaging interval [ms]")
    ap.add_argument("--starts", type=int, default=40, help="alignments drawn per row")
    args = ap.parse_args(argv)
    rng = np.random.default_rng(1)
    print(f"{'fs [MHz]':>9} {'PRN':>4} {'1 ms sd [m]':>12} "
          f"{args.interval} ms mean sd [m]: {'GEO-like':>9} {'MEO-like':>9}")
    for fs in args.fs:
        for prn in args.prn:
            starts = rng.uniform(0.0, CODE_LENGTH, args.starts)
            one = [discriminator_errors(prn, fs, s0, args.drift, 1)[0] for s0 in starts]
            geo = [discriminator_errors(prn, fs, s0, args.drift, args.interval).mean()
                   for s0 in starts]
            meo = [discriminator_errors(prn, fs, s0, 16.0, args.interval).mean()
                   for s0 in starts]
            print(f"{fs / 1e6:9.4f} C{prn:02d} {np.std(one) * CHIP_M:12.3f} "
                  f"{'':>22}{np.std(geo) * CHIP_M:9.3f} {np.std(meo) * CHIP_M:9.3f}")


if __name__ == "__main__":
    main()
