"""``sdr-di acquire``: one acquisition search over the start of an IF file, as a table.

The search is :func:`~sdr_di.receiver.acquisition.acquire_source` (DC removal and blanking of
narrowband lines first, then the FFT search; module notes there). It uses what the file
holds: a file shorter than ``coherent_ms x noncoherent`` is searched with the whole coherent
blocks it has, down to one code period, and the report says which sensitivity that gives
(:func:`~sdr_di.receiver.acquisition.detection_cn0_dbhz`).

Output ``STEM_acquisition.csv`` (one row per searched PRN):

=====================  ================================================================
column                 meaning
=====================  ================================================================
``prn``                PRN (1..63)
``detected``           ``true`` / ``false``: metric above the threshold
``doppler_hz``         carrier Doppler relative to the IF [Hz] (refined when detected)
``code_phase_chips``   code phase at the first sample searched [chips], in [0, 10230)
``code_phase_samples`` sample index where the first code period begins
``cn0_dbhz``           C/N0 estimate [dB-Hz] (empty when not detected)
``metric``             peak ``S / sigma2`` (Gamma(K, 1) with noise only)
``threshold``          detection threshold on ``metric`` for ``pfa``
``pfa``                false-alarm probability over this PRN's search
``coherent_ms``        M [ms]
``noncoherent``        K actually used
``doppler_refined``    ``true`` when the Doppler was refined from the squared prompts
``notes``              remarks, ``;``-separated (Doppler not refined, shared Doppler bin,
                       no signal power)
=====================  ================================================================
"""

from __future__ import annotations

import csv
import dataclasses
import math
from pathlib import Path

import numpy as np

from ..io.atomic import atomic_open, ensure_output_dir
from .acquisition import (
    AcquisitionResult,
    acquire_source,
    default_doppler_step_hz,
    detection_cn0_dbhz,
    doppler_offsets,
)
from .ifreader import IfSource

__all__ = ["CSV_COLUMNS", "AcquisitionReport", "run_acquisition"]

CSV_COLUMNS = ("prn", "detected", "doppler_hz", "code_phase_chips", "code_phase_samples",
               "cn0_dbhz", "metric", "threshold", "pfa", "coherent_ms", "noncoherent",
               "doppler_refined", "notes")


@dataclasses.dataclass
class AcquisitionReport:
    """What ``sdr-di acquire`` found.

    Attributes
    ----------
    results : list of AcquisitionResult
        One per searched PRN.
    coherent_ms, noncoherent : int
        M and K used (K may be below the requested one on a short file).
    requested_noncoherent : int
        K asked for.
    searched_s : float
        Seconds of the file searched.
    file_s : float
        Seconds in the file.
    doppler_bins_hz : tuple of float
        First bin, last bin and step of the Doppler grid [Hz].
    cn0_pd90_dbhz : float
        C/N0 at which the search detects with probability 0.9, without losses [dB-Hz].
    lines_hz : numpy.ndarray
        Narrowband lines blanked in the input [Hz].
    csv_path : Path
        The written table.
    """

    results: list[AcquisitionResult]
    coherent_ms: int
    noncoherent: int
    requested_noncoherent: int
    searched_s: float
    file_s: float
    doppler_bins_hz: tuple[float, float, float]
    cn0_pd90_dbhz: float
    lines_hz: np.ndarray
    csv_path: Path


def run_acquisition(source: IfSource, out_dir: str | Path, *, prns=None, coherent_ms: int = 1,
                    noncoherent: int = 40, doppler_center_hz: float = 0.0,
                    doppler_range_hz: float = 5000.0, pfa: float = 1e-3,
                    stem: str | None = None) -> AcquisitionReport:
    """Search ``prns`` (default all 63) at the start of ``source``; write the CSV table.

    Parameters
    ----------
    source : IfSource
        The IF samples.
    out_dir : path
        Output directory (created); ``STEM_acquisition.csv`` is written there atomically.
    prns : iterable of int, optional
        PRNs to search (default 1..63).
    coherent_ms, noncoherent : int
        M [ms] and K (non-coherent sums); K is reduced to what the file holds.
    doppler_center_hz, doppler_range_hz : float
        Centre and half-width of the Doppler search [Hz].
    pfa : float
        False-alarm probability per PRN search.
    stem : str, optional
        Base name of the output (default the IF file's stem).

    Raises
    ------
    AcquisitionError
        A file shorter than one coherent block, or search parameters out of range.
    OutputError
        The table cannot be written.
    """
    from ..paths import check_outputs

    stem = stem or source.path.stem
    check_outputs([Path(out_dir) / f"{stem}_acquisition.csv"])
    prn_list = list(range(1, 64)) if prns is None else list(prns)
    results = acquire_source(source, 0, prns=prn_list, coherent_ms=coherent_ms,
                             noncoherent=noncoherent, doppler_center_hz=doppler_center_hz,
                             doppler_range_hz=doppler_range_hz, pfa=pfa)
    out_dir = ensure_output_dir(out_dir)  # after the search: a refused file leaves nothing
    k_used = results[0].noncoherent if results else int(noncoherent)
    fs = source.sampling_rate_hz
    step = default_doppler_step_hz(coherent_ms, fs)
    bins = doppler_center_hz + doppler_offsets(doppler_range_hz, step)
    thr = next((r.threshold for r in results if math.isfinite(r.threshold)), math.nan)
    path = out_dir / f"{stem}_acquisition.csv"
    with atomic_open(path, "w") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(CSV_COLUMNS)
        for r in results:
            w.writerow(_row(r))
    lines = next((r.lines_hz for r in results if r.lines_hz is not None), np.zeros(0))
    return AcquisitionReport(
        results=results, coherent_ms=int(coherent_ms), noncoherent=k_used,
        requested_noncoherent=int(noncoherent),
        searched_s=k_used * round(coherent_ms * fs * 1e-3) / fs, file_s=source.duration_s,
        doppler_bins_hz=(float(bins[0]), float(bins[-1]),
                         step),
        cn0_pd90_dbhz=(detection_cn0_dbhz(thr, k_used, coherent_ms) if math.isfinite(thr)
                       else math.nan),
        lines_hz=np.asarray(lines, dtype=float), csv_path=path)


def _num(v: float, nd: int) -> str:
    return "" if not math.isfinite(v) else f"{v:.{nd}f}"


def _row(r: AcquisitionResult) -> list[str]:
    return [str(r.prn), "true" if r.detected else "false", _num(r.doppler_hz, 2),
            _num(r.code_phase_chips, 4), _num(r.code_phase_samples, 3),
            _num(r.cn0_dbhz, 2) if r.detected else "", _num(r.peak_metric, 2),
            _num(r.threshold, 2), f"{r.pfa:g}", str(r.coherent_ms), str(r.noncoherent),
            "true" if r.doppler_refined else "false", "; ".join(r.notes)]
