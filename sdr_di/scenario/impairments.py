"""Scenario tables of the signal impairments: ``[[interference]]``, ``[[multipath]]``, ``[agc]``.

What each key means, its units and the models behind it: ``docs/impairments.md``. Every
problem is a :class:`~sdr_di.errors.ScenarioError` (or
:class:`~sdr_di.errors.UnknownPrnError`) in one line naming the file, the table and the key.
The checks that need the signal table (a band outside the sampled band) are made by
:func:`check_bands` once ``[signal]`` is known.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from ..errors import ScenarioError

#: Interference types and their keys: (required, optional) besides ``type``.
INTERFERENCE_KEYS: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    "cw": (("js_db",), ("offset_hz", "phase_deg", "start_s", "end_s", "js_end_db")),
    "noise": (("js_db", "bandwidth_hz"), ("offset_hz", "start_s", "end_s", "js_end_db")),
}
#: Accepted J/S [dB]: below -60 dB a jammer is far under the thermal noise of any B3I
#: front end; above 90 dB (J/N0 of 130 dB-Hz at 40 dB-Hz) no quantizer model here means much.
JS_RANGE_DB = (-60.0, 90.0)
#: Largest multipath delay [chips]: beyond a few chips a replica is a separate, resolvable
#: signal (no correlation with the direct one).
MAX_MULTIPATH_DELAY_CHIPS = 20.0


@dataclasses.dataclass(frozen=True)
class Interference:
    """One jammer. J/S is relative to a satellite at the scenario's nominal ``cn0_dbhz``.

    ``js_db`` holds from ``start_s``; with ``js_end_db`` it changes linearly in dB to that
    value at ``end_s``. Times are seconds of true time from the start; ``end_s`` may be inf.
    """

    kind: str  # "cw" or "noise"
    offset_hz: float  # from the IF (the B3I carrier in the sampled band) [Hz]
    js_db: float
    js_end_db: float | None
    start_s: float
    end_s: float
    bandwidth_hz: float = 0.0  # noise: two-sided width of the band [Hz]
    phase_deg: float = 0.0  # cw: carrier phase at sample 0 [deg]

    def js_db_at(self, t):
        """J/S [dB] at true times ``t`` (NaN outside ``[start_s, end_s)``)."""
        t = np.asarray(t, float)
        js = np.full(t.shape, self.js_db)
        if self.js_end_db is not None:
            js = self.js_db + (self.js_end_db - self.js_db) * (t - self.start_s) / (
                self.end_s - self.start_s)
        return np.where((t >= self.start_s) & (t < self.end_s), js, np.nan)

    def as_dict(self) -> dict:
        d = {"type": self.kind, "offset_hz": self.offset_hz, "js_db": self.js_db,
             "js_end_db": self.js_end_db, "start_s": self.start_s,
             "end_s": None if math.isinf(self.end_s) else self.end_s}
        if self.kind == "noise":
            d["bandwidth_hz"] = self.bandwidth_hz
        else:
            d["phase_deg"] = self.phase_deg
        return d


@dataclasses.dataclass(frozen=True)
class Multipath:
    """One delayed replica of a satellite's signal (``prn`` None: every satellite).

    The replica is ``alpha`` times the direct signal, ``delay_chips`` later in code (and in
    data), with the carrier phase ``phase_deg`` from the direct one at the start and the
    carrier Doppler ``doppler_offset_hz`` above it.
    """

    prn: int | None
    alpha: float
    delay_chips: float
    phase_deg: float
    doppler_offset_hz: float
    #: ``reflector = "ground"``: antenna height [m] over a horizontal ground plane; the delay,
    #: its rate (Doppler) and the carrier phase then follow the satellite's elevation
    #: (``delay_chips`` and ``doppler_offset_hz`` are not given; ``phase_deg`` adds to the
    #: reflection's 180 deg). None: the fixed replica above.
    antenna_height_m: float | None = None

    def as_dict(self) -> dict:
        d = {"prn": "all" if self.prn is None else self.prn, "alpha": self.alpha,
             "phase_deg": self.phase_deg}
        if self.antenna_height_m is None:
            d.update(delay_chips=self.delay_chips, doppler_offset_hz=self.doppler_offset_hz)
        else:
            d.update(reflector="ground", antenna_height_m=self.antenna_height_m)
        return d


@dataclasses.dataclass(frozen=True)
class AgcSpec:
    """Front-end AGC: first-order power detector with time constant ``time_constant_s``;
    ``target_sigma_lsb`` the RMS of each quantizer input component it holds [LSB] (None:
    the step that maximizes a uniform quantizer's SNR for a Gaussian input, Max 1960)."""

    time_constant_s: float
    target_sigma_lsb: float | None

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


def parse_interference(raw: Any, where: str) -> tuple[Interference, ...]:
    """``[[interference]]`` array -> jammers (errors name ``where`` and the key)."""
    from .schema import _REQUIRED, _Reader

    if not isinstance(raw, list):
        raise ScenarioError(f"{where}: [[interference]] must be an array of tables")
    out = []
    for i, table in enumerate(raw):
        w = f"{where}: [[interference]][{i}]"
        r = _Reader(table, w)
        kind = r.str_("type", _REQUIRED, tuple(INTERFERENCE_KEYS))
        required, optional = INTERFERENCE_KEYS[kind]
        lo, hi = JS_RANGE_DB
        js = r.num("js_db", _REQUIRED, lo=lo, hi=hi)
        js_end = r.num("js_end_db", lo=lo, hi=hi) if "js_end_db" in table else None
        offset = r.num("offset_hz", 0.0)
        t0 = r.num("start_s", 0.0, lo=0.0)
        t1 = r.num("end_s", math.inf) if "end_s" in table else math.inf
        if t1 <= t0:
            raise ScenarioError(f"{w}.end_s: must be after start_s ({t0:g}), got {t1:g}")
        if js_end is not None and math.isinf(t1):
            raise ScenarioError(f"{w}.js_end_db: a ramp needs end_s")
        bw = r.num("bandwidth_hz", _REQUIRED, lo=0.0, lo_open=True) if kind == "noise" else 0.0
        phase = r.num("phase_deg", 0.0) if "phase_deg" in optional else 0.0
        extra = sorted(set(table) - set(required + optional + ("type",)))
        if extra:
            raise ScenarioError(f"{w}: key(s) {', '.join(map(repr, extra))} not allowed for "
                                f"type {kind!r} (allowed: {', '.join(required + optional)})")
        r.check_unknown()
        out.append(Interference(kind, offset, js, js_end, t0, t1, bw, phase))
    return tuple(out)


def parse_multipath(raw: Any, where: str) -> tuple[Multipath, ...]:
    """``[[multipath]]`` array -> replicas (errors name ``where`` and the key)."""
    from .schema import _REQUIRED, _prn_or_all, _Reader

    if not isinstance(raw, list):
        raise ScenarioError(f"{where}: [[multipath]] must be an array of tables")
    out = []
    for i, table in enumerate(raw):
        w = f"{where}: [[multipath]][{i}]"
        r = _Reader(table, w)
        prn = _prn_or_all(r, w)
        alpha = r.num("alpha", _REQUIRED, lo=0.0, hi=1.0)
        phase = r.num("phase_deg", 0.0)
        if "reflector" in table:
            r.str_("reflector", _REQUIRED, ("ground",))
            for key in ("delay_chips", "doppler_offset_hz"):
                if key in table:
                    raise ScenarioError(f"{w}.{key}: not with reflector (the geometry gives it)")
            height = r.num("antenna_height_m", _REQUIRED, lo=0.0, lo_open=True, hi=1000.0)
            r.check_unknown()
            out.append(Multipath(prn, alpha, 0.0, phase, 0.0, height))
            continue
        delay = r.num("delay_chips", _REQUIRED, lo=0.0, hi=MAX_MULTIPATH_DELAY_CHIPS)
        dop = r.num("doppler_offset_hz", 0.0, lo=-500.0, hi=500.0)
        r.check_unknown()
        out.append(Multipath(prn, alpha, delay, phase, dop))
    return tuple(out)


def parse_agc(raw: Any, where: str) -> AgcSpec:
    """``[agc]`` table (absent: the defaults)."""
    from .schema import _Reader

    r = _Reader(raw, f"{where}: [agc]")
    tc = r.num("time_constant_s", 0.01, lo=0.0, lo_open=True, hi=10.0)
    tgt = r.num("target_sigma_lsb", lo=0.0, lo_open=True) if "target_sigma_lsb" in raw else None
    r.check_unknown()
    return AgcSpec(tc, tgt)


def check_bands(jammers: tuple[Interference, ...], fs: float, if_hz: float,
                complex_baseband: bool, where: str) -> None:
    """Each jammer's band inside the sampled band: ``(-fs/2, fs/2)`` for complex samples,
    ``(0, fs/2)`` for real ones (frequencies of the IF plus the offset)."""
    lo, hi = (-fs / 2, fs / 2) if complex_baseband else (0.0, fs / 2)
    for i, j in enumerate(jammers):
        f0 = if_hz + j.offset_hz - j.bandwidth_hz / 2
        f1 = if_hz + j.offset_hz + j.bandwidth_hz / 2
        if not (lo < f0 and f1 < hi):
            key = "bandwidth_hz" if j.kind == "noise" and lo < if_hz + j.offset_hz < hi \
                else "offset_hz"
            raise ScenarioError(
                f"{where}: [[interference]][{i}].{key}: band {f0 / 1e6:.4g}..{f1 / 1e6:.4g} MHz "
                f"is outside the sampled band {lo / 1e6:.4g}..{hi / 1e6:.4g} MHz")
