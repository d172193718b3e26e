"""Navigation data in force (receiver/navdata.py) and the deep loop's decoding after the
hand-over (deep/navdecode.py, integration/handover.py), issue 18."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from sdr_di.integration.run_integrated import SOLUTION_COLUMNS
from sdr_di.errors import NoEphemerisError
from sdr_di.orbits.rinex_nav import load_nav
from sdr_di.receiver.navdata import BROADCAST, RINEX, NavDataInForce
from sdr_di.scenario import REPO_ROOT
from sdr_di.signal.navmsg import (
    EphemerisAssembler,
    assistance_klobuchar,
    decode_stream,
    nav_bits,
)

NAV = REPO_ROOT / "ephemeris" / "ESBC00DNK_R_20201770000_01D_MN.rnx.gz"
WEEK = 755


@pytest.fixture(scope="module")
def nav():
    return load_nav(NAV)


class _NoIono:
    """An assistance file without ionosphere lines (the records of ``nav``, changed by
    ``change(record)``)."""

    iono = None
    iono_gps = None

    def __init__(self, nav, change=None):
        self._nav = nav
        self._change = change

    def select(self, prn, week, sow, max_age_s=None, broadcast=False):
        e = self._nav.select(prn, week, sow, max_age_s, broadcast)
        return e if self._change is None else self._change(e)


# ---- the rules ---------------------------------------------------------------------------------
def test_decoded_record_wins_and_its_checks(nav):
    recs = {r.toe: r for r in nav.records[27]}
    r6, r7 = recs[367200.0], recs[370800.0]
    sow = 367200.0 + 1800.0                                     # 06:30: r6 on the air
    nd = NavDataInForce(nav)
    assert nd.select_with_source(27, WEEK, sow) == (r6, RINEX)
    # same toe, other content (a foreign file's rounding): the decoded record wins
    d6 = dataclasses.replace(r6, af0=r6.af0 + 1e-9)
    assert nd.offer_ephemeris(d6, 1.0)
    assert nd.select_with_source(27, WEEK, sow) == (d6, BROADCAST)
    # a second copy of the data set (same week, toe, AODE) with other bits: ignored, counted
    assert not nd.offer_ephemeris(dataclasses.replace(d6, af0=0.0))
    assert nd.n_conflicts == 1 and nd.select(27, WEEK, sow) is d6
    # a newer upload (next toe) replaces it; an older one afterwards is stale
    assert nd.offer_ephemeris(r7, 2.0)
    assert nd.select_with_source(27, WEEK, sow) == (r7, BROADCAST)
    assert not nd.offer_ephemeris(d6) and nd.n_rejected == 1
    # same toe, new AODE: a new upload
    r7b = dataclasses.replace(r7, AODE=r7.AODE + 1, af0=r7.af0 + 2e-9)
    assert nd.offer_ephemeris(r7b) and nd.select(27, WEEK, sow) is r7b
    # health flag set: the decoded data is withdrawn, the assistance record is used
    assert nd.offer_ephemeris(dataclasses.replace(r7b, SatH1=1))
    assert nd.select_with_source(27, WEEK, sow) == (r6, RINEX)
    assert [e.kind for e in nd.events] == ["ephemeris", "ephemeris", "ephemeris", "unhealthy"]
    # a decoded record older than the file's record on the air still wins (the signal's)
    r5 = recs[363600.0]
    nd2 = NavDataInForce(nav, decoded={27: r5})
    assert nd2.select_with_source(27, WEEK, sow) == (r5, BROADCAST)
    # a decoded record too old to be used, and no assistance: no record
    nd3 = NavDataInForce(None, decoded={27: r6})
    assert nd3.select(27, WEEK, sow) is r6
    assert not nd3.has(27, WEEK, 367200.0 + 7300.0)
    with pytest.raises(NoEphemerisError, match="no assistance file"):
        nd3.select(27, WEEK, 367200.0 + 7300.0)


def test_klobuchar_in_force_and_models(nav):
    rinex_klob, label = assistance_klobuchar(nav)
    assert rinex_klob is not None and label.startswith("GPSA")  # this file: GPS lines only
    nd = NavDataInForce(nav)
    assert nd.klobuchar == rinex_klob and nd.iono_source == RINEX
    none = NavDataInForce(_NoIono(nav))
    assert none.klobuchar is None and none.models()["ionosphere"]["model"] == "none"
    decoded = dataclasses.replace(rinex_klob, alpha=(1e-8, 0.0, 0.0, 0.0))
    assert none.offer_klobuchar(decoded, 3.0) and not none.offer_klobuchar(decoded)
    assert none.klobuchar is decoded and none.iono_source == BROADCAST
    assert none.models()["troposphere"]["model"] == "saastamoinen"


def test_scalar_pvt_takes_the_same_rules(nav):
    """run_scalar's on_epoch feeds PvtEngine.navdata; an unhealthy decoded record never
    reaches the solver."""
    from sdr_di.receiver.pvt import PvtEngine

    eng = PvtEngine(2.5e6, {}, None)
    r6 = {r.toe: r for r in nav.records[27]}[367200.0]
    src = eng.navdata.offer_decoded({27: dataclasses.replace(r6, SatH1=1), 8: None}, None)
    assert src is eng.navdata and not src.has(27, WEEK, 369000.0)
    src.offer_decoded({27: r6})
    assert src.select(27, WEEK, 369000.0) is r6


# ---- decoding in the vector loop -------------------------------------------------------------
def _prompts(bits, bit_ms, ms0, n_ms, rng, cn0_dbhz=35.0, f_hz=2.0, phase=0.3):
    """1 ms prompts (NH wiped) of a signal carrying ``bits`` (bit k starts at ms ``k
    bit_ms`` of ``bits``' time base), with a residual Doppler ``f_hz`` and noise."""
    ms = ms0 + np.arange(n_ms)
    sign = 1.0 - 2.0 * bits[ms // bit_ms].astype(float)
    amp = math.sqrt(2.0 * 10 ** (cn0_dbhz / 10) * 1e-3)          # |P| over unit noise
    ph = phase + 2 * np.pi * f_hz * ms * 1e-3
    noise = rng.normal(size=n_ms) + 1j * rng.normal(size=n_ms)
    return sign * amp * np.exp(1j * ph) + noise


@pytest.mark.parametrize("prn, toe", [(27, 367200.0), (5, 367200.0)])
def test_channel_decoder_rebuilds_the_broadcast_record(nav, prn, toe):
    """D1 (C27) and D2 (C05): the loop's decoder, fed 1 ms prompts with a residual Doppler,
    noise, a half-cycle phase and a start in the middle of a bit and of a subframe, rebuilds
    the record the scalar decoders rebuild from the same bits."""
    from sdr_di.deep.navdecode import ChannelNavDecoder

    eph = {r.toe: r for r in nav.records[prn]}[toe]
    klob = assistance_klobuchar(nav)[0]
    nb = nav_bits(eph, WEEK, 367200.0 + 600.0, 70.0, klob)
    bit_ms = 20 if nb.nav_type == "D1" else 2
    expect = EphemerisAssembler(prn)
    want = None
    for d in decode_stream(nb.bits, prn=prn):
        want = expect.add(d) or want
    assert want is not None
    ms_t0 = round(nb.t0 * 1000)
    n_ms = nb.bits.size * bit_ms
    rng = np.random.default_rng(prn)
    start = 3 * 6000 // (1 if bit_ms == 20 else 10) + 7        # mid-subframe, mid-bit
    p = _prompts(nb.bits, bit_ms, start, n_ms - start, rng, phase=0.3 + np.pi)
    dec = ChannelNavDecoder(prn, bit_ms == 20, ms_t0 - 1000)    # loop epoch e = ms - ms0
    out = []
    for a in range(0, p.size, 20):              # the loop's fast test passes every 20 ms
        ep = np.arange(start + a, start + min(a + 20, p.size)) + 1000
        dec.add(p[a:a + 20], ep)
        out += dec.confirm(60 // bit_ms)
    ephs = [e for e, _ in out if e is not None]
    assert ephs and ephs[-1] == want[0]
    assert any(k == want[1] for _, k in out)
    if bit_ms == 20:       # D1: the coefficients as soon as subframe 1 is decoded
        first_k = next(i for i, (_, k) in enumerate(out) if k is not None)
        first_e = next(i for i, (e, _) in enumerate(out) if e is not None)
        assert first_k <= first_e
    assert dec.n_failed <= 1                                    # the cut first subframe
    # the same prompts one subframe late on the loop's clock: the time check refuses them
    late = ChannelNavDecoder(prn, bit_ms == 20, ms_t0 - 1000 + (6000 if bit_ms == 20 else 600))
    got = []
    for a in range(0, p.size, 20):
        ep = np.arange(start + a, start + min(a + 20, p.size)) + 1000
        late.add(p[a:a + 20], ep)
        got += late.confirm(60 // bit_ms)
    assert got == [] and late.n_subframes == 0 and late.n_failed > 3


def test_seeded_bits_complete_the_subframe_cut_by_the_hand_over(nav):
    """The scalar channel's bits of the subframe in progress at the hand-over plus the
    loop's prompts decode that subframe (no subframe is lost at the hand-over)."""
    from sdr_di.deep.navdecode import ChannelNavDecoder

    eph = {r.toe: r for r in nav.records[27]}[367200.0]
    nb = nav_bits(eph, WEEK, 367200.0 + 600.0, 12.0, assistance_klobuchar(nav)[0])
    ms_t0 = round(nb.t0 * 1000)
    cut = 150                                                   # bits before the hand-over
    dec = ChannelNavDecoder(27, True, ms_t0)
    dec.seed(0, nb.bits[:cut])
    rng = np.random.default_rng(1)
    p = _prompts(nb.bits, 20, cut * 20, (300 - cut) * 20 + 40, rng)
    dec.add(p, np.arange(cut * 20, cut * 20 + p.size))
    assert dec.n_subframes == 1 and dec.n_failed == 0


def test_decoded_subframe_waits_for_the_signal_test_after_its_last_bit(nav):
    """A decoded subframe reaches the assembler only when a passed test's window of bit sums
    starts after its last bit; a failed test before that drops it (the scalar channel's rule,
    signal.navmsg.HeldSubframes)."""
    from sdr_di.deep.navdecode import ChannelNavDecoder

    eph = {r.toe: r for r in nav.records[27]}[367200.0]
    klob = assistance_klobuchar(nav)[0]
    nb = nav_bits(eph, WEEK, 367200.0 + 600.0, 12.0, klob)    # subframes 1 and 2 of a frame
    ms_t0 = round(nb.t0 * 1000)
    p = _prompts(nb.bits, 20, 0, 300 * 20 + 4 * 20 + 1, np.random.default_rng(2))

    def decoder(n_ms):
        dec = ChannelNavDecoder(27, True, ms_t0)
        dec.add(p[:n_ms], np.arange(n_ms))
        return dec

    dec = decoder(300 * 20 + 1)           # subframe 1's last bit just ended
    assert dec.n_subframes == 1 and dec.confirm(3) == []
    dec.add(p[300 * 20 + 1:], np.arange(300 * 20 + 1, p.size))   # 4 more bits
    assert dec.confirm(5) == []           # the window starts before the last bit ended
    got = dec.confirm(3)                  # starts after it: the coefficients of subframe 1
    assert len(got) == 1 and got[0][1] is not None and dec.confirm(3) == []
    dec = decoder(p.size)
    dec.interrupt()                       # the test failed: the subframe is dropped
    assert dec.confirm(3) == []


def test_held_subframes_are_taken_with_their_ends():
    """HeldSubframes.take hands every held (end, subframe) pair over, oldest first, and holds
    nothing after (the deep hand-over moves them to the loop's decoder)."""
    from sdr_di.signal.navmsg import HeldSubframes

    held = HeldSubframes()
    a, b = {"FraID": 2}, {"FraID": 3}
    held.hold(a, 120)
    held.hold(b, 6120)
    assert held.take() == [(120, a), (6120, b)]
    assert len(held) == 0 and held.confirmed(10 ** 6) == []


_SC_OFF = 500       # scalar epoch = ms of the frame + _SC_OFF
_LOOP_OFF = 1000    # loop epoch = ms of the frame + _LOOP_OFF
_H = 18010          # hand-over: 10 ms after subframe 3 ended (ms of the frame)


def _handed_over_subframe_3(nav):
    """A scalar channel of C27 that confirmed subframes 1-2 of a frame and still held
    subframe 3 (ended 10 ms before the hand-over), the loop decoder
    :func:`~sdr_di.integration.handover.handover_decoder` made of it, the loop's prompts after
    the hand-over (the signal there, 35 dB-Hz) and the record of the frame."""
    from sdr_di.integration.handover import handover_decoder
    from sdr_di.receiver.channel import Channel

    eph = {r.toe: r for r in nav.records[27]}[367200.0]
    nb = nav_bits(eph, WEEK, 367200.0 + 600.0, 24.0, assistance_klobuchar(nav)[0])
    sfs = {d["FraID"]: d for d in decode_stream(nb.bits, prn=27)}
    want = EphemerisAssembler(27)
    assert want.add(sfs[1]) is None and want.add(sfs[2]) is None
    want = want.add(sfs[3])
    assert want is not None
    sc = Channel(27, 2.5e6, 0.0, log=False)
    for k in (1, 2):                       # confirmed before the hand-over
        assert sc.assembler.add(sfs[k]) is None
    sc._accept_subframe(dict(sfs[3], epoch=sfs[3]["offset"] * 20 + _SC_OFF))
    sc.epoch = _H + _SC_OFF                # next epoch: the hand-over's
    sc.bit_runs = [[_SC_OFF, bytearray(nb.bits[:_H // 20].tolist())]]
    ms0 = round(nb.t0 * 1000) - _LOOP_OFF
    dec = handover_decoder(sc, _H + _LOOP_OFF, ms0)
    p = _prompts(nb.bits, 20, _H, 5 * 20, np.random.default_rng(3))
    return sc, dec, p, want


def test_subframe_held_at_the_hand_over_is_confirmed_by_the_loop_test(nav):
    """A subframe the scalar channel still held at the hand-over waits in the loop's decoder
    for a passed test whose window starts after its last bit, and the data set it completes
    comes out of confirm (what the vector loop offers to its navigation data). Before, the
    hand-over passed it to the assembler unconfirmed and the set landed in the scalar
    channel's ``ephemeris``, which nothing reads after the hand-over."""
    sc, dec, p, want = _handed_over_subframe_3(nav)
    assert sc.assembler.ephemeris is None and sc.ephemeris is None
    ep = np.arange(_H, _H + p.size) + _LOOP_OFF
    n = 45                                 # bits 900-901 complete: the window starts before
    dec.add(p[:n], ep[:n])                 # subframe 3's end (bit 900)
    assert dec.confirm(3) == []
    dec.add(p[n:n + 20], ep[n:n + 20])     # bits 900-902 complete: it starts at the end
    got = dec.confirm(3)
    assert got == [want] and dec.confirm(3) == []
    assert dec.n_subframes == 0            # the loop decoded none itself


def test_subframe_held_at_the_hand_over_is_dropped_by_a_failed_loop_test(nav):
    """The loop's test fails before it confirmed the handed-over subframe (a blockage at
    the hand-over): the subframe is dropped and never reaches the assembler, even when the
    signal returns."""
    sc, dec, p, _ = _handed_over_subframe_3(nav)
    ep = np.arange(_H, _H + p.size) + _LOOP_OFF
    dec.add(p[:30], ep[:30])
    dec.interrupt()                        # the fast C/N0 test failed
    dec.add(p[30:], ep[30:])
    assert dec.confirm(3) == []
    assert sc.assembler.ephemeris is None and 3 not in sc.assembler._parts


# ---- end to end ----------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def late_start_file(tmp_path_factory):
    """40 s default scenario at 2.5 MHz starting at 06:30:14 BDT: the scalar receiver has its
    time from subframe 4 (+4..+10 s) and hands over in subframe 5; subframe 1 (Klobuchar)
    arrives at +16..+22 s and subframes 2-3 at +22..+34 s, all in the vector loop."""
    from sdr_di.cli import main

    out = tmp_path_factory.mktemp("navdata")
    text = (REPO_ROOT / "signals" / "default.toml").read_text()
    text = text.replace('start = "2020-06-25T06:30:00"', 'start = "2020-06-25T06:30:14"')
    text = text.replace('"../ephemeris/', f'"{REPO_ROOT / "ephemeris"}/')
    sc = out / "late.toml"
    sc.write_text(text)
    assert main(["generate", "--scenario", str(sc), "--duration", "40", "--fs", "2.5e6",
                 "--out", str(out), "--no-progress"]) == 0
    return out


def _iono_bias_m(nav, prns, t_sow, truth_llh):
    """Position error [m] of a fix on ``prns`` that leaves the B3I Klobuchar delays out
    (least squares over position and clock, equal weights)."""
    from sdr_di.deep import predict_ranges
    from sdr_di.frames import llh_to_ecef

    ephs = [nav.select(p, WEEK, t_sow, broadcast=True) for p in prns]
    r = llh_to_ecef(*truth_llh)
    with_i = predict_ranges(ephs, WEEK, [t_sow], [r], [0.0], assistance_klobuchar(nav)[0])
    without = predict_ranges(ephs, WEEK, [t_sow], [r], [0.0], None)
    dI = with_i.P[:, 0] - without.P[:, 0]
    H = np.column_stack([-with_i.U[:, 0], np.ones(len(prns))])
    return float(np.linalg.norm(np.linalg.lstsq(H, dI, rcond=None)[0][:3]))


@pytest.mark.slow
@pytest.mark.parametrize("nco_latency", [0, 1])
def test_deep_without_iono_lines_and_a_differing_record_takes_up_the_decoded_data(
        late_start_file, nav, monkeypatch, capsys, nco_latency):
    """Issue 18 on a generated file: the assistance file has no ionosphere lines and records
    whose clocks differ from the broadcast ones by +-3 ns; the hand-over does not wait
    (``iono_wait_s=0``). The run warns once, switches the Klobuchar model on when the loop
    decodes subframe 1, takes up the decoded records when subframes 2-3 complete them, and
    after both its position error is that of a run with the right models.

    Bound: the EKF's position RMSE on the generated default scenario with every model right
    is below 0.3 m (tests/test_deep.py; 0.163 m measured on this file); the ionosphere left
    out would bias the position by the least-squares projection of the delays (computed
    here, metres), the clock errors by up to ~1 m. The error from 2 s after the last switch
    must be below 0.3 m and below a fifth of the ionosphere bias.

    ``nco_latency=1`` (NCOs one interval ahead): each model change is taken up at the end of
    the interval being correlated, and its pre-filter step waits for that interval's
    correlations; the same bounds hold."""
    import sdr_di.orbits.rinex_nav as rinex_nav
    from sdr_di.integration.run_integrated import run_integrated
    from sdr_di.integration.receiver import IntegrationConfig
    from sdr_di.receiver.run_scalar import open_source

    def change(e):
        return dataclasses.replace(e, af0=e.af0 + (3e-9 if e.prn % 2 else -3e-9))

    monkeypatch.setattr(rinex_nav, "load_nav", lambda path: _NoIono(nav, change))
    src = open_source(late_start_file / "default.bin")
    out = late_start_file / f"run{nco_latency}"
    summ = run_integrated(src, out, config=IntegrationConfig(filter="ekf", iono_wait_s=0.0,
                                                       nco_latency=nco_latency),
                    progress=False)
    err = capsys.readouterr().err
    assert err.count("sdr-di: warning:") == 1 and "without ionosphere" in err
    s = json.loads((out / "default_deep_summary.json").read_text())
    assert len(s["warnings"]) == 1
    navs = s["navigation"]
    t_h = s["handover_s"]
    hist = navs["ionosphere"]["history"]
    assert hist[0]["model"] == "none" and hist[0]["t_s"] == pytest.approx(t_h, abs=0.2)
    assert hist[-1]["model"] == "klobuchar" and hist[-1]["source"] == "broadcast"
    t_iono = hist[-1]["t_s"]
    assert t_h < t_iono < 24.0                                  # subframe 1 ends at +22 s
    assert navs["ionosphere"]["source"] == "broadcast"
    assert navs["troposphere"]["model"] == "saastamoinen"
    t_eph = []
    for name, h in navs["ephemerides"].items():
        prn = int(name[1:])
        on_air = nav.select(prn, WEEK, 369014.0, broadcast=True)
        assert h[0]["source"] == "rinex" and h[-1]["source"] == "broadcast", (name, h)
        assert h[-1]["toe"] == on_air.toe and h[-1]["week"] == on_air.week
        t_eph.append(h[-1]["t_s"])
    assert t_iono < min(t_eph) and max(t_eph) < 36.0            # subframe 3 ends at +34 s
    rows = np.loadtxt(out / "default_deep.csv", delimiter=",", skiprows=2)
    t, flag = rows[:, 0], rows[:, SOLUTION_COLUMNS.index("nav_change")].astype(int)
    assert np.any(flag & 2) and np.any(flag & 1)
    assert t[np.flatnonzero(flag & 2)[0]] == pytest.approx(t_iono, abs=0.21)
    pe = rows[:, 21:24]
    settled = t >= max(t_eph) + 2.0
    assert settled.sum() >= 15
    rmse = float(np.sqrt(np.mean(np.sum(pe[settled] ** 2, axis=1))))
    truth_llh = np.array([math.radians(40.0), math.radians(116.0), 100.0])
    bias = _iono_bias_m(nav, [int(p) for p in s["prns"]], 369014.0 + 38.0, truth_llh)
    assert rmse < 0.3 and rmse < bias / 5.0, (rmse, bias)
    # before the ionosphere switch the position carried the missing model
    early = (t > t_h + 3.0) & (t < t_iono)
    early_rmse = float(np.sqrt(np.mean(np.sum(pe[early] ** 2, axis=1))))
    assert early_rmse > 3.0 * rmse, (early_rmse, rmse)
    assert summ.result.nav_change.size == t.size


@pytest.mark.slow
def test_deep_hand_over_waits_for_subframe_1(late_start_file, nav, monkeypatch, capsys):
    """Same file and assistance without ionosphere lines, ``iono_wait_s`` 30 s: the
    hand-over waits for the scalar channels' first subframe 1 (+16..+22 s; their ephemeris
    sets would complete only at +34 s), so there is no warning and the loop starts with the
    broadcast Klobuchar model."""
    import sdr_di.orbits.rinex_nav as rinex_nav
    from sdr_di.integration.run_integrated import run_integrated
    from sdr_di.integration.receiver import IntegrationConfig
    from sdr_di.receiver.run_scalar import open_source

    monkeypatch.setattr(rinex_nav, "load_nav", lambda path: _NoIono(nav))
    src = open_source(late_start_file / "default.bin")
    out = late_start_file / "run_wait"
    run_integrated(src, out, config=IntegrationConfig(filter="ekf", iono_wait_s=30.0), progress=False,
             duration_s=27.0)
    assert "warning" not in capsys.readouterr().err
    s = json.loads((out / "default_deep_summary.json").read_text())
    assert s["warnings"] == []
    assert 22.0 <= s["handover_s"] < 24.0
    hist = s["navigation"]["ionosphere"]["history"]
    assert hist == [{"t_s": pytest.approx(s["handover_s"], abs=0.2), "model": "klobuchar",
                     "source": "broadcast"}]


def test_deep_config_checks_iono_wait():
    from sdr_di.integration.receiver import IntegrationConfig

    assert IntegrationConfig().iono_wait_s == 0.0      # hand over at once, flag the rows
    for bad in (-1.0, math.inf, math.nan):
        with pytest.raises(ValueError, match="iono_wait_s"):
            IntegrationConfig(iono_wait_s=bad)
