"""Broadcast orbit and clock computation: velocity, relativistic term, GEO, week crossover."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from sdr_di.constants import C_LIGHT, F_REL, GM_CGCS, OMEGA_E
from sdr_di.errors import NoEphemerisError
from sdr_di.orbits.broadcast import kepler_E, sat_pos_vel_clock, sat_states
from sdr_di.orbits.rinex_nav import load_nav

EPH_DIR = Path(__file__).resolve().parents[1] / "ephemeris"


@pytest.fixture(scope="module")
def esbc():
    return load_nav(EPH_DIR / "ESBC00DNK_R_20201770000_01D_MN.rnx.gz")


@pytest.fixture(scope="module")
def wrd():
    return load_nav(EPH_DIR / "BRDC00WRD_S_20230990000_01D_MN.rnx")


def _poly(eph, t):
    d = t - eph.toc
    return eph.af0 + eph.af1 * d + eph.af2 * d * d


def test_shapes_scalar_and_vector(esbc):
    eph = esbc.records[20][0]
    r, v, dt, ddt = sat_pos_vel_clock(eph, eph.toe)
    assert r.shape == (1, 3) and v.shape == (1, 3) and dt.shape == (1,) and ddt.shape == (1,)
    t = eph.toe + np.linspace(-1800, 1800, 7)
    r, v, dt, ddt = sat_pos_vel_clock(eph, t)
    assert r.shape == (7, 3) and v.shape == (7, 3) and dt.shape == (7,) and ddt.shape == (7,)
    for k, tk in enumerate(t):  # vectorized == one by one
        r1, v1, dt1, _ = sat_pos_vel_clock(eph, tk)
        np.testing.assert_array_equal(r1[0], r[k])
        assert dt1[0] == dt[k]


@pytest.mark.parametrize("prn", [5, 6, 7, 11, 20, 33])  # GEO, IGSO x2, BDS-2 MEO, BDS-3 MEO
def test_radius_and_speed_plausible(esbc, prn):
    eph = esbc.records[prn][0]
    t = eph.toe + np.linspace(-3600, 3600, 25)
    r, v, _, _ = sat_pos_vel_clock(eph, t)
    radius = np.linalg.norm(r, axis=1)
    A = eph.sqrtA**2
    assert np.all(np.abs(radius - A) < A * eph.e + 2000.0)
    # inertial speed ~ sqrt(GM / A)
    v_i = v + np.cross([0.0, 0.0, OMEGA_E], r)
    np.testing.assert_allclose(np.linalg.norm(v_i, axis=1), np.sqrt(GM_CGCS / A), rtol=0.02)
    if eph.is_geo:
        # a GEO barely moves in ECEF: C05 stays near 58.75 E on the equator; an inclination
        # of ~1.5 deg gives a daily north-south swing of ~+-1100 km (|v| up to ~80 m/s)
        assert np.max(np.linalg.norm(v, axis=1)) < 150.0
        lat = np.degrees(np.arcsin(r[:, 2] / radius))
        lon = np.degrees(np.arctan2(r[:, 1], r[:, 0]))
        assert np.all(np.abs(lat) < 3.0) and np.all(np.abs(lon - 58.75) < 1.0)


@pytest.mark.parametrize("prn", [5, 6, 7, 11, 20, 33])
def test_velocity_and_drift_match_finite_difference(esbc, prn):
    h = 0.5
    for eph in esbc.records[prn][::3]:
        t = eph.toe + np.linspace(-3600, 3600, 13)
        _, v, _, ddt = sat_pos_vel_clock(eph, t)
        rp, _, dtp, _ = sat_pos_vel_clock(eph, t + h)
        rm, _, dtm, _ = sat_pos_vel_clock(eph, t - h)
        v_fd = (rp - rm) / (2 * h)
        assert np.max(np.linalg.norm(v - v_fd, axis=1)) < 1e-3  # < 1 mm/s
        np.testing.assert_allclose(ddt, (dtp - dtm) / (2 * h), rtol=0, atol=1e-15)


@pytest.mark.parametrize("prn", [6, 7, 9, 20])
def test_relativistic_term_sign_and_magnitude(esbc, prn):
    """F e sqrtA sin E equals -2 r.v / c^2 (IGS convention), amplitude F e sqrtA."""
    eph = esbc.records[prn][0]
    t = eph.toe + np.linspace(-43200, 43200, 289)
    r, v, dt, _ = sat_pos_vel_clock(eph, t)
    rel = dt - _poly(eph, t)
    rel_igs = -2.0 * np.einsum("ij,ij->i", r, v) / C_LIGHT**2  # r.v same in ECEF and inertial
    np.testing.assert_allclose(rel, rel_igs, atol=0.3e-9)
    amp = abs(F_REL) * eph.e * eph.sqrtA
    assert np.max(np.abs(rel)) == pytest.approx(amp, rel=0.02)
    if prn in (6, 7, 9):  # BDS-2 IGSO, e ~ 0.007-0.01: tens of ns
        assert 15e-9 < amp < 40e-9
    # at perigee (E = 0) the term is zero, after perigee it is negative (F < 0)
    A = eph.sqrtA**2
    n = np.sqrt(GM_CGCS / A**3) + eph.Delta_n
    t_perigee = eph.toe - eph.M0 / n
    _, _, dtp, _ = sat_pos_vel_clock(eph, np.array([t_perigee, t_perigee + 600.0]))
    relp = dtp - _poly(eph, np.array([t_perigee, t_perigee + 600.0]))
    assert abs(relp[0]) < 1e-13 and relp[1] < 0


def test_no_tgd_applied(esbc):
    eph = esbc.records[20][0]
    e2 = dataclasses.replace(eph, TGD1=1e-6, TGD2=-1e-6)
    a = sat_pos_vel_clock(eph, eph.toe + 100.0)
    b = sat_pos_vel_clock(e2, eph.toe + 100.0)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)


def test_kepler_solver():
    M = np.linspace(-10, 10, 1001)
    for e in (0.0, 0.001, 0.01, 0.3):
        E = kepler_E(M, e)
        np.testing.assert_allclose(E - e * np.sin(E), M, atol=1e-13)


def test_week_crossover(wrd):
    """WRD records have toe = 0 (week 901): times late in week 900 must wrap to t_k < 0."""
    eph = wrd.records[20][0]
    assert eph.toe == 0.0 and eph.week == 901
    t_prev = 604800.0 - np.array([10.0, 600.0, 3600.0])
    a = sat_pos_vel_clock(eph, t_prev)                # ICD wrap
    b = sat_pos_vel_clock(eph, t_prev, week=900)      # explicit week
    c = sat_pos_vel_clock(eph, t_prev - 604800.0, week=901)
    for x, y, z in zip(a, b, c):
        np.testing.assert_allclose(x, y, rtol=0, atol=1e-9 * max(1.0, np.max(np.abs(x))))
        np.testing.assert_allclose(x, z, rtol=0, atol=1e-9 * max(1.0, np.max(np.abs(x))))
    # continuity across the week boundary
    r1 = sat_pos_vel_clock(eph, 604799.5)[0]
    r2 = sat_pos_vel_clock(eph, 0.5)[0]
    assert 2000.0 < np.linalg.norm(r2 - r1) < 4000.0  # ~1 s of motion, not a week


def test_geo_rotation_differs_from_meo_formula(esbc):
    """Computing a GEO with the MEO formula is wrong by kilometres: the GEO path is used."""
    eph = esbc.records[5][0]
    as_meo = dataclasses.replace(eph, prn=20)  # same elements, MEO formula
    t = eph.toe + np.array([0.0, 1800.0])
    r_geo = sat_pos_vel_clock(eph, t)[0]
    r_meo = sat_pos_vel_clock(as_meo, t)[0]
    assert np.all(np.linalg.norm(r_geo - r_meo, axis=1) > 1e6)


def test_sat_states_selects_per_time(esbc):
    recs = esbc.records[20]
    a, b = recs[0], recs[1]
    t = np.array([a.toe + 100.0, b.toe - 100.0, b.toe + 200.0])
    r, v, dt, ddt = sat_states(esbc, 20, a.week, t)
    np.testing.assert_array_equal(r[0], sat_pos_vel_clock(a, t[0], week=a.week)[0][0])
    np.testing.assert_array_equal(r[1], sat_pos_vel_clock(b, t[1], week=a.week)[0][0])
    np.testing.assert_array_equal(dt[2], sat_pos_vel_clock(b, t[2], week=a.week)[2][0])
    with pytest.raises(NoEphemerisError):
        sat_states(esbc, 20, a.week, np.array([a.toe, a.toe - 86400.0]))


def test_stacked_rows_equal_one_record_at_a_time(esbc):
    """sat_pos_vel_clock_stacked: row i is record i alone, bit for bit (GEO, IGSO, MEO mixed;
    different eccentricities converge Kepler's equation in different iteration counts)."""
    from sdr_di.orbits.broadcast import sat_pos_vel_clock_stacked, stack_ephemerides

    ephs = [esbc.records[p][0] for p in (5, 6, 11, 20, 33, 1, 59) if p in esbc.records]
    assert any(e.is_geo for e in ephs) and not all(e.is_geo for e in ephs)
    rng = np.random.default_rng(3)
    t = ephs[0].toe + rng.uniform(-7200.0, 7200.0, (len(ephs), 5))
    st = stack_ephemerides(ephs)
    assert stack_ephemerides(list(ephs)) is st          # cached by record identity
    for week in (None, ephs[0].week):
        got = sat_pos_vel_clock_stacked(st, t, week=week)
        for i, eph in enumerate(ephs):
            one = sat_pos_vel_clock(eph, t[i], week=week)
            for g, o in zip(got, one):
                np.testing.assert_array_equal(g[i], o)
    # one row of times for every record (broadcast)
    got = sat_pos_vel_clock_stacked(st, t[0])
    np.testing.assert_array_equal(got[0][3], sat_pos_vel_clock(ephs[3], t[0])[0])
