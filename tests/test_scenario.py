"""Scenario parsing and validation: the shipped default and every class of bad input."""

import math
from pathlib import Path

import pytest

from sdr_di.errors import ScenarioError, UnknownPrnError
from sdr_di.scenario import DEFAULT_SCENARIO, load_scenario, parse_scenario

MINIMAL = {
    "scenario": {"name": "t", "duration_s": 2.0, "seed": 3},
    "time": {"start": "2020-06-25T04:00:00", "scale": "BDT"},
    "start": {"lat_deg": 40.0, "lon_deg": 116.0, "height_m": 100.0,
              "velocity_enu_mps": [0.0, 20.0, 0.0]},
    "satellites": {"ephemeris": "ephemeris/ESBC00DNK_R_20201770000_01D_MN.rnx.gz"},
}


def _with(**tables):
    raw = {k: dict(v) if isinstance(v, dict) else v for k, v in MINIMAL.items()}
    for key, value in tables.items():
        if isinstance(value, dict) and key in raw:
            raw[key] = {**raw[key], **value}
        else:
            raw[key] = value
    return raw


def test_default_scenario_is_paper_004():
    sc = load_scenario(DEFAULT_SCENARIO)
    assert math.isclose(math.degrees(sc.lat), 40.0) and math.isclose(math.degrees(sc.lon), 116.0)
    assert sc.height == 100.0 and sc.v_n == (0.0, 20.0, 0.0) and sc.att == (0.0, 0.0, 0.0)
    assert sc.signal.sampling_rate_hz == 25e6 and sc.signal.quantization_bits == 4
    assert sc.signal.complex_baseband and sc.satellites.count == 7
    assert sc.satellites.cn0_dbhz == 40.0 and sc.imu.rate_hz == 200.0
    assert (sc.imu.accel_bias_mg, sc.imu.gyro_bias_deg_h) == (4.0, 8.0)
    assert sc.satellites.ephemeris.exists()
    assert sum(s["duration_s"] for s in sc.motion) == pytest.approx(sc.duration_s)


def test_utc_start_applies_leap_seconds():
    bdt = parse_scenario(_with(time={"start": "2020-06-25T04:00:00", "scale": "BDT"}))
    utc = parse_scenario(_with(time={"start": "2020-06-25T04:00:00", "scale": "UTC"}))
    assert utc.sow - bdt.sow == pytest.approx(4.0)  # BDT - UTC = 4 s since 2017


def test_hash_changes_with_content():
    a = parse_scenario(_with())
    b = parse_scenario(_with(scenario={"seed": 4}))
    assert a.hash != b.hash and a.hash == parse_scenario(_with()).hash


@pytest.mark.parametrize(
    "tables, message",
    [
        ({"scenario": {"duration_s": -1.0}}, "duration_s: must be > 0"),
        ({"start": {"lat_deg": 95.0}}, "lat_deg: must be <= 90"),
        ({"start": {"velocity_enu_mps": [1, 2]}}, "expected 3 finite numbers"),
        ({"time": {"start": "yesterday"}}, "not an ISO date-time"),
        ({"signal": {"sample_format": "mp3"}}, "is not one of"),
        ({"signal": {"sample_format": "iq_int4", "quantization_bits": 8}}, "does not fit"),
        ({"signal": {"kind": "real", "sample_format": "real_int8", "if_hz": 0.0}},
         "must be > 0 for real"),
        ({"motion": [{"type": "teleport", "duration_s": 1.0}]}, "is not one of"),
        ({"motion": [{"type": "circle", "duration_s": 8.0, "direction": "left"}]},
         "exactly one of rate_dps or radius_m"),
        ({"motion": [{"type": "uniform"}]}, "missing key 'duration_s'"),
        ({"outage": [{"prn": 21, "start_s": 5.0, "end_s": 4.0, "blockage": True}]},
         "must be after start_s"),
        ({"bogus": {}}, "unknown table"),
        ({"imu": {"grade": "mems", "acel_bias_mg": 3}}, "unknown key"),
    ],
)
def test_malformed_scenarios_are_rejected(tables, message):
    with pytest.raises(ScenarioError, match=message):
        parse_scenario(_with(**tables))


def test_unknown_prn_is_rejected():
    with pytest.raises(UnknownPrnError, match="C64"):
        parse_scenario(_with(satellites={"prns": ["C21", "C64"]}))


def test_bad_files(tmp_path: Path):
    with pytest.raises(ScenarioError, match="cannot read"):
        load_scenario(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[scenario\nname=1")
    with pytest.raises(ScenarioError, match="not valid TOML"):
        load_scenario(bad)


def test_overrides_revalidate():
    sc = parse_scenario(_with())
    sc2 = sc.with_overrides(duration_s=5.0, sample_format="iq_int16", quantization_bits=12)
    assert sc2.duration_s == 5.0 and sc2.signal.sample_format == "iq_int16"
    with pytest.raises(ScenarioError):
        sc.with_overrides(quantization_bits=12)  # does not fit iq_int8
