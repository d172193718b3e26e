"""The range model's one-instant kernel (receiver/_numba_range_model.py) against its numpy
form (``range_model.jit = False``), and the point forms it uses (the kernels'
``ecef_to_llh`` and ``saastamoinen_zenith``) against the array forms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sdr_di.constants import is_geo
from sdr_di.errors import NoEphemerisError
from sdr_di.frames import ecef_to_llh, llh_to_ecef
from sdr_di.orbits.atmosphere import saastamoinen_delay, saastamoinen_zenith
from sdr_di.orbits.rinex_nav import load_nav
from sdr_di.receiver import _numba_range_model, range_model
from sdr_di.receiver.pvt import PvtConfig
from sdr_di.scenario import REPO_ROOT
from sdr_di.signal.navmsg import assistance_klobuchar

NAV = REPO_ROOT / "ephemeris" / "ESBC00DNK_R_20201770000_01D_MN.rnx.gz"
WEEK, SOW0 = 755, 369000.0
FIELDS = ("P", "Pc", "tau", "r_sat", "v_sat", "U")


@pytest.fixture(scope="module")
def nav():
    return load_nav(NAV)


def _both(monkeypatch, *args, **kwargs):
    monkeypatch.setattr(range_model, "jit", True)
    fast = range_model.predict_ranges(*args, **kwargs)
    monkeypatch.setattr(range_model, "jit", False)
    ref = range_model.predict_ranges(*args, **kwargs)
    return fast, ref


def _assert_agree(fast, ref):
    for name in FIELDS:
        a, b = getattr(fast, name), getattr(ref, name)
        assert a.shape == b.shape, name
        scale = np.max(np.abs(b))
        np.testing.assert_allclose(a, b, rtol=0.0, atol=1e-12 * scale, err_msg=name)


def _ephs_in_force(nav) -> list:
    """Every record of the file in force at SOW0 (GEO, IGSO, MEO)."""
    ephs = []
    for p in nav.prns:
        try:
            ephs.append(nav.select(p, WEEK, SOW0))
        except NoEphemerisError:
            pass
    return ephs


def _cases(nav, seed: int):
    """40 receivers from below sea level to above the troposphere's 11 km, both
    hemispheres, within an hour of SOW0, each atmosphere switch in turn: ``(r, sow, ion,
    cfg, rng)``."""
    iono = assistance_klobuchar(nav)[0]
    rng = np.random.default_rng(seed)
    configs = [PvtConfig(), PvtConfig(ionosphere=False), PvtConfig(troposphere=False)]
    for k in range(40):
        lat, lon = rng.uniform(-80, 80), rng.uniform(-180, 180)
        h = rng.choice([-50.0, 30.0, 4000.0, 15000.0]) + rng.uniform(0, 10)
        r = llh_to_ecef(math.radians(lat), math.radians(lon), h)
        sow = SOW0 + rng.uniform(-3600.0, 3600.0)
        yield r, sow, (None if k % 5 == 4 else iono), configs[k % 3], rng


def test_one_instant_kernels_equal_the_numpy_form(nav, monkeypatch):
    """Every record in force (GEO, IGSO, MEO), receivers from below sea level to above the
    troposphere's 11 km, both hemispheres, seeded and unseeded travel times, each
    atmosphere switch."""
    ephs = _ephs_in_force(nav)
    assert any(is_geo(e.prn) for e in ephs) and any(not is_geo(e.prn) for e in ephs)
    for r, sow, ion, cfg, rng in _cases(nav, 47):
        b = rng.uniform(-3e5, 3e5)
        fast, ref = _both(monkeypatch, ephs, WEEK, [sow], [r], [b], ion, config=cfg)
        _assert_agree(fast, ref)
        # the deep loop's call: seeded by the last travel times, one pass
        fast1, ref1 = _both(monkeypatch, ephs, WEEK, [sow + 0.02], [r + 0.3], [b + 1.0], ion,
                            tau0=ref.tau, passes=1, config=cfg)
        _assert_agree(fast1, ref1)


def test_several_instants_take_the_numpy_form(nav, monkeypatch):
    ephs = [nav.select(p, WEEK, SOW0) for p in (27, 8, 13)]
    r = llh_to_ecef(0.7, 2.0, 100.0)
    fast, ref = _both(monkeypatch, ephs, WEEK, [SOW0, SOW0 + 1.0], [r, r], [0.0, 1.0], None)
    for name in FIELDS:
        assert np.array_equal(getattr(fast, name), getattr(ref, name)), name


def test_the_kernels_ecef_to_llh_equals_the_array_form():
    rng = np.random.default_rng(1)
    for _ in range(300):
        lat, lon = rng.uniform(-math.pi / 2, math.pi / 2), rng.uniform(-math.pi, math.pi)
        h = rng.uniform(-1e3, 3e7)
        r = llh_to_ecef(lat, lon, h)
        ref = ecef_to_llh(r)
        pt = _numba_range_model.ecef_to_llh(np.asarray(r, float))
        np.testing.assert_allclose(pt[:2], ref[:2], rtol=0.0, atol=1e-15)
        assert pt[2] == pytest.approx(ref[2], rel=1e-12, abs=1e-9)


def test_saastamoinen_zenith_is_the_slant_delay_at_the_zenith():
    rng = np.random.default_rng(2)
    lat = rng.uniform(-1.5, 1.5, 200)
    h = rng.uniform(-100.0, 12000.0, 200)
    el = rng.uniform(0.05, 1.5, 200)
    slant = saastamoinen_delay(lat, h, el)
    zen = saastamoinen_zenith(lat, h)
    np.testing.assert_allclose(slant, zen / np.sin(el), rtol=1e-15)
    for i in range(0, 200, 20):     # one receiver: numpy scalars, the kernel's point form
        z = saastamoinen_zenith(np.float64(lat[i]), np.float64(h[i]))
        assert float(z) == pytest.approx(zen[i], rel=1e-15)
        assert _numba_range_model.saastamoinen_zenith(lat[i], h[i], 0.5) == \
            pytest.approx(zen[i], rel=1e-14)
        one = saastamoinen_delay(lat[i], h[i], el[i:i + 3])
        np.testing.assert_allclose(one, z / np.sin(el[i:i + 3]), rtol=1e-15)


def test_pvt_atmosphere_kernel_equals_the_numpy_form(nav, monkeypatch):
    """The PVT's elevations, azimuths and delays (``pvt.atmosphere_delays``) by the range
    model's atmosphere kernel against the numpy form, for receivers from below sea level to
    above 11 km, every atmosphere switch, satellites below the horizon included."""
    from sdr_di.receiver import pvt

    ephs = _ephs_in_force(nav)
    iono = assistance_klobuchar(nav)[0]
    for r, sow, ion, cfg, _ in _cases(nav, 28):
        r_rot = range_model.predict_ranges(ephs, WEEK, [sow], [r], [0.0], iono).r_sat[:, 0]
        fast = pvt.atmosphere_delays(r, r_rot, sow, ion, cfg)
        monkeypatch.setattr(pvt, "jit", False)
        ref = pvt.atmosphere_delays(r, r_rot, sow, ion, cfg)
        monkeypatch.setattr(pvt, "jit", True)
        assert (ref[0] < 0.0).any()
        for a, b, tol in zip(fast, ref, (1e-14, 1e-13, 1e-12, 1e-12)):
            np.testing.assert_allclose(a, b, rtol=0.0, atol=tol * max(1.0, np.max(np.abs(b))))
