"""BeiDou time (BDT) conversions.

BDT starts 2006-01-01 00:00:00 UTC, has no leap seconds, and BDT = GPST - 14 s; the BDT week
number is the GPS week number minus 1356. Times are carried as (week, seconds of week) or as
float seconds since a scenario epoch.
"""

from __future__ import annotations

import datetime as _dt

from .constants import SECONDS_PER_WEEK

#: BDT epoch (week 0, sow 0) as a naive datetime on the BDT scale.
BDT_EPOCH = _dt.datetime(2006, 1, 1, 0, 0, 0)
#: UTC - BDT leap-second offset table: (first UTC instant it applies, BDT - UTC [s]).
#: BDT - UTC was 0 at the BDT epoch; leap seconds added since then.
_LEAPS_SINCE_2006 = (
    (_dt.datetime(2006, 1, 1), 0),
    (_dt.datetime(2009, 1, 1), 1),
    (_dt.datetime(2012, 7, 1), 2),
    (_dt.datetime(2015, 7, 1), 3),
    (_dt.datetime(2017, 1, 1), 4),
)


def bdt_minus_utc(utc: _dt.datetime) -> int:
    """Leap seconds BDT - UTC [s] in force at the UTC instant ``utc`` (2006 onward)."""
    if utc < BDT_EPOCH:
        raise ValueError(f"UTC time {utc} is before the BDT epoch 2006-01-01")
    off = 0
    for start, value in _LEAPS_SINCE_2006:
        if utc >= start:
            off = value
    return off


def datetime_to_bdt(t: _dt.datetime) -> tuple[int, float]:
    """Convert a naive datetime on the BDT scale to (BDT week, seconds of week [s])."""
    dt = (t - BDT_EPOCH).total_seconds()
    if dt < 0:
        raise ValueError(f"time {t} is before the BDT epoch 2006-01-01")
    week = int(dt // SECONDS_PER_WEEK)
    return week, dt - week * SECONDS_PER_WEEK


def utc_to_bdt(utc: _dt.datetime) -> tuple[int, float]:
    """Convert a naive UTC datetime to (BDT week, seconds of week [s])."""
    return datetime_to_bdt(utc + _dt.timedelta(seconds=bdt_minus_utc(utc)))


def bdt_to_datetime(week: int, sow: float) -> _dt.datetime:
    """Convert (BDT week, sow [s]) to a naive datetime on the BDT scale."""
    return BDT_EPOCH + _dt.timedelta(seconds=week * SECONDS_PER_WEEK + sow)


def gpst_datetime_to_bdt_datetime(t_gpst: _dt.datetime) -> _dt.datetime:
    """Shift a GPST datetime to the BDT scale (BDT = GPST - 14 s)."""
    return t_gpst - _dt.timedelta(seconds=14)


def wrap_week_seconds(dt: float) -> float:
    """Wrap a time difference [s] into [-302400, 302400) (ICD week-crossover rule)."""
    half = SECONDS_PER_WEEK / 2.0
    return (dt + half) % SECONDS_PER_WEEK - half
