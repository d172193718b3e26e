"""RINEX 4 navigation files: BDS D1/D2 EPH frames, BDS Klobuchar ION frames, skipped frames,
errors, and the shipped IGS merged daily file (BRD400DLR, 2023-03-12) through the CLI."""

from __future__ import annotations

import gzip
import json
import re
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from sdr_di.cli import main
from sdr_di.constants import is_geo
from sdr_di.errors import EphemerisError
from sdr_di.orbits.broadcast import sat_pos_vel_clock
from sdr_di.orbits.ephemeris import Klobuchar
from sdr_di.orbits.rinex_nav import load_nav, merge_nav, read_klobuchar
from sdr_di.signal.navmsg import assistance_klobuchar

REPO = Path(__file__).resolve().parents[1]
BRD4 = REPO / "ephemeris" / "BRD400DLR_S_20230710000_01D_MN.rnx.gz"
GOP = REPO / "ephemeris" / "BRDC00GOP_R_20210010000_01D_MN.rnx.gz"
NYA = REPO / "ephemeris" / "NYA100NOR_S_20241240000_01D_CN.rnx.gz"

#: Geostationary orbit radius [km] (GM = 3.986004418e14 m^3/s^2, sidereal day 86164.0905 s).
R_GEO_KM = 42164.2


@pytest.fixture(scope="module")
def text() -> str:
    return gzip.decompress(BRD4.read_bytes()).decode("latin-1")


@pytest.fixture(scope="module")
def nav():
    return load_nav(BRD4)


# ---- fixture text ------------------------------------------------------------------------

HDR4 = (
    "     4.00           NAVIGATION DATA     M                   RINEX VERSION / TYPE\n"
    "BCEmerge            congo               20230313 004604 GMT PGM / RUN BY / DATE \n"
    "    18    18  1929     7                                    LEAP SECONDS        \n"
    "                                                            END OF HEADER       \n"
)
# Frames copied from BRD400DLR (C01 D2 00:00, C20 D1 00:00, C05 and C02 ION D1D2), with a
# skipped CNV1 record of the same satellite and STO/EOP/GPS frames between them.
EPH_C01 = (
    "> EPH C01 D2  \n"
    "C01 2023 03 12 00 00 00 9.050882654265e-04-2.618349981276e-12 0.000000000000e+00\n"
    "     1.000000000000e+00-3.022187500000e+02-1.132904332870e-09 1.639863675133e+00\n"
    "    -1.014024019241e-05 4.634374054149e-04 1.808675006032e-05 6.493325918198e+03\n"
    "     0.000000000000e+00 2.887099981308e-08-2.843751285290e+00-8.102506399155e-08\n"
    "     9.005722671926e-02-5.558125000000e+02-2.556429343966e+00 2.302953070096e-09\n"
    "     4.485901141503e-10 0.000000000000e+00 8.970000000000e+02 0.000000000000e+00\n"
    "     2.000000000000e+00 0.000000000000e+00-5.400000000000e-09-9.700000000000e-09\n"
    "     0.000000000000e+00 0.000000000000e+00                                      \n"
)
EPH_C20 = (
    "> EPH C20 D1  \n"
    "C20 2023 03 12 00 00 00 6.842537550256e-04-1.909405966671e-11 0.000000000000e+00\n"
    "     1.000000000000e+00-4.281250000000e+00 3.977308528008e-09 1.218233934276e+00\n"
    "    -1.983717083931e-07 8.093395736068e-04 5.035661160946e-06 5.282622047424e+03\n"
    "     0.000000000000e+00 1.164153218269e-08-1.162521132060e+00-2.421438694000e-08\n"
    "     9.721966251717e-01 2.607656250000e+02-7.432932949550e-01-6.930645832075e-09\n"
    "     1.225051028293e-10 0.000000000000e+00 8.970000000000e+02 0.000000000000e+00\n"
    "     2.000000000000e+00 0.000000000000e+00 1.960000000000e-08 1.960000000000e-08\n"
    "     0.000000000000e+00 1.000000000000e+00                                      \n"
)
# A CNV1 frame of C20 whose record line looks like a D1 record: it must be skipped whole.
CNV1_C20 = EPH_C20.replace("> EPH C20 D1  ", "> EPH C20 CNV1").replace(
    "6.842537550256e-04", "1.111111111111e-04")
ION_C02 = (
    "> ION C02 D1D2\n"
    "    2023 03 12 01 59 30 4.097819328308e-08 5.066394805908e-07-3.337860107422e-06\n"
    "     4.529953002930e-06 8.601600000000e+04 9.175040000000e+05-7.143424000000e+06\n"
    "     8.192000000000e+06\n"
)
ION_C05 = (
    "> ION C05 D1D2\n"
    "    2023 03 12 00 00 00 4.190951585770e-08 4.395842552185e-07-2.861022949219e-06\n"
    "     3.576278686523e-06 8.396800000000e+04 9.994240000000e+05-7.798784000000e+06\n"
    "     8.323072000000e+06\n"
)
OTHER = (
    "> STO C19 D1D2\n"
    "    2023 03 12 00 00 14 BDUT                                  UTC(NTSC)         \n"
    "     2.400000000000e+02 1.862645149231e-09 0.000000000000e+00 0.000000000000e+00\n"
    "> ION C21 CNVX\n"
    "    2023 03 12 00 00 00 1.000000000000e+01 2.000000000000e+00 3.000000000000e+00\n"
    "     4.000000000000e+00 5.000000000000e+00 6.000000000000e+00 7.000000000000e+00\n"
    "     8.000000000000e+00 9.000000000000e+00 1.000000000000e+00 0.000000000000e+00\n"
    "> EOP C21 CNVX\n"
    "    2023 03 12 00 00 00 1.0e-09 2.0e-09 3.0e-09\n"
    "> ION G02 LNAV\n"
    "    2023 03 12 00 00 00 1.000000000000e-08 2.000000000000e-08 3.000000000000e-08\n"
    "     4.000000000000e-08 5.000000000000e+04 6.000000000000e+04 7.000000000000e+04\n"
    "     8.000000000000e+04 1.000000000000e+00\n"
)
K_C05 = Klobuchar(alpha=(4.190951585770e-08, 4.395842552185e-07, -2.861022949219e-06,
                         3.576278686523e-06),
                  beta=(8.396800000000e+04, 9.994240000000e+05, -7.798784000000e+06,
                        8.323072000000e+06))


def _write(tmp_path: Path, name: str, body: str, header: str = HDR4) -> Path:
    p = tmp_path / name
    p.write_text(header + body)
    return p


def _err(path: Path) -> str:
    with pytest.raises(EphemerisError) as ei:
        load_nav(path)
    msg = str(ei.value)
    assert "\n" not in msg and path.name in msg
    return msg


# ---- the shipped merged daily file ---------------------------------------------------------


def test_prns_and_record_counts_match_the_frame_lines(text, nav):
    """Every ``> EPH Cnn D1|D2`` frame is read; the kept records per PRN are its distinct
    (week, toe) pairs, counted here from the text with a plain split."""
    lines = text.splitlines()
    frames = [(i, ln.split()) for i, ln in enumerate(lines)
              if re.fullmatch(r"> EPH C\d\d (D1|D2)\s*", ln)]
    per_prn = Counter(int(tok[2][1:]) for _, tok in frames)
    distinct: dict[int, set] = {}
    for i, tok in frames:
        toe = float(lines[i + 4][4:23])
        week = float(lines[i + 6][42:61])
        distinct.setdefault(int(tok[2][1:]), set()).add((week, toe))
    assert nav.version == 4.0
    assert nav.prns == tuple(sorted(per_prn))
    assert nav.n_records_read == len(frames) == sum(per_prn.values())
    assert {p: len(r) for p, r in nav.records.items()} == {p: len(s) for p, s in distinct.items()}
    assert nav.n_records + nav.n_duplicates == nav.n_records_read
    # D2 frames exactly for the GEO PRNs
    d2 = {int(tok[2][1:]) for _, tok in frames if tok[3] == "D2"}
    assert d2 == {p for p in per_prn if is_geo(p)}
    for prn, recs in nav.records.items():
        assert all(r.finite() and r.prn == prn for r in recs)
        toes = [r.week * 604800 + r.toe for r in recs]
        assert toes == sorted(toes) and len(set(toes)) == len(toes)


def test_one_record_equals_the_text(nav):
    r = nav.records[1][0]  # the first C01 D2 frame (EPH_C01 above)
    assert (r.week, r.toe, r.toc) == (897, 0.0, 0.0)
    assert r.af0 == 9.050882654265e-04 and r.af1 == -2.618349981276e-12 and r.af2 == 0.0
    assert r.Crs == -3.022187500000e+02 and r.Delta_n == -1.132904332870e-09
    assert r.M0 == 1.639863675133e+00 and r.e == 4.634374054149e-04
    assert r.sqrtA == 6.493325918198e+03 and r.Cic == 2.887099981308e-08
    assert r.Omega0 == -2.843751285290e+00 and r.i0 == 9.005722671926e-02
    assert r.omega == -2.556429343966e+00 and r.Omega_dot == 2.302953070096e-09
    assert r.IDOT == 4.485901141503e-10 and r.TGD1 == -5.4e-09 and r.TGD2 == -9.7e-09
    assert (r.AODE, r.AODC, r.SatH1) == (1, 0, 0) and r.is_geo


# Longitudes [deg E] of the GEO slots: C03 110.5, C04 160.0 (BDS-2), C59 140.0 and C60 80.0
# (BDS-3 G1/G2). C01 and C02 were at 140 E and 80 E; in this 2023 file their broadcast orbits
# put them 4.5 and 4.0 deg east of that (144.5 E, 84.0 E: the BDS-3 GEOs hold 140 E and
# 80 E), so they are checked within 5 deg of the old slots.
GEO_SLOTS = [(1, 140.0, 5.0), (2, 80.0, 5.0), (3, 110.5, 1.0), (4, 160.0, 1.0),
             (59, 140.0, 1.0), (60, 80.0, 1.0)]


@pytest.mark.parametrize("prn,lon_deg,tol_deg", GEO_SLOTS)
def test_geo_satellites_at_their_slots(nav, prn, lon_deg, tol_deg):
    for r in nav.records[prn][::6]:
        assert r.is_geo
        r_e, _, _, _ = sat_pos_vel_clock(r, r.toe, r.week)
        x, y, z = np.asarray(r_e, float).ravel()
        radius_km = np.sqrt(x * x + y * y + z * z) / 1e3
        assert abs(radius_km - R_GEO_KM) < 100.0, (prn, radius_km)
        assert abs(np.degrees(np.arcsin(z / 1e3 / radius_km))) < 3.0  # inclination < 3 deg
        lon = np.degrees(np.arctan2(y, x))
        assert abs((lon - lon_deg + 180.0) % 360.0 - 180.0) < tol_deg, (prn, lon)


def test_klobuchar_is_the_earliest_ion_frame(text, nav):
    """The first ``> ION Cnn D1D2`` frame of the day (C05, 00:00:00), read from the text."""
    lines = text.splitlines()
    ions = [i for i, ln in enumerate(lines) if re.fullmatch(r"> ION C\d\d D1D2\s*", ln)]
    assert len(nav.iono_frames) == len(ions) > 1
    first = min(ions, key=lambda i: lines[i + 1][4:23])
    nums = (lines[first + 1][23:] + lines[first + 2][4:] + lines[first + 3][4:]).replace("e", "E")
    vals = [float(nums[19 * k:19 * (k + 1)]) for k in range(8)]
    assert nav.iono == Klobuchar(alpha=tuple(vals[:4]), beta=tuple(vals[4:])) == K_C05
    assert nav.iono_frames[0].prn == 5 and str(nav.iono_frames[0].epoch) == "2023-03-12 00:00:00"
    assert [f.epoch for f in nav.iono_frames] == sorted(f.epoch for f in nav.iono_frames)
    assert read_klobuchar(BRD4) == nav.iono
    coeffs, label = assistance_klobuchar(nav)
    assert label == "ION C05 D1D2 frame of 2023-03-12 00:00:00 BDT (earliest of 15)"
    assert coeffs is not None and np.allclose(coeffs.alpha, K_C05.alpha, rtol=0.02)


# ---- fixture files -------------------------------------------------------------------------


def test_frames_read_and_skipped(tmp_path):
    p = _write(tmp_path, "mini.rnx", ION_C02 + OTHER + EPH_C20 + CNV1_C20 + EPH_C01 + ION_C05)
    nav = load_nav(p)
    assert nav.prns == (1, 20) and nav.n_records_read == 2
    assert nav.records[20][0].af0 == 6.842537550256e-04  # not the CNV1 copy
    assert nav.records[20][0].AODC == 1 and not nav.records[20][0].is_geo
    assert nav.iono == K_C05  # earliest, though second in the file
    assert [f.prn for f in nav.iono_frames] == [5, 2]
    assert nav.iono_gps is None
    gz = tmp_path / "mini.rnx.gz"
    gz.write_bytes(gzip.compress(p.read_bytes()))
    assert load_nav(gz).records == nav.records


def test_no_ion_frame_no_klobuchar(tmp_path):
    nav = load_nav(_write(tmp_path, "noion.rnx", EPH_C01))
    assert nav.iono is None and nav.iono_frames == () and nav.iono_label == ""
    assert assistance_klobuchar(nav)[0] is None


def test_versions_401_402_read(tmp_path):
    for v in ("4.01", "4.02"):
        nav = load_nav(_write(tmp_path, f"v{v}.rnx", EPH_C01, HDR4.replace("4.00", v)))
        assert nav.version == float(v) and nav.prns == (1,)


def test_rinex5_rejected(tmp_path):
    msg = _err(_write(tmp_path, "v5.rnx", EPH_C01, HDR4.replace("4.00", "5.00")))
    assert msg.startswith("unsupported RINEX version 5.00: ")


@pytest.mark.parametrize("cut", [3, 8])
def test_truncated_eph_frame(tmp_path, cut):
    """A frame cut after ``cut`` lines, followed by a complete frame or the end of file."""
    short = "".join(EPH_C01.splitlines(keepends=True)[:cut])
    assert "truncated" in _err(_write(tmp_path, "cut.rnx", short + EPH_C20))
    assert "truncated" in _err(_write(tmp_path, "end.rnx", EPH_C20 + short))


def test_eph_frame_without_its_record(tmp_path):
    msg = _err(_write(tmp_path, "bare.rnx", "> EPH C01 D2\n" + EPH_C20))
    assert "truncated EPH C01 D2 frame" in msg


def test_truncated_ion_frame(tmp_path):
    short = "".join(ION_C05.splitlines(keepends=True)[:3])
    assert "truncated ION C05" in _err(_write(tmp_path, "ion.rnx", EPH_C01 + short + EPH_C20))
    assert "truncated ION C05" in _err(_write(tmp_path, "ion2.rnx", EPH_C01 + short))


def test_bad_numbers(tmp_path):
    bad = EPH_C01.replace("6.493325918198e+03", "6.4933x5918198e+03")
    assert "malformed number" in _err(_write(tmp_path, "bad.rnx", bad))
    bad_ion = ION_C05.replace("9.994240000000e+05", "9.99424000000Oe+05")
    assert "malformed number" in _err(_write(tmp_path, "badion.rnx", EPH_C01 + bad_ion))
    nan_ion = ION_C05.replace("9.994240000000e+05", "               nan")
    assert "non-finite" in _err(_write(tmp_path, "nanion.rnx", EPH_C01 + nan_ion))


def test_malformed_frame_marker(tmp_path):
    assert "frame marker" in _err(_write(tmp_path, "m.rnx", EPH_C01 + "> XYZ C01 D1\n"))
    assert "frame marker" in _err(_write(tmp_path, "m2.rnx", EPH_C01 + ">\n"))


def test_no_bds_record(tmp_path):
    assert "no BDS records" in _err(_write(tmp_path, "ionly.rnx", ION_C05 + OTHER))


def test_rinex3_files_unchanged():
    """RINEX 3 files read as before: header Klobuchar labelled BDSA/BDSB, no ION frames."""
    gop = load_nav(GOP)
    assert gop.version == 3.04 and gop.iono_frames == () and gop.iono_label == "BDSA/BDSB"
    assert assistance_klobuchar(gop)[1] == "BDSA/BDSB"
    nya = load_nav(NYA)
    assert nya.n_records == 194 and nya.iono is None and nya.iono_label == ""
    m = merge_nav([nya, gop])
    assert m.iono == gop.iono and m.iono_label == "BDSA/BDSB"


# ---- end to end through the CLI -------------------------------------------------------------

PRNS = (1, 2, 3, 28, 37)  # GEOs C01-C03, BDS-3 MEOs C28, C37: all above 30 deg at 06:30


@pytest.fixture(scope="module")
def generated(tmp_path_factory):
    d = tmp_path_factory.mktemp("rinex4_cli")
    s = (REPO / "signals" / "default.toml").read_text()
    for old, new in (('start = "2020-06-25T06:30:00"', 'start = "2023-03-12T06:30:00"'),
                     ('prns = "auto"', f"prns = {list(PRNS)}"),
                     ("duration_s = 60.0", "duration_s = 0.05")):
        assert old in s
        s = s.replace(old, new, 1)
    s = re.sub(r'ephemeris = ".*"', f'ephemeris = "{BRD4.as_posix()}"', s)
    scenario = d / "r4.toml"
    scenario.write_text(s)
    rc = main(["generate", "--no-progress", "--scenario", str(scenario), "--fs", "2.5e6",
               "--out", str(d / "out")])
    return rc, d / "out"


def test_generate_with_rinex4(generated):
    rc, out = generated
    assert rc == 0
    meta = json.loads((out / "default.json").read_text())
    sats = {s["prn"]: s for s in meta["satellites"]}
    assert tuple(sorted(sats)) == PRNS
    assert all(s["nav"] == ("D2" if is_geo(p) else "D1") for p, s in sats.items())
    assert {s["nav"] for s in sats.values()} == {"D1", "D2"}
    assert all(s["week"] == 897 for s in sats.values())
    assert meta["klobuchar_source"].startswith("ION C05 D1D2 frame")
    assert meta["ephemeris_file"].endswith(BRD4.name)


def test_run_takes_rinex4_assistance(generated, capsys, tmp_path):
    """``sdr-di run --ephemeris`` reads the RINEX 4 file (a RINEX 5 header is refused with
    exit status 2); 0.05 s is too short for a fix, so the run ends with status 1."""
    _, out = generated
    capsys.readouterr()
    v5 = tmp_path / "v5.rnx"
    v5.write_text(HDR4.replace("4.00", "5.00") + EPH_C01)
    rc = main(["run", str(out / "default.bin"), "--no-progress", "--ephemeris", str(v5),
               "--out", str(tmp_path / "bad")])
    assert rc == 2 and "unsupported RINEX version 5.00" in capsys.readouterr().err
    rc = main(["run", str(out / "default.bin"), "--no-progress", "--ephemeris", str(BRD4),
               "--out", str(tmp_path / "run")])
    cap = capsys.readouterr()
    assert rc == 1 and "no fix" in cap.err, cap.err
    assert f"assistance: {BRD4}" in cap.out
    summary = json.loads((tmp_path / "run" / "default_scalar_summary.json").read_text())
    assert summary["ephemeris_file"] == str(BRD4)
