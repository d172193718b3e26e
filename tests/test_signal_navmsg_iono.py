"""The ionosphere coefficients the generator simulates are exactly those the message carries."""

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
