"""Property-based fuzzing of every parser (issue 12 item 5).

Each parser is given arbitrary input and mutations of a valid file; it must either parse or
raise the project's own error type (:class:`~sdr_di.errors.SdrDiError` subclasses), never
anything else (``ValueError``, ``KeyError``, ``TypeError``, ``IndexError``...). Parsers:
scenario TOML (file and parsed tables), IF sidecar JSON (and opening the IF file it describes),
peers' ``.tag`` files, IMU and truth CSV, RINEX 3 and 4 navigation files and SP3 orbits (plain and
gzip, including corrupted gzip streams).

Found and fixed: a sidecar with ``"carrier_hz": null`` (TypeError in the IF reader; the
sidecar reader now refuses null for every key but the companion files), a gzip file whose
deflate stream is corrupt (``zlib.error`` from the RINEX and SP3 readers).

Settings are modest (``max_examples`` 100-200 each, no deadline) so that the file runs in well
under a minute; a failure prints the shrunk input to add as a regression case. Set
``SDR_DI_FUZZ_EXAMPLES`` for a longer search.
"""

from __future__ import annotations

import copy
import gzip
import json
import math
import os
import shutil
import tomllib
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sdr_di.errors import EphemerisError, SdrDiError
from sdr_di.io.imu_files import read_imu, read_truth
from sdr_di.io.sidecar import read_sidecar
from sdr_di.io.tag_sidecar import read_tag, tag_source
from sdr_di.orbits.rinex_nav import load_nav
from sdr_di.orbits.sp3 import load_sp3
from sdr_di.receiver.ifreader import IfSource
from sdr_di.scenario import DEFAULT_SCENARIO, load_scenario
from sdr_di.scenario.schema import parse_scenario

#: ``SDR_DI_FUZZ_EXAMPLES=5000 pytest tests/test_fuzz_parsers.py`` for a longer hunt.
FUZZ = settings(max_examples=int(os.environ.get("SDR_DI_FUZZ_EXAMPLES", "150")), deadline=None,
                suppress_health_check=[HealthCheck.too_slow,
                                       HealthCheck.function_scoped_fixture])
REPO = DEFAULT_SCENARIO.parent.parent


def parses_or_own_error(fn, *args, **kw):
    """Call the parser; an SdrDiError is an accepted outcome, anything else fails the test."""
    try:
        return fn(*args, **kw)
    except SdrDiError as exc:
        msg = str(exc)
        assert msg and "\n" not in msg.strip(), f"error message not one line: {msg!r}"
        return None


# -- values --------------------------------------------------------------------------------------

_scalars = (st.none() | st.booleans() | st.integers(-2**70, 2**70)
            | st.floats(allow_nan=True, allow_infinity=True) | st.text(max_size=20))
json_values = st.recursive(_scalars, lambda kids: st.lists(kids, max_size=4)
                           | st.dictionaries(st.text(max_size=8), kids, max_size=4),
                           max_leaves=12)
_toml_scalars = (st.booleans() | st.integers(-2**64, 2**64)
                 | st.floats(allow_nan=True, allow_infinity=True) | st.text(max_size=20)
                 | st.datetimes() | st.dates() | st.times())
toml_values = st.recursive(_toml_scalars, lambda kids: st.lists(kids, max_size=4)
                           | st.dictionaries(st.text(max_size=8), kids, max_size=4),
                           max_leaves=12)
tokens = st.sampled_from(["", " ", "nan", "NaN", "inf", "-inf", "1e999", "-0", "0", "-1",
                          "1.5", "abc", "1,2", "1e-300", "0x10", "٣", "  7  ", "\t",
                          "1.0D+02", "9" * 40]) | st.text(max_size=12)


# -- scenario TOML -------------------------------------------------------------------------------

_DEFAULT_RAW = tomllib.loads(DEFAULT_SCENARIO.read_text())


def _paths(obj, prefix=()):
    """Every (key path) into nested dicts/lists of a parsed TOML document."""
    out = [prefix] if prefix else []
    if isinstance(obj, dict):
        for k, v in obj.items():
            out += _paths(v, prefix + (k,))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            out += _paths(v, prefix + (i,))
    return out


_SCENARIO_PATHS = _paths(_DEFAULT_RAW)


def _set(obj, path, value):
    for k in path[:-1]:
        obj = obj[k]
    if value is _DELETE:
        del obj[path[-1]]
    else:
        obj[path[-1]] = value


_DELETE = object()


@FUZZ
@given(edits=st.lists(st.tuples(st.sampled_from(_SCENARIO_PATHS),
                                toml_values | st.just(_DELETE)), min_size=1, max_size=3))
def test_scenario_tables_parse_or_scenario_error(edits):
    raw = copy.deepcopy(_DEFAULT_RAW)
    for path, value in edits:
        try:
            _set(raw, path, value)
        except (KeyError, IndexError, TypeError):  # an earlier edit removed the path
            continue
    parses_or_own_error(parse_scenario, raw, source=DEFAULT_SCENARIO,
                        base_dir=DEFAULT_SCENARIO.parent)


@FUZZ
@given(doc=st.dictionaries(st.sampled_from(list(_DEFAULT_RAW) + ["lc", "x"]), toml_values,
                           max_size=6))
def test_scenario_arbitrary_tables(doc):
    parses_or_own_error(parse_scenario, doc, base_dir=DEFAULT_SCENARIO.parent)


@FUZZ
@given(data=st.binary(max_size=300) | st.text(max_size=300).map(str.encode))
def test_scenario_file_arbitrary_bytes(tmp_path_factory, data):
    p = tmp_path_factory.getbasetemp() / "fuzz.toml"
    p.write_bytes(data)
    parses_or_own_error(load_scenario, p)


@FUZZ
@given(kw=st.fixed_dictionaries({}, optional={
    "duration_s": st.floats(allow_nan=True, allow_infinity=True) | st.integers(),
    "seed": st.integers(-5, 2**70), "sampling_rate_hz": st.floats(allow_nan=True),
    "if_hz": st.floats(allow_nan=True), "quantization_bits": st.integers(-3, 40),
    "cn0_dbhz": st.floats(allow_nan=True), "prns": st.lists(tokens, max_size=3),
    "sample_format": tokens}))
def test_scenario_overrides(kw):
    sc = load_scenario(DEFAULT_SCENARIO)
    parses_or_own_error(sc.with_overrides, **kw)


# -- IF sidecar JSON -----------------------------------------------------------------------------

@pytest.fixture(scope="module")
def generated(if_files, tmp_path_factory) -> Path:
    """A private copy of the session's 0.02 s set (``s.*``): the cases write beside it."""
    return shutil.copytree(if_files(0.02, name="s").if_file.parent,
                           tmp_path_factory.mktemp("fuzz") / "set")


_FORMATS = st.sampled_from(["iq_int8", "iq_int16", "real_int8", "real_int16", "iq_int4",
                            "gr_complex", "iq_int4_sm", "pocket_raw8_iq2", "cs8", "int3"])
_SIDECAR_KEYS = ["schema", "if_file", "sampling_rate_hz", "if_hz", "carrier_hz",
                 "sample_format", "quantization_bits", "spectrum_inverted", "n_samples",
                 "start", "imu_file", "truth_file", "ephemeris_file", "files"]


@FUZZ
@given(doc=json_values)
def test_sidecar_arbitrary_json(generated, doc):
    p = generated / "fuzz.json"
    p.write_text(json.dumps(doc))
    parses_or_own_error(read_sidecar, p)


@pytest.mark.filterwarnings("ignore::sdr_di.receiver.ifreader.IfFileWarning")
@FUZZ
@given(edits=st.dictionaries(st.sampled_from(_SIDECAR_KEYS),
                             json_values | _FORMATS | st.integers(1, 10**6) | st.just(_DELETE),
                             min_size=1, max_size=3),
       start=st.dictionaries(st.sampled_from(["week", "sow", "bdt"]), json_values,
                             max_size=2),
       check_format=st.booleans())
def test_sidecar_mutations_read_or_refused(generated, edits, start, check_format):
    meta = json.loads((generated / "s.json").read_text())
    meta["start"] = {**meta["start"], **start}
    for k, v in edits.items():
        if v is _DELETE:
            meta.pop(k, None)
        else:
            meta[k] = v
    p = generated / "fuzz.json"
    p.write_text(json.dumps(meta))
    if parses_or_own_error(read_sidecar, p) is not None:
        parses_or_own_error(IfSource.from_sidecar, p, check_format=check_format)


@FUZZ
@given(data=st.binary(max_size=200))
def test_sidecar_arbitrary_bytes(generated, data):
    p = generated / "fuzz.json"
    p.write_bytes(data)
    parses_or_own_error(read_sidecar, p)


# -- peers' .tag files ---------------------------------------------------------------------------

_TAG_KEYS = ["PROG", "FMT", "F_S", "F_LO", "IQ", "BITS", "TIME", "SCALE", "X"]
_TAG_VALUES = (st.sampled_from(["INT8", "INT8X2", "RAW8", "RAW16", "RAW16I", "RAW32", "CS8",
                                "CS16", "INT2X2", "INT4X2", "Pocket SDR", "IFDataGen",
                                "24.000", "1268.52", "1262.52,1575.42", "1,2", "2,2", "2",
                                "3,3,3,3", "-1", "0"]) | tokens)


@FUZZ
@given(lines=st.lists(st.tuples(st.sampled_from(_TAG_KEYS), _TAG_VALUES), max_size=8),
       junk=st.lists(st.text(max_size=15), max_size=2),
       rfch=st.none() | st.integers(-1, 5))
def test_tag_parses_or_sample_format_error(generated, lines, junk, rfch):
    p = generated / "fuzz.bin.tag"
    text = "\n".join([f"{k} = {v}" for k, v in lines] + junk)
    p.write_bytes(text.encode("utf-8", "replace"))
    tag = parses_or_own_error(read_tag, p)
    if tag is not None:
        parses_or_own_error(tag_source, tag, rfch)


@FUZZ
@given(data=st.binary(max_size=200))
def test_tag_arbitrary_bytes(generated, data):
    p = generated / "fuzz.bin.tag"
    p.write_bytes(data)
    parses_or_own_error(read_tag, p)


# -- IMU / truth CSV -------------------------------------------------------------------------------

def _mutate_lines(lines: list[str], data) -> list[str]:
    """Apply a few random line edits: replace a field, replace/delete/duplicate/swap lines."""
    lines = list(lines)
    for _ in range(data.draw(st.integers(1, 3))):
        if not lines:
            break
        i = data.draw(st.integers(0, len(lines) - 1))
        op = data.draw(st.sampled_from(["field", "line", "delete", "dup", "swap", "cut"]))
        if op == "field":
            sep = "," if "," in lines[i] else ":"
            parts = lines[i].split(sep)
            j = data.draw(st.integers(0, len(parts) - 1))
            parts[j] = data.draw(tokens)
            lines[i] = sep.join(parts)
        elif op == "line":
            lines[i] = data.draw(st.text(max_size=30))
        elif op == "delete":
            del lines[i]
        elif op == "dup":
            lines.insert(i, lines[i])
        elif op == "swap":
            k = data.draw(st.integers(0, len(lines) - 1))
            lines[i], lines[k] = lines[k], lines[i]
        else:
            lines[i] = lines[i][:data.draw(st.integers(0, len(lines[i])))]
    return lines


@FUZZ
@given(data=st.data(), kind=st.sampled_from(["imu", "truth"]))
def test_imu_truth_mutations(generated, data, kind):
    lines = (generated / f"s_{kind}.csv").read_text().splitlines()
    p = generated / f"fuzz_{kind}.csv"
    p.write_text("\n".join(_mutate_lines(lines, data)) + "\n")
    parses_or_own_error(read_imu if kind == "imu" else read_truth, p)


@FUZZ
@given(data=st.binary(max_size=300) | st.text(max_size=300).map(str.encode),
       kind=st.sampled_from(["imu", "truth"]))
def test_imu_truth_arbitrary_bytes(generated, data, kind):
    p = generated / f"fuzz_{kind}.csv"
    p.write_bytes(data)
    parses_or_own_error(read_imu if kind == "imu" else read_truth, p)


# -- RINEX navigation ------------------------------------------------------------------------------

def _small_nav() -> list[str]:
    """Header and the first two BDS records (plus one GPS record) of a shipped file."""
    text = gzip.decompress((REPO / "ephemeris" / "ESBC00DNK_R_20201770000_01D_MN.rnx.gz")
                           .read_bytes()).decode("latin-1")
    lines = text.splitlines()
    end = next(i for i, ln in enumerate(lines) if "END OF HEADER" in ln)
    out, n_c, n_g = lines[:end + 1], 0, 0
    i = end + 1
    while i < len(lines) and (n_c < 2 or n_g < 1):
        sys_ = lines[i][:1]
        if sys_ == "C" and n_c < 2:
            out += lines[i:i + 8]
            n_c += 1
        elif sys_ == "G" and n_g < 1:
            out += lines[i:i + 8]
            n_g += 1
        i += 1
    return out


_NAV = _small_nav()


def _mutate_nav_lines(data, lines: list[str]) -> None:
    """One to three mutations of a navigation file's lines, in place: a 19-character number
    field of a record line, one column, a whole line, a deleted line, a cut line."""
    for _ in range(data.draw(st.integers(1, 3))):
        i = data.draw(st.integers(0, len(lines) - 1))
        ln = lines[i].ljust(80)
        op = data.draw(st.sampled_from(["field", "column", "line", "delete", "cut"]))
        if op == "field":  # one 19-character number field of a record line
            k = data.draw(st.integers(0, 3))
            ln = ln[:4 + 19 * k] + data.draw(tokens).rjust(19)[:19] + ln[4 + 19 * (k + 1):]
        elif op == "column":
            j = data.draw(st.integers(0, 79))
            ln = ln[:j] + data.draw(st.characters(max_codepoint=255)) + ln[j + 1:]
        elif op == "line":
            ln = data.draw(st.text(max_size=80))
        elif op == "delete":
            del lines[i]
            continue
        else:
            ln = ln[:data.draw(st.integers(0, 80))]
        lines[i] = ln


def test_the_seed_nav_file_parses(generated):
    p = generated / "seed.rnx"
    p.write_text("\n".join(_NAV) + "\n")
    assert sum(len(v) for v in load_nav(p).records.values()) == 2


@FUZZ
@given(data=st.data(), gz=st.booleans())
def test_rinex_nav_mutations(generated, data, gz):
    lines = list(_NAV)
    _mutate_nav_lines(data, lines)
    text = ("\n".join(lines) + "\n").encode("latin-1", "replace")
    p = generated / ("fuzz.rnx.gz" if gz else "fuzz.rnx")
    p.write_bytes(gzip.compress(text) if gz else text)
    nav = parses_or_own_error(load_nav, p)
    if nav is not None:
        for recs in nav.records.values():
            for eph in recs:
                assert math.isfinite(eph.sqrtA) and math.isfinite(eph.toe)


def _small_nav4() -> list[str]:
    """RINEX 4: header, a BDS ION frame, a D2 and a D1 EPH frame, a skipped CNV1 frame."""
    text = gzip.decompress((REPO / "ephemeris" / "BRD400DLR_S_20230710000_01D_MN.rnx.gz")
                           .read_bytes()).decode("latin-1")
    lines = text.splitlines()
    end = next(i for i, ln in enumerate(lines) if "END OF HEADER" in ln)
    out = lines[:end + 1]
    for marker, n in (("> ION C05 D1D2", 4), ("> EPH C01 D2", 9), ("> EPH C20 D1", 9),
                      ("> EPH C20 CNV1", 10)):
        i = next(i for i, ln in enumerate(lines) if ln.rstrip() == marker)
        out += lines[i:i + n]
    return out


_NAV4 = _small_nav4()


def test_the_seed_nav4_file_parses(generated):
    p = generated / "seed4.rnx"
    p.write_text("\n".join(_NAV4) + "\n")
    nav = load_nav(p)
    assert nav.prns == (1, 20) and nav.iono is not None


def test_nav_record_before_the_bdt_epoch_is_the_parsers_error(generated):
    """A record dated before 2006 (the year column "0023": hypothesis's find in
    test_rinex4_nav_mutations) is an EphemerisError naming the line, not the time
    conversion's ValueError."""
    lines = list(_NAV4)
    k = next(i for i, ln in enumerate(lines) if ln.startswith("C20 2023"))
    lines[k] = lines[k].replace("C20 2023", "C20 0023", 1)
    p = generated / "y0023.rnx"
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(EphemerisError, match=f"line {k + 1} is before the BDT epoch"):
        load_nav(p)


@FUZZ
@given(data=st.data())
def test_rinex4_nav_mutations(generated, data):
    lines = list(_NAV4)
    _mutate_nav_lines(data, lines)
    p = generated / "fuzz4.rnx"
    p.write_bytes(("\n".join(lines) + "\n").encode("latin-1", "replace"))
    nav = parses_or_own_error(load_nav, p)
    if nav is not None:
        for recs in nav.records.values():
            for eph in recs:
                assert eph.finite()
        for f in nav.iono_frames:
            assert all(math.isfinite(v) for v in (*f.klobuchar.alpha, *f.klobuchar.beta))


@FUZZ
@given(data=st.binary(max_size=400), gz_magic=st.booleans())
def test_rinex_nav_arbitrary_bytes(generated, data, gz_magic):
    p = generated / "fuzz.rnx"
    p.write_bytes((b"\x1f\x8b" if gz_magic else b"") + data)
    parses_or_own_error(load_nav, p)


@FUZZ
@given(data=st.data())
def test_rinex_nav_corrupt_gzip(generated, data):
    z = bytearray(gzip.compress(("\n".join(_NAV) + "\n").encode("latin-1")))
    for _ in range(data.draw(st.integers(1, 4))):
        i = data.draw(st.integers(10, len(z) - 1))  # past the gzip header: the deflate data
        z[i] = data.draw(st.integers(0, 255))
    z = z[:data.draw(st.integers(11, len(z)))]
    p = generated / "fuzz.rnx.gz"
    p.write_bytes(bytes(z))
    parses_or_own_error(load_nav, p)


# -- SP3 orbits ------------------------------------------------------------------------------------

_SP3 = gzip.decompress((REPO / "ephemeris" / "Sta21114.sp3.gz").read_bytes()).decode(
    "latin-1").splitlines()[:200]


def test_sp3_utc_epochs_before_the_bdt_epoch_are_the_parsers_error(generated):
    """An SP3 file on the UTC scale dated 2005 (no BDT - UTC leap seconds before 2006) is
    an EphemerisError naming the file, not the leap-second table's ValueError."""
    lines = gzip.decompress((REPO / "ephemeris" / "Sta21114.sp3.gz").read_bytes()).decode(
        "latin-1").splitlines()
    k = next(i for i, ln in enumerate(lines) if ln.startswith("%c"))
    lines[k] = lines[k].replace(" GPS ", " UTC ", 1)
    lines = [ln.replace("*  2020", "*  2005", 1) for ln in lines]
    p = generated / "utc2005.sp3"
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(EphemerisError, match="utc2005.sp3: UTC time 2005-06-25 00:00:00 is "
                                             "before the BDT epoch"):
        load_sp3(p)


@FUZZ
@given(data=st.data(), gz=st.booleans())
def test_sp3_mutations(generated, data, gz):
    lines = _mutate_lines(_SP3, data)
    raw = ("\n".join(lines) + "\n").encode("latin-1", "replace")
    if gz:
        z = bytearray(gzip.compress(raw))
        if data.draw(st.booleans()):
            z[data.draw(st.integers(10, len(z) - 1))] ^= data.draw(st.integers(1, 255))
        raw = bytes(z)
    p = generated / "fuzz.sp3"
    p.write_bytes(raw)
    parses_or_own_error(load_sp3, p)
