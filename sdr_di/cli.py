"""Command-line interface: ``sdr-di <command> ...``.

Every :class:`~sdr_di.errors.SdrDiError` is printed as one line ``sdr-di: error: ...`` on
stderr with exit status 2; nothing half-written is left under a final name.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .errors import SdrDiError


def _prn_list(text: str) -> list[str]:
    return [p for p in text.replace(" ", "").split(",") if p]


def _add_generate(sub) -> None:
    p = sub.add_parser(
        "generate",
        help="generate a B3I IF file with IMU data and truth from a scenario",
        description="Generate BeiDou B3I IF samples, 200 Hz IMU data, truth and a metadata "
        "sidecar from a scenario (default: the shipped paper-004 scenario).",
    )
    p.add_argument("--scenario", type=Path, default=None,
                   help="scenario TOML file (default: signals/default.toml)")
    p.add_argument("--out", type=Path, default=None,
                   help="output directory (default: signals/out)")
    p.add_argument("--name", default=None, help="base name of the output files "
                   "(default: the scenario name)")
    p.add_argument("--duration", type=float, default=None, metavar="S",
                   help="override the duration [s]")
    p.add_argument("--seed", type=int, default=None, help="override the random seed")
    p.add_argument("--fs", type=float, default=None, metavar="HZ",
                   help="override the sampling rate [Hz]")
    p.add_argument("--if", dest="if_hz", type=float, default=None, metavar="HZ",
                   help="override the intermediate frequency [Hz]")
    p.add_argument("--format", dest="sample_format", default=None,
                   help="override the sample format (iq_int8, real_int8, iq_int16, "
                   "real_int16, iq_int4)")
    p.add_argument("--bits", type=int, default=None, help="override the quantization bits")
    p.add_argument("--cn0", type=float, default=None, metavar="DBHZ",
                   help="override the C/N0 of every satellite [dB-Hz]")
    p.add_argument("--ephemeris", type=Path, default=None,
                   help="override the RINEX 3 navigation file")
    p.add_argument("--prn", type=_prn_list, default=None, metavar="LIST",
                   help="comma-separated PRNs instead of automatic selection (e.g. C21,C22)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_generate)


def _cmd_generate(args: argparse.Namespace) -> int:
    from .scenario import DEFAULT_SCENARIO, REPO_ROOT, load_scenario
    from .sim.generate import generate_files

    sc = load_scenario(args.scenario or DEFAULT_SCENARIO)
    kind = None
    if args.sample_format is not None:
        from .io.sample_formats import get_format

        fmt = get_format(args.sample_format)
        kind = "complex" if fmt.is_complex else "real"
        args.sample_format = fmt.name
    sc = sc.with_overrides(
        duration_s=args.duration, seed=args.seed, sampling_rate_hz=args.fs,
        if_hz=args.if_hz, sample_format=args.sample_format, kind=kind,
        quantization_bits=args.bits, cn0_dbhz=args.cn0, ephemeris=args.ephemeris,
        prns=args.prn,
    )
    out = args.out or (REPO_ROOT / "signals" / "out")
    files = generate_files(sc, out, name=args.name, progress=not args.no_progress)
    for label, path in files.items():
        print(f"{label:9s} {path}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The ``sdr-di`` argument parser."""
    from . import __version__

    parser = argparse.ArgumentParser(
        prog="sdr-di",
        description="BeiDou B3I / INS deeply integrated software-receiver simulator.",
    )
    parser.add_argument("--version", action="version", version=f"sdr-di {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    _add_generate(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``sdr-di`` console script; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except SdrDiError as exc:
        print(f"sdr-di: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("sdr-di: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
