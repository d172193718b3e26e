"""Why a scalar run ended without a fix: the likely causes, ordered by what the run saw.

A wrong description of the file (sample format, IF sign, rate) leaves every channel at noise
level; channels that track at 30 dB-Hz or more and decode subframes rule it out, and then
the file's length (a fix needs the ephemerides and the time of week: about 18 s without
assistance) or the start time come first (issue 49 item 20: a 12 s file with 7 channels at
36 dB-Hz was told "the sample format" first).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

#: C/N0 from which a channel counts as tracking a real signal [dB-Hz].
STRONG_CN0_DBHZ = 30.0
#: File length a first fix needs from decoded data alone [s] (the README's 20 s file had its
#: first fix at 18.4 s: three D1 subframes of 6 s).
FIX_NEEDS_S = 18.0


def _cn0(row: dict) -> float:
    try:
        v = float(row.get("cn0_dbhz"))
    except (TypeError, ValueError):
        return math.nan
    return v


def likely_causes(channels: Sequence[dict], file_s: float, *, format_name: str,
                  given: str, if_hz: float, sampling_rate_hz: float) -> tuple[str, list[str]]:
    """The evidence in words and the likely causes of a run without a fix, most likely first.

    Parameters
    ----------
    channels : sequence of dict
        The run's channel rows (``cn0_dbhz``, ``subframes``, ``ephemeris_decoded``).
    file_s : float
        Seconds of IF processed.
    format_name, given : str
        The sample format and whether it was ``"given"`` on the command line or ``"read"``.
    if_hz, sampling_rate_hz : float
        The declared IF and the rate [Hz].
    """
    strong = [r for r in channels if _cn0(r) >= STRONG_CN0_DBHZ]
    decoding = [r for r in strong if (r.get("subframes") or 0) > 0 or r.get("ephemeris_decoded")]
    n_eph = sum(bool(r.get("ephemeris_decoded")) for r in channels)
    described = [f"the sample format ({format_name} {given}: --format)",
                 f"the IF sign ({if_hz:g} Hz: --if with the other sign, or --inverted)",
                 f"the sample rate ({sampling_rate_hz:g} Hz: --fs)"]
    start = "the start time (--start-week, --start-sow)"
    short = (f"a file too short for the navigation data ({file_s:.1f} s; a first fix from "
             f"decoded data needs about {FIX_NEEDS_S:g} s, or --ephemeris NAV.rnx)")
    if strong:
        cn0 = sorted(_cn0(r) for r in strong)[len(strong) // 2]
        evidence = (f"{len(strong)} channels track at {cn0:.0f} dB-Hz"
                    + (f", {len(decoding)} decoding subframes" if decoding else
                       ", none decoding subframes"))
    else:
        evidence = f"{len(channels)} channels, none above {STRONG_CN0_DBHZ:g} dB-Hz"
    if decoding:                      # the samples are read right: time and length remain
        first = [short, start] if file_s < FIX_NEEDS_S or n_eph < 4 else [start, short]
        return evidence, first + described
    if strong:                        # signals, but no data bits: too short, or the time
        if file_s < FIX_NEEDS_S:
            return evidence, [short, *described, start]
        return evidence, [described[1], start, described[0], described[2], short]
    return evidence, [*described, start, short]


def no_fix_diagnosis(source, res, *, given: bool) -> str:
    """The one line of a scalar run that ended without a fix: what it got, where its outputs
    are, and :func:`likely_causes` in order."""
    n_eph = sum(bool(r["ephemeris_decoded"]) for r in res.channels)
    file_s = getattr(res, "processed_s", None) or source.duration_s
    evidence, causes = likely_causes(
        res.channels, file_s, format_name=source.format.name,
        given="given" if given else "read", if_hz=source.declared_if_hz,
        sampling_rate_hz=source.sampling_rate_hz)
    return (f"no fix in {res.n_epochs} epochs ({len(res.channels)} channels acquired, {n_eph} "
            f"with ephemeris; {evidence}; outputs kept in {res.files['pvt'].parent}); likely "
            f"causes, most likely first: {', '.join(causes)}")
