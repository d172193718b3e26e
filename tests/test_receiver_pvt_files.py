"""Solution files: CSV round trip, NMEA GGA/RMC format and checksums, atomic streaming."""

from __future__ import annotations

import dataclasses
import datetime as dt
import errno
import functools
import math
import operator

import numpy as np
import pytest

from sdr_di.errors import OutputError
from sdr_di.frames import C_e_n, llh_to_ecef
from sdr_di.io import solution_files as sf
from sdr_di.receiver.pvt import Dops, PvtSolution, PvtStatus

WEEK = 755
SOW = 360004.25          # 2020-06-25 04:00:04.25 BDT = 04:00:00.25 UTC (BDT - UTC = 4 s)


def make_solution(lat_deg=-33.8568, lon_deg=151.2153, h=45.123, v_n=(3.0, 4.0, 0.5),
                  week=WEEK, sow=SOW, status=PvtStatus.FIX, n_sats=7, hdop=1.234,
                  velocity_status=PvtStatus.FIX, bias=1234.5678, drift=-12.34567):
    llh = np.array([math.radians(lat_deg), math.radians(lon_deg), h])
    r = llh_to_ecef(*llh)
    v_n = np.array(v_n, float)
    v_e = C_e_n(llh[0], llh[1]).T @ v_n
    ok = status is PvtStatus.FIX or status is PvtStatus.LARGE_RESIDUALS
    nan3 = np.full(3, np.nan)
    return PvtSolution(
        status=status, sample_index=100, week=week, sow=sow, rx_week=week,
        rx_sow=sow + bias / 299792458.0, r_e=r if ok else nan3, llh=llh if ok else nan3,
        v_e=v_e if ok else nan3, v_n=v_n if ok else nan3,
        clock_bias_m=bias if ok else math.nan, clock_drift_mps=drift if ok else math.nan,
        dops=Dops(2.5, 2.0, hdop, 1.7, 1.1) if ok else Dops.nan(), n_sats=n_sats,
        velocity_status=velocity_status if ok else PvtStatus.NOT_COMPUTED)


def xor_checksum(body: str) -> str:
    return f"{functools.reduce(operator.xor, (ord(c) for c in body), 0):02X}"


# --- NMEA ------------------------------------------------------------------------------------
def test_checksum_of_published_examples():
    # classic NMEA examples with their published checksums
    assert sf.nmea_checksum("GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,") == "47"
    assert sf.nmea_checksum(
        "GPRMC,123519,A,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W") == "6A"
    assert sf.nmea_sentence("GPXXX,1") == "$GPXXX,1*" + xor_checksum("GPXXX,1")
    with pytest.raises(ValueError):
        sf.nmea_sentence("GP*X")


def test_gga_hand_computed():
    # -33.8568 deg = 33 deg 51.408 min S; 151.2153 deg = 151 deg 12.918 min E
    sol = make_solution()
    body = "GNGGA,040000.25,3351.4080,S,15112.9180,E,1,07,1.2,45.123,M,0.0,M,,"
    assert sf.format_gga(sol, decimals=4) == f"${body}*67"
    assert xor_checksum(body) == "67"
    g5 = sf.format_gga(sol, talker="GB")
    assert g5.startswith("$GBGGA,040000.25,3351.40800,S,15112.91800,E,1,07,")
    fields = g5.split("*")[0].split(",")
    assert len(fields) == 15
    assert g5.endswith("*" + xor_checksum(g5[1:g5.index("*")]))


def test_gga_north_west_padding_and_minute_carry():
    sol = make_solution(lat_deg=5.5, lon_deg=-7.25)
    f = sf.format_gga(sol, decimals=4).split(",")
    assert f[2:6] == ["0530.0000", "N", "00715.0000", "W"]
    # 39.99999999999 deg rounds to 40 deg 00.00000 min, not 39 deg 60.00000 min
    sol = make_solution(lat_deg=40.0 - 1e-11, lon_deg=116.0 - 1e-11)
    f = sf.format_gga(sol).split(",")
    assert f[2:6] == ["4000.00000", "N", "11600.00000", "E"]


def test_rmc_hand_computed():
    sol = make_solution()
    # ENU velocity (3, 4): 5 m/s = 9.719 kn, course atan2(3, 4) = 36.87 deg
    body = "GNRMC,040000.25,A,3351.4080,S,15112.9180,E,9.719,36.87,250620,,,A"
    assert sf.format_rmc(sol, decimals=4) == f"${body}*5F"
    assert xor_checksum(body) == "5F"


def test_no_fix_sentences():
    sol = make_solution(status=PvtStatus.TOO_FEW_SATELLITES, n_sats=2)
    assert sf.format_gga(sol) == "$" + (b := "GNGGA,040000.25,,,,,0,02,,,,,,,") + "*" + xor_checksum(b)
    assert sf.format_rmc(sol) == "$" + (b := "GNRMC,040000.25,V,,,,,,,250620,,,N") + "*" + xor_checksum(b)
    # no receiver time at all: empty time and date
    sol = dataclasses.replace(sol, sow=math.nan)
    assert sf.format_gga(sol).startswith("$GNGGA,,,,,,0,")


def test_utc_from_bdt_leap_seconds_and_rounding_carry():
    assert sf.bdt_to_utc(WEEK, SOW) == dt.datetime(2020, 6, 25, 4, 0, 0, 250000)
    # 2016: BDT - UTC = 3 s
    assert sf.bdt_to_utc(*_bdt(dt.datetime(2016, 3, 1, 12, 0, 0))) == dt.datetime(2016, 3, 1, 11, 59, 57)
    # 23:59:59.996 UTC rounds to 00:00:00.00 of the next day (time and date together)
    week, sow = _bdt(dt.datetime(2020, 6, 26, 0, 0, 3, 996000))
    sol = make_solution(week=week, sow=sow)
    f = sf.format_rmc(sol).split(",")
    assert f[1] == "000000.00" and f[9] == "260620"


def _bdt(t_bdt: dt.datetime) -> tuple[int, float]:
    from sdr_di.timebase import datetime_to_bdt
    return datetime_to_bdt(t_bdt)


def test_nmea_writer_file_and_rate(tmp_path):
    path = tmp_path / "sol.nmea"
    sols = [make_solution(sow=SOW - 0.001 + 0.2 * i) for i in range(15)]   # 5 Hz, 3 s
    with sf.NmeaWriter(path, rate_hz=1.0) as w:
        assert not path.exists() and (tmp_path / "sol.nmea.part").exists()
        n = w.write_all(sols)
    assert n == 3 or n == 4
    raw = path.read_bytes()
    lines = raw.split(b"\r\n")
    assert lines[-1] == b"" and len(lines) - 1 == 2 * n
    for ln in lines[:-1]:
        s = ln.decode("ascii")
        assert s[0] == "$" and s[-3] == "*" and s[-2:] == xor_checksum(s[1:-3])
    assert lines[0].startswith(b"$GNGGA") and lines[1].startswith(b"$GNRMC")
    t = [ln.split(b",")[1] for ln in lines[:-1:2]]
    assert len(set(t)) == len(t)                        # one epoch per second
    with pytest.raises(ValueError):
        sf.NmeaWriter(tmp_path / "x.nmea", talker="gps")
    with pytest.raises(ValueError):
        sf.NmeaWriter(tmp_path / "x.nmea", sentences=("VTG",))
    assert not (tmp_path / "x.nmea.part").exists()


# --- CSV -------------------------------------------------------------------------------------
def test_csv_round_trip(tmp_path):
    path = tmp_path / "sol.csv"
    sols = [make_solution(sow=SOW + 0.2 * i, lat_deg=40 + 1e-5 * i, v_n=(0.1 * i, 20, -0.3))
            for i in range(5)]
    sols.append(make_solution(sow=SOW + 1.0, status=PvtStatus.TOO_FEW_SATELLITES, n_sats=3))
    sols.append(make_solution(sow=SOW + 1.2, velocity_status=PvtStatus.LARGE_RESIDUALS))
    sf.write_solution_csv(path, sols)
    text = path.read_text()
    assert text.startswith(sf.CSV_MAGIC + "\n")
    d = sf.read_solution_csv(path)
    assert set(d) == set(sf.CSV_COLUMNS) and len(d["sow"]) == 7
    for i, s in enumerate(sols):
        assert d["week"][i] == s.week and d["rx_week"][i] == s.rx_week
        assert d["sow"][i] == pytest.approx(s.sow, abs=1e-9)
        assert d["rx_sow"][i] == pytest.approx(s.rx_sow, abs=1e-9)
        assert d["status"][i] == s.status.value
        assert d["velocity_status"][i] == s.velocity_status.value
        assert d["n_sats"][i] == s.n_sats
        utc = sf.bdt_to_utc(s.week, s.sow)
        assert d["utc"][i] == utc.strftime("%Y-%m-%dT%H:%M:%S.%f") + "Z"
        if s.valid or s.status is PvtStatus.LARGE_RESIDUALS:
            np.testing.assert_allclose([d["lat_deg"][i], d["lon_deg"][i]],
                                       np.degrees(s.llh[:2]), atol=1e-10)
            assert d["h_m"][i] == pytest.approx(s.llh[2], abs=1e-4)
            np.testing.assert_allclose([d["x_m"][i], d["y_m"][i], d["z_m"][i]], s.r_e, atol=1e-4)
            np.testing.assert_allclose([d["ve_mps"][i], d["vn_mps"][i], d["vu_mps"][i]], s.v_n,
                                       atol=1e-5)
            assert d["clock_bias_m"][i] == pytest.approx(s.clock_bias_m, abs=1e-4)
            assert d["clock_drift_mps"][i] == pytest.approx(s.clock_drift_mps, abs=1e-5)
            assert d["hdop"][i] == pytest.approx(s.dops.hdop, abs=1e-3)
            assert d["gdop"][i] == pytest.approx(s.dops.gdop, abs=1e-3)
        else:
            assert np.isnan(d["lat_deg"][i]) and np.isnan(d["x_m"][i]) and np.isnan(d["pdop"][i])
    assert d["utc"][0] == "2020-06-25T04:00:00.250000Z"


def test_csv_rate_decimation(tmp_path):
    path = tmp_path / "sol.csv"
    sols = [make_solution(sow=SOW + 0.2 * i) for i in range(25)]     # 5 Hz for 5 s
    with sf.SolutionCsvWriter(path, rate_hz=2.0) as w:
        n = w.write_all(sols)
    d = sf.read_solution_csv(path)
    all_slots = np.floor(np.array([s.sow for s in sols]) * 2.0 + 1e-6)
    first = np.unique(all_slots, return_index=True)[1]
    assert n == len(d["sow"]) == 11                    # 4.25 .. 9.05 s touches 11 half-seconds
    np.testing.assert_allclose(d["sow"], [sols[i].sow for i in first], atol=1e-9)
    assert np.diff(d["sow"]).max() <= 0.6 + 1e-6         # never a gap of a whole interval


def test_csv_reader_rejects_bad_files(tmp_path):
    p = tmp_path / "bad.csv"
    p.write_text("hello\n")
    with pytest.raises(sf.SolutionFileError, match="not an sdr-di solution"):
        sf.read_solution_csv(p)
    sf.write_solution_csv(p, [make_solution()])
    lines = p.read_text().splitlines()
    p.write_text("\n".join(lines[:-1] + [lines[-1].replace(",fix,", ",fix,extra,")]) + "\n")
    with pytest.raises(sf.SolutionFileError, match="fields"):
        sf.read_solution_csv(p)
    p.write_text("\n".join(lines[:-1] + [lines[-1].replace("755", "x55", 1)]) + "\n")
    with pytest.raises(sf.SolutionFileError, match="column week"):
        sf.read_solution_csv(p)


# --- atomicity -------------------------------------------------------------------------------
@pytest.mark.parametrize("cls", [sf.SolutionCsvWriter, sf.NmeaWriter])
def test_nothing_under_final_name_if_writing_fails(tmp_path, cls):
    path = tmp_path / "out"
    part = tmp_path / "out.part"
    # an exception in the producer
    with pytest.raises(RuntimeError), cls(path, rate_hz=None) as w:
        w.write(make_solution())
        assert part.exists() and not path.exists()
        raise RuntimeError("tracking crashed")
    assert not path.exists() and not part.exists()

    # a write error (disk full) in the middle of the stream
    class DiskFull:
        def __init__(self, fh):
            self.fh = fh

        def write(self, s):
            raise OSError(errno.ENOSPC, "No space left on device")

    w = cls(path, rate_hz=None)
    w.write(make_solution())
    w._fh = DiskFull(w._fh)
    with pytest.raises(OutputError, match="No space left"):
        w.write(make_solution(sow=SOW + 1))
    assert w.closed and not path.exists() and not part.exists()
    with pytest.raises(ValueError, match="closed"):
        w.write(make_solution())

    # explicit abort
    w = cls(path, rate_hz=None)
    w.write(make_solution())
    w.abort()
    assert not path.exists() and not part.exists()

    # output directory that does not exist
    with pytest.raises(OutputError):
        cls(tmp_path / "missing" / "out")


def test_close_is_the_only_way_to_the_final_name(tmp_path):
    path = tmp_path / "a.csv"
    w = sf.SolutionCsvWriter(path)
    w.write(make_solution())
    assert not path.exists()
    assert w.close() == path and path.exists() and not (tmp_path / "a.csv.part").exists()
    assert w.close() == path                       # idempotent
    assert len(sf.read_solution_csv(path)["sow"]) == 1


def test_csv_sigma_columns_are_the_covariance_in_enu_and_old_files_still_read(tmp_path):
    """``pos_sd_*``/``vel_sd_*``: sqrt of the diagonal of ``C_e_n P C_e_n^T`` of the fix's
    ``cov`` / ``cov_v`` (x, y, z block); NaN without a fix; a 24-column file reads with
    NaN sigmas."""
    A = np.array([[4.0, 1.0, 0.5], [1.0, 9.0, -2.0], [0.5, -2.0, 16.0]])
    cov = np.zeros((4, 4))
    cov[:3, :3] = A
    sol = dataclasses.replace(make_solution(lat_deg=40.0, lon_deg=116.0), cov=cov,
                              cov_v=cov * 1e-4)
    bad = make_solution(sow=SOW + 0.2, status=PvtStatus.TOO_FEW_SATELLITES)
    path = sf.write_solution_csv(tmp_path / "s.csv", [sol, bad])
    d = sf.read_solution_csv(path)
    C = C_e_n(math.radians(40.0), math.radians(116.0))
    enu = np.sqrt(np.diagonal(C @ A @ C.T))
    got = [d[c][0] for c in ("pos_sd_e_m", "pos_sd_n_m", "pos_sd_u_m")]
    assert got == pytest.approx(enu, abs=1e-4)
    got = [d[c][0] for c in ("vel_sd_e", "vel_sd_n", "vel_sd_u")]
    assert got == pytest.approx(enu * 1e-2, abs=1e-5)
    assert np.isnan([d[c][1] for c in sf.CSV_COLUMNS[-6:]]).all()
    # a file of the 24 columns before the sigmas
    lines = path.read_text().splitlines()
    head = [ln for ln in lines if ln.startswith("#")]
    rows = [",".join(ln.split(",")[:24]) for ln in lines[len(head):]]
    (tmp_path / "old.csv").write_text("\n".join(head + rows) + "\n")
    old = sf.read_solution_csv(tmp_path / "old.csv")
    assert old["h_m"][0] == d["h_m"][0] and np.isnan(old["pos_sd_e_m"]).all()
