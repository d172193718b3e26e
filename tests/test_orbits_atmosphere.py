"""BDS Klobuchar ionosphere and Saastamoinen troposphere."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sdr_di.constants import C_LIGHT
from sdr_di.orbits.atmosphere import (
    B1I_TO_B3I,
    iono_delay_b3i_m,
    klobuchar_delay,
    saastamoinen_delay,
)
from sdr_di.orbits.ephemeris import Klobuchar
from sdr_di.orbits.rinex_nav import read_klobuchar

GOP = Path(__file__).resolve().parents[1] / "ephemeris" / "BRDC00GOP_R_20210010000_01D_MN.rnx.gz"
LAT, LON = np.deg2rad(40.0), np.deg2rad(116.0)


@pytest.fixture(scope="module")
def kb() -> Klobuchar:
    k = read_klobuchar(GOP)
    assert k is not None
    return k


def _bdt_for_local(hour_local: float, lon_rad: float = LON) -> float:
    """BDT seconds of day giving local time ``hour_local`` at longitude ``lon_rad``."""
    return (hour_local * 3600.0 - lon_rad * 43200.0 / np.pi) % 86400.0


def test_night_floor_5ns(kb):
    # zenith: the pierce point is above the receiver, local time 02:00 -> 5 ns exactly
    d = klobuchar_delay(kb, LAT, LON, np.pi / 2, 0.0, _bdt_for_local(2.0))
    assert d == pytest.approx(5e-9, rel=1e-12)
    # slant: 5 ns times the obliquity factor (>= 1, ~3 at 5 deg)
    el = np.deg2rad([90, 45, 20, 5])
    d = klobuchar_delay(kb, LAT, LON, el, np.pi, _bdt_for_local(2.0))
    ratio = 6378.0 / (6378.0 + 375.0) * np.cos(el)
    np.testing.assert_allclose(d, 5e-9 / np.sqrt(1 - ratio**2), rtol=1e-12)
    assert 2.5 < d[-1] / d[0] < 3.2


def test_daytime_peak_plausible(kb):
    t = np.arange(0.0, 86400.0, 600.0)
    d = klobuchar_delay(kb, LAT, LON, np.pi / 2, 0.0, t)
    k = np.argmax(d)
    local = (t[k] + LON * 43200 / np.pi) % 86400 / 3600
    assert abs(local - 14.0) < 0.2  # maximum at 14:00 local time
    # 2021-01-01, 40 N: a few ns to a few tens of ns vertical on B1I (1-10 m)
    assert 6e-9 < d[k] < 40e-9
    assert np.all(d >= 5e-9 - 1e-20)
    # hand evaluation of the ICD formula at the zenith at 14:00 local time
    x = abs(LAT / np.pi)
    A2 = sum(a * x**n for n, a in enumerate(kb.alpha))
    assert klobuchar_delay(kb, LAT, LON, np.pi / 2, 0.0, _bdt_for_local(14.0)) == \
        pytest.approx(5e-9 + A2, rel=1e-9)


def test_klobuchar_vectorized_and_b3i_scaling(kb):
    el = np.deg2rad(np.array([[80.0], [30.0], [10.0]]))
    az = np.deg2rad(np.array([0.0, 90.0, 180.0, 270.0]))
    d = klobuchar_delay(kb, LAT, LON, el, az, 20000.0)
    assert d.shape == (3, 4)
    for i in range(3):
        for j in range(4):
            assert d[i, j] == klobuchar_delay(kb, LAT, LON, el[i, 0], az[j], 20000.0)
    m = iono_delay_b3i_m(kb, LAT, LON, el, az, 20000.0)
    assert B1I_TO_B3I == pytest.approx((1561.098 / 1268.52) ** 2)
    assert B1I_TO_B3I == pytest.approx(1.5145, abs=1e-4)
    np.testing.assert_allclose(m, d * C_LIGHT * B1I_TO_B3I)
    # below the horizon: no delay
    assert klobuchar_delay(kb, LAT, LON, -0.1, 0.0, 20000.0) == 0.0


def test_klobuchar_uses_abs_latitude(kb):
    """The BDS model uses |phi_M|: mirror receivers N/S at the same local time agree."""
    t = _bdt_for_local(13.0)
    n = klobuchar_delay(kb, LAT, LON, np.pi / 2, 0.0, t)
    s = klobuchar_delay(kb, -LAT, LON, np.pi / 2, 0.0, t)
    assert n == pytest.approx(s, rel=1e-12)


def test_saastamoinen_zenith_sea_level():
    z = saastamoinen_delay(np.deg2rad(45.0), 0.0, np.pi / 2)
    assert 2.3 < z < 2.45
    # hydrostatic part alone (humidity 0) ~2.30 m
    assert saastamoinen_delay(np.deg2rad(45.0), 0.0, np.pi / 2, humidity=0.0) == \
        pytest.approx(2.30, abs=0.02)


def test_saastamoinen_height_and_mapping():
    el = np.deg2rad([90.0, 60.0, 30.0, 15.0, 10.0, 5.0])
    d = saastamoinen_delay(LAT, 100.0, el)
    assert np.all(np.diff(d) > 0)  # grows as elevation decreases
    np.testing.assert_allclose(d / d[0], 1.0 / np.sin(el), rtol=1e-12)
    assert 20.0 < d[-1] < 30.0
    assert saastamoinen_delay(LAT, 3000.0, np.pi / 2) < 0.75 * saastamoinen_delay(LAT, 0.0, np.pi / 2)
    assert saastamoinen_delay(LAT, 0.0, -0.01) == 0.0
    # vectorized over all arguments
    out = saastamoinen_delay(np.full(4, LAT), np.array([0.0, 100.0, 1000.0, 5000.0]), np.pi / 4)
    assert out.shape == (4,) and np.all(np.diff(out) < 0)


def test_saastamoinen_of_one_receiver_equals_the_broadcast_inputs():
    """One receiver and several elevations (the range model's call) take the receiver's
    terms on one-element arrays: each delay equals the one of fully broadcast inputs, bit
    for bit (numpy's power of a 0-d value would not), and a 0-d elevation stays 0-d."""
    rng = np.random.default_rng(4)
    for _ in range(2000):
        lat, h = rng.uniform(-1.5, 1.5), rng.uniform(-100.0, 12000.0)
        el = rng.uniform(-0.2, 1.6, size=int(rng.integers(1, 16)))
        got = saastamoinen_delay(lat, h, el)
        want = saastamoinen_delay(np.full(el.size, lat), np.full(el.size, h), el)
        assert got.shape == el.shape and np.array_equal(got, want)
    assert saastamoinen_delay(0.5, 100.0, 0.7).shape == ()
