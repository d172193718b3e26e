"""The ionosphere coefficients the generator simulates are exactly those the message carries."""

import pytest

from sdr_di.orbits.ephemeris import Klobuchar
from sdr_di.orbits.rinex_nav import load_nav
from sdr_di.scenario import REPO_ROOT
from sdr_di.signal.navmsg import (EphemerisAssembler, broadcast_klobuchar, decode_stream,
                                  nav_bits)


def test_generator_iono_equals_decoded_iono():
    nav = load_nav(REPO_ROOT / "ephemeris" / "ESBC00DNK_R_20201770000_01D_MN.rnx.gz")
    iono = broadcast_klobuchar(nav.iono_gps)
    assert iono.beta[3] == -524288.0 and nav.iono_gps.beta[3] == -524290.0  # RINEX rounding
    eph = nav.select(28, 755, 360000.0)
    nb = nav_bits(eph, 755, 360000.0, 31.0, iono=nav.iono_gps)
    asm = EphemerisAssembler(28)
    got = None
    for sf in decode_stream(nb.bits, prn=28):
        got = asm.add(sf) or got
    assert got is not None
    decoded_eph, decoded_iono = got
    assert decoded_iono == iono and isinstance(decoded_iono, Klobuchar)


def _d1_subframes(prn=28, sow=369000.0, seconds=61.0):
    nav = load_nav(REPO_ROOT / "ephemeris" / "ESBC00DNK_R_20201770000_01D_MN.rnx.gz")
    eph = nav.select(prn, 755, sow)
    nb = nav_bits(eph, 755, sow, seconds, iono=nav.iono_gps)
    return eph, decode_stream(nb.bits, prn=prn)


def test_d1_set_completed_with_next_frames_subframe_1():
    """A receiver that missed the first subframe 1 decodes at the next one (toc == toe)."""
    eph, sfs = _d1_subframes()
    assert [s["FraID"] for s in sfs[:6]] == [1, 2, 3, 4, 5, 1]
    asm = EphemerisAssembler(28)
    got = [asm.add(sf) for sf in sfs[1:]]  # subframe 1 of frame 0 missed
    first = next(i for i, g in enumerate(got) if g is not None)
    assert sfs[1:][first]["FraID"] == 1 and sfs[1:][first]["SOW"] == sfs[0]["SOW"] + 30
    assert got[first][0].toe == eph.toe and got[first][0].M0 == pytest.approx(eph.M0, abs=1e-8)


def test_d1_subframe_1_of_another_upload_is_not_mixed():
    eph, sfs = _d1_subframes()
    asm = EphemerisAssembler(28)
    sf1_next = dict(sfs[5])
    sf1_next["raw"] = {**sf1_next["raw"], "toc": sf1_next["raw"]["toc"] + 450}  # toc + 1 h
    assert asm.add(sfs[1]) is None and asm.add(sfs[2]) is None
    assert asm.add(sf1_next) is None  # different upload: wait for a consistent set
