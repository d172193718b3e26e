"""``sdr-di run --mode scalar``: IF file -> acquisition, tracking, decoding -> PVT files.

Pipeline: :class:`~sdr_di.receiver.ifreader.IfSource` (sidecar or explicit options for a
foreign file) -> :class:`~sdr_di.receiver.scalar.ScalarReceiver` (acquisition, scalar loops,
NH/bit/frame sync, D1/D2 decoding) -> at every output epoch
:class:`~sdr_di.receiver.pvt.PvtEngine` (observables at a common receive time, WLS position
and velocity from the decoded ephemerides and Klobuchar set) -> streaming CSV and NMEA
writers (nothing under the final names until the run completed).

Outputs in ``out_dir`` (``STEM`` = IF file name without extension):

``STEM_pvt.csv``   one row per output epoch (``docs/solution_format.md``)
``STEM.nmea``      GGA and RMC sentences at the output rate (valid fixes)
``STEM_channels.csv``  one row per channel: final state, C/N0, decoded ephemeris, time
``STEM_obs.rnx``   RINEX 3.05 observations (B3I ``C6I L6I D6I S6I``, BDT)
``STEM_nav.rnx``   RINEX 3.05 navigation file of the decoded records and Klobuchar set
``STEM_scalar_summary.json``  the run's record: mode ``scalar``, its input files (IF,
                   sidecar, reference trajectory, assistance navigation file: absolute
                   paths), start time, epochs and fixes (read by ``sdr-di report``)
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from pathlib import Path

from ..errors import NoSatelliteError  # noqa: F401  (defined in sdr_di.errors, imported from here)
from ..io.atomic import atomic_open, ensure_output_dir
from ..io.rinex_writer import RinexOutputs, rinex_names
from ..io.solution_files import NmeaWriter, SolutionCsvWriter
from .ifreader import IfSource
from .navdata import NavDataInForce
from .prediction import FixPredictor
from .pvt import PvtEngine
from .scalar import ScalarReceiver




def open_source(path: str | Path, *, sampling_rate_hz: float | None = None,
                if_hz: float | None = None, sample_format: str | None = None,
                spectrum_inverted: bool = False, start_week: int | None = None,
                start_sow: float | None = None, rfch: int | None = None,
                ignore_sidecar: bool = False, check_format: bool = True) -> IfSource:
    """Open an IF file: a SigMF recording when the path names one (``X.sigmf-meta``,
    ``X.sigmf-data`` or the base name ``X``: :func:`open_sigmf`); else from its sidecar
    (``X.json`` beside ``X.bin``, or the JSON itself); else from a peer's tag
    (``X.bin.tag``, PocketSDR/SignalSim, :mod:`sdr_di.io.tag_sidecar`), the explicit options
    overriding the tag's values; else from the explicit options alone (foreign files).

    With a sidecar, explicit options must agree with it (``--fs``, ``--if``, ``--format``,
    ``--inverted``, ``--start-week``, ``--start-sow``): a contradiction is an error naming
    both values (:func:`~sdr_di.io.sidecar.flag_conflicts`), and agreeing options read the
    file through its sidecar (its size check included). ``ignore_sidecar`` (``sdr-di run
    --ignore-sidecar``) reads the file with the options alone, as if it had no sidecar.
    ``check_format=False`` (``--no-format-check``) skips the layout heuristic.

    ``rfch`` picks the RF channel (1-based) of a multi-channel layout (PocketSDR ``RAW*``).

    Raises
    ------
    SampleFormatError
        Missing sidecar, tag and options, bad options or tag, options that contradict the
        sidecar, truncated or inconsistent file.
    """
    from ..errors import SampleFormatError, SidecarError
    from ..io.sidecar import flag_conflicts, read_sidecar
    from ..io.sigmf_files import sigmf_meta_path
    from ..io.tag_sidecar import read_tag, tag_path, tag_source

    path = Path(path)
    sigmf_meta = sigmf_meta_path(path)
    if sigmf_meta is not None:  # X.sigmf-meta, X.sigmf-data or the base name X
        return open_sigmf(sigmf_meta, sampling_rate_hz=sampling_rate_hz, if_hz=if_hz,
                          sample_format=sample_format, spectrum_inverted=spectrum_inverted,
                          start_week=start_week, start_sow=start_sow, rfch=rfch)
    if path.suffix == ".tag":  # the tag itself was named: read the file it describes
        path = path.with_suffix("")
    explicit = sampling_rate_hz is not None or sample_format is not None
    sidecar = path if path.suffix == ".json" else path.with_suffix(".json")
    tag = tag_path(path)
    if not ignore_sidecar and sidecar.exists():
        if rfch not in (None, 1):
            raise SampleFormatError(f"{path}: --rfch {rfch}: an sdr-di file has one RF channel")
        try:
            meta = read_sidecar(sidecar)
        except SidecarError as exc:
            if path.suffix == ".json":
                raise
            # the IF file was named: X.json beside it may be another program's file (a
            # SignalSim configuration named like its output)
            raise SidecarError(f"{exc}; it is read as the sidecar of {path.name} "
                               "(--ignore-sidecar reads the file without it: by its tag, "
                               "else --fs/--if/--format)") from None
        conflicts = flag_conflicts(meta, sampling_rate_hz=sampling_rate_hz,
                                   if_hz=if_hz, sample_format=sample_format,
                                   spectrum_inverted=spectrum_inverted,
                                   start_week=start_week, start_sow=start_sow)
        if conflicts:
            raise SidecarError(f"{path}: the options contradict its sidecar {sidecar.name}: "
                               f"{'; '.join(conflicts)} (--ignore-sidecar reads the file "
                               "with the options alone)")
        return IfSource.from_sidecar(sidecar, check_format=check_format)
    if ignore_sidecar and path.suffix == ".json":
        raise SampleFormatError(f"{path}: --ignore-sidecar needs the IF file, not its sidecar")
    if path.suffix != ".json" and tag.exists():
        ts = tag_source(read_tag(tag), rfch, sample_format=sample_format,
                        sampling_rate_hz=sampling_rate_hz, if_hz=if_hz,
                        spectrum_inverted=spectrum_inverted)
        return IfSource(path, ts.sampling_rate_hz, ts.if_hz, ts.sample_format,
                        spectrum_inverted=ts.spectrum_inverted, start_week=start_week,
                        start_sow=start_sow, rf_channel=ts.rf_channel,
                        check_format=check_format)
    if not explicit:
        raise SampleFormatError(
            f"{path}: no sidecar {sidecar.name} and no tag {tag.name}; give --fs, --if and "
            "--format for a foreign IF file")
    if sampling_rate_hz is None or sample_format is None:
        raise SampleFormatError(f"{path}: a foreign IF file needs both --fs and --format")
    if not path.exists():
        raise SampleFormatError(f"IF file {path} not found")
    return IfSource(path, sampling_rate_hz, if_hz or 0.0, sample_format,
                    spectrum_inverted=spectrum_inverted, start_week=start_week,
                    start_sow=start_sow, rf_channel=rfch, check_format=check_format)


def open_sigmf(meta_path: str | Path, *, rfch: int | None = None, **options) -> IfSource:
    """Open a SigMF recording (:mod:`sdr_di.io.sigmf_files`): datatype, rate, IF from the
    first capture's centre frequency, start time from its ``core:datetime``; the explicit
    ``options`` of :func:`open_source` override them one by one, as for a tag.

    Raises
    ------
    SampleFormatError
        Unreadable or invalid metadata, unreadable datatype, B3I outside the band, ...
    """
    from ..errors import SampleFormatError
    from ..io.sigmf_files import sigmf_source

    if rfch not in (None, 1):
        raise SampleFormatError(f"{meta_path}: --rfch {rfch}: a SigMF recording read here has "
                                "one channel")
    from ..paths import note_input

    ss = sigmf_source(meta_path, **options)
    note_input(meta_path, what="SigMF metadata")
    return IfSource(ss.data_path, ss.sampling_rate_hz, ss.if_hz, ss.sample_format,
                    spectrum_inverted=ss.spectrum_inverted, start_week=ss.start_week,
                    start_sow=ss.start_sow)


@dataclasses.dataclass
class RunSummary:
    """What a scalar run produced."""

    files: dict[str, Path]
    n_epochs: int
    n_fixes: int
    processed_s: float
    wall_s: float
    channels: list[dict]
    profile: dict
    first_fix_s: float = math.nan
    #: per output epoch: ``t_s`` [s since the file start], ``n_sats`` (satellites in the fix,
    #: 0 without one), ``cn0_dbhz`` ``{prn: (t_s list, C/N0 list [dB-Hz])}`` of the
    #: channels observed (in memory, for a caller of the API; the report reads the files)
    series: dict = dataclasses.field(default_factory=dict)


def sidecar_assistance(source: IfSource) -> dict[int, float | None]:
    """``{prn: Doppler at sample 0 [Hz]}`` of the satellites the file's sidecar lists (empty
    without a sidecar list): the expected satellites and where to look for them, as the
    metadata of a recording made with an almanac prediction gives them."""
    sats = (source.meta or {}).get("satellites") if isinstance(source.meta, dict) else None
    out: dict[int, float | None] = {}
    for s in sats or []:
        try:
            prn = int(s["prn"])
        except (KeyError, TypeError, ValueError):
            continue
        fd = s.get("doppler_hz")
        out[prn] = float(fd) if isinstance(fd, (int, float)) and math.isfinite(fd) else None
    return out


def search_assistance(source: IfSource, prns=None,
                      assist: bool | dict[int, float | None] = True
                      ) -> dict[int, float | None] | None:
    """The acquisition assistance of a run: the rule every ``sdr-di run`` mode shares.

    Parameters
    ----------
    source : IfSource
        The IF samples (its sidecar list, :func:`sidecar_assistance`).
    prns : iterable of int, optional
        An explicit PRN list: kept, with the sidecar's Dopplers where it has them.
    assist : bool or dict
        True: the sidecar's list; a dict ``{prn: Doppler [Hz] or None}``: that assistance;
        False: none.

    Returns
    -------
    dict or None
        ``{prn: Doppler at sample 0 [Hz] or None}``; None for a cold search of ``prns``.
    """
    aid = dict(assist) if isinstance(assist, dict) else \
        sidecar_assistance(source) if assist else {}
    if prns is not None:  # an explicit list: the sidecar's Dopplers where it has them
        aid = {p: aid.get(p) for p in prns}
    return aid or None


def run_scalar(source: IfSource, out_dir: str | Path, *, prns=None, rate_hz: float = 5.0,
               stem: str | None = None, progress: bool = True,
               receiver: ScalarReceiver | None = None,
               assist: bool | dict[int, float | None] = True, nav=None,
               duration_s: float | None = None,
               truth_path: str | Path | None = None) -> RunSummary:
    """Run the scalar receiver over ``source`` and write the solution files.

    Parameters
    ----------
    source : IfSource
        The IF samples.
    out_dir : path
        Output directory (created).
    prns : iterable of int, optional
        PRNs to search (default all 63).
    rate_hz : float
        Output epoch rate [Hz] (default 5, paper 004's solution rate).
    stem : str, optional
        Base name of the outputs (default the IF file's stem).
    progress : bool
        Show a progress bar (seconds processed, real-time factor, channels in lock).
    receiver : ScalarReceiver, optional
        Preconfigured receiver (loop settings, acquisition options).
    assist : bool or dict
        True (default): search the satellites the sidecar lists, around their start Doppler,
        with the long search for those the first search misses (:func:`sidecar_assistance`).
        A dict ``{prn: Doppler [Hz] or None}``: that assistance (e.g. the visible satellites
        from ephemeris and a time hint, :func:`~sdr_di.receiver.prediction
        .visible_satellites`). False: a cold search of ``prns`` (default all 63).
    nav : NavData, optional
        Assistance navigation data (the RINEX file the sidecar names, as the integrated
        modes take it): ephemerides and ionosphere before they are decoded, the decoded
        data winning as it arrives (:class:`~sdr_di.receiver.navdata.NavDataInForce`, the
        rules every mode shares). With it the first fix needs a transmit time, not a
        decoded ephemeris. None: decoded data only.
    duration_s : float, optional
        Process only the first ``duration_s`` seconds of the file.
    truth_path : path, optional
        The reference trajectory the caller compares the fixes with (``--truth``, else the
        sidecar's): recorded in ``STEM_scalar_summary.json`` so that ``sdr-di report`` finds
        it wherever the outputs went. Not read here.

    Raises
    ------
    NoSatelliteError
        No satellite acquired.
    OutputError
        Outputs cannot be written (nothing is left under the final names).
    """
    from ..paths import check_outputs

    out_dir = Path(out_dir)
    stem = stem or source.path.stem
    files = {"pvt": out_dir / f"{stem}_pvt.csv", "nmea": out_dir / f"{stem}.nmea",
             "channels": out_dir / f"{stem}_channels.csv",
             "summary": out_dir / f"{stem}_scalar_summary.json"}
    files["rinex_obs"], files["rinex_nav"] = (out_dir / n for n in rinex_names(stem))
    check_outputs(files.values())  # none of them an input (--ephemeris ... --out)
    out_dir = ensure_output_dir(out_dir)
    rx = receiver or ScalarReceiver(log=False)
    engine = PvtEngine(source.sampling_rate_hz, {}, None)
    engine.navdata = NavDataInForce(nav)
    if source.start_week is not None and source.start_sow is not None:
        # the file's start time: the week of transmit times decoded before the week number
        engine.builder.rx_time.time_hint = (int(source.start_week), float(source.start_sow))
    stop = source.n_samples if duration_s is None else min(
        source.n_samples, round(duration_s * source.sampling_rate_hz))
    processed_s = stop / source.sampling_rate_hz
    # after a blockage, lost channels are searched around, and timed from, the last fix
    rx.predictor = FixPredictor(engine, source.sampling_rate_hz, source.carrier_hz)
    csv_w = SolutionCsvWriter(files["pvt"])
    nmea_w = NmeaWriter(files["nmea"], rate_hz=None)
    rinex_w = RinexOutputs(files["rinex_obs"], files["rinex_nav"], marker_name=stem,
                           interval_s=1.0 / rate_hz)
    bar = None
    t_wall = time.perf_counter()
    counts = {"epochs": 0, "fixes": 0}
    series: dict = {"t_s": [], "n_sats": [], "cn0_dbhz": {}}
    if progress:
        from tqdm import tqdm

        from ..kernel_cache import first_use_note

        bar = tqdm(total=round(processed_s, 2), unit="s", desc="run scalar: tracking and fixes",
                   bar_format="{l_bar}{bar}| {n:.1f}/{total:.1f} s [{elapsed}<{remaining}"
                              "{postfix}]",  # shown before epoch 1
                   postfix="; ".join(filter(None, ["acquisition", first_use_note()])))

    def on_epoch(sample, observations, ephemerides):
        engine.ephemerides = engine.navdata.offer_decoded(
            ephemerides, rx.klobuchar, sample / source.sampling_rate_hz)
        engine.iono = engine.navdata.klobuchar
        sol = engine.process(observations, sample)
        counts["epochs"] += 1
        csv_w.write(sol)
        t_s = sample / source.sampling_rate_hz
        series["t_s"].append(t_s)
        series["n_sats"].append(int(sol.n_sats) if sol.valid else 0)
        for o in observations:
            tc = series["cn0_dbhz"].setdefault(int(o.prn), ([], []))
            tc[0].append(t_s)
            tc[1].append(float(o.cn0_dbhz))
        if sol.valid:
            if not counts["fixes"]:
                counts["first_fix_s"] = sample / source.sampling_rate_hz
            counts["fixes"] += 1
            nmea_w.write(sol)
        if observations:  # the observables the PVT used (formed again: same clock, same sample)
            rinex_w.write(engine.builder(observations), observations, sol, ephemerides,
                          rx.klobuchar)
        if bar is not None:
            done = sample / source.sampling_rate_hz
            locked = sum(1 for o in observations if o.code_lock)
            rt = done / max(time.perf_counter() - t_wall, 1e-9)
            bar.set_postfix_str(f"x{rt:.2f} real time, {locked} in lock, "
                                f"{len(ephemerides)} eph decoded, {counts['fixes']} fixes",
                                refresh=False)
            bar.update(round(done - bar.n, 3))

    try:
        rx.run(source, prns=prns, on_epoch=on_epoch, epoch_interval_s=1.0 / rate_hz,
               stop_sample=stop, assist=search_assistance(source, prns, assist))
        if not any(r.detected for r in rx.acquisition_results) and not any(
                c.tracking for c in rx.channels.values()):
            raise NoSatelliteError(f"{source.path}: no satellite found by acquisition "
                                   f"({_search_summary(rx)})")
        channels = _channel_rows(rx)
        with atomic_open(files["channels"], "w") as fh:
            keys = list(channels[0]) if channels else ["prn"]
            fh.write(",".join(keys) + "\n")
            for row in channels:
                fh.write(",".join(str(row[k]) for k in keys) + "\n")
        csv_w.close()
        nmea_w.close()
        rinex_w.close()
        _write_record(files["summary"], source, nav, truth_path, counts, processed_s,
                      rate_hz)
        if bar is not None:    # the last epoch is before the end of the file: the run is
            bar.update(bar.total - bar.n)    # done, so is the bar
    except BaseException:
        csv_w.abort()
        nmea_w.abort()
        rinex_w.abort()
        raise
    finally:
        if bar is not None:
            bar.close()
    wall = time.perf_counter() - t_wall
    return RunSummary(files, counts["epochs"], counts["fixes"], processed_s, wall,
                      channels, dict(rx.profile), counts.get("first_fix_s", math.nan),
                      series)


def _write_record(path: Path, source: IfSource, nav, truth_path, counts: dict,
                  processed_s: float, rate_hz: float) -> None:
    """``STEM_scalar_summary.json``: the run's inputs (absolute paths) and counts, for
    ``sdr-di report`` (atomic)."""
    def name(p):
        return None if p is None else str(Path(p).resolve())

    record = {"mode": "scalar", "if_file": name(source.path),
              "sidecar": name(getattr(source, "sidecar_path", None)),
              "truth_file": name(truth_path),
              "ephemeris_file": name(getattr(nav, "path", None)),
              "start": {"week": source.start_week, "sow": source.start_sow},
              "rate_hz": rate_hz, "processed_s": processed_s, "epochs": counts["epochs"],
              "fixes": counts["fixes"],
              "first_fix_s": counts.get("first_fix_s")}
    with atomic_open(path, "w") as fh:
        json.dump(record, fh, indent=2)
        fh.write("\n")


def _search_summary(rx: ScalarReceiver) -> str:
    """What the searches of a run covered, for the no-satellite message."""
    res = rx.acquisition_results
    if not res:
        return f"{len(rx.channels)} PRNs, but the file is shorter than one code period"
    k = max(r.noncoherent for r in res)
    m = res[0].coherent_ms
    return (f"searched {len(res)} PRNs, up to {k} x {m} ms non-coherent; "
            f"'sdr-di acquire' shows each PRN's metric and threshold")


def _channel_rows(rx: ScalarReceiver) -> list[dict]:
    rows = []
    acq = {r.prn: r for r in rx.acquisition_results}
    for prn, c in rx.channels.items():
        a = acq.get(prn)
        if (a is None or not a.detected) and not c.tracking and c.ephemeris is None:
            continue
        cn0 = getattr(c, "cn0_dbhz", math.nan)
        rows.append({
            "prn": prn,
            "state": getattr(c.state, "name", str(c.state)),
            "acq_doppler_hz": round(a.doppler_hz, 1) if a is not None else "",
            "acq_cn0_dbhz": round(a.cn0_dbhz, 1) if a is not None else "",
            "cn0_dbhz": round(float(cn0), 1) if cn0 is not None else "",
            "ephemeris_decoded": c.ephemeris is not None,
            "toe": c.ephemeris.toe if c.ephemeris is not None else "",
            "subframes": len(getattr(c, "subframes", []) or []),
        })
    return rows
