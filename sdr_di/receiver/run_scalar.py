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
"""

from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path

from ..errors import SdrDiError
from ..io.atomic import atomic_open, ensure_output_dir
from ..io.rinex_writer import RinexOutputs, rinex_names
from ..io.solution_files import NmeaWriter, SolutionCsvWriter
from .ifreader import IfSource
from .prediction import FixPredictor
from .pvt import PvtEngine
from .scalar import ScalarReceiver


class NoSatelliteError(SdrDiError):
    """Acquisition found no satellite in the IF file."""


def open_source(path: str | Path, *, sampling_rate_hz: float | None = None,
                if_hz: float | None = None, sample_format: str | None = None,
                spectrum_inverted: bool = False, start_week: int | None = None,
                start_sow: float | None = None, rfch: int | None = None) -> IfSource:
    """Open an IF file: a SigMF recording when the path names one (``X.sigmf-meta``,
    ``X.sigmf-data`` or the base name ``X``: :func:`open_sigmf`); else from its sidecar
    (``X.json`` beside ``X.bin``, or the JSON itself); else from a peer's tag
    (``X.bin.tag``, PocketSDR/SignalSim, :mod:`sdr_di.io.tag_sidecar`), the explicit options
    overriding the tag's values; else from the explicit options alone
    (foreign files). Explicit options given, a JSON sidecar is not read.

    ``rfch`` picks the RF channel (1-based) of a multi-channel layout (PocketSDR ``RAW*``).

    Raises
    ------
    SampleFormatError
        Missing sidecar, tag and options, bad options or tag, truncated or inconsistent
        file.
    """
    from ..errors import SampleFormatError
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
    if not explicit and sidecar.exists():
        if rfch not in (None, 1):
            raise SampleFormatError(f"{path}: --rfch {rfch}: an sdr-di file has one RF channel")
        return IfSource.from_sidecar(sidecar)
    if path.suffix != ".json" and tag.exists():
        ts = tag_source(read_tag(tag), rfch, sample_format=sample_format,
                        sampling_rate_hz=sampling_rate_hz, if_hz=if_hz,
                        spectrum_inverted=spectrum_inverted)
        return IfSource(path, ts.sampling_rate_hz, ts.if_hz, ts.sample_format,
                        spectrum_inverted=ts.spectrum_inverted, start_week=start_week,
                        start_sow=start_sow, rf_channel=ts.rf_channel)
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
                    start_sow=start_sow, rf_channel=rfch)


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
    ss = sigmf_source(meta_path, **options)
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
               assist: bool | dict[int, float | None] = True) -> RunSummary:
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

    Raises
    ------
    NoSatelliteError
        No satellite acquired.
    OutputError
        Outputs cannot be written (nothing is left under the final names).
    """
    out_dir = ensure_output_dir(out_dir)
    stem = stem or source.path.stem
    rx = receiver or ScalarReceiver(log=False)
    engine = PvtEngine(source.sampling_rate_hz, {}, None)
    # after a blockage, lost channels are searched around, and timed from, the last fix
    rx.predictor = FixPredictor(engine, source.sampling_rate_hz, source.carrier_hz)
    files = {"pvt": out_dir / f"{stem}_pvt.csv", "nmea": out_dir / f"{stem}.nmea",
             "channels": out_dir / f"{stem}_channels.csv"}
    files["rinex_obs"], files["rinex_nav"] = (out_dir / n for n in rinex_names(stem))
    csv_w = SolutionCsvWriter(files["pvt"])
    nmea_w = NmeaWriter(files["nmea"], rate_hz=None)
    rinex_w = RinexOutputs(files["rinex_obs"], files["rinex_nav"], marker_name=stem,
                           interval_s=1.0 / rate_hz)
    bar = None
    t_wall = time.perf_counter()
    counts = {"epochs": 0, "fixes": 0}
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=round(source.duration_s, 2), unit="s", desc="run scalar",
                   bar_format="{l_bar}{bar}| {n:.1f}/{total:.1f} s [{elapsed}<{remaining}"
                              "{postfix}]")

    def on_epoch(sample, observations, ephemerides):
        engine.ephemerides = engine.navdata.offer_decoded(ephemerides, rx.klobuchar)
        engine.iono = engine.navdata.klobuchar
        sol = engine.process(observations, sample)
        counts["epochs"] += 1
        csv_w.write(sol)
        if sol.valid:
            counts["fixes"] += 1
            nmea_w.write(sol)
        if observations:  # the observables the PVT used (formed again: same clock, same sample)
            rinex_w.write(engine.builder(observations), observations, sol, ephemerides,
                          rx.klobuchar)
        if bar is not None:
            done = sample / source.sampling_rate_hz
            bar.update(round(done - bar.n, 3))
            locked = sum(1 for o in observations if o.code_lock)
            rt = done / max(time.perf_counter() - t_wall, 1e-9)
            bar.set_postfix_str(f"x{rt:.2f} real time, {locked} in lock, "
                                f"{len(ephemerides)} eph")

    try:
        rx.run(source, prns=prns, on_epoch=on_epoch, epoch_interval_s=1.0 / rate_hz,
               assist=search_assistance(source, prns, assist))
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
    except BaseException:
        csv_w.abort()
        nmea_w.abort()
        rinex_w.abort()
        raise
    finally:
        if bar is not None:
            bar.close()
    wall = time.perf_counter() - t_wall
    return RunSummary(files, counts["epochs"], counts["fixes"], source.duration_s, wall,
                      channels, dict(rx.profile))


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
