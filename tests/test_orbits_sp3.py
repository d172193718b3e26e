"""SP3 reader, and broadcast orbits/clocks against IAC precise orbits (2020-06-25).

Comparison set-up: Sta21114.sp3.gz (IAC final, GPST, 15 min, IGS14, centre of mass) against
the merged ESBC + MOJN broadcast records of the same day. For every SP3 epoch (converted to
BDT: t_BDT = t_GPST - 14 s) and every BDS satellite present in both, the healthy record whose
toe is nearest (within 1 h) is evaluated at that epoch. Epochs without such a record (the
station files only hold records while the satellite was visible from Denmark) are skipped.

Not compensated: the broadcast orbit refers to the antenna phase centre, SP3 to the centre of
mass (BDS-3 MEO show a steady ~-1.2 m radial offset from it); IGS14 vs CGCS2000 (~cm).

Known misses of the 3 m median bound (kept as strict xfail, the bound is not widened): the
BDS-2 satellites C07 (IGSO, median 5.9 m) and C14 (MEO, median 3.2 m). Their error is the
broadcast orbit's own: it is the same for records 0, 1 and 2 h old (not a selection
problem), smooth and mostly along-track, and the CODE MGEX final orbit (not shipped) gives
the same picture (C07 4.8 m, C14 3.3 m median), so it is not an IAC product problem either.
"""

from __future__ import annotations

import datetime as dt
import gzip
from pathlib import Path

import numpy as np
import pytest

from sdr_di.constants import C_LIGHT, is_geo
from sdr_di.errors import EphemerisError, NoEphemerisError
from sdr_di.orbits.broadcast import sat_pos_vel_clock
from sdr_di.orbits.rinex_nav import load_nav, merge_nav
from sdr_di.orbits.sp3 import Sp3Orbits, bdt_seconds, load_sp3

EPH_DIR = Path(__file__).resolve().parents[1] / "ephemeris"
SP3 = EPH_DIR / "Sta21114.sp3.gz"
ESBC_PRNS = (5, *range(6, 15), 16, *range(19, 31), *range(32, 38))
MEDIAN_XFAIL = {7: "BDS-2 IGSO broadcast orbit error ~6 m along-track (confirmed vs CODE MGEX)",
                14: "BDS-2 MEO broadcast orbit error ~3-4 m along-track (confirmed vs CODE MGEX)"}


@pytest.fixture(scope="module")
def sp3() -> Sp3Orbits:
    return load_sp3(SP3)


@pytest.fixture(scope="module")
def nav():
    return merge_nav([load_nav(EPH_DIR / "ESBC00DNK_R_20201770000_01D_MN.rnx.gz"),
                      load_nav(EPH_DIR / "MOJN00DNK_R_20201770000_01D_MN.rnx.gz")])


@pytest.fixture(scope="module")
def comparison(sp3, nav):
    """prn -> dict(err 3D [m], radial [m], clk_res [s], clk_raw [s]) over the day."""
    week, sow = sp3.bdt_week_sow()
    out = {}
    for prn in nav.prns:
        sv = f"C{prn:02d}"
        if sv not in sp3.svs:
            continue
        k = sp3.index(sv)
        err, rad, clk_res, clk_raw = [], [], [], []
        for j in range(len(sp3.epochs)):
            p = sp3.positions[j, k]
            if not np.all(np.isfinite(p)):
                continue
            try:
                eph = nav.select(prn, int(week[j]), sow[j], max_age_s=3600.0)
            except NoEphemerisError:
                continue
            r, v, dts, _ = sat_pos_vel_clock(eph, sow[j], week=int(week[j]))
            d = r[0] - p
            err.append(np.linalg.norm(d))
            rad.append(d @ p / np.linalg.norm(p))
            if np.isfinite(sp3.clocks[j, k]):
                # SP3 clocks exclude the periodic relativistic term (IGS convention): add it
                # back from the SP3 orbit itself, -2 r.v / c^2, v by central difference
                tp = min(sp3.t_bdt[j] + 1.0, sp3.t_bdt[-1])
                tm = max(sp3.t_bdt[j] - 1.0, sp3.t_bdt[0])
                pv = (sp3.position(sv, tp) - sp3.position(sv, tm))[0] / (tp - tm)
                rel = -2.0 * (p @ pv) / C_LIGHT**2
                clk_res.append(dts[0] - (sp3.clocks[j, k] + rel))
                clk_raw.append(dts[0] - sp3.clocks[j, k])
        out[prn] = {k_: np.array(v_) for k_, v_ in
                    dict(err=err, rad=rad, clk_res=clk_res, clk_raw=clk_raw).items()}
    return out


# ---- reader ----------------------------------------------------------------------------


def test_sp3_header_and_epochs(sp3):
    assert sp3.version == "d" and sp3.time_system == "GPS" and sp3.coord_system == "IGS14"
    assert len(sp3.epochs) == 97 and len(sp3.svs) == 121
    assert sp3.epochs[0] == dt.datetime(2020, 6, 25) and sp3.epochs[-1] == dt.datetime(2020, 6, 26)
    assert sp3.positions.shape == (97, 121, 3) and sp3.clocks.shape == (97, 121)
    bds = [s for s in sp3.svs if s.startswith("C")]
    assert len(bds) == 40 and {"C01", "C05", "C60"} <= set(bds)
    # GPST 2020-06-25 00:00:00 = GPS week 2111 sow 345600 = BDT week 755 sow 345586
    week, sow = sp3.bdt_week_sow()
    assert week[0] == 755 and sow[0] == 345600.0 - 14.0
    assert sp3.t_bdt[0] == bdt_seconds(755, 345586.0)
    assert np.all(np.diff(sp3.t_bdt) == 900.0)


def test_sp3_values_and_bad_clocks(sp3):
    k = sp3.index("C01")
    np.testing.assert_allclose(sp3.positions[0, k], [-34346145.771, 24493239.073, 626704.364])
    assert sp3.clocks[0, k] == pytest.approx(-387.166264e-6)
    assert np.isnan(sp3.clocks).sum() > 0  # the 999999.999999 entries
    assert not np.any(np.abs(sp3.clocks[np.isfinite(sp3.clocks)]) > 1e-2)
    with pytest.raises(KeyError, match="C99"):
        sp3.index("C99")


def test_sp3_interpolation_leave_one_out(sp3):
    keep = np.ones(len(sp3.epochs), bool)
    for j in (20, 47, 71):
        keep[:] = True
        keep[j] = False
        thin = Sp3Orbits(sp3.path, sp3.version, sp3.time_system, sp3.coord_system, sp3.agency,
                         [e for e, m in zip(sp3.epochs, keep) if m], sp3.t_bdt[keep], sp3.svs,
                         sp3.positions[keep], sp3.clocks[keep])
        for sv in ("C05", "C07", "C20", "C38", "G01"):
            p = thin.position(sv, sp3.t_bdt[j])[0]
            assert np.linalg.norm(p - sp3.positions[j, sp3.index(sv)]) < 0.02  # 2 cm over a 30 min gap
    # exact at the nodes, NaN outside the span
    assert np.all(sp3.position("C20", sp3.t_bdt[5])[0] == sp3.positions[5, sp3.index("C20")])
    assert np.all(np.isnan(sp3.position("C20", sp3.t_bdt[-1] + 60.0)))


def test_sp3_plain_file_and_errors(tmp_path, sp3):
    plain = tmp_path / "x.sp3"
    plain.write_bytes(gzip.decompress(SP3.read_bytes()))
    np.testing.assert_array_equal(load_sp3(plain).positions, sp3.positions)
    lines = plain.read_text().splitlines(True)
    cut = tmp_path / "cut.sp3"
    cut.write_text("".join(lines[:200]))
    with pytest.raises(EphemerisError, match="truncated"):
        load_sp3(cut)
    bad = tmp_path / "bad.sp3"
    bad.write_text("hello\n")
    with pytest.raises(EphemerisError, match="not an SP3"):
        load_sp3(bad)
    with pytest.raises(EphemerisError, match="not found"):
        load_sp3(tmp_path / "none.sp3")


# ---- broadcast vs precise ----------------------------------------------------------------


def test_all_satellites_compared(comparison):
    assert tuple(sorted(comparison)) == ESBC_PRNS
    for prn, c in comparison.items():
        assert c["err"].size >= 30, (prn, c["err"].size)  # >= 7.5 h of the day per satellite


def test_missing_14s_offset_would_fail_loudly(sp3, nav):
    """Evaluating at GPST instead of BDT moves a MEO by ~14 s x 3 km/s = tens of km."""
    week, sow = sp3.bdt_week_sow()
    k = sp3.index("C20")
    j = next(j for j in range(97)
             if any(abs(sow[j] - r.toe) < 1800 for r in nav.records[20]))
    eph = nav.select(20, int(week[j]), sow[j])
    good = np.linalg.norm(sat_pos_vel_clock(eph, sow[j])[0][0] - sp3.positions[j, k])
    bad = np.linalg.norm(sat_pos_vel_clock(eph, sow[j] + 14.0)[0][0] - sp3.positions[j, k])
    assert good < 3.0 and bad > 30e3


MEO_IGSO = [p for p in ESBC_PRNS if not is_geo(p)]


@pytest.mark.parametrize("prn", MEO_IGSO)
def test_meo_igso_max_error_below_10m(comparison, prn):
    assert comparison[prn]["err"].max() < 10.0


@pytest.mark.parametrize("prn", [
    pytest.param(p, marks=pytest.mark.xfail(strict=True, reason=MEDIAN_XFAIL[p]))
    if p in MEDIAN_XFAIL else p for p in MEO_IGSO])
def test_meo_igso_median_error_below_3m(comparison, prn):
    assert np.median(comparison[prn]["err"]) < 3.0


def test_geo_error_below_25m(comparison):
    e = comparison[5]["err"]
    assert e.size == 97  # C05 records cover the whole day
    assert np.median(e) < 25.0 and e.max() < 25.0


def test_bds3_phase_centre_offset_visible(comparison):
    """BDS-3 MEO (C19-C37): ~1.1-1.3 m 3D, almost all radial (APC below the CoM)."""
    for prn in range(19, 38):
        if prn in comparison:
            c = comparison[prn]
            assert 0.8 < np.median(c["err"]) < 1.6
            assert -1.5 < np.mean(c["rad"]) < -0.9


@pytest.mark.parametrize("prn", [6, 7, 8, 9, 10, 13, 16])  # BDS-2 IGSO, e = 0.003-0.01
def test_clock_with_relativistic_term_matches_sp3(comparison, prn):
    """Broadcast clock (with our F e sqrtA sin E) vs SP3 clock + (-2 r.v/c^2) from SP3.

    The difference is a constant (B3I vs the B1I/B3I ionosphere-free clock datum, about
    2.94 TGD1) plus noise; without the relativistic term it would swing by 2 x 10-28 ns.
    """
    c = comparison[prn]
    res, raw = c["clk_res"], c["clk_raw"]
    assert res.size > 20
    assert np.std(res) < 2.5e-9
    assert np.std(raw) > 2.0 * np.std(res)
