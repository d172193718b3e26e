"""RINEX 3 navigation reader: shipped files, georinex pitfall, errors, record selection."""

from __future__ import annotations

import dataclasses
import gzip
import itertools
import logging
import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from sdr_di.errors import EphemerisError, NoEphemerisError, UnknownPrnError
from sdr_di.orbits.ephemeris import Klobuchar
from sdr_di.orbits.rinex_nav import (
    DEFAULT_MAX_AGE_GEO_S,
    DEFAULT_MAX_AGE_S,
    NavData,
    crosscheck_with_georinex,
    load_nav,
    merge_nav,
    read_klobuchar,
    ura_index,
)

EPH_DIR = Path(__file__).resolve().parents[1] / "ephemeris"
ESBC = EPH_DIR / "ESBC00DNK_R_20201770000_01D_MN.rnx.gz"
MOJN = EPH_DIR / "MOJN00DNK_R_20201770000_01D_MN.rnx.gz"
NYA = EPH_DIR / "NYA100NOR_S_20241240000_01D_CN.rnx.gz"
WRD = EPH_DIR / "BRDC00WRD_S_20230990000_01D_MN.rnx"
GOP = EPH_DIR / "BRDC00GOP_R_20210010000_01D_MN.rnx.gz"

# 29 PRNs of ESBC/MOJN (SOURCES.md): C05 (GEO), C06-C14, C16, C19-C30, C32-C37.
ESBC_PRNS = (5, *range(6, 15), 16, *range(19, 31), *range(32, 38))

# (file, BDS records, PRNs) as documented in shared/data/SOURCES.md; no file has internal
# duplicates, so the kept count equals the read count.
SHIPPED = [
    (ESBC, 357, 29),
    (MOJN, 344, 29),
    (NYA, 194, 18),
    (WRD, 33, 33),
    (GOP, 1, 1),
]

# ---- fixture text -----------------------------------------------------------------------

HDR_BDS = (
    "     3.05           N: GNSS NAV DATA    C: BEIDOU           RINEX VERSION / TYPE\n"
    "test                test                20240504 003737 UTC PGM / RUN BY / DATE \n"
    "                                                            END OF HEADER       \n"
)
# NYA1 C06 record (2024-05-03), blank spare fields as in the real file.
REC_C06 = (
    "C06 2024 05 03 00 00 00 3.918854054064E-04 2.833466794527E-11 0.000000000000E+00\n"
    "     1.000000000000E+00-2.071562500000E+02 9.303958975808E-10-8.308130068794E-01\n"
    "    -7.017515599728E-06 4.157007322647E-03 3.262050449848E-05 6.492921838760E+03\n"
    "     4.320000000000E+05 1.005828380585E-07-8.108378465138E-01 1.741573214531E-07\n"
    "     9.467232042387E-01-7.717968750000E+02-2.723800353126E+00-1.740786796472E-09\n"
    "     2.521533603424E-10                    9.560000000000E+02                   \n"
    "     2.000000000000E+00 0.000000000000E+00 8.499999815115E-09-1.200000000000E-09\n"
    "     4.320000000000E+05 0.000000000000E+00                                      \n"
)
REC_G01 = (
    "G01 2024 05 03 00 00 00 3.918854054064E-04 2.833466794527E-11 0.000000000000E+00\n"
    "     1.000000000000E+00-2.071562500000E+02 9.303958975808E-10-8.308130068794E-01\n"
    "    -7.017515599728E-06 4.157007322647E-03 3.262050449848E-05 5.153700000000E+03\n"
    "     4.320000000000E+05 1.005828380585E-07-8.108378465138E-01 1.741573214531E-07\n"
    "     9.467232042387E-01-7.717968750000E+02-2.723800353126E+00-1.740786796472E-09\n"
    "     2.521533603424E-10 1.000000000000E+00 2.312000000000E+03 0.000000000000E+00\n"
    "     2.000000000000E+00 0.000000000000E+00 8.499999815115E-09 1.000000000000E+00\n"
    "     4.320000000000E+05 4.000000000000E+00\n"
)
HDR_RINEX4 = (
    "     4.00           NAVIGATION DATA     M                   RINEX VERSION / TYPE\n"
    "BCEmerge            congo               20230313 004604 GMT PGM / RUN BY / DATE \n"
    "    18    18  1929     7                                    LEAP SECONDS        \n"
    "                                                            END OF HEADER       \n"
    "> EPH C01 D2  \n"
    "C01 2023 03 12 00 00 00 9.050882654265e-04-2.618349981276e-12 0.000000000000e+00\n"
)


def _write(tmp_path: Path, name: str, text: str | bytes) -> Path:
    p = tmp_path / name
    if isinstance(text, bytes):
        p.write_bytes(text)
    else:
        p.write_text(text)
    return p


def _replace_field(record: str, line: int, field: int, new: str) -> str:
    """Replace field ``field`` (0-based) of record line ``line`` (0 = first line)."""
    lines = record.splitlines(keepends=True)
    ln = lines[line].rstrip("\n").ljust(80)
    start = (23 if line == 0 else 4) + 19 * field
    lines[line] = ln[:start] + new.rjust(19)[:19] + ln[start + 19:] + "\n"
    return "".join(lines)


# ---- shipped files ---------------------------------------------------------------------


@pytest.mark.parametrize("path,n_rec,n_prn", SHIPPED, ids=lambda v: getattr(v, "name", str(v)))
def test_shipped_files_load_finite(path, n_rec, n_prn):
    nav = load_nav(path)
    assert nav.n_records_read == n_rec
    assert nav.n_records == n_rec and nav.n_duplicates == 0
    assert len(nav.prns) == n_prn
    for prn, recs in nav.records.items():
        assert recs, prn
        for r in recs:
            assert r.finite(), r
            assert r.prn == prn and 1 <= prn <= 63
            assert 5000 < r.sqrtA < 6600 and 0 <= r.e < 0.02
        toes = [r.week * 604800 + r.toe for r in recs]
        assert toes == sorted(toes) and len(set(toes)) == len(toes)


def test_esbc_prns_and_values():
    nav = load_nav(ESBC)
    assert nav.prns == ESBC_PRNS
    assert nav.iono is None  # ESBC header has GPS/GAL iono but no BDSA/BDSB
    # first C05 record, values straight from the file
    r = nav.records[5][0]
    assert (r.week, r.toe, r.toc) == (755, 338400.0, 338400.0)
    assert r.af0 == -5.154609680176e-04 and r.Crs == -4.142968750000e+02
    assert r.sqrtA == 6.493378950119e+03 and r.Omega_dot == 4.100527946305e-09
    assert r.TGD1 == 1.0e-10 and r.TGD2 == -9.3e-09 and r.SatH1 == 0
    assert r.AODE == 1 and r.AODC == 0 and r.URAI == ura_index(2.0) == 0
    assert r.is_geo


def test_bds_klobuchar_from_gop_header():
    k = load_nav(GOP).iono
    assert k == Klobuchar(alpha=(1.1180e-08, 2.9800e-08, -4.1720e-07, 6.5570e-07),
                          beta=(1.4130e+05, -5.2430e+05, 1.6380e+06, -4.5880e+05))
    assert read_klobuchar(GOP) == k
    assert read_klobuchar(ESBC) is None


def test_header_without_bds_klobuchar_does_not_import_georinex():
    """Nothing to cross-check without BDSA/BDSB: loading the shipped ESBC file (every
    ``sdr-di run``'s assistance) leaves georinex (xarray, pandas) unimported; the GOP file,
    which has them, is still compared with georinex's header reader."""
    import subprocess
    import sys

    code = ("import sys; from sdr_di.orbits.rinex_nav import load_nav; "
            "load_nav(sys.argv[1]); print('georinex' in sys.modules)")
    out = [subprocess.run([sys.executable, "-c", code, str(f)], capture_output=True,
                          text=True, check=True).stdout.split()[-1] for f in (ESBC, GOP)]
    assert out == ["False", "True"]


def test_georinex_nan_pitfall_and_crosscheck():
    """georinex 1.16.2 gives NaN for every BDS value of the station files; we do not."""
    import georinex

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        logging.getLogger().setLevel(logging.WARNING)
        ds = georinex.load(ESBC, use="C")
    values = np.concatenate([np.ravel(ds[v].values) for v in ("sqrtA", "Eccentricity", "M0")])
    if georinex.__version__ == "1.16.2":
        assert np.all(np.isnan(values)), "georinex pitfall no longer present: update the docs"
    nav = load_nav(ESBC)
    assert all(r.finite() for recs in nav.records.values() for r in recs)
    stats = crosscheck_with_georinex(nav)
    assert stats["nan"] + stats["compared"] == 357


def test_crosscheck_agrees_where_georinex_is_finite():
    stats = crosscheck_with_georinex(load_nav(GOP, crosscheck=True))
    assert stats == {"compared": 1, "nan": 0, "unavailable": 0}


def test_plain_and_gzip_identical(tmp_path):
    plain = _write(tmp_path, "nya.rnx", gzip.decompress(NYA.read_bytes()))
    gz_no_suffix = _write(tmp_path, "nya_gz.rnx", NYA.read_bytes())  # gzip detected by magic
    a, b, c = load_nav(NYA), load_nav(plain), load_nav(gz_no_suffix)
    assert a.records == b.records == c.records


def test_merge_deduplicates_identical_records():
    a, b = load_nav(ESBC), load_nav(MOJN)
    m = merge_nav([a, b])
    assert m.n_records_read == 357 + 344
    assert m.n_records + m.n_duplicates == 357 + 344
    assert m.n_duplicates > 300 and m.n_conflicts == 0
    assert m.prns == ESBC_PRNS
    keys = {(r.prn, r.week, r.toe) for recs in m.records.values() for r in recs}
    assert len(keys) == m.n_records
    assert m.sources == (ESBC, MOJN)


def test_duplicate_rule_is_deterministic(tmp_path):
    # same (PRN, week, toe) twice in one file, the second unhealthy then healthy
    healthy = REC_C06
    unhealthy = _replace_field(REC_C06, 6, 1, "1.000000000000E+00")
    changed = _replace_field(REC_C06, 0, 0, "3.900000000000E-04")
    p1 = _write(tmp_path, "d1.rnx", HDR_BDS + unhealthy + healthy)
    nav = load_nav(p1)
    assert nav.n_records == 1 and nav.n_duplicates == 1 and nav.n_conflicts == 1
    assert nav.records[6][0].healthy  # healthy wins over an earlier unhealthy one
    p2 = _write(tmp_path, "d2.rnx", HDR_BDS + healthy + changed)
    p3 = _write(tmp_path, "d3.rnx", HDR_BDS + changed + healthy)
    assert load_nav(p2).records[6][0].af0 == 3.918854054064e-04  # first occurrence wins
    assert load_nav(p3).records[6][0].af0 == 3.9e-04


# ---- errors ----------------------------------------------------------------------------


def _err(path) -> str:
    with pytest.raises(EphemerisError) as ei:
        load_nav(path)
    msg = str(ei.value)
    assert "\n" not in msg
    assert Path(path).name in msg
    return msg


def test_fixture_record_itself_is_fine(tmp_path):
    """The NYA1 record has all four spare fields blank: they read as 0, the rest is intact."""
    nav = load_nav(_write(tmp_path, "ok.rnx", HDR_BDS + REC_C06))
    r = nav.records[6][0]
    assert r.finite() and r.week == 956 and r.toe == 432000.0 and r.SatH1 == 0


def test_rinex5_rejected(tmp_path):
    """RINEX 4 is read (tests/test_orbits_rinex4.py); a later major version is refused."""
    msg = _err(_write(tmp_path, "BRD500DLR_S_20230710000_01D_MN.rnx",
                      HDR_RINEX4.replace("4.00", "5.00")))
    assert msg.startswith("unsupported RINEX version 5.00: ")


def test_rinex2_rejected(tmp_path):
    text = "     2.11           N: GPS NAV DATA                         RINEX VERSION / TYPE\n" \
           "                                                            END OF HEADER\n"
    assert "unsupported RINEX version 2.11" in _err(_write(tmp_path, "old.21n", text))


def test_gps_only_rinex3_rejected(tmp_path):
    hdr = HDR_BDS.replace("C: BEIDOU", "G: GPS   ")
    assert "no BDS records" in _err(_write(tmp_path, "gps.rnx", hdr + REC_G01))
    # mixed header but only GPS records
    hdr_m = HDR_BDS.replace("C: BEIDOU", "M: MIXED ")
    assert "no BDS records" in _err(_write(tmp_path, "gps_m.rnx", hdr_m + REC_G01))


def test_mixed_file_skips_other_systems(tmp_path):
    hdr_m = HDR_BDS.replace("C: BEIDOU", "M: MIXED ")
    nav = load_nav(_write(tmp_path, "mix.rnx", hdr_m + REC_G01 + REC_C06 + REC_G01))
    assert nav.prns == (6,) and nav.n_records == 1


def test_observation_file_rejected(tmp_path):
    text = "     3.04           OBSERVATION DATA    M (MIXED)           RINEX VERSION / TYPE\n" \
           "                                                            END OF HEADER\n"
    assert "observation file" in _err(_write(tmp_path, "obs.rnx", text))


@pytest.mark.parametrize("content", [
    bytes(range(256)) * 8,                                   # binary garbage
    np.random.default_rng(1).integers(32, 127, 4000).astype(np.uint8).tobytes(),  # text garbage
    b"",                                                     # empty
    b"\x1f\x8b\x08\x00garbage",                              # corrupt gzip
])
def test_garbage_rejected(tmp_path, content):
    _err(_write(tmp_path, "garbage.rnx", content))


def test_missing_file_and_directory(tmp_path):
    assert "not found" in _err(tmp_path / "nope.rnx")
    assert "not a regular file" in _err(tmp_path)


def test_blank_required_field_rejected(tmp_path):
    rec = _replace_field(REC_C06, 1, 1, "")  # Crs
    msg = _err(_write(tmp_path, "blank.rnx", HDR_BDS + rec))
    assert "blank required field 'Crs'" in msg and "C06" in msg


def test_blank_aodc_rejected(tmp_path):
    rec = _replace_field(REC_C06, 7, 1, "")  # AODC is required (only the 4 spares may be blank)
    assert "'AODC'" in _err(_write(tmp_path, "aodc.rnx", HDR_BDS + rec))


@pytest.mark.parametrize("bad,what", [("NaN", "non-finite"), ("inf", "non-finite"),
                                      ("1.2.3E+00", "malformed number")])
def test_nan_inf_malformed_rejected(tmp_path, bad, what):
    rec = _replace_field(REC_C06, 2, 1, bad)  # e
    msg = _err(_write(tmp_path, "bad.rnx", HDR_BDS + rec))
    assert what in msg and "'e'" in msg


def test_truncated_record_rejected(tmp_path):
    cut = "".join(REC_C06.splitlines(keepends=True)[:5])
    assert "truncated" in _err(_write(tmp_path, "cut.rnx", HDR_BDS + cut))
    assert "truncated" in _err(_write(tmp_path, "cut2.rnx", HDR_BDS + cut + REC_C06))


def test_missing_end_of_header_rejected(tmp_path):
    assert "END OF HEADER" in _err(_write(tmp_path, "noend.rnx", HDR_BDS.splitlines(True)[0]))


def test_gps_week_in_bdt_field_is_corrected(tmp_path):
    rec = _replace_field(REC_C06, 5, 2, "2.312000000000E+03")  # 956 + 1356
    nav = load_nav(_write(tmp_path, "gpsweek.rnx", HDR_BDS + rec))
    assert nav.records[6][0].week == 956
    rec = _replace_field(REC_C06, 5, 2, "9.000000000000E+02")
    assert "inconsistent" in _err(_write(tmp_path, "badweek.rnx", HDR_BDS + rec))


# ---- select ----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def esbc() -> NavData:
    return load_nav(ESBC)


@pytest.mark.parametrize("prn", [0, 64, -1, 1.5, "C05", None])
def test_select_unknown_prn(esbc, prn):
    with pytest.raises(UnknownPrnError, match="unknown BDS PRN"):
        esbc.select(prn, 755, 345600.0)


def test_select_prn_without_record(esbc):
    with pytest.raises(NoEphemerisError) as ei:
        esbc.select(1, 755, 345600.0)
    assert "C01" in str(ei.value) and "week 755" in str(ei.value) and "345600" in str(ei.value)


def test_select_time_outside_window(esbc):
    last = esbc.records[5][-1]
    t = last.toe + DEFAULT_MAX_AGE_GEO_S + 1.0
    with pytest.raises(NoEphemerisError) as ei:
        esbc.select(5, last.week, t)
    assert "C05" in str(ei.value) and f"{t:.3f}" in str(ei.value)
    assert esbc.select(5, last.week, t, max_age_s=2 * DEFAULT_MAX_AGE_GEO_S) is last
    with pytest.raises(NoEphemerisError):
        esbc.select(20, 755, 0.0)  # two days before the data


def test_select_nearest_and_tie(esbc):
    recs = esbc.records[20]
    a, b = next((x, y) for x, y in itertools.pairwise(recs) if y.toe - x.toe == 3600.0)
    assert esbc.select(20, a.week, a.toe + 1799.0) is a
    assert esbc.select(20, a.week, a.toe + 1801.0) is b
    assert esbc.select(20, a.week, a.toe + 1800.0) is a  # tie -> earlier toe
    # week-aware: the same instant expressed from the next week
    assert esbc.select(20, a.week + 1, a.toe + 1801.0 - 604800.0) is b


def test_select_broadcast_is_the_record_on_the_air(esbc):
    """C27 of 2020-06-25: the 06:00 record (toe 367200) went on the air at 06:00:18 (its
    RINEX transmission time). From 06:30 the nearest toe is 07:00's, but the satellite still
    sends the 06:00 record until 07:00:18."""
    recs = {r.toe: r for r in esbc.records[27]}
    r6, r7 = recs[367200.0], recs[370800.0]
    w = r6.week
    assert esbc.tx_times[(27, w, 367200.0)] == w * 604800 + 367218.0
    assert esbc.select(27, w, 367200.0 + 2412.0) is r7                  # nearest toe
    assert esbc.select(27, w, 367200.0 + 2412.0, broadcast=True) is r6  # on the air
    assert esbc.select(27, w, 370800.0 + 10.0, broadcast=True) is r6
    assert esbc.select(27, w, 370800.0 + 30.0, broadcast=True) is r7
    assert esbc.select(27, w, 367200.0 + 5.0, broadcast=True).toe == 363600.0
    # before any record was sent: the nearest toe
    first = esbc.records[27][0]
    assert esbc.select(27, first.week, first.toe - 100.0, broadcast=True) is first
    # C32: the file has no record between 01:00 and 08:00; at 06:30 the one on the air in
    # the file (01:00) is outside the 2 h window, so the nearest toe (08:00) is used
    c32 = esbc.select(32, w, 367200.0 + 1800.0, broadcast=True)
    assert c32 is esbc.select(32, w, 367200.0 + 1800.0) and c32.toe == 374400.0
    # merged files keep the earliest transmission time of a record
    m = merge_nav([esbc, load_nav(MOJN)])
    key = (27, w, 367200.0)
    assert m.tx_times[key] == min(esbc.tx_times[key], load_nav(MOJN).tx_times.get(key, 1e300))


def test_select_default_windows(esbc):
    meo = esbc.records[20][-1]
    assert esbc.select(20, meo.week, meo.toe + DEFAULT_MAX_AGE_S) is meo
    with pytest.raises(NoEphemerisError):
        esbc.select(20, meo.week, meo.toe + DEFAULT_MAX_AGE_S + 1)


def test_select_skips_unhealthy(esbc):
    recs = esbc.records[20]
    sick = dataclasses.replace(recs[0], SatH1=1)
    nav = NavData(records={20: [sick, *recs[1:]]}, iono=None, path=ESBC)
    chosen = nav.select(20, recs[0].week, recs[0].toe)
    assert chosen is recs[1] and chosen.healthy
    only_sick = NavData(records={20: [sick]}, iono=None, path=ESBC)
    with pytest.raises(NoEphemerisError, match="none healthy"):
        only_sick.select(20, recs[0].week, recs[0].toe)


def test_ura_index():
    assert [ura_index(x) for x in (0.0, 2.4, 2.5, 24.0, 6144.0, 1e5)] == [0, 0, 1, 6, 14, 15]
    assert not math.isnan(ura_index(2.0))


def test_assisted_ephemerides_decoded_first_then_the_broadcast_record(esbc):
    from sdr_di.receiver.assistance import AssistedEphemerides

    recs = {r.toe: r for r in esbc.records[27]}
    r6, r7 = recs[367200.0], recs[370800.0]
    src = AssistedEphemerides(esbc)
    assert src.select(27, r6.week, 367200.0 + 2412.0) is r6   # what C27 sends at 06:40:12
    src.decoded = {27: r7}
    assert src.select(27, r6.week, 367200.0 + 2412.0) is r7   # a decoded record wins
    src.decoded = {27: dataclasses.replace(r7, SatH1=1)}      # unless unhealthy
    assert src.select(27, r6.week, 367200.0 + 2412.0) is r6
    assert not src.has(1, r6.week, 367200.0) and src.has(27, r6.week, 367200.0)
    with pytest.raises(NoEphemerisError):
        AssistedEphemerides(None).select(27, r6.week, 367200.0)
