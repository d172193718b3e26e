"""RINEX 3.05 output: observation and navigation files, read back with georinex and our reader.

The end-to-end test runs the scalar receiver on 8 s of a generated file at 2.5 MHz (the
session's 16 s file):
long enough for frame synchronization (pseudoranges) on some satellites and not on others
(phase, Doppler and C/N0 only, with the half-cycle flag), too short for a decoded ephemeris.
Fix-dependent fields (clock offset, approximate position) are tested with synthetic epochs.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import math
from pathlib import Path

import georinex
import numpy as np
import pytest

from sdr_di.cli import main
from sdr_di.io import rinex_writer as rw
from sdr_di.orbits.ephemeris import Klobuchar
from sdr_di.orbits.rinex_nav import crosscheck_with_georinex, load_nav
from sdr_di.receiver import run_scalar as run_scalar_mod
from sdr_di.receiver.observables import ReceiverTime, form_observables
from sdr_di.receiver.pvt import PvtEngine
from sdr_di.receiver.tracking import ChannelObservation
from sdr_di.timebase import bdt_to_datetime

# georinex 1.16's navigation reader merges datasets the way xarray plans to change
pytestmark = pytest.mark.filterwarnings("ignore:In a future version of xarray:FutureWarning")

REPO = Path(__file__).resolve().parents[1]
NAV = REPO / "ephemeris" / "ESBC00DNK_R_20201770000_01D_MN.rnx.gz"
WEEK, SOW = 755, 369612.3456789123
CREATED = dt.datetime(2026, 1, 2, 3, 4, 5)
KLOB = Klobuchar(alpha=(1.1175870895e-08, 2.2351741791e-08, -5.9604644775e-08, 1.1920928955e-07),
                 beta=(122880.0, 98304.0, -131072.0, -458752.0))
REQUIRED_OBS = ("RINEX VERSION / TYPE", "PGM / RUN BY / DATE", "MARKER NAME", "OBSERVER / AGENCY",
                "REC # / TYPE / VERS", "ANT # / TYPE", "APPROX POSITION XYZ",
                "ANTENNA: DELTA H/E/N", "SYS / # / OBS TYPES", "SIGNAL STRENGTH UNIT",
                "TIME OF FIRST OBS", "SYS / PHASE SHIFT", "END OF HEADER")


# --- a small fixed-width reader of our own (georinex gives no LLI for band 6) ---------------
def _read_obs(path: Path) -> tuple[dict[str, list[str]], list[dict]]:
    """Header (label -> contents) and epochs [{'line', 'sats': {prn: [(value, lli, ssi)]}}]."""
    lines = path.read_text(encoding="ascii").splitlines()
    hdr: dict[str, list[str]] = {}
    i = 0
    while True:
        ln = lines[i]
        assert len(ln) == 80 or ln[60:].strip() == "END OF HEADER", ln
        hdr.setdefault(ln[60:].strip(), []).append(ln[:60])
        i += 1
        if ln[60:].strip() == "END OF HEADER":
            break
    epochs = []
    while i < len(lines):
        head = lines[i]
        assert head.startswith("> ")
        n = int(head[32:35])
        sats = {}
        for ln in lines[i + 1:i + 1 + n]:
            fields = []
            for k in range(4):
                f = ln[3 + 16 * k:3 + 16 * (k + 1)].ljust(16)
                v = float(f[:14]) if f[:14].strip() else math.nan
                fields.append((v, int(f[14]) if f[14].strip() else 0,
                               int(f[15]) if f[15].strip() else None))
            sats[int(ln[1:3])] = fields
        epochs.append({"line": head, "sats": sats})
        i += 1 + n
    return hdr, epochs


def _epoch_time(line: str) -> dt.datetime:
    """Time of an epoch record to the microsecond (plus the 0.1 us digit, rounded)."""
    y, mo, d, h, mi = (int(x) for x in line[2:18].split())
    return dt.datetime(y, mo, d, h, mi) + dt.timedelta(seconds=float(line[18:29]))


def _georinex_times(ds) -> list[dt.datetime]:
    return [dt.datetime(1970, 1, 1) + dt.timedelta(microseconds=int(t))
            for t in ds.time.values.astype("datetime64[us]").astype(np.int64)]


def _bdt(week: int, sow: float) -> dt.datetime:
    return bdt_to_datetime(week, sow)


# --- observation file: format and georinex --------------------------------------------------
def test_obs_file_header_epochs_and_georinex(tmp_path):
    path = tmp_path / "x_obs.rnx"
    s = rw.SatObservation
    with rw.RinexObsWriter(path, marker_name="x", interval_s=0.2,
                           creation_time=CREATED) as w:
        assert w.write_epoch(WEEK, SOW, [s(27, 22000000.1234, -1234567.891, 2500.5, 40.2, 3),
                                         s(8, math.nan, 55.0, -1000.25, 38.0, 2)])
        assert not w.write_epoch(WEEK, math.nan, [s(27, 2.0e7)])     # no receiver time yet
        assert not w.write_epoch(WEEK, SOW + 0.1, [s(30)])          # nothing observed
        assert w.write_epoch(WEEK, SOW + 0.2, [s(8, 23000000.0, 56.0, -1000.0, 38.0, 1),
                                               s(27, 22000500.1234, -1234000.0, 2500.5, 40.2)],
                             clock_offset_s=1.234567890123e-3,
                             position_e=(-2148000.1, 4426000.2, 4044000.3))
        assert path.with_name(path.name + ".body.part").exists() and not path.exists()
    assert not path.with_name(path.name + ".body.part").exists()
    hdr, epochs = _read_obs(path)
    assert [k for k in REQUIRED_OBS if k not in hdr] == []
    assert list(hdr)[0] == "RINEX VERSION / TYPE" and list(hdr)[-1] == "END OF HEADER"
    v = hdr["RINEX VERSION / TYPE"][0]
    assert v[:9] == "     3.05" and v[20] == "O" and v[40] == "C"
    assert hdr["PGM / RUN BY / DATE"][0][40:59] == "20260102 030405 UTC"
    assert hdr["SYS / # / OBS TYPES"] == ["C    4 C6I L6I D6I S6I".ljust(60)]
    assert hdr["SIGNAL STRENGTH UNIT"][0].strip() == "DBHZ"
    assert hdr["SYS / PHASE SHIFT"][0].rstrip() == "C L6I  0.00000"
    assert hdr["RCV CLOCK OFFS APPL"][0].strip() == "0"
    first = hdr["TIME OF FIRST OBS"][0]
    assert first[:43] == "  2020     6    25     6    40   12.3456789" and first[48:51] == "BDT"
    assert hdr["TIME OF LAST OBS"][0][30:43] == "   12.5456789"
    assert [float(x) for x in hdr["APPROX POSITION XYZ"][0].split()] == [-2148000.1, 4426000.2,
                                                                       4044000.3]
    assert hdr["PRN / # / OBS"] == ["   C08     1     2     2     2".ljust(60),
                                    "   C27     2     2     2     2".ljust(60)]
    # epoch records: exact columns, receiver clock offset F15.12 in columns 42-56
    assert epochs[0]["line"] == "> 2020 06 25 06 40 12.3456789  0  2"
    assert epochs[1]["line"] == "> 2020 06 25 06 40 12.5456789  0  2       0.001234567890"
    assert epochs[0]["sats"][27][1] == (-1234567.891, 3, 6)            # L, LLI, SSI (40 dB-Hz)
    assert epochs[0]["sats"][8][0][0] != epochs[0]["sats"][8][0][0]    # blank C: NaN

    ds = georinex.load(path, useindicators=True)
    assert ds.attrs["time_system"] == "BDT" and ds.attrs["version"] == 3.05
    assert sorted(ds.sv.values.tolist()) == ["C08", "C27"]
    expect = [_bdt(WEEK, SOW), _bdt(WEEK, SOW + 0.2)]
    # georinex truncates to the microsecond, datetime rounds to it: 1.5 us at most
    assert [abs((a - b).total_seconds()) <= 1.5e-6 for a, b in zip(_georinex_times(ds), expect)] \
        == [True, True]
    c27 = ds.sel(sv="C27")
    np.testing.assert_array_equal(c27["C6I"].values, [22000000.123, 22000500.123])
    np.testing.assert_array_equal(ds.sel(sv="C08")["D6I"].values, [-1000.25, -1000.0])
    np.testing.assert_array_equal(c27["S6I"].values, [40.2, 40.2])
    np.testing.assert_array_equal(c27["C6Issi"].values, [6, 6])
    assert ds.attrs["time_offset"] == [0.00123456789]
    assert ds.attrs["position"] == [-2148000.1, 4426000.2, 4044000.3]


def test_obs_abort_and_failure_leave_nothing(tmp_path):
    path = tmp_path / "y_obs.rnx"
    w = rw.RinexObsWriter(path)
    w.write_epoch(WEEK, SOW, [rw.SatObservation(1, 3.6e7)])
    w.abort()
    with pytest.raises(RuntimeError):
        with rw.RinexObsWriter(path) as w2:
            w2.write_epoch(WEEK, SOW, [rw.SatObservation(1, 3.6e7)])
            raise RuntimeError("boom")
    with pytest.raises(ValueError, match="distinct"):
        with rw.RinexObsWriter(path) as w3:
            w3.write_epoch(WEEK, SOW, [rw.SatObservation(1, 3.6e7), rw.SatObservation(1, 3.6e7)])
    assert list(tmp_path.iterdir()) == []
    # a run that never got a receiver time: a valid header, no epoch, no TIME OF FIRST OBS
    rw.RinexObsWriter(path).close()
    hdr, epochs = _read_obs(path)
    assert epochs == [] and "TIME OF FIRST OBS" not in hdr


def test_signal_strength_indicator():
    assert [rw.signal_strength_indicator(c) for c in (5.0, 12.0, 29.9, 30.0, 40.0, 53.9, 54.0,
                                                      70.0)] == [1, 2, 4, 5, 6, 8, 9, 9]
    assert rw.signal_strength_indicator(math.nan) is None


# --- receiver adapter: observables, signs, LLI ----------------------------------------------
def _ch(prn, k, *, tx=math.nan, dop=0.0, cyc=0.0, tv=True, cl=True, slips=0, res=None):
    return ChannelObservation(prn=prn, sample_index=k, t_tx_week=WEEK if tv else None,
                              t_tx_sow=tx, doppler_hz=dop, carrier_phase_cycles=cyc,
                              cn0_dbhz=41.0, code_lock=True, carrier_lock=cl, time_valid=tv,
                              slip_count=slips, half_cycle_resolved=tv if res is None else res)


@dataclasses.dataclass
class _Fix:
    valid: bool
    clock_bias_m: float
    r_e: tuple
    sow: float = math.nan


def test_receiver_epochs_signs_and_lli(tmp_path):
    fs = 1.0e6
    rt = ReceiverTime(fs)
    path = tmp_path / "z_obs.rnx"
    w = rw.RinexObsWriter(path)
    # C27 frame-synced and approaching (Doppler > 0: integrated Doppler grows, L falls);
    # C08 in carrier lock, no frame sync yet (no C, half cycle open), then resolved;
    # C30 slips between epochs 2 and 3
    plan = [  # (k, C08 time valid, C30 slips)
        (0, False, 0), (200_000, False, 0), (400_000, True, 0), (600_000, True, 1)]
    written = []
    for j, (k, c08_tv, slips) in enumerate(plan):
        t = k / fs
        chans = [_ch(27, k, tx=SOW + t * (1 + 2e-6) - 0.070, dop=2000.0, cyc=2000.0 * t),
                 _ch(8, k, tx=SOW + t - 0.080 if c08_tv else math.nan, dop=-500.0,
                     cyc=-500.0 * t + 7.25, tv=c08_tv),
                 _ch(30, k, tx=SOW + t - 0.075, dop=100.0, cyc=100.0 * t, slips=slips),
                 _ch(11, k, cl=False, tv=False)]
        chans[3] = dataclasses.replace(chans[3], code_lock=False)   # lost: not written
        obs = form_observables(chans, rt)
        fix = _Fix(j >= 1, 299792.458 * (j + 1), (-2.1e6, 4.4e6, 4.0e6))
        assert w.write(obs, chans, fix)
        written.append(obs)
    w.close()
    hdr, epochs = _read_obs(path)
    assert [sorted(e["sats"]) for e in epochs] == [[8, 27, 30]] * 4
    for e, obs in zip(epochs, written):
        for i, prn in enumerate(obs.prn):
            assert e["sats"][int(prn)][0][0] == round(obs.pseudorange_m[i], 3)
    c27 = [e["sats"][27] for e in epochs]
    assert [f[2][0] for f in c27] == [2000.0] * 4                      # D > 0 approaching
    assert np.all(np.diff([f[1][0] for f in c27]) < 0)                 # L = -integrated Doppler
    assert [f[1][0] for f in c27] == [-0.0, -400.0, -800.0, -1200.0]
    assert np.all(np.diff([f[0][0] for f in c27]) < 0)                 # range decreasing too
    assert [f[1][1] for f in c27] == [1, 0, 0, 0]                      # arc start only
    c08 = [e["sats"][8] for e in epochs]
    assert [math.isnan(f[0][0]) for f in c08] == [True, True, False, False]
    assert [f[1][1] for f in c08] == [3, 2, 1, 0]                      # half cycle until sync
    assert [f[1][0] for f in c08] == [-7.25, 100.0 - 7.25, 200.0 - 7.25, 300.0 - 7.25]
    assert [e["sats"][30][1][1] for e in epochs] == [1, 0, 0, 1]       # the slip
    # clock offset = PVT bias / c where there is a fix; position of the first fix
    assert epochs[0]["line"][41:].strip() == ""
    assert [float(e["line"][41:56]) for e in epochs[1:]] == [2e-3, 3e-3, 4e-3]
    assert [float(x) for x in hdr["APPROX POSITION XYZ"][0].split()] == [-2.1e6, 4.4e6, 4.0e6]
    # epochs at the receiver-clock times of the samples, not rounded to seconds
    for e, obs in zip(epochs, written):
        assert abs((_epoch_time(e["line"]) - _bdt(obs.week, obs.sow)).total_seconds()) <= 5e-8
    assert _epoch_time(epochs[0]["line"]).microsecond != 0


# --- navigation file ------------------------------------------------------------------------
def test_nav_file_round_trip_ours_and_georinex(tmp_path):
    src = load_nav(NAV)
    recs = [r for p in src.prns for r in src.records[p][:2]]
    order = recs[::-1]                      # the decoding order, not the file's
    path = tmp_path / "x_nav.rnx"
    w = rw.RinexNavWriter(path, creation_time=CREATED)
    assert w.update(order[:5], KLOB, t_tx_sow=None) == 5
    assert w.update({o.prn: o for o in order[:5]}) == 0                # each record once
    other = rw.RinexNavWriter(tmp_path / "y_nav.rnx", creation_time=CREATED)
    assert other.add(order[0])
    assert not other.add(dataclasses.replace(order[0]))  # an equal record, another object
    assert other.add(dataclasses.replace(order[0], URAI=order[0].URAI + 1))
    other.abort()
    for r in order[5:]:
        assert w.add(r, t_tx_sow=r.toe + 18.0)
    assert not path.exists()
    w.close()
    text = path.read_text(encoding="ascii")
    body = text.split("END OF HEADER", 1)[1].splitlines()[1:]
    assert [ln[:3] for ln in body[::8]] == [f"C{r.prn:02d}" for r in order]
    assert all(len(ln) == 80 for ln in body)
    back = load_nav(path)
    assert back.n_records == len(recs) and back.n_duplicates == 0
    by_key = {(b.prn, b.week, b.toe): b for p in back.prns for b in back.records[p]}
    for r in recs:
        b = by_key[(r.prn, r.week, r.toe)]
        for f in dataclasses.fields(r):
            x, y = float(getattr(r, f.name)), float(getattr(b, f.name))
            assert math.isclose(x, y, rel_tol=5e-13, abs_tol=1e-300), (r.prn, f.name, x, y)
    r = order[5]
    assert back.tx_times[(r.prn, r.week, r.toe)] == r.week * 604800.0 + r.toe + 18.0
    r = order[0]
    assert back.tx_times[(r.prn, r.week, r.toe)] == r.week * 604800.0 + r.toe
    # Klobuchar: D12.4 keeps 5 significant digits; our reader and georinex agree exactly
    np.testing.assert_allclose(back.iono.alpha + back.iono.beta, KLOB.alpha + KLOB.beta,
                               rtol=5e-5)
    ds = georinex.load(path)
    np.testing.assert_array_equal(ds.attrs["ionospheric_corr_BDS"],
                                  np.array(back.iono.alpha + back.iono.beta))
    stats = crosscheck_with_georinex(back)       # every value georinex reads = ours (1e-12)
    assert stats == {"compared": len(recs), "nan": 0, "unavailable": 0}


def test_nav_abort_writes_nothing(tmp_path):
    path = tmp_path / "n_nav.rnx"
    with pytest.raises(KeyError):
        with rw.RinexNavWriter(path) as w:
            w.add(load_nav(NAV).records[27][0])
            raise KeyError("x")
    assert list(tmp_path.iterdir()) == []


# --- end to end: sdr-di run ------------------------------------------------------------------
class _RecordingEngine(PvtEngine):
    """PvtEngine that keeps the observables its PVT used, epoch by epoch."""

    def __init__(self, *a, **kw):
        super().__init__(*a, **kw)
        self.used, self._inside = [], False
        inner = self.builder

        def builder(*args, **kwargs):
            obs = inner(*args, **kwargs)
            if self._inside:
                self.used.append(obs)
            return obs
        builder.rx_time = inner.rx_time       # the receiver time the run sets its hint on
        self.builder = builder
        _RecordingEngine.last = self

    def process(self, *a, **kw):
        self._inside = True
        try:
            return super().process(*a, **kw)
        finally:
            self._inside = False


def test_run_writes_rinex_read_back_with_georinex(if_files, tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(run_scalar_mod, "PvtEngine", _RecordingEngine)
    # 8 s without assistance (--no-assist: not the sidecar's navigation file): too short
    # for decoded ephemerides, hence no fix: exit 1 (docs/errors.md); the observation and
    # navigation files are written all the same
    assert main(["run", str(if_files(16.0).if_file), "--duration", "8", "--out",
                 str(tmp_path / "run"), "--no-progress", "--no-assist"]) == 1
    out = capsys.readouterr().out
    obs_path, nav_path = tmp_path / "run" / "default_obs.rnx", tmp_path / "run" / "default_nav.rnx"
    assert f"rinex_obs {obs_path}" in out and f"rinex_nav {nav_path}" in out
    used = [o for o in _RecordingEngine.last.used if math.isfinite(o.sow)]
    with_pr = [o for o in used if o.n]
    assert len(with_pr) >= 5
    ds = georinex.load(obs_path, useindicators=True)
    hdr, epochs = _read_obs(obs_path)
    # epochs: every PVT epoch with a receiver time, at that time (georinex: microseconds)
    times = _georinex_times(ds)
    assert len(times) == len(epochs) == len(used)
    assert all(abs((t - _bdt(o.week, o.sow)).total_seconds()) <= 1.5e-6
               for t, o in zip(times, used))
    # satellites: those with a pseudorange, plus those tracked without one yet
    prs = {int(p) for o in with_pr for p in o.prn}
    svs = {int(s[1:]) for s in ds.sv.values}
    assert prs and prs <= svs
    only_phase = svs - prs
    # pseudoranges and Dopplers equal the observables the PVT used, to the file's 1 mm
    for it, o in enumerate(used):
        for i, prn in enumerate(o.prn):
            c = float(ds["C6I"].sel(sv=f"C{int(prn):02d}").values[it])
            assert abs(c - o.pseudorange_m[i]) <= 0.0005 + 1e-6, (prn, c, o.pseudorange_m[i])
            d = float(ds["D6I"].sel(sv=f"C{int(prn):02d}").values[it])
            assert abs(d - o.doppler_hz[i]) <= 0.0005 + 1e-6
            # D > 0 when approaching: the pseudorange rate has the opposite sign
            assert np.sign(d) == -np.sign(o.pseudorange_rate_mps[i])
    # LLI: first phase of every satellite flags an arc start; half-cycle bit on satellites
    # without frame sync, cleared once their pseudorange appears
    first_l = {}
    for e in epochs:
        for prn, f in e["sats"].items():
            if not math.isnan(f[1][0]):
                first_l.setdefault(prn, f[1][1])
                assert bool(f[1][1] & 2) == math.isnan(f[0][0]), (prn, e["line"], f)
    assert all(v & 1 for v in first_l.values()), first_l
    assert only_phase or any(math.isnan(f[0][0]) for e in epochs for f in e["sats"].values())
    # no fix in 8 s (no ephemeris decoded): blank clock offsets, a navigation file with a
    # header only
    assert all(e["line"][41:].strip() == "" for e in epochs)
    assert "END OF HEADER" in nav_path.read_text()


def test_outputs_pair_stamps_new_records_with_the_epoch_time(tmp_path):
    """RinexOutputs: a record is written once, with the BDT time of the epoch it first
    appeared at as its transmission time; the Klobuchar set goes to the header."""
    src = load_nav(NAV)
    a, b = src.records[27][3], src.records[30][3]
    out = rw.RinexOutputs(tmp_path / "p_obs.rnx", tmp_path / "p_nav.rnx", marker_name="p")
    rt = ReceiverTime(1.0e6)
    for j, (ephs, sow) in enumerate((({27: a}, a.toe + 20.0), ({27: a, 30: b}, a.toe + 20.2),
                                     ({27: a, 30: b}, a.toe + 20.4))):
        k = 200_000 * j
        chans = [_ch(27, k, tx=a.toe + 20.0 + k / 1e6 - 0.07)]
        fix = _Fix(True, 30.0, (-2.1e6, 4.4e6, 4.0e6), sow=sow)
        assert out.write(form_observables(chans, rt), chans, fix, ephs, KLOB if j else None)
    assert out.close() == (tmp_path / "p_obs.rnx", tmp_path / "p_nav.rnx")
    nav = load_nav(tmp_path / "p_nav.rnx")
    assert nav.n_records == 2 and nav.iono is not None
    assert nav.tx_times[(27, a.week, a.toe)] == a.week * 604800.0 + a.toe + 20.0
    assert nav.tx_times[(30, b.week, b.toe)] == b.week * 604800.0 + a.toe + 20.2
    hdr, epochs = _read_obs(tmp_path / "p_obs.rnx")
    assert len(epochs) == 3 and hdr["MARKER NAME"][0].strip() == "p"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p_nav.rnx", "p_obs.rnx"]
