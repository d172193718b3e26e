"""Predicted transmit time and Doppler of a satellite from the receiver's last fix.

After a total blockage (a tunnel: every channel lost) the scalar receiver still knows where
it was, how fast it moved and its clock: the last valid fix of the
:class:`~sdr_di.receiver.pvt.PvtEngine`. Extrapolated to the sample where a lost channel is
searched again, with the decoded broadcast orbit, the forward range model
(:func:`~sdr_di.receiver.range_model.predict_ranges`) gives

* the **Doppler** to centre the re-acquisition search on (from the carrier phase-range rate
  over ``_RATE_DT_S``), and
* the satellite-clock **transmit time** of the code received at that sample,
  ``t_sv = t_nom - P / c``. The re-acquired code phase fixes its fraction of a millisecond;
  the prediction picks the whole millisecond, which needs the predicted pseudorange within
  +-150 km (half a code period). Extrapolating a fix at 30 m/s for 10 s with the last
  velocity errs by at most a few hundred metres (a turn), and the clock drift of a TCXO adds
  about 1 m/s of bias rate: three orders of magnitude of margin. So the channel's time (and
  bit and subframe edges) is rebuilt without waiting for a new subframe
  (:meth:`~sdr_di.receiver.channel.Channel.reacquired`).

No prediction (``None``) before the first fix, for a satellite without a decoded ephemeris,
or when the last fix is older than ``max_age_s``; the receiver then falls back to coasting the
channel's NCO through the outage.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..constants import C_LIGHT, F_B3I, SECONDS_PER_WEEK
from .pvt import PvtEngine, lookup_ephemeris
from .range_model import predict_ranges

__all__ = ["FixPredictor", "SignalPrediction", "visible_satellites"]

_RATE_DT_S = 0.01


def _doppler(pc0: float, pc1: float, carrier_hz: float) -> float:
    """Carrier Doppler [Hz] from two carrier phase-ranges [m] ``_RATE_DT_S`` apart (positive
    when the range shrinks)."""
    return -(carrier_hz / C_LIGHT) * float(pc1 - pc0) / _RATE_DT_S


@dataclasses.dataclass(frozen=True)
class SignalPrediction:
    """Predicted signal of one satellite at one IF sample.

    Attributes
    ----------
    t_tx_week : int
        BDT week of the transmit time.
    t_tx_sow : float
        Satellite-clock transmit time of the code received at the sample [s of week].
    doppler_hz : float
        Carrier Doppler [Hz] (positive for an approaching satellite), receiver clock drift
        included.
    age_s : float
        Time since the fix it is extrapolated from [s].
    """

    t_tx_week: int
    t_tx_sow: float
    doppler_hz: float
    age_s: float


class FixPredictor:
    """``predictor(prn, sample) -> SignalPrediction | None`` from a PVT engine's last fix.

    Parameters
    ----------
    engine : PvtEngine
        The engine of the run (its ``last_fix``, ``ephemerides``, ``iono`` and receiver clock
        are read at each call).
    fs : float
        IF sampling rate [Hz].
    carrier_hz : float, optional
        RF carrier [Hz].
    max_age_s : float, optional
        Oldest fix to extrapolate [s]. Default 600 (10 minutes at 30 m/s with a 1 m/s^2
        velocity error would be 180 km: beyond that the whole millisecond is not safe).
    """

    def __init__(self, engine: PvtEngine, fs: float, carrier_hz: float = F_B3I,
                 max_age_s: float = 600.0):
        self.engine = engine
        self.fs = float(fs)
        self.carrier_hz = float(carrier_hz)
        self.max_age_s = float(max_age_s)

    def __call__(self, prn: int, sample: int) -> SignalPrediction | None:
        eng = self.engine
        fix = eng.last_fix
        rx_time = eng.builder.rx_time
        if fix is None or not rx_time.initialized:
            return None
        dt = (int(sample) - int(fix.sample_index)) / self.fs
        if not 0.0 <= dt <= self.max_age_s:
            return None
        week, sow_nom = rx_time.time_at(int(sample))
        eph = lookup_ephemeris(eng.ephemerides, int(prn), week, sow_nom)
        if eph is None:
            return None
        v = np.asarray(fix.v_e, float)
        drift = float(fix.clock_drift_mps)
        if not (np.all(np.isfinite(v)) and math.isfinite(drift)):
            v, drift = np.zeros(3), 0.0
        t = np.array([dt, dt + _RATE_DT_S])
        r = np.asarray(fix.r_e, float)[None, :] + t[:, None] * v[None, :]
        b = float(fix.clock_bias_m) + drift * t
        pred = predict_ranges([eph], week, sow_nom + t - dt, r, b, eng.iono)
        p0, pc = pred.P[0, 0], pred.Pc[0]
        if not math.isfinite(p0):
            return None
        doppler = _doppler(pc[0], pc[1], self.carrier_hz)
        sow_tx = sow_nom - p0 / C_LIGHT
        w = math.floor(sow_tx / SECONDS_PER_WEEK)
        return SignalPrediction(t_tx_week=int(week + w), t_tx_sow=sow_tx - w * SECONDS_PER_WEEK,
                                doppler_hz=doppler, age_s=dt)


def visible_satellites(nav, week: int, sow: float, r_e, *, mask_deg: float = 5.0
                       ) -> dict[int, float]:
    """``{prn: predicted Doppler [Hz]}`` of the satellites above ``mask_deg`` at a time and an
    approximate position, from a navigation file: the assistance of a cold start with
    ephemeris and a time hint (the scalar receiver searches these first, each around its
    Doppler).

    The receiver is taken as static with a perfect clock: the Doppler errs by the receiver's
    velocity along the line of sight (100 m/s = 420 Hz) and its oscillator offset (1 ppm =
    1.27 kHz), which the search window must cover; a position error of 100 km moves it by
    about 100 Hz.

    Parameters
    ----------
    nav : NavData
        Navigation file (:func:`~sdr_di.orbits.rinex_nav.load_nav`); per satellite the record
        on the air at the time.
    week, sow : int, float
        BDT of the time hint (e.g. the IF file's start) [week, s of week].
    r_e : array_like (3,)
        Approximate receiver position, ECEF [m].
    mask_deg : float
        Elevation mask [deg].
    """
    from ..errors import NoEphemerisError
    from ..frames import elevation_azimuth

    r = np.asarray(r_e, float).reshape(3)
    out: dict[int, float] = {}
    for prn in nav.prns:
        try:
            eph = nav.select(prn, int(week), float(sow), broadcast=True)
        except NoEphemerisError:
            continue
        pred = predict_ranges([eph], int(week), [float(sow), float(sow) + _RATE_DT_S],
                              [r, r], [0.0, 0.0], None)
        el, _ = elevation_azimuth(r, pred.r_sat[0, 0])
        if np.degrees(float(el)) < mask_deg:
            continue
        out[int(prn)] = _doppler(pred.Pc[0, 0], pred.Pc[0, 1], F_B3I)
    return dict(sorted(out.items()))
