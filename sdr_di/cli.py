"""Command-line interface: ``sdr-di <command> ...``.

Every :class:`~sdr_di.errors.SdrDiError` is printed as one line ``sdr-di: error: ...`` on
stderr with exit status 2; nothing half-written is left under a final name.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path
from typing import NoReturn

from .errors import OptionsError, SdrDiError

#: ``coupling.config.DEEP_MEASUREMENTS`` without importing the coupling package at
#: start-up (a scalar run does not need it); tests/test_deep_measurements.py keeps them equal
_DEEP_MEASUREMENTS = ("prefilter", "reset", "discriminator")


class UsageError(OptionsError):
    """Command-line arguments argparse refuses (one-line message, exit 2); options that do not
    fit together are the options objects' :class:`~sdr_di.errors.OptionsError`."""


class _ArgumentParser(argparse.ArgumentParser):
    """argparse with its errors in the CLI's one-line form (``sdr-di: error: ...``, exit 2).

    argparse prints the usage and ``PROG: error: ...`` itself; here the error is raised as a
    :class:`UsageError` naming the sub-command and pointing at its ``--help``, and printed by
    :func:`main` like every other bad input. Sub-parsers inherit the class.
    """

    def error(self, message: str):
        sub = self.prog.split(" ", 1)[1] if " " in self.prog else ""
        where = f"{sub}: " if sub else ""
        raise UsageError(f"{where}{message} (see {self.prog} --help)")


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
                   help="override the RINEX 3 or 4 navigation file")
    p.add_argument("--prn", type=_prn_list, default=None, metavar="LIST",
                   help="comma-separated PRNs instead of automatic selection (e.g. C21,C22)")
    p.add_argument("--sigmf", action="store_true",
                   help="also write the SigMF pair NAME.sigmf-meta and NAME.sigmf-data (the "
                   "IF samples, hard-linked to NAME.bin)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_generate)


#: ``generate``'s flags by the option they set (messages name the flag).
GENERATE_FLAGS = {"duration_s": "--duration", "seed": "--seed", "sampling_rate_hz": "--fs",
                  "if_hz": "--if", "sample_format": "--format", "bits": "--bits",
                  "cn0_dbhz": "--cn0", "ephemeris": "--ephemeris", "prns": "--prn"}


def _cmd_generate(args: argparse.Namespace) -> int:
    from .api import generate_with
    from .options import GenerateOptions

    files = generate_with(GenerateOptions(
        out=args.out, scenario=args.scenario, name=args.name, duration_s=args.duration,
        seed=args.seed, sampling_rate_hz=args.fs, if_hz=args.if_hz,
        sample_format=args.sample_format, bits=args.bits, cn0_dbhz=args.cn0,
        ephemeris=args.ephemeris, prns=args.prn, progress=not args.no_progress,
        sigmf=args.sigmf, names=GENERATE_FLAGS))
    for label, path in files.files.items():
        print(f"{label:9s} {path}")
    return 0


def _add_file_options(p) -> None:
    """Options that describe an IF file sdr-di did not write (``run`` and ``acquire``)."""
    p.add_argument("--fs", type=float, default=None, metavar="HZ",
                   help="foreign file: sampling rate [Hz]")
    p.add_argument("--if", dest="if_hz", type=float, default=None, metavar="HZ",
                   help="foreign file: intermediate frequency [Hz] (default 0)")
    p.add_argument("--format", dest="sample_format", default=None,
                   help="foreign file: sample format (iq_int8/ibyte, real_int8, iq_int16, "
                   "real_int16, iq_int4, gr_complex, and peers' formats: docs/formats.md). "
                   "A file with a PocketSDR/SignalSim tag (X.bin.tag) or a SigMF recording "
                   "needs no options; these override the tag's or SigMF's values")
    p.add_argument("--rfch", type=int, default=None, metavar="N",
                   help="RF channel (1-based) of a multi-channel PocketSDR RAW file (default: "
                   "the channel whose tagged LO is nearest B3I)")
    p.add_argument("--inverted", action="store_true",
                   help="foreign file: spectrum inverted")
    p.add_argument("--start-week", type=int, default=None, help="foreign file: BDT week hint")
    p.add_argument("--start-sow", type=float, default=None,
                   help="foreign file: BDT seconds of week of sample 0 (hint)")
    p.add_argument("--ignore-sidecar", action="store_true",
                   help="read the file with --fs/--if/--format alone, even where a sidecar "
                   "(X.json) beside it says otherwise (without this, options that contradict "
                   "the sidecar are an error)")
    p.add_argument("--no-format-check", action="store_true",
                   help="read the file even where its bytes do not look like the declared "
                   "sample format")


#: The flags of the options that describe an IF file (``run`` and ``acquire``), by the
#: option they set (:class:`~sdr_di.options.IfFileOptions`).
FILE_FLAGS = {"sampling_rate_hz": "--fs", "if_hz": "--if", "sample_format": "--format",
              "rfch": "--rfch", "inverted": "--inverted", "start_week": "--start-week",
              "start_sow": "--start-sow", "ignore_sidecar": "--ignore-sidecar",
              "check_format": "--no-format-check"}


def _file_options(args: argparse.Namespace) -> dict:
    """The :class:`~sdr_di.options.IfFileOptions` fields of ``run`` and ``acquire``."""
    return dict(if_file=args.if_file, sampling_rate_hz=args.fs, if_hz=args.if_hz,
                sample_format=args.sample_format, rfch=args.rfch, inverted=args.inverted,
                start_week=args.start_week, start_sow=args.start_sow,
                ignore_sidecar=args.ignore_sidecar, check_format=not args.no_format_check)


def _add_acquire(sub) -> None:
    p = sub.add_parser(
        "acquire",
        help="search the satellites at the start of an IF file (table and CSV)",
        description="One acquisition search (DC removal, blanking of narrowband lines, FFT "
        "code-phase search over a Doppler grid) at the start of an IF file; prints a table "
        "and writes STEM_acquisition.csv with one row per searched PRN. Works on any file "
        "of at least one code period (1 ms) and says which sensitivity it gives.",
    )
    p.add_argument("if_file", type=Path,
                   help="IF samples (or its .json sidecar, or a SigMF X.sigmf-meta/-data)")
    p.add_argument("--prn", type=_prn_list, default=None, metavar="LIST",
                   help="comma-separated PRNs to search (default all 63)")
    p.add_argument("--coherent-ms", type=int, default=1, metavar="MS",
                   help="coherent integration per block [ms] (default 1: safe with NH and "
                   "data bit transitions)")
    p.add_argument("--noncoherent", type=int, default=40, metavar="K",
                   help="blocks summed non-coherently (default 40; reduced to what the file "
                   "holds; about 400 for 30 dB-Hz)")
    p.add_argument("--doppler-center", type=float, default=0.0, metavar="HZ",
                   help="centre of the Doppler search [Hz] (default 0)")
    p.add_argument("--doppler-range", type=float, default=5000.0, metavar="HZ",
                   help="half-width of the Doppler search [Hz] (default 5000: B3 MEO Doppler "
                   "is within +-3.6 kHz, the rest is about 1 ppm of oscillator offset)")
    p.add_argument("--pfa", type=float, default=1e-3,
                   help="false-alarm probability per PRN search (default 1e-3)")
    p.add_argument("--out", type=Path, default=None,
                   help="output directory (default: beside the IF file, in <stem>_acq/)")
    _add_file_options(p)
    p.set_defaults(func=_cmd_acquire)


def _cmd_acquire(args: argparse.Namespace) -> int:
    import math

    from .constants import parse_prns
    from .io.atomic import check_output_dir, output_dir_removed_on_failure
    from .receiver.acquisition import (
        LIKELY_CAUSES,
        AcquisitionWarning,
        check_search,
        implausible_detections,
    )
    from .receiver.run_acquire import run_acquisition

    check_search(args.coherent_ms, args.noncoherent, args.doppler_range, args.pfa)
    if not math.isfinite(args.doppler_center):
        raise UsageError(f"--doppler-center must be finite, got {args.doppler_center}")
    from .options import IfFileOptions

    prns = None if args.prn is None else parse_prns(args.prn)
    source = IfFileOptions(**_file_options(args), names=FILE_FLAGS).open_source()
    out = check_output_dir(args.out or args.if_file.with_name(args.if_file.stem + "_acq"))
    with output_dir_removed_on_failure(out):
        rep = run_acquisition(source, out, prns=prns, coherent_ms=args.coherent_ms,
                              noncoherent=args.noncoherent,
                              doppler_center_hz=args.doppler_center,
                              doppler_range_hz=args.doppler_range, pfa=args.pfa)
    lo, hi, step = rep.doppler_bins_hz
    short = "" if rep.noncoherent == rep.requested_noncoherent else \
        f" (the file holds {rep.file_s * 1e3:.1f} ms: {rep.requested_noncoherent} asked)"
    print(f"search: {rep.noncoherent} x {rep.coherent_ms} ms non-coherent{short}; Doppler "
          f"{lo:+.0f}..{hi:+.0f} Hz in {step:g} Hz steps; pfa {args.pfa:g} per PRN")
    print(f"sensitivity: detection probability 0.9 at {rep.cn0_pd90_dbhz:.1f} dB-Hz without "
          "losses (add about 1-3 dB for bin straddle and bit transitions)")
    if rep.lines_hz.size:
        shown = ", ".join(f"{f:+.0f}" for f in rep.lines_hz[:8])
        more = f" and {rep.lines_hz.size - 8} more" if rep.lines_hz.size > 8 else ""
        print(f"input: {rep.lines_hz.size} narrowband line(s) blanked at {shown}{more} Hz")
    rows = [r for r in rep.results if r.detected or len(rep.results) <= 16]
    print("PRN  detected  Doppler [Hz]  code phase [chips]  C/N0 [dB-Hz]  metric  threshold"
          "  notes")
    for r in rows:
        cn0 = f"{r.cn0_dbhz:12.1f}" if r.detected and math.isfinite(r.cn0_dbhz) else " " * 12
        print(f"C{r.prn:02d}  {'yes' if r.detected else 'no':8s}  {r.doppler_hz:12.1f}  "
              f"{r.code_phase_chips:18.3f}  {cn0}  {r.peak_metric:6.1f}  {r.threshold:9.1f}"
              f"  {'; '.join(r.notes)}")
    problem, _ = implausible_detections(rep.results)
    if problem is not None:
        import warnings

        warnings.warn(f"{source.path}: {problem}: not satellites; likely causes, most likely "
                      f"first: {LIKELY_CAUSES}", AcquisitionWarning, stacklevel=1)
    n_det = sum(r.detected for r in rep.results)
    print(f"{n_det} of {len(rep.results)} PRNs detected"
          + ("" if len(rows) == len(rep.results) else " (every PRN in the CSV)"))
    print(f"table     {rep.csv_path}")
    return 0


def _approx_pos(text: str) -> tuple[float, float, float]:
    parts = text.replace(" ", "").split(",")
    try:
        lat, lon, h = (float(v) for v in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected LAT,LON,H (degrees, degrees, metres), got {text!r}") from None
    from .options import check_approx_pos

    problem = check_approx_pos(lat, lon, h)
    if problem is not None:
        raise argparse.ArgumentTypeError(f"{problem}: {text!r}")
    return lat, lon, h


def _add_run(sub) -> None:
    p = sub.add_parser(
        "run",
        help="run the receiver on a recorded IF file",
        description="Acquire, track and decode the B3I signals of an IF file and write the "
        "navigation solution (CSV and NMEA). The file is described by its sidecar (X.json "
        "beside X.bin), a SigMF recording (X.sigmf-meta) or, for a file sdr-di did not "
        "write, by --fs/--if/--format.",
    )
    p.add_argument("if_file", type=Path,
                   help="IF samples (or its .json sidecar, or a SigMF X.sigmf-meta/-data)")
    p.add_argument("--mode", choices=("scalar", "deep", "loose", "tight"), default="scalar",
                   help="receiver architecture: scalar tracking loops; deep (INS-aided "
                   "vector tracking: scalar start-up, then every NCO commanded from the "
                   "INS corrected by the integration filter); loose or tight (the scalar "
                   "receiver's WLS fixes, or its pseudoranges and rates, into the "
                   "integration filter; docs/coupling.md)")
    p.add_argument("--prn", type=_prn_list, default=None, metavar="LIST",
                   help="comma-separated PRNs to search (default all 63)")
    p.add_argument("--out", type=Path, default=None,
                   help="output directory (default: beside the IF file, in <stem>_run/)")
    p.add_argument("--rate", type=float, default=5.0, metavar="HZ",
                   help="solution output rate [Hz] (default 5)")
    p.add_argument("--cold", action="store_true",
                   help="cold start (every mode): ignore the sidecar's satellite list and "
                   "Dopplers, search --prn (default all 63) over +-5 kHz")
    p.add_argument("--pll-bw", type=float, default=None, metavar="HZ",
                   help="noise bandwidth of the tracking PLL once locked (default 15 Hz; at "
                   "most 25 Hz with the 10 ms D1 coherent time): widen it for a poor "
                   "oscillator (docs/assumptions.md); any mode (deep's start-up)")
    p.add_argument("--approx-pos", type=_approx_pos, default=None, metavar="LAT,LON,H",
                   help="scalar mode, with --ephemeris and the file's start time: search the "
                   "satellites visible from this approximate position [deg, deg, m] around "
                   "their predicted Doppler (a cold start with assistance data)")
    _add_file_options(p)
    g = p.add_argument_group("deep, loose and tight modes")
    g.add_argument("--filter", default=None, metavar="NAME[:OPT=VALUE...]",
                   help="integration filter and its options (default ekf, chosen by a paired "
                   "study: docs/filters.md; any of ekf, ukf, ckf, ff-aukf, rae-aukf, "
                   "ml-q-ukf, sage-husa-ukf, q-scaling-ekf, q-scaling-ukf, ml-r-ckf, a "
                   "plugin name, or an import path "
                   "package.module:Name; e.g. ff-aukf:q_states=nominal; sdr-di filters "
                   "lists the options)")
    g.add_argument("--imu", type=Path, default=None,
                   help="IMU file (default: the sidecar's imu_file)")
    g.add_argument("--truth", type=Path, default=None,
                   help="reference file for --align truth and the error columns; any mode: "
                   "the errors printed (default: the sidecar's truth_file)")
    g.add_argument("--ephemeris", type=Path, default=None,
                   help="RINEX navigation file used as assistance data, any mode (default: "
                   "the sidecar's ephemeris_file)")
    g.add_argument("--no-assist", action="store_true",
                   help="use decoded ephemerides and ionosphere only (any mode)")
    g.add_argument("--filter-rate", type=float, default=None, metavar="HZ",
                   help="integration filter / NCO command rate [Hz] (default 50)")
    g.add_argument("--align", choices=("truth", "gnss"), default=None,
                   help="INS initial alignment: from the reference at the IMU start "
                   "(default) or from the GNSS fix at the hand-over")
    g.add_argument("--duration", type=float, default=None, metavar="S",
                   help="process only the first S seconds (any mode)")
    g.add_argument("--gnss-rate", type=float, default=None, metavar="HZ",
                   help="loose and tight: GNSS measurement rate [Hz], 10 divided by a whole "
                   "number (default 5)")
    g.add_argument("--iono-wait", type=float, default=None, metavar="S",
                   help="seconds after the first fix the hand-over waits for ionosphere "
                   "coefficients (assistance file or decoded subframe 1) before it goes "
                   "without them, with a warning (default 0: hand over at once and take the "
                   "model up when subframe 1 is decoded, the rows before it flagged in the "
                   "solution's iono column; 30: one D1 frame)")
    g.add_argument("--nco-latency", type=int, choices=(0, 1), default=None,
                   help="deep: filter intervals between an update and the NCO commands that "
                   "first use it, beyond the next (default 0; 1: the next interval is "
                   "correlated while the filter updates, on a second core: docs/deep.md)")
    g.add_argument("--deep-measurements", choices=_DEEP_MEASUREMENTS, default=None,
                   help="deep: what each channel hands the integration filter: 'prefilter' "
                   "(default, paper 004's cascaded pre-filters), 'reset' (pre-filters "
                   "whose output is only what they measured since the last fusion, "
                   "restarted after each, --fusion-rate) or "
                   "'discriminator' (the interval's discriminator outputs; docs/deep.md)")
    g.add_argument("--fusion-rate", type=float, default=None, metavar="HZ",
                   help="deep, --deep-measurements reset: rate of the filter's updates with "
                   "the pre-filters' outputs, each followed by their information reset; the "
                   "filter rate divided by a whole number (default 5; docs/deep.md)")
    g.add_argument("--assume", type=Path, default=None, metavar="FILE.toml",
                   help="what the integration filter believes: IMU spec, oscillator, R, P0, "
                   "initial errors (docs/assumptions.md)")
    p.add_argument("--plots", action="store_true",
                   help="also write the run's figures as PNG beside its files (errors per axis "
                   "with the filter's 3-sigma, NIS, trajectory, C/N0 and lock per channel, "
                   "sky, ...); 'sdr-di report OUT' draws the same ones when missing and "
                   "writes OUT/report.html")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_run)


#: ``run``'s flags by the option they set (:class:`~sdr_di.options.RunOptions`; messages name
#: the flag).
RUN_FLAGS = {"mode": "--mode", "out": "--out", "prns": "--prn", "rate_hz": "--rate",
             "cold": "--cold", "pll_bw_hz": "--pll-bw", "approx_pos": "--approx-pos",
             "filter": "--filter", "imu": "--imu", "truth": "--truth",
             "ephemeris": "--ephemeris", "assist": "--no-assist",
             "filter_rate_hz": "--filter-rate", "align": "--align", "duration_s": "--duration",
             "gnss_rate_hz": "--gnss-rate", "iono_wait_s": "--iono-wait",
             "assume": "--assume", "nco_latency": "--nco-latency",
             "deep_measurements": "--deep-measurements", "fusion_rate_hz": "--fusion-rate",
             **FILE_FLAGS}


def run_options(args: argparse.Namespace):
    """``run``'s arguments as :class:`~sdr_di.options.RunOptions` (messages name the flags)."""
    from .options import RunOptions

    return RunOptions(
        mode=args.mode, out=args.out, prns=args.prn, rate_hz=args.rate, cold=args.cold,
        pll_bw_hz=args.pll_bw, approx_pos=args.approx_pos, filter=args.filter, imu=args.imu,
        truth=args.truth, ephemeris=args.ephemeris, assist=not args.no_assist,
        filter_rate_hz=args.filter_rate, align=args.align, duration_s=args.duration,
        gnss_rate_hz=args.gnss_rate, iono_wait_s=args.iono_wait, assume=args.assume,
        nco_latency=args.nco_latency, deep_measurements=args.deep_measurements,
        fusion_rate_hz=args.fusion_rate, progress=not args.no_progress, **_file_options(args),
        names=RUN_FLAGS)


def _cmd_run(args: argparse.Namespace) -> int:
    from .api import run_with

    opts = run_options(args)
    res = run_with(opts)
    if res.mode == "scalar":
        _print_scalar(res, opts, args.plots)
    else:
        _print_integrated(res, args.plots)
    for label, path in res.files.items():
        print(f"{label:9s} {path}")
    if res.mode == "scalar" and res.metrics["n_fixes"] == 0:
        from .errors import RunFailed

        raise RunFailed(_no_fix_diagnosis(opts, res))
    return 0


def _print_scalar(res, opts, plots: bool) -> None:
    """A scalar run's report: speed, fixes, assistance, channels, plots, errors vs the
    reference."""
    d, m = res.details, res.metrics
    rt = d.processed_s / max(d.wall_s, 1e-9)
    nav = res.inputs.get("ephemeris")
    print(f"processed {d.processed_s:.1f} s in {d.wall_s:.1f} s (x{rt:.2f} real time); "
          f"{d.n_fixes}/{d.n_epochs} epochs with a fix"
          + (f", the first at {d.first_fix_s:.1f} s" if d.n_fixes else "")
          + ("" if nav is None else "; assistance: the sidecar's navigation file"
             if opts.ephemeris is None else f"; assistance: {opts.ephemeris}"))
    for row in d.channels:
        print(f"  C{row['prn']:02d} {row['state']:8s} C/N0 {row['cn0_dbhz']} dB-Hz  "
              f"ephemeris {'decoded' if row['ephemeris_decoded'] else 'not decoded'}")
    if plots:
        _print_plots(_run_plots(res))
    if m.get("n"):
        print(f"errors vs reference ({m['n']} fixes from {m['first_fix_s']:.1f} s): "
              f"velocity {m['vel_mps_rmse']:.4f} m/s (max {m['vel_mps_max']:.4f}), "
              f"position {m['pos_m_rmse']:.3f} m (max {m['pos_m_max']:.3f})")


def _print_integrated(res, plots: bool) -> None:
    """A deep, loose or tight run's report: speed, hand-over, loop time, errors vs the
    reference, plots."""
    r, prof, m = res.details.result, res.details.result.profile, res.details.metrics
    print(f"processed {prof['processed_s']:.1f} s in {res.wall_s:.1f} s "
          f"(x{prof['processed_s'] / max(res.wall_s, 1e-9):.2f} real time); hand-over to the "
          f"{'vector' if r.mode == 'deep' else r.mode} loop at {r.handover_s:.2f} s with "
          f"{', '.join(f'C{p:02d}' for p in r.prns)}")
    loop = max(prof["loop"], 1e-9)
    if r.mode == "deep":
        print("vector loop time: " + ", ".join(
            f"{k} {100 * prof[k] / loop:.0f}%" for k in ("correlate", "prefilter", "filter",
                                                        "ins", "nco", "read")))
    else:
        print(f"scalar receiver {prof['scalar']:.1f} s; {r.mode} loop {prof['loop']:.1f} s: "
              + ", ".join(f"{k} {100 * prof[k] / loop:.0f}%" for k in ("measure", "filter",
                                                                     "ins")))
    if m["n"] and m["pos_m_rmse"] == m["pos_m_rmse"]:
        print(f"errors vs reference ({m['n']} epochs after the hand-over): attitude RMSE "
              f"{m['att_deg_rmse']:.4f} deg (max {m['att_deg_max']:.4f}), velocity "
              f"{m['vel_mps_rmse']:.4f} m/s (max {m['vel_mps_max']:.4f}), position "
              f"{m['pos_m_rmse']:.3f} m (max {m['pos_m_max']:.3f})")
        mi = res.details.metrics_after_iono
        if mi is not None and mi["n"]:
            print(f"  after the ionosphere take-up at {res.details.iono_from_s:.1f} s "
                  f"({mi['n']} epochs; the rows before it have iono = 0): velocity "
                  f"{mi['vel_mps_rmse']:.4f} m/s, position {mi['pos_m_rmse']:.3f} m "
                  f"(max {mi['pos_m_max']:.3f})")
    else:  # null metrics say why (issue 49 item 7)
        print(f"errors vs reference: none ({res.details.metrics_note})")
    if plots:
        _print_plots(_run_plots(res))


def _no_fix_diagnosis(opts, res) -> str:
    """One line for a run that ended without a single fix: what it got, and the likely
    causes in the order the run's evidence gives (:mod:`sdr_di.receiver.diagnosis`)."""
    import warnings

    from .receiver.diagnosis import no_fix_diagnosis

    with warnings.catch_warnings():     # read again: its warnings were shown at the start
        warnings.simplefilter("ignore")
        source = opts.open_source()
    return no_fix_diagnosis(source, res.details, given=opts.sampling_rate_hz is not None
                            or opts.sample_format is not None)


def _run_plots(res):
    """``run --plots``: the report's figures of this run, drawn from the files it wrote
    (:func:`sdr_di.report.write_run_plots`); the paths, or a warning's text."""
    from .report import write_run_plots

    if res.mode == "scalar":
        pvt = res.files["pvt"]
        return write_run_plots(pvt.parent, pvt.name.removesuffix("_pvt.csv"))
    sol = res.files["solution"]
    return write_run_plots(sol.parent, sol.stem)


def _print_plots(out) -> None:
    if isinstance(out, str):
        print(f"sdr-di: warning: {out}", file=sys.stderr)
        return
    for p in out:
        print(f"plot      {p}")


def _probe_filter(name: str, options: dict, dt: float) -> None:
    """Build the integration filter once on the models of its ``error_states`` layout
    (FilterError: one line)."""
    import numpy as np

    from .filters import make_filter
    from .filters.state import layout_of_options
    from .ins.error_model import InsErrorModel
    from .coupling.measurements import RangeRateMeasurementModel

    layout = layout_of_options(options)
    n = layout.n
    make_filter(name, InsErrorModel(layout=layout), RangeRateMeasurementModel(n_states=n),
                np.zeros(n), np.eye(n), np.eye(n), None, dt=dt, **options)


def _add_lc(sub) -> None:
    """``sdr-di lc``: closed-loop loosely coupled INS/GNSS run (:mod:`sdr_di.integration`)."""
    p = sub.add_parser(
        "lc", help="loosely coupled INS/GNSS run with a chosen filter",
        description="Closed-loop loosely coupled INS/GNSS run: INS from the scenario's (or "
        "a file's) IMU data, simulated 1 Hz GNSS position/velocity, 17-state nonlinear error "
        "filter; prints RMSE/max of attitude, velocity and position and writes the error "
        "time series as CSV.")
    p.add_argument("--scenario", type=Path, default=None,
                   help="scenario TOML with an optional [lc] table (default: "
                   "signals/default.toml)")
    p.add_argument("--filter", default=None, metavar="NAME[:OPT=VALUE...]",
                   help="filter and its options (sdr-di filters lists them): ekf, ukf, ckf, "
                   "ff-aukf, rae-aukf, ml-q-ukf, sage-husa-ukf, q-scaling-ekf, q-scaling-ukf, "
                   "ml-r-ckf, a plugin name, or an import path package.module:Name")
    p.add_argument("--duration", type=float, default=None, metavar="S", help="run length [s]")
    p.add_argument("--out", type=Path, default=None,
                   help="output directory of the error CSV (default: signals/out)")
    p.add_argument("--q-scale", type=float, default=None, metavar="X",
                   help="filter Q = X * model Q (wrong Q: X != 1)")
    p.add_argument("--r-scale", type=float, default=None, metavar="X",
                   help="filter R = X * nominal GNSS variances")
    p.add_argument("--r-window", type=float, nargs=3, action="append", default=None,
                   metavar=("T0", "T1", "FACTOR"), help="true GNSS noise variance times "
                   "FACTOR for T0 <= t <= T1 (repeatable; replaces the scenario's windows)")
    p.add_argument("--seed", type=int, default=None, help="override the scenario seed")
    p.add_argument("--imu", type=Path, default=None,
                   help="IMU file (sdr-di imu CSV) instead of simulating; needs --truth")
    p.add_argument("--truth", type=Path, default=None, help="truth file for --imu")
    p.add_argument("--assume", type=Path, default=None, metavar="FILE.toml",
                   help="what the filter believes (IMU spec, R, P0, initial errors; "
                   "docs/assumptions.md); replaces the scenario's [assume] table")
    p.set_defaults(func=_cmd_lc)


def _cmd_lc(args: argparse.Namespace) -> int:
    import dataclasses
    import json

    from .errors import ImuDataError, ScenarioError
    from .filters import parse_filter_spec
    from .ins.imu import ImuErrorModel
    from .integration.assumptions import apply_to_lc, resolve_assumptions
    from .integration.loose import (
        check_lc_duration,
        lc_summary,
        load_lc_scenario,
        min_lc_duration_s,
        run_loose,
    )
    from .integration.noise import NoiseWindow
    from .io.atomic import (
        atomic_open,
        check_output_dir,
        ensure_output_dir,
        output_dir_removed_on_failure,
    )
    from .scenario import DEFAULT_SCENARIO, REPO_ROOT
    from .sim.lc_inputs import make_inputs

    sc, st = load_lc_scenario(args.scenario or DEFAULT_SCENARIO)
    assumed = resolve_assumptions(sc, args.assume)  # checked before any work
    filter_imu = None
    if assumed is not None:
        st, filter_imu = apply_to_lc(st, assumed)
    spec = parse_filter_spec(args.filter or st.filter)  # typed options; FilterError: exit 2
    name = spec.name
    kw = {"filter": name}
    if spec.options:
        kw["filter_options"] = {**st.filter_options, **spec.options}
    # a plugin's interface, before the output folder is made
    _probe_filter(name, {**st.options_by_filter.get(name, {}),
                         **kw.get("filter_options", st.filter_options)}, 1.0)
    for opt, key in ((args.q_scale, "q_scale"), (args.r_scale, "r_scale")):
        if opt is not None:
            if not opt > 0:
                raise ScenarioError(f"--{key.replace('_', '-')} must be > 0, got {opt:g}")
            kw[key] = float(opt)
    if args.r_window is not None:
        try:
            wins = tuple(NoiseWindow(*w) for w in args.r_window)
        except ValueError as exc:
            raise ScenarioError(f"--r-window: {exc}") from None
        kw["noise"] = dataclasses.replace(st.noise, windows=wins)
    st = st.replace(**kw)
    out = check_output_dir(args.out or (REPO_ROOT / "signals" / "out"))
    shortest = min_lc_duration_s(st)
    if args.duration is not None:
        check_lc_duration(args.duration, st, "--duration")
    if args.seed is not None and args.seed < 0:
        raise ScenarioError(f"--seed must be >= 0, got {args.seed}")
    seed = sc.seed if args.seed is None else args.seed
    if args.imu is not None or args.truth is not None:
        if args.imu is None or args.truth is None:
            raise ImuDataError("--imu and --truth must be given together")
        from .io.imu_files import read_imu, read_truth

        imu = read_imu(args.imu)
        truth, _, _ = read_truth(args.truth)
        model = ImuErrorModel.from_spec(sc.imu)
        span = float(imu.t[-1] - imu.t[0])
        if span < shortest:
            raise ImuDataError(f"IMU file {args.imu}: spans {span:g} s, shorter than one GNSS "
                               f"interval ({shortest:g} s): no filter update, no result")
    else:
        if args.duration is not None:
            sc = sc.with_overrides(duration_s=args.duration)
        if args.seed is not None:
            sc = sc.with_overrides(seed=args.seed)
        if sc.duration_s < shortest:
            raise ScenarioError(f"{sc.source}: duration {sc.duration_s:g} s is shorter than one "
                                f"GNSS interval ({shortest:g} s): no filter update, no result")
        check_lc_duration(sc.duration_s, st, f"{sc.source}: duration_s")
        truth, imu, model = make_inputs(sc, st)
    from .paths import check_outputs, file_safe

    stem = file_safe(name)  # an import path's ':' out of file names
    csv, summary = out / f"{sc.name}_lc_{stem}.csv", out / f"{sc.name}_lc_{stem}_summary.json"
    check_outputs([csv, summary])
    model = filter_imu or model  # the filter's IMU spec: assumed, else the truth's
    with output_dir_removed_on_failure(out):  # a failed run leaves no empty folder
        ensure_output_dir(out)  # created only now that every input is checked
        res = run_loose(truth, imu, model, st, seed=seed, duration_s=args.duration)
        csv = res.write_csv(csv)
        with atomic_open(summary, "w") as fh:
            json.dump(lc_summary(sc, st, model, assumed, res, seed=seed), fh, indent=2)
            fh.write("\n")
    head = (f"{'filter':14s} {'span_s':>11s} {'att_rmse_deg':>12s} {'att_max_deg':>11s} "
            f"{'vel_rmse':>9s} {'vel_max':>8s} {'pos_rmse_m':>10s} {'pos_max_m':>9s}")
    print(head)
    spans = [(None, None)] + [(w.t0, w.t1) for w in st.noise.windows]
    for t0, t1 in spans:
        m = res.metrics(t0, t1)
        span = "all" if t0 is None else f"{t0:g}-{t1:g}"
        print(f"{name:14s} {span:>11s} {m['att_deg_rmse']:12.4f} {m['att_deg_max']:11.4f} "
              f"{m['vel_mps_rmse']:9.4f} {m['vel_mps_max']:8.4f} {m['pos_m_rmse']:10.3f} "
              f"{m['pos_m_max']:9.3f}")
    print(f"errors    {csv}")
    print(f"summary   {summary}")
    return 0


def _add_filters(sub) -> None:
    p = sub.add_parser(
        "filters", help="list the integration filters with their options",
        description="Every filter name (built-in, registered and installed plugins) with "
        "the paper equations behind it and its options (type, default); an entry is "
        "NAME[:OPT=VALUE...] wherever a filter is named (--filter, study specs).")
    p.set_defaults(func=_cmd_filters)


def _cmd_filters(args: argparse.Namespace) -> int:
    from .filters import filter_table

    for row in filter_table():
        core = row["core"] + (f" + {row['rule']}" if row["rule"] else "")
        print(f"{row['name']:14s} {core:28s} {row['equations']}")
        for o in row["options"]:
            print(f"    {o['name']:16s} {o['type']:22s} default {o['default']!r:14s} "
                  f"({o['target']})")
        if row["open"]:
            print("    (takes further options)")
    print("error_states (model, every filter): none (17 states), sf (+ gyro and accel scale "
          "factors, 23), gm (Gauss-Markov biases), sf+gm (docs/filters.md, Error states)")
    print("entry: NAME[:OPT=VALUE...]; an import path package.module:Name is a plugin "
          "(docs/filters.md)")
    return 0


def _add_study(sub) -> None:
    p = sub.add_parser(
        "study", help="cells x filters x seeds, paired on the same files, with statistics",
        description="Run a study spec (docs/studies.md): every cell's experiment with every "
        "filter on the same generated files per seed, on a local Dask cluster (or "
        "--scheduler), each (cell, seed) written as it finishes; then paired differences "
        "against the baseline filter with Holm-corrected intervals, the claims' verdicts, "
        "cells.csv, runs.csv and report.html. Re-running the same spec into the same folder "
        "resumes it.")
    p.add_argument("spec", type=Path, help="study TOML file (studies/*.toml)")
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="output folder")
    p.add_argument("--runs", type=int, default=None, metavar="N",
                   help="seeds per cell (default: the spec's runs)")
    p.add_argument("--scheduler", default=None, metavar="ADDR",
                   help="Dask scheduler address (tcp://host:8786); default: local processes")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="local worker processes (default: number of cores; 0: run in this "
                   "process, no cluster)")
    p.add_argument("--force", action="store_true",
                   help="replace a different study's runs in --out (runs of unchanged cells are "
                   "kept); run a study beyond 10,000 (cell, seed) runs")
    p.add_argument("--no-report", action="store_true", help="do not write report.html")
    p.set_defaults(func=_cmd_study)


#: ``study``'s flags by the option they set (:class:`~sdr_di.options.StudyOptions`).
STUDY_FLAGS = {"runs": "--runs", "workers": "--workers", "scheduler": "--scheduler",
               "force": "--force", "report": "--no-report"}


def _cmd_study(args: argparse.Namespace) -> int:
    """``sdr-di study``: :func:`sdr_di.api.study_with` with the parsed options."""
    import dataclasses

    import dask

    from .api import study_with
    from .options import StudyOptions
    from .studies.commands import WORKERS_IGNORE_SIGINT, StudyProgress
    from .studies.study import study_outputs

    opts = StudyOptions(spec=args.spec, out=args.out, runs=args.runs,
                        scheduler=args.scheduler, workers=args.workers, force=args.force,
                        report=not args.no_report, names=STUDY_FLAGS)
    spec = opts.load_spec()     # refused here in one line, before the bar
    opts = dataclasses.replace(opts, spec=spec)
    # the training runs of a tuned study come first and count on the same bar
    n_train = (sum(c.name in spec.tuning.cells for c in spec.cells) * spec.tuning.runs
               if spec.tuning is not None else 0)
    show = StudyProgress(len(spec.cells) * (args.runs or spec.runs) + n_train)
    preload = [*dask.config.get("distributed.worker.preload", []), WORKERS_IGNORE_SIGINT]
    with dask.config.set({"distributed.worker.preload": preload}), show:
        res = study_with(opts, on_record=show)
        if res.n_skipped:                       # the runs already in the folder
            show.bar.update(res.n_skipped)
    spec = res.spec
    print(f"study {spec.name} ({spec.hash}): {res.n_run} (cell, seed) runs done, "
          f"{res.n_skipped} already there; {len(res.failed)} filter runs failed or diverged; "
          f"{res.elapsed_s:.1f} s")
    for c in (res.tuning or {}).values():
        where = f" in {c.cell}" if c.cell else ""
        edge = f"; on the grid's edge: {', '.join(c.edge)}" if c.edge else ""
        print(f"tuned: {c.filter}{where} -> {c.entry} (training score {c.score:.4g}{edge})")
    for r in res.failed:
        print(f"  failed: {r['cell']} seed {r['seed_index']} {r['filter']}: {r['error']}",
              file=sys.stderr)
    for j, cl in enumerate(spec.claims, 1):
        verdicts = [f"{r['cell']}: {r[f'claim{j}']}" for r in res.cells if r[f"claim{j}"]]
        print(f"claim {j} ({cl.text}): {'; '.join(verdicts)}")
    for label, path in study_outputs(args.out).items():   # every file, named
        print(f"{label:11s} {path}")
    return 1 if res.failed else 0


def build_parser() -> argparse.ArgumentParser:
    """The ``sdr-di`` argument parser."""
    from . import __version__

    parser = _ArgumentParser(
        prog="sdr-di",
        description="BeiDou B3I / INS deeply integrated software-receiver simulator.",
    )
    parser.add_argument("--version", action="version", version=f"sdr-di {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    _add_generate(sub)
    _add_run(sub)
    _add_acquire(sub)
    _add_lc(sub)
    _add_filters(sub)
    from .studies.commands import add_parsers as add_experiment_parsers

    add_experiment_parsers(sub)
    sub.choices["report"].set_defaults(func=_cmd_report)
    _add_study(sub)
    return parser


def _cmd_report(args: argparse.Namespace) -> int:
    """``sdr-di report DIR``: a run's folder (``run``, ``lc``) to :mod:`sdr_di.report`, a
    campaign, robustness or study folder to :func:`sdr_di.studies.commands.cmd_report`."""
    from .report import is_run_folder, render_run_report
    from .studies.commands import cmd_report

    folder = Path(args.dir)
    if not any((folder / f).is_file() for f in ("campaign.json", "result.json", "study.json")) \
            and is_run_folder(folder):
        print(render_run_report(folder))
        return 0
    return cmd_report(args)


_NEGATIVE_NUMBER = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$")


def attach_negative_values(argv: list[str]) -> list[str]:
    """``--if -5.12e6`` -> ``--if=-5.12e6``.

    argparse takes a token that starts with ``-`` for an option unless it looks like a plain
    negative number without exponent (``-5``, ``-0.5``), so a negative IF or Doppler centre
    in engineering notation would be refused; attached with ``=`` it is a value. Only a
    negative number that follows a long option without ``=`` is attached.
    """
    out: list[str] = []
    for tok in argv:
        if (out and _NEGATIVE_NUMBER.match(tok) and out[-1].startswith("--")
                and "=" not in out[-1] and out[-1] != "--"):
            out[-1] = f"{out[-1]}={tok}"
        else:
            out.append(tok)
    return out


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``sdr-di`` console script; returns the exit status.

    Bad input (any :class:`~sdr_di.errors.SdrDiError`, argument errors included): one line
    ``sdr-di: error: ...`` on stderr, status 2 (1 for an error with ``exit_status = 1``: a
    run that ended without a result it can stand behind, :class:`~sdr_di.errors.RunFailed`).
    Warnings: one line ``sdr-di: warning: ...`` each. Ctrl-C anywhere (while modules are imported,
    while files are written, during a campaign): ``sdr-di: interrupted``, status 130, no
    traceback; the commands' outputs are removed or left complete (``sdr_di.io.atomic``).
    """
    import warnings

    shown = warnings.showwarning
    warnings.showwarning = _show_warning
    try:
        argv = list(sys.argv[1:] if argv is None else argv)
        if argv[:1] in (["run"], ["generate"], ["acquire"]) and not {
                "--no-progress", "-h", "--help"} & {a.split("=")[0] for a in argv}:
            from .kernel_cache import NOTE, kernels_cached  # imports no kernel

            _show_status("sdr-di: " + ("loading the signal-processing kernels ..."
                                       if kernels_cached() else NOTE + " ..."))
        parser = build_parser()
        argv = attach_negative_values(argv)
        args = parser.parse_args(argv)
        from .paths import command_scope, path_error

        with command_scope():  # no output may land on an input (sdr_di.paths)
            try:
                return args.func(args)
            except OSError as exc:  # a path the system refused: a bad input, one line
                raise path_error(exc) from None
            except RecursionError:
                raise UsageError("an input is nested too deeply to be read") from None
    except SdrDiError as exc:
        _clear_status()
        print(f"sdr-di: error: {_one_line(str(exc))}", file=sys.stderr)
        return getattr(exc, "exit_status", 2)
    except KeyboardInterrupt:
        _clear_status()
        _quiet_after_interrupt()
        print("sdr-di: interrupted", file=sys.stderr)
        return 130
    finally:
        warnings.showwarning = shown


#: A status line is on the terminal, to be overwritten (by the first progress bar) or cleared.
_status_shown = False


def _show_status(text: str) -> None:
    """``text`` on stderr at once, without a newline, when stderr is a terminal: the first
    thing a user sees while the numba kernels load (issue 28 item 4); the first progress bar
    (``\\r``, full width) overwrites it."""
    global _status_shown
    if sys.stderr.isatty():
        sys.stderr.write(text + "\r")
        sys.stderr.flush()
        _status_shown = True


def _clear_status() -> None:
    """Clear the status line of :func:`_show_status` before a message is printed over it."""
    global _status_shown
    if _status_shown:
        sys.stderr.write("\r\033[K")
        _status_shown = False


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Every warning the CLI shows as one line ``sdr-di: warning: ...`` on stderr (no source
    file, line number or quoted code: they point into sdr-di, not at what the user gave)."""
    _clear_status()
    print(f"sdr-di: warning: {_one_line(str(message))}", file=file or sys.stderr)


def _one_line(text: str) -> str:
    """An error message on one line (a message quoting file content may hold newlines)."""
    return " ".join(text.split()) if "\n" in text or "\r" in text else text


def _quiet_after_interrupt() -> None:
    """Silence what would still print after Ctrl-C: Dask's shutdown logging (scheduler,
    nanny and workers in this process) and warnings from interpreter shutdown."""
    import logging
    import warnings

    families = ("distributed", "tornado", "asyncio")
    # children too: one with a level of its own (Dask sets tornado.application's) ignores
    # its parent's (the same rule as studies.campaign.quiet_loggers, kept here so that
    # an interrupt during start-up does not import Dask)
    for name in [*families, *(n for n in list(logging.root.manager.loggerDict)
                              if n.split(".", 1)[0] in families)]:
        logging.getLogger(name).setLevel(logging.CRITICAL + 1)
    warnings.filterwarnings("ignore")


def exit_program(status: int) -> NoReturn:
    """End the process with ``status`` after :func:`main`: the console script, ``python -m
    sdr_di.cli`` and the benchmarks' child processes end this way.

    The objects still alive are first moved out of the garbage collector's reach
    (:func:`gc.freeze`): the interpreter's teardown then frees them by reference counts
    alone instead of searching numba's and LLVM's large object graphs for cycles: after a
    deep run, 0.12-0.23 s from ``main``'s return to the process's end, 0.03 s frozen
    (2-core VM, 2026-12-05).
    The outputs are written and closed before :func:`main` returns, so nothing waits on a
    cycle's finalizer."""
    import gc

    gc.freeze()
    sys.exit(status)


def console_main() -> NoReturn:
    """The ``sdr-di`` program: :func:`main` on the command line, then :func:`exit_program`."""
    exit_program(main())


if __name__ == "__main__":
    console_main()
