"""Azimuth and elevation of the satellites over a run, from broadcast ephemerides.

The receiver position and the times come from the run (its fixes, BDT); the orbits from
the navigation file the run wrote (``STEM_nav.rnx``: the records it decoded) and the
assistance file its sidecar names, merged (:func:`~sdr_di.orbits.rinex_nav.merge_nav`), so
that a satellite without a decoded record still has its track. Satellite positions:
:func:`~sdr_di.orbits.broadcast.sat_states` (GEO satellites by their own rotation), angles:
:func:`~sdr_di.frames.elevation_azimuth`.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from ..errors import SdrDiError
from ..frames import elevation_azimuth

__all__ = ["load_navigation", "sky_tracks"]


def load_navigation(paths) -> object | None:
    """The navigation data of the files that read (merged), None when none does.

    A file without BDS records (a run too short to decode one writes a header only) or
    that cannot be read is skipped."""
    from ..orbits.rinex_nav import load_nav, merge_nav

    navs = []
    for p in paths:
        if p is None or not Path(p).is_file():
            continue
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                navs.append(load_nav(p))
        except (SdrDiError, OSError, ValueError):
            continue
    if not navs:
        return None
    return navs[0] if len(navs) == 1 else merge_nav(navs)


def sky_tracks(nav, week: int, sow: np.ndarray, r_rx_e: np.ndarray, prns=None,
               step_s: float = 2.0) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """Azimuth and elevation [deg] of each satellite seen from the receiver over time.

    Parameters
    ----------
    nav : NavData
        Broadcast ephemerides.
    week : int
        BDT week ``sow`` counts from.
    sow : (k,) array
        BDT times [s of ``week``] (thinned to one every ``step_s``).
    r_rx_e : (k, 3) or (3,) array
        Receiver ECEF position [m] at each time (or one for all).
    prns : iterable of int, optional
        Satellites (default: every PRN of ``nav``).

    Returns
    -------
    dict
        ``{prn: (az_deg (m,), el_deg (m,))}``; a satellite without a usable record at these
        times is left out.
    """
    sow = np.asarray(sow, float)
    r = np.asarray(r_rx_e, float)
    r = np.broadcast_to(r, (sow.size, 3)) if r.ndim == 1 else r
    ok = np.isfinite(sow) & np.isfinite(r).all(axis=1)
    sow, r = sow[ok], r[ok]
    if sow.size == 0:
        return {}
    keep = [0]
    for i in range(1, sow.size):
        if sow[i] - sow[keep[-1]] >= step_s:
            keep.append(i)
    if keep[-1] != sow.size - 1:
        keep.append(sow.size - 1)
    sow, r = sow[keep], r[keep]
    from ..orbits.broadcast import sat_states

    out = {}
    for prn in (nav.prns if prns is None else prns):
        try:
            r_sat = sat_states(nav, int(prn), int(week), sow)[0]
        except (SdrDiError, ValueError, KeyError):
            continue
        el, az = elevation_azimuth(r, r_sat)
        if np.isfinite(el).any():
            out[int(prn)] = (np.degrees(az), np.degrees(el))
    return out
