"""A blockage that starts just before a subframe ends must not leave a wrong ephemeris.

The scalar channel keeps demodulating bits until its lock detector declares the loss, a few
hundred ms after the signal is gone. D1 words are BCH(15,11) coded, a perfect code: every
noise word "corrects" to some codeword, so a subframe whose last bits are noise decodes
without an error and completes the data set with wrong fields. Seen in the count-change
experiment (7-3-7, seed 0, 2.5 MHz): C10 was blocked 120 ms before the end of its subframe 3,
the record it then decoded had an argument of perigee 2.4e-5 rad off (1 km of satellite
position, 40 m of modelled range), and that record stayed in force after the satellite came
back, so the loose and tight couplings' gates rejected C10 for the rest of the run.

The file (2.5 MHz, two D1 satellites, 19.6 s) starts one second before a D1 frame, so the
channels decode subframes 1-3, the last one received at t = 19.07 s. The first satellite is
blocked from 18.9 s (its last ~8 bits are noise), the second is never blocked.

Second line of defence (:class:`~sdr_di.receiver.navdata.NavDataInForce`): a wrong first copy
of a data set is replaced once two later copies agree against it.
"""

import dataclasses
import json
import math

import numpy as np
import pytest

from sdr_di.constants import C_LIGHT
from sdr_di.orbits.broadcast import sat_pos_vel_clock
from sdr_di.orbits.rinex_nav import load_nav
from sdr_di.receiver.ifreader import IfSource
from sdr_di.receiver.navdata import BROADCAST, RINEX, NavDataInForce
from sdr_di.receiver.scalar import ScalarReceiver
from sdr_di.scenario import DEFAULT_SCENARIO, REPO_ROOT, load_scenario, parse_scenario
from sdr_di.signal.navmsg import EphemerisAssembler, decode_stream, nav_bits
from sdr_di.sim.generate import generate_files, make_generator
from sdr_di.timebase import bdt_to_datetime

FS = 2.5e6
T_BLOCK = 18.9      # the third subframe ends at ~19.07 s of file time


@pytest.fixture(scope="module")
def blocked_run(tmp_path_factory):
    sc0 = load_scenario(DEFAULT_SCENARIO)
    d1 = [s.prn for s in make_generator(sc0.with_overrides(duration_s=1.0)).sats
          if s.is_d1][:2]
    raw = json.loads(json.dumps(sc0.raw))
    sow = math.ceil((sc0.sow + 1.0) / 30.0) * 30.0 - 1.0
    raw["time"] = {"start": bdt_to_datetime(sc0.week, sow).isoformat(), "scale": "BDT"}
    raw["scenario"]["duration_s"] = 19.6
    raw["signal"]["sampling_rate_hz"] = FS
    raw["satellites"]["prns"] = d1
    raw["outage"] = [{"prn": d1[0], "start_s": T_BLOCK, "end_s": 30.0, "blockage": True}]
    sc = parse_scenario(raw, source=sc0.source, base_dir=sc0.source.parent)
    out = tmp_path_factory.mktemp("navblock")
    meta = generate_files(sc, out, name="nb", progress=False)["metadata"]
    gen = make_generator(sc)
    rx = ScalarReceiver(log=False)
    rx.run(IfSource.from_sidecar(meta), prns=d1)
    return gen, rx, d1


def _model_difference_m(eph, ref) -> tuple[float, float]:
    """Satellite position [m] and clock [m] difference of two records over the hour
    around the reference toe (largest over 5 times)."""
    t = float(ref.toe) + np.linspace(-1800.0, 1800.0, 5)
    p1, _, c1, _ = sat_pos_vel_clock(eph, t)
    p2, _, c2, _ = sat_pos_vel_clock(ref, t)
    return (float(np.max(np.linalg.norm(p1 - p2, axis=1))),
            float(np.max(np.abs(c1 - c2))) * C_LIGHT)


def test_subframe_ending_in_noise_gives_no_ephemeris(blocked_run):
    gen, rx, (blocked, clear) = blocked_run
    ref = {s.prn: s.eph for s in gen.sats}
    # the satellite in view throughout decodes its record, equal to the simulated one
    eph = rx.channels[clear].ephemeris
    assert eph is not None, f"C{clear:02d}: no ephemeris decoded"
    dpos, dclk = _model_difference_m(eph, ref[clear])
    assert dpos < 0.05 and dclk < 0.05, (dpos, dclk)
    # the blocked one: its subframe 3 ended in noise; no record rather than a wrong one
    eph = rx.channels[blocked].ephemeris
    if eph is not None:
        dpos, dclk = _model_difference_m(eph, ref[blocked])
        assert dpos < 0.05 and dclk < 0.05, (
            f"C{blocked:02d}: decoded record {dpos:.1f} m / {dclk:.1f} m off the simulated one")
    assert all(d["SOW"] % 30 != 12 for d in rx.channels[blocked].subframes), \
        "the subframe that ended in noise was kept"


def test_two_agreeing_copies_replace_a_wrong_first_copy():
    nav = load_nav(REPO_ROOT / "ephemeris" / "ESBC00DNK_R_20201770000_01D_MN.rnx.gz")
    good = next(r for r in nav.records[10] if r.toe == 367200.0)
    wrong = dataclasses.replace(good, omega=good.omega - 2.4e-5)   # the count-change copy
    sow = 367200.0 + 1800.0
    nd = NavDataInForce()     # no assistance record: nothing to check the first copy against
    assert nd.offer_ephemeris(wrong, 18.2)
    assert nd.select_with_source(10, good.week, sow) == (wrong, BROADCAST)
    # one good copy against the wrong one: undecided, the first stays (counted)
    copy1 = dataclasses.replace(good)
    assert not nd.offer_ephemeris(copy1, 48.2) and nd.n_conflicts == 1
    assert not nd.offer_ephemeris(copy1, 48.4)      # the same copy offered again is no vote
    assert nd.select(10, good.week, sow) is wrong and nd.n_conflicts == 1
    # a second good copy agrees with the first: two against one
    copy2 = dataclasses.replace(good)
    assert nd.offer_ephemeris(copy2, 78.2)
    assert nd.select_with_source(10, good.week, sow) == (copy2, BROADCAST)
    # and a copy of the wrong one now is a single dissent again
    assert not nd.offer_ephemeris(dataclasses.replace(wrong), 108.2)
    assert nd.select(10, good.week, sow) is copy2


def test_implausible_new_data_set_waits_for_a_second_copy():
    """A decoded record that moves the satellite far from the record in force (here the
    assistance record) is held until a second identical copy; a real next data set is not."""
    nav = load_nav(REPO_ROOT / "ephemeris" / "ESBC00DNK_R_20201770000_01D_MN.rnx.gz")
    good = next(r for r in nav.records[10] if r.toe == 367200.0)
    prev = next(r for r in nav.records[10] if r.toe == good.toe - 3600.0)
    sow = good.toe + 600.0
    # a wrong AODE and a wrong omega, as the TCXO seed-3 C30 copy: a new data set by identity
    wrong = dataclasses.replace(good, AODE=30, omega=good.omega - 2.4e-5)
    nd = NavDataInForce(nav)
    assert nd.select_with_source(10, good.week, sow)[1] == RINEX
    assert not nd.offer_ephemeris(wrong, 48.1)
    assert nd.select_with_source(10, good.week, sow)[1] == RINEX
    assert (nd.n_implausible, nd.n_rejected) == (1, 1)
    assert not nd.offer_ephemeris(wrong, 48.2)          # the same copy again is no vote
    assert (nd.n_implausible, nd.n_rejected) == (1, 1)
    assert nd.offer_ephemeris(dataclasses.replace(wrong), 78.1)   # a second identical copy
    assert nd.select_with_source(10, good.week, sow)[0].AODE == 30
    # against the wrong record now in force even the real data set needs two copies
    assert not nd.offer_ephemeris(dataclasses.replace(good), 100.0) and nd.n_implausible == 2
    # a decoded record and the next data set (toe one hour later, metres apart): at once
    nd = NavDataInForce(nav)
    assert nd.offer_ephemeris(dataclasses.replace(prev), 10.0)
    assert nd.offer_ephemeris(dataclasses.replace(good), 20.0) and nd.n_rejected == 0
    assert nd.select_with_source(10, good.week, sow) == (good, BROADCAST)


@pytest.mark.parametrize("field,delta", [("IDOT", 1e-8), ("af0", 3e-7), ("M0", 1e-5),
                                         ("toe", 8.0)])
def test_implausible_field_is_held(field, delta):
    """One field off as a BCH miscorrection leaves it (a rate term, invisible at toe, shows
    30 min away); the record in force stays."""
    nav = load_nav(REPO_ROOT / "ephemeris" / "ESBC00DNK_R_20201770000_01D_MN.rnx.gz")
    good = next(r for r in nav.records[10] if r.toe == 367200.0)
    nd = NavDataInForce(nav)
    assert nd.offer_ephemeris(dataclasses.replace(good), 1.0)
    bad = dataclasses.replace(good, AODE=good.AODE + 1, **{field: getattr(good, field) + delta})
    assert not nd.offer_ephemeris(bad, 2.0) and nd.n_implausible == 1
    assert nd.select(10, good.week, good.toe) == good


@pytest.mark.parametrize("field,delta", [("week", 1), ("toe", 4 * 3600.0)])
@pytest.mark.parametrize("assistance", [False, True])
def test_forward_corrupted_week_or_toe_does_not_displace_the_decoded_record(field, delta,
                                                                           assistance):
    """A decoded copy whose week or toe is corrupted forwards has no record in force near its
    toe to be compared with; it would displace the good decoded record (and be in force at
    no time the receiver sees). It is held for a second copy; the good record stays."""
    nav = load_nav(REPO_ROOT / "ephemeris" / "ESBC00DNK_R_20201770000_01D_MN.rnx.gz")
    good = next(r for r in nav.records[10] if r.toe == 367200.0)
    sow = good.toe + 600.0
    nd = NavDataInForce(nav if assistance else None)
    assert nd.offer_ephemeris(dataclasses.replace(good), 1.0)
    bad = dataclasses.replace(good, **{field: getattr(good, field) + delta})
    assert not nd.offer_ephemeris(bad, 31.0)
    assert nd.select_with_source(10, good.week, sow) == (good, BROADCAST)
    assert (nd.n_implausible, nd.n_rejected) == (1, 1)
    # a second, separately decoded identical copy decides (a real record after a long gap)
    assert nd.offer_ephemeris(dataclasses.replace(bad), 61.0)
    assert nd.decoded[10] == bad
    # without a decoded record the first copy is still taken as it is (nothing to check)
    nd = NavDataInForce()
    assert nd.offer_ephemeris(dataclasses.replace(bad), 1.0)


def test_assembler_returns_no_rebuilt_copy_as_a_second_one():
    """A D1 set rebuilt with some of the subframes of the set returned before is not a second,
    independent copy for the two-copies rule: it is not returned again unless it differs."""
    nav = load_nav(REPO_ROOT / "ephemeris" / "ESBC00DNK_R_20201770000_01D_MN.rnx.gz")
    good = next(r for r in nav.records[10] if r.toe == 367200.0)
    subs = decode_stream(nav_bits(good, good.week, good.toe, 90.0).bits, prn=10)
    frame = {(d["SOW"] - int(good.toe)) // 30: {} for d in subs}
    for d in subs:
        frame[(d["SOW"] - int(good.toe)) // 30][d["FraID"]] = d
    asm = EphemerisAssembler(10)
    got = [asm.add(frame[0][k]) for k in (1, 2, 3)]
    ref = got[2][0]           # good, to the fields' LSBs
    assert got[:2] == [None, None] and _model_difference_m(ref, good)[0] < 0.05
    assert asm.add(frame[1][1]) is None          # new subframe 1, the same 2 and 3
    assert asm.add(frame[2][2]) is None
    assert asm.add(frame[2][3])[0] == ref        # none of the first copy's subframes: a copy
    asm = EphemerisAssembler(10)
    assert [asm.add(frame[0][k]) for k in (1, 2, 3)][2][0] == ref
    assert [asm.add(frame[1][k]) for k in (2, 3)] == [None, None]   # the same subframe 1
    assert asm.add(frame[2][1])[0] == ref        # none of the first copy's subframes: a copy
    # a wrong subframe 1 (AODE) corrected by the next one: the corrected set is returned
    asm = EphemerisAssembler(10)
    bad1 = {**frame[0][1], "raw": {**frame[0][1]["raw"], "AODE": 30}}
    assert [asm.add(d) for d in (bad1, frame[0][2])] == [None, None]
    assert asm.add(frame[0][3])[0].AODE == 30
    assert asm.add(frame[1][1])[0] == ref
