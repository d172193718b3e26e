"""SigMF recordings: read with no flags (pairs written by the ``sigmf`` library itself, not by
sdr-di's writer), written by ``generate --sigmf`` and validated by the library, and the
one-line refusals (unreadable datatype, B3I outside the band, captures at two frequencies)."""

import datetime as dt
import io
import json

import numpy as np
import pytest
import sigmf
from sigmf import SigMFFile

from sdr_di.cli import main
from sdr_di.constants import F_B3I
from sdr_di.errors import SampleFormatError
from sdr_di.io.sigmf_files import check_b3i_in_band, sigmf_meta_path, sigmf_source
from sdr_di.receiver.acquisition import acquire_source
from sdr_di.receiver.ifreader import IfSource
from sdr_di.receiver.run_scalar import open_source

IF_SHIFT_HZ = 300e3  # the foreign recording is centred 300 kHz below B3I


@pytest.fixture(scope="module")
def generated(tmp_path_factory):
    """0.1 s of the default scenario at 2.5 MHz (iq_int8, 4-bit), with its SigMF pair."""
    g = tmp_path_factory.mktemp("gen")
    assert main(["generate", "--no-progress", "--duration", "0.1", "--fs", "2.5e6", "--out",
                 str(g), "--sigmf"]) == 0
    meta = json.loads((g / "default.json").read_text())
    x = IfSource.from_sidecar(g / "default.json").read(0, meta["n_samples"])
    return g, x, meta


def library_pair(base, datatype, samples: bytes, fs, captures, **glob):
    """A SigMF pair written by the sigmf library from raw sample bytes (not by sdr-di)."""
    rec = SigMFFile(global_info={"core:datatype": datatype, "core:sample_rate": fs,
                                 "core:recorder": "test", **glob})
    rec.set_data_file(data_buffer=io.BytesIO(samples), skip_checksum=True)
    for start, fields in captures:
        rec.add_capture(start, metadata=dict(fields))
    rec.tofile(base, overwrite=True)
    return base.with_name(base.name + ".sigmf-meta")


@pytest.fixture(scope="module")
def foreign(generated, tmp_path_factory):
    """The snippet moved to +300 kHz and stored as ci16_le by the library, with the
    sidecar's start time as core:datetime."""
    _, x, meta = generated
    t = np.arange(x.size) / meta["sampling_rate_hz"]
    y = x * np.exp(2j * np.pi * IF_SHIFT_HZ * t) * 100.0
    iq = np.round(np.stack([y.real, y.imag], axis=1)).astype("<i2")
    base = tmp_path_factory.mktemp("foreign") / "capture"
    library_pair(base, "ci16_le", iq.tobytes(), meta["sampling_rate_hz"],
                 [(0, {"core:frequency": F_B3I - IF_SHIFT_HZ,
                       "core:datetime": meta["start"]["utc"] + "Z"})])
    return base


def test_library_pair_read_without_flags(generated, foreign):
    _, _, meta = generated
    for name in ("capture", "capture.sigmf-data", "capture.sigmf-meta"):
        src = open_source(foreign.with_name(name))
        assert src.path == foreign.with_name("capture.sigmf-data")
        assert (src.format.name, src.sampling_rate_hz) == ("iq_int16", 2.5e6)
        assert src.if_hz == pytest.approx(IF_SHIFT_HZ, abs=1e-3)
        assert src.start_week == meta["start"]["week"]
        assert src.start_sow == pytest.approx(meta["start"]["sow"], abs=1e-6)
    truth = {s["prn"]: s for s in meta["satellites"]}
    res = {r.prn: r for r in acquire_source(src, prns=[*truth, 1, 40], noncoherent=20)}
    for prn, s in truth.items():
        # a wrong IF sign would put every satellite 600 kHz away: none would be found
        assert res[prn].detected and abs(res[prn].doppler_hz - s["doppler_hz"]) < 100.0
    assert not res[1].detected and not res[40].detected


def test_acquire_cli_on_library_pair(generated, foreign, capsys, tmp_path):
    _, _, meta = generated
    prns = [s["prn"] for s in meta["satellites"]][:3]
    assert main(["acquire", str(foreign), "--prn", ",".join(f"C{p:02d}" for p in prns),
                 "--noncoherent", "20", "--out", str(tmp_path / "acq")]) == 0
    out = capsys.readouterr().out
    assert all(f"C{p:02d}  yes" in out for p in prns), out
    assert f"{len(prns)} of {len(prns)} PRNs detected" in out


def test_generate_sigmf_pair_validated_by_the_library(generated):
    g, x, meta = generated
    rec = sigmf.sigmffile.fromfile(g / "default.sigmf-meta", autoscale=False)
    rec.validate()
    assert (g / "default.sigmf-data").read_bytes() == (g / "default.bin").read_bytes()
    assert rec.get_global_field("core:datatype") == "ci8"
    assert rec.get_global_field("core:sample_rate") == meta["sampling_rate_hz"]
    assert rec.get_global_field("sdr_di:scenario_hash") == meta["scenario"]["hash"]
    cap = rec.get_captures()
    assert len(cap) == 1 and cap[0]["core:frequency"] == F_B3I - meta["if_hz"]
    assert cap[0]["core:datetime"] == meta["start"]["utc"] + ".000000Z"
    np.testing.assert_array_equal(rec.read_samples(0, 2000), x[:2000])  # the library's reading
    # and read back by sdr-di with no flags, from the SigMF pair rather than the JSON
    src = open_source(g / "default.sigmf-meta")
    assert src.path.name == "default.sigmf-data"
    assert (src.start_week, src.start_sow) == (meta["start"]["week"], meta["start"]["sow"])


@pytest.mark.parametrize("flags, words", [
    (["--format", "iq_int4"], "iq_int4 has no SigMF datatype"),
    (["--format", "real_int8", "--if", "0.2e6"], "--sigmf: core:frequency"),
])
def test_generate_sigmf_refusals_before_any_work(tmp_path, capsys, flags, words):
    out = tmp_path / "o"
    assert main(["generate", "--no-progress", "--duration", "0.1", "--fs", "2.5e6", *flags,
                 "--out", str(out), "--sigmf"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and words in err, err
    assert not out.exists()


def _noise_pair(tmp_path, datatype="ci8", captures=None, fs=2.5e6, **glob):
    rng = np.random.default_rng(1)
    data = rng.integers(-8, 8, 20000, dtype=np.int8).tobytes()
    captures = captures or [(0, {"core:frequency": F_B3I})]
    return library_pair(tmp_path / "n", datatype, data, fs, captures, **glob)


@pytest.mark.parametrize("datatype, captures, words", [
    ("cu8", None, "core:datatype cu8 cannot be read"),
    ("ci16_be", None, "core:datatype ci16_be cannot be read"),
    ("ci8", [(0, {"core:frequency": 1575.42e6})], "outside the complex band"),
    ("ci8", [(0, {"core:frequency": F_B3I + 0.7e6})], "outside the complex band"),
    ("ci8", [(0, {"core:frequency": F_B3I}), (5000, {"core:frequency": F_B3I + 1e5})],
     "2 captures at different frequencies"),
    ("ci8", [(0, {"core:datetime": "2020-01-01T00:00:00Z"})], "no core:frequency"),
])
def test_refused_recordings_one_line_exit_2(tmp_path, capsys, datatype, captures, words):
    meta = _noise_pair(tmp_path, datatype, captures)
    out = tmp_path / "acq"
    assert main(["acquire", str(meta), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("sdr-di: error: SigMF ") and err.count("\n") == 1, err
    assert words in err, err
    assert not out.exists()


def test_invalid_metadata_one_line(tmp_path, capsys):
    meta = _noise_pair(tmp_path)
    doc = json.loads(meta.read_text())
    doc["global"]["core:sample_rate"] = "fast"
    meta.write_text(json.dumps(doc))
    assert main(["acquire", str(meta)]) == 2
    err = capsys.readouterr().err
    assert "not valid SigMF metadata (global/core:sample_rate" in err and err.count("\n") == 1


def test_several_captures_use_the_first_and_say_so(tmp_path):
    caps = [(100, {"core:frequency": F_B3I, "core:datetime": "2017-01-01T00:00:01Z"}),
            (5000, {"core:frequency": F_B3I, "core:datetime": "2017-01-01T00:00:09Z"})]
    meta = _noise_pair(tmp_path, captures=caps, fs=1e3)
    with pytest.warns(UserWarning, match="2 captures: using the first"):
        ss = sigmf_source(meta)
    # sample 0 is 100 samples (0.1 s at 1 kHz) before 2017-01-01T00:00:01 UTC, i.e. before the
    # leap second of 2017-01-01: BDT - UTC is 3 s there, 4 s after
    week, sow = ss.start_week, ss.start_sow
    bdt0 = dt.datetime(2006, 1, 1) + dt.timedelta(weeks=week, seconds=sow)
    assert bdt0 == dt.datetime(2017, 1, 1, 0, 0, 4, 900000)
    caps[0][1]["core:datetime"] = "2016-12-31T23:59:58Z"
    meta = _noise_pair(tmp_path, captures=caps[:1], fs=1e3)
    ss = sigmf_source(meta)
    bdt0 = dt.datetime(2006, 1, 1) + dt.timedelta(weeks=ss.start_week, seconds=ss.start_sow)
    assert bdt0 == dt.datetime(2017, 1, 1, 0, 0, 0, 900000)


def test_real_datatype_lo_convention_and_override(tmp_path):
    fs = 10e6
    meta = _noise_pair(tmp_path, "ri8", [(0, {"core:frequency": F_B3I - fs / 4})], fs=fs)
    ss = sigmf_source(meta)
    assert (ss.sample_format, ss.if_hz, ss.spectrum_inverted) == ("real_int8", fs / 4, False)
    meta = _noise_pair(tmp_path, "ri8", [(0, {"core:frequency": F_B3I + fs / 4})], fs=fs)
    ss = sigmf_source(meta)  # LO above the carrier: read at |IF| with the spectrum inverted
    assert (ss.if_hz, ss.spectrum_inverted) == (fs / 4, True)
    ss = sigmf_source(meta, if_hz=1e6, sample_format="real_int8")
    assert (ss.if_hz, ss.spectrum_inverted) == (1e6, False)


@pytest.mark.parametrize("center_off, fs, cplx, ok", [
    (0.0, 25e6, True, True),         # whole main lobe in +-12.5 MHz
    (2.2e6, 25e6, True, True),       # 2.2 + 10.23 <= 12.5
    (2.4e6, 25e6, True, False),      # one side of the main lobe cut
    (0.6e6, 2.5e6, True, True),      # narrow band: carrier in the inner half (0.625 MHz)
    (0.7e6, 2.5e6, True, False),
    (2.2e6, 16e6, True, True),       # band narrower than the lobe: inside it (8 + 2.2 <= 10.23)
    (2.3e6, 16e6, True, False),
    (-12.5e6, 50e6, False, True),    # real: LO 12.5 MHz below, band 0..25 MHz
    (-2e6, 50e6, False, False),      # real: the main lobe reaches below the LO
])
def test_band_rule(center_off, fs, cplx, ok):
    center = F_B3I + center_off
    if ok:
        assert check_b3i_in_band(center, fs, cplx) == pytest.approx(-center_off)
    else:
        with pytest.raises(SampleFormatError, match="outside the"):
            check_b3i_in_band(center, fs, cplx)


def test_meta_path_resolution(tmp_path):
    (tmp_path / "a.sigmf-meta").write_text("{}")
    (tmp_path / "a.sigmf-data").write_bytes(b"")
    (tmp_path / "b.bin").write_bytes(b"")
    assert sigmf_meta_path(tmp_path / "a") == tmp_path / "a.sigmf-meta"
    assert sigmf_meta_path(tmp_path / "a.sigmf-data") == tmp_path / "a.sigmf-meta"
    assert sigmf_meta_path(tmp_path / "a.sigmf-meta") == tmp_path / "a.sigmf-meta"
    assert sigmf_meta_path(tmp_path / "b.bin") is None
    assert sigmf_meta_path(tmp_path / "c") is None
    with pytest.raises(SampleFormatError, match="archives and collections are not read"):
        sigmf_meta_path(tmp_path / "a.sigmf")


def _edit(f):
    doc = {"global": {"core:datatype": "ci8", "core:sample_rate": 2.5e6, "core:version": "1.2.0"},
           "captures": [{"core:sample_start": 0, "core:frequency": F_B3I}], "annotations": []}
    f(doc)
    return doc


@pytest.mark.parametrize("doc, words", [
    ("[1, 2]", 'no "global" object'),
    ("{not json", "not JSON"),
    (_edit(lambda m: m.update(captures="x")), "captures: 'x' is not of type 'array'"),
    (_edit(lambda m: m["captures"][0].update({"core:datetime": "2020-13-45T00:00:00Z"})),
     "is not an ISO 8601 UTC time"),
    (_edit(lambda m: m["captures"][0].update({"core:datetime": "1999-01-01T00:00:00Z"})),
     "before the BDT epoch"),
    (_edit(lambda m: m["global"].update({"core:num_channels": 2})), "core:num_channels 2"),
    (_edit(lambda m: m["global"].pop("core:sample_rate")), "give --fs"),
    (_edit(lambda m: m["captures"][0].update({"core:header_bytes": 16})), "non-sample bytes"),
    (_edit(lambda m: m["global"].update({"core:extensions": [
        {"name": "foo", "version": "1", "optional": False}]})), "extension 'foo'"),
    (_edit(lambda m: m["global"].update({"core:dataset": "missing.bin"})), "not found"),
    (_edit(lambda m: m.update(captures=[])), "no capture"),
])
def test_malformed_metadata_is_a_sample_format_error(tmp_path, doc, words):
    (tmp_path / "a.sigmf-data").write_bytes(bytes(20000))
    (tmp_path / "a.sigmf-meta").write_text(doc if isinstance(doc, str) else json.dumps(doc))
    with pytest.raises(SampleFormatError, match="SigMF .*") as exc:
        sigmf_source(tmp_path / "a.sigmf-meta")
    assert words in str(exc.value) and "\n" not in str(exc.value)


def test_byte_datatypes_with_byte_order_suffix(tmp_path):
    doc = _edit(lambda m: m["global"].update({"core:datatype": "ci8_le"}))
    (tmp_path / "a.sigmf-data").write_bytes(bytes(20000))
    (tmp_path / "a.sigmf-meta").write_text(json.dumps(doc))
    assert sigmf_source(tmp_path / "a.sigmf-meta").sample_format == "iq_int8"


@pytest.mark.parametrize("hard_links", [True, False])
def test_output_set_link_is_a_member(tmp_path, monkeypatch, hard_links):
    import os

    from sdr_di.io.atomic import OutputSet

    if not hard_links:  # a file system without hard links: the member is a copy
        def no_link(*a):
            raise OSError(1, "Operation not permitted")
        monkeypatch.setattr(os, "link", no_link)
    a, b = tmp_path / "x.bin", tmp_path / "x.sigmf-data"
    with pytest.raises(KeyboardInterrupt), OutputSet() as files:
        with files.open(a) as fh:
            fh.write(b"123")
        files.link(a, b)
        raise KeyboardInterrupt  # before the commit: nothing under any name
    assert list(tmp_path.iterdir()) == []
    with OutputSet() as files:
        with files.open(a) as fh:
            fh.write(b"456")
        files.link(a, b)
        files.commit()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.bin", "x.sigmf-data"]
    assert b.read_bytes() == b"456" and os.path.samefile(a, b) == hard_links


@pytest.mark.parametrize("mode", ["scalar", "deep"])
def test_run_refuses_unreadable_datatype_before_any_work(tmp_path, capsys, mode):
    meta = _noise_pair(tmp_path, "cu8")
    out = tmp_path / "run"
    assert main(["run", str(meta.with_name("n.sigmf-data")), "--mode", mode, "--no-progress",
                 "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "core:datatype cu8 cannot be read" in err and err.count("\n") == 1, err
    assert not out.exists()
