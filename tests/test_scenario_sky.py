"""The shipped BeiDou-sky scenario (issue 46 items 3 and 6): GEO, IGSO and MEO satellites
from a real RINEX 4 broadcast file, a tactical IMU drawn per seed and an atmosphere apart
from the receiver's models, all recorded in the sidecar."""

import json

import numpy as np

import sdr_di
from sdr_di.orbits.rinex_nav import load_nav
from sdr_di.scenario import REPO_ROOT
from sdr_di.scenario.schema import load_scenario

SKY = REPO_ROOT / "signals" / "beidou_sky.toml"
GEO_RADIUS_M = 42_164e3


def test_the_sky_scenario_tracks_geo_igso_and_meo_satellites_in_a_world_apart(tmp_path):
    sc = load_scenario(SKY)
    files = sdr_di.generate(tmp_path, scenario=SKY, duration_s=0.02, sampling_rate_hz=2.5e6)
    meta = json.loads(files.metadata.read_text())
    sats = meta["satellites"]
    assert len(sats) == sc.satellites.count == 12
    nav = load_nav(sc.satellites.ephemeris)
    kinds = {"GEO": 0, "IGSO": 0, "MEO": 0}
    for s in sats:
        eph = nav.select(s["prn"], sc.week, sc.sow, broadcast=True)
        a = eph.sqrtA ** 2                      # semi-major axis [m]
        if s["nav"] == "D2":
            kinds["GEO"] += 1
            assert abs(a - GEO_RADIUS_M) < 100e3 and eph.is_geo, s
        else:
            kinds["IGSO" if abs(a - GEO_RADIUS_M) < 100e3 else "MEO"] += 1
        assert s["elevation_deg"] >= sc.satellites.elevation_mask_deg
    assert kinds["GEO"] >= 3 and kinds["IGSO"] >= 3 and kinds["MEO"] >= 2, kinds
    # the world apart from the filter's models, drawn from the seed and recorded
    assert meta["atmosphere_truth"]["truth"] == "residuals"
    scales = np.array(list(meta["atmosphere_truth"]["iono_scale"].values()))
    assert scales.size == 12 and np.std(scales) > 0.1
    assert meta["imu"]["grade"] == "tactical"
    assert np.any(np.abs(meta["imu_unit"]["gyro_scale"]) > 0)     # this seed's unit
    assert "klobuchar_source" in meta and "ION" in meta["klobuchar_source"]
