"""Peers' sample formats (SignalSim, PocketSDR) and their ``.tag`` sidecars.

Every vector is packed here from the bit layout written in ``docs/formats.md`` (not with the
package's tables), read back through ``open_source``/``IfSource`` and compared exactly.
"""

import json
from pathlib import Path

import numpy as np
import pytest

from sdr_di.cli import main
from sdr_di.errors import SampleFormatError
from sdr_di.io.tag_sidecar import read_tag, tag_source
from sdr_di.receiver.acquisition import acquire_source
from sdr_di.receiver.ifreader import IfSource
from sdr_di.receiver.run_scalar import open_source

N = 5003  # odd, so chunk offsets and parities are exercised


def tag_text(fmt, fs_mhz="4", f_lo="1268.52", iq=None, bits=None, prog="Pocket SDR", **extra):
    lines = [f"PROG = {prog}", "TIME = 2024/01/02 03:04:05.678", f"FMT  = {fmt}",
             f"F_S  = {fs_mhz}", f"F_LO = {f_lo}"]
    if iq is not None:
        lines.append(f"IQ   = {iq}")
    if bits is not None:
        lines.append(f"BITS = {bits}")
    lines += [f"{k} = {v}" for k, v in extra.items()]
    return "\n".join(lines) + "\n"


#: 10240 bytes of noise: a file the format check takes for a recording (a repeating pattern
#: is refused: ifreader.content_problem).
NOISE_BYTES = np.random.default_rng(7).integers(0, 256, 10240, dtype=np.uint8).tobytes()


def write(tmp_path, data: bytes, tag: str, name="x.bin") -> Path:
    p = tmp_path / name
    p.write_bytes(data)
    (tmp_path / (name + ".tag")).write_text(tag)
    return p


def sign_mag(sign, m):
    """Odd-level sign-magnitude value: sign bit 1 is negative, value +-(2m+1)."""
    return (1 - 2 * np.asarray(sign, np.int64)) * (2 * np.asarray(m, np.int64) + 1)


def check_reads(src: IfSource, expected: np.ndarray, stored: np.ndarray | None = None):
    """Whole-file, chunked and stored reads all equal ``expected`` exactly."""
    assert src.n_samples == expected.size
    np.testing.assert_array_equal(src.read(0, expected.size), expected)
    got = np.concatenate([blk for _, blk in src.chunks(997)])
    np.testing.assert_array_equal(got, expected)
    np.testing.assert_array_equal(src.read(1001, 7), expected[1001:1008])
    if stored is not None:
        vals, n_comp = src.read_stored(3, 500)
        assert n_comp == (2 if src.is_complex else 1)
        np.testing.assert_array_equal(vals, stored[3 * n_comp:(3 + 500) * n_comp])


# -- SignalSim ------------------------------------------------------------------------------

def test_signalsim_int4x2_sign_magnitude(tmp_path):
    rng = np.random.default_rng(4)
    si, mi, sq, mq = (rng.integers(0, k, N) for k in (2, 8, 2, 8))
    # IFdataGen.cpp QuantSamplesIQ4: I nibble high, Q nibble low, bit 3 the sign
    byte = (si << 7) | (mi << 4) | (sq << 3) | mq
    p = write(tmp_path, byte.astype(np.uint8).tobytes(),
              tag_text("INT4X2", iq="1", bits="4", prog="IFDataGen", SCALE="1.0"))
    src = open_source(p)
    i, q = sign_mag(si, mi), sign_mag(sq, mq)
    assert src.format.name == "iq_int4_sm" and not src.spectrum_inverted
    assert src.sampling_rate_hz == 4e6 and src.if_hz == pytest.approx(0.0, abs=1e-3)
    assert set(np.unique(i)) == set(range(-15, 16, 2))
    check_reads(src, (i + 1j * q).astype(np.complex64),
                np.stack([i, q], axis=1).reshape(-1).astype(np.int8))


@pytest.mark.parametrize("prog, iq, q_sign", [("IFDataGen", "1", 1), ("Pocket SDR", "2", -1),
                                             ("", "1", 1), ("", "2", -1)])
def test_int8x2_q_convention_by_program(tmp_path, prog, iq, q_sign):
    """SignalSim INT8X2 is iq_int8; PocketSDR INT8X2 has Q negated (PROG, else IQ, decides)."""
    rng = np.random.default_rng(8)
    v = rng.integers(-128, 128, (N, 2))
    p = write(tmp_path, v.astype(np.int8).tobytes(),
              tag_text("INT8X2", f_lo="1268.02", iq=iq, bits="8", prog=prog))
    src = open_source(p)
    assert src.format.name == "iq_int8" and src.if_hz == pytest.approx(0.5e6)
    check_reads(src, (v[:, 0] + 1j * q_sign * v[:, 1]).astype(np.complex64))


def test_signalsim_2bit_refused(tmp_path):
    p = write(tmp_path, bytes(100), tag_text("INT2X2", iq="1", bits="2", prog="IFDataGen"))
    with pytest.raises(SampleFormatError, match="INT2X2 not supported.*QuantSamplesIQ2"):
        open_source(p)


# -- PocketSDR ------------------------------------------------------------------------------

RAW = {"RAW8": 1, "RAW16": 2, "RAW32": 4}  # bytes per sample time; two channels per byte


def pack_nibbles(nibbles: np.ndarray) -> np.ndarray:
    """(N, n_ch) nibbles -> (N, n_ch // 2) bytes: channel 2j in the low nibble of byte j."""
    return (nibbles[:, 0::2] | (nibbles[:, 1::2] << 4)).astype(np.uint8)


@pytest.mark.parametrize("fmt", sorted(RAW))
def test_pocket_raw_iq_2bit_every_channel(tmp_path, fmt):
    rng = np.random.default_rng(len(fmt))
    n_ch = 2 * RAW[fmt]
    si, mi, sq, mq = (rng.integers(0, 2, (N, n_ch)) for _ in range(4))
    # sdr_rcv.c gen_LUTC: I code in bits 1-0 of the channel's nibble, Q code in bits 3-2;
    # code bit 1 the sign, bit 0 the magnitude; Q negated
    nib = (si << 1) | mi | (sq << 3) | (mq << 2)
    f_lo = ",".join(["1268.52"] * n_ch)
    p = write(tmp_path, pack_nibbles(nib).tobytes(),
              tag_text(fmt, f_lo=f_lo, iq=",".join("2" * n_ch), bits=",".join("2" * n_ch)))
    for ch in range(1, n_ch + 1):
        src = open_source(p, rfch=ch)
        assert src.format.name == f"pocket_{fmt.lower()}_iq2" and src.rf_channel == ch
        i, q = sign_mag(si[:, ch - 1], mi[:, ch - 1]), -sign_mag(sq[:, ch - 1], mq[:, ch - 1])
        check_reads(src, (i + 1j * q).astype(np.complex64),
                    np.stack([i, q], axis=1).reshape(-1).astype(np.int8))


def test_pocket_raw8_real_2_and_3_bit(tmp_path):
    rng = np.random.default_rng(33)
    s1, m1 = rng.integers(0, 2, N), rng.integers(0, 2, N)
    s2, m2, junk = rng.integers(0, 2, N), rng.integers(0, 4, N), rng.integers(0, 2, N)
    # channel 1: 2-bit real (bits 1-0; bits 3-2 unused); channel 2: 3-bit real, bit 1 the
    # sign, magnitude 2*b0 + b3, bit 2 unused (sdr_rcv.c gen_LUTC valI_3b index)
    nib1 = (s1 << 1) | m1 | (junk << 3)
    nib2 = (s2 << 1) | (m2 >> 1) | ((m2 & 1) << 3) | (junk << 2)
    # channel 1 below the carrier (IF +0.5 MHz), channel 2 above it (IF -0.75 MHz)
    p = write(tmp_path, pack_nibbles(np.stack([nib1, nib2], axis=1)).tobytes(),
              tag_text("RAW8", f_lo="1268.02,1269.27", iq="1,1", bits="2,3"))
    a = open_source(p, rfch=1)
    assert a.format.name == "pocket_raw8_real2" and not a.spectrum_inverted
    assert a.if_hz == pytest.approx(0.5e6)
    check_reads(a, sign_mag(s1, m1).astype(np.float32),
                sign_mag(s1, m1).astype(np.int8))
    b = open_source(p, rfch=2)
    # LO above the carrier: real samples with an inverted spectrum at |IF| (mirrored on read)
    assert b.format.name == "pocket_raw8_real3" and b.spectrum_inverted
    assert b.declared_if_hz == pytest.approx(0.75e6) and b.if_hz == pytest.approx(1.25e6)
    mirror = np.where(np.arange(N) % 2, -1.0, 1.0)
    check_reads(b, (sign_mag(s2, m2) * mirror).astype(np.float32))
    assert set(np.unique(sign_mag(s2, m2))) == {-7, -5, -3, -1, 1, 3, 5, 7}


def test_pocket_raw16i_real_2bit(tmp_path):
    rng = np.random.default_rng(16)
    s, m = rng.integers(0, 2, (N, 8)), rng.integers(0, 2, (N, 8))
    code = (s << 1) | m
    # Spider FE: channel k at bits 2((k-1) % 4) of byte (k-1) // 4
    byte = np.stack([sum(code[:, 4 * j + c] << (2 * c) for c in range(4)) for j in range(2)],
                    axis=1).astype(np.uint8)
    p = write(tmp_path, byte.tobytes(),
              tag_text("RAW16I", f_lo=",".join(["1268.02"] * 8), iq=",".join("1" * 8),
                       bits=",".join("2" * 8)))
    for ch in (1, 4, 5, 8):
        src = open_source(p, rfch=ch)
        assert src.format.name == "pocket_raw16i_real2"
        check_reads(src, sign_mag(s[:, ch - 1], m[:, ch - 1]).astype(np.float32))


def test_default_channel_is_nearest_lo_and_flags_override(tmp_path):
    rng = np.random.default_rng(5)
    b = rng.integers(0, 256, N).astype(np.uint8)
    p = write(tmp_path, b.tobytes(),
              tag_text("RAW8", fs_mhz="2.5", f_lo="1575.42,1268.02", iq="2,2", bits="2,2"))
    src = open_source(p)
    assert src.rf_channel == 2 and src.if_hz == pytest.approx(0.5e6)
    assert src.sampling_rate_hz == 2.5e6 and src.start_week is None
    # explicit flags override the tag's values
    src = open_source(p, sampling_rate_hz=4e6, if_hz=-0.25e6, start_week=2300, start_sow=5.0)
    assert (src.sampling_rate_hz, src.if_hz, src.start_week) == (4e6, -0.25e6, 2300)
    assert src.format.name == "pocket_raw8_iq2" and src.rf_channel == 2
    # the tag itself may be named; the file it describes is read
    assert open_source(p.with_name("x.bin.tag")).path == p
    # --format replaces the layout, and PocketSDR's INT8X2 Q negation with it
    q = write(tmp_path, b[:-1].tobytes(), tag_text("INT8X2", iq="2", bits="8"), name="y.bin")
    assert open_source(q).spectrum_inverted
    assert not open_source(q, sample_format="iq_int8").spectrum_inverted


def test_json_sidecar_wins_over_tag(tmp_path):
    p = write(tmp_path, NOISE_BYTES, tag_text("INT4X2", prog="IFDataGen"))
    meta = {"schema": "sdr-di-if/1", "if_file": "x.bin", "sampling_rate_hz": 1e6, "if_hz": 0.0,
            "sample_format": "iq_int8", "n_samples": 5120, "start": {"week": 1, "sow": 2.0}}
    (tmp_path / "x.json").write_text(json.dumps(meta))
    src = open_source(p)
    assert src.format.name == "iq_int8" and src.sampling_rate_hz == 1e6


def test_foreign_json_named_like_the_file_is_refused_with_the_way_out(tmp_path, capsys):
    """A JSON file beside the IF file with its stem that is not an sdr-di sidecar (a
    SignalSim configuration named like its output): one line saying so and naming
    --ignore-sidecar, exit 2 before any work; with --ignore-sidecar the tag describes the
    file. The sidecar named itself keeps the plain message."""
    from sdr_di.cli import main
    from sdr_di.errors import SidecarError

    p = write(tmp_path, NOISE_BYTES, tag_text("INT4X2", prog="IFDataGen"))
    (tmp_path / "x.json").write_text(json.dumps({"time": {"type": "UTC"},
                                                 "output": {"format": "IQ4"}}))
    with pytest.raises(SidecarError, match=r"not an sdr-di sidecar .*sidecar of x\.bin "
                                           r"\(--ignore-sidecar reads the file without it"):
        open_source(p)
    with pytest.raises(SidecarError, match=r"not an sdr-di sidecar \(no \"schema\""):
        open_source(tmp_path / "x.json")
    src = open_source(p, ignore_sidecar=True)
    assert src.format.name == "iq_int4_sm" and src.sampling_rate_hz == 4e6   # the tag's
    assert main(["run", str(p), "--no-progress", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("sdr-di: error: sidecar ") and "\n" not in err
    assert "--ignore-sidecar" in err and not (tmp_path / "out").exists()


# -- bad tags: one line naming the key ----------------------------------------------------------

BAD = [
    (tag_text("FOO8"), "FMT = FOO8 unknown"),
    ("PROG = x\nFMT = RAW8\nF_LO = 1268.52,1268.52\nIQ = 2,2\nBITS = 2,2\n", "missing key F_S"),
    ("FMT = INT4X2\nF_S = 4\n", "missing key F_LO"),
    ("F_S = 4\nF_LO = 1268.52\n", "missing key FMT"),
    (tag_text("INT4X2", fs_mhz="4MHz"), "F_S = '4MHz'"),
    (tag_text("INT4X2", fs_mhz="nan"), "F_S = 'nan': not a finite"),
    (tag_text("INT4X2", fs_mhz="0"), "F_S = 0 MHz is not positive"),
    (tag_text("INT4X2", fs_mhz="4,8"), "F_S has 2 values"),
    (tag_text("INT4X2", f_lo="1268.52,-3"), "F_LO = 1268.52,-3 MHz has a negative"),
    (tag_text("INT4X2", f_lo="1268.52,1268.52"), "F_LO has 2 value"),
    (tag_text("RAW8", f_lo="1268.52", iq="2,2", bits="2,2"), "F_LO has 1 value"),
    (tag_text("RAW8", f_lo="1268.52,1268.52", bits="2,2"), "missing key IQ"),
    (tag_text("RAW8", f_lo="1268.52,1268.52", iq="2,2", bits="2"), "BITS has 1 value"),
    (tag_text("RAW8", f_lo="1268.52,1268.52", iq="2,x", bits="2,2"), "IQ = '2,x'"),
    (tag_text("RAW8", f_lo="1268.52,1268.52", iq="2,2", bits="3,3"), "IQ = 2, BITS = 3"),
    (tag_text("INT4X2", f_lo="1575.42"), "F_LO = 1575.42 MHz .* outside the band"),
    (tag_text("INT8X2", prog=""), "INT8X2 with PROG = None and no IQ"),
    (tag_text("INT4X2") + "garbage line\n", "line 6 'garbage line' is not KEY = VALUE"),
    (tag_text("INT4X2") + "F_S = 8\n", "key F_S given twice"),
]


@pytest.mark.parametrize("text, message", BAD, ids=[m[:24] for _, m in BAD])
def test_bad_tag_one_line_error(tmp_path, text, message):
    p = write(tmp_path, bytes(64), text)
    with pytest.raises(SampleFormatError, match=message) as err:
        open_source(p)
    assert "\n" not in str(err.value) and "x.bin.tag" in str(err.value)


def test_bad_rfch_and_binary_tag(tmp_path):
    p = write(tmp_path, bytes(64), tag_text("RAW8", f_lo="1268.52,1268.52", iq="2,2",
                                            bits="2,2"))
    for ch in (0, 3):
        with pytest.raises(SampleFormatError, match=f"--rfch {ch} outside the 2 RF channel"):
            open_source(p, rfch=ch)
    q = write(tmp_path, bytes(64), tag_text("INT4X2", prog="IFDataGen"), name="y.bin")
    with pytest.raises(SampleFormatError, match="--rfch 2 outside the 1 RF channel"):
        open_source(q, rfch=2)
    (tmp_path / "y.bin.tag").write_bytes(bytes(range(256)))
    with pytest.raises(SampleFormatError, match="not an ASCII text file"):
        read_tag(tmp_path / "y.bin.tag")
    # a multi-channel format by flags alone needs --rfch
    with pytest.raises(SampleFormatError, match="choose one with --rfch"):
        IfSource(tmp_path / "y.bin", 4e6, 0.0, "pocket_raw8_iq2")
    # the CLI: one line, exit 2, before any work
    assert main(["run", str(p), "--rfch", "3", "--no-progress"]) == 2


def test_tag_source_reads_pocketsdr_lists(tmp_path):
    """A PocketSDR FE 4CH tag as sdr_tag_write writes it (%.9g values, comma lists)."""
    p = tmp_path / "fe.bin.tag"
    p.write_text("PROG = Pocket\nTIME = 2024/08/26 01:02:03.000\nFMT  = RAW16\n"
                 "F_S  = 24\nF_LO = 1575.42,1575.42,1227.6,1268.52\nIQ   = 2,2,1,2\n"
                 "BITS = 2,2,3,2\n")
    tag = read_tag(p)
    assert tag.f_lo_hz == (1575.42e6, 1575.42e6, 1227.6e6, 1268.52e6)
    ts = tag_source(tag)
    assert (ts.sample_format, ts.rf_channel, ts.if_hz, ts.peer) == (
        "pocket_raw16_iq2", 4, pytest.approx(0.0, abs=1e-3), "PocketSDR")
    assert tag_source(tag, 3, if_hz=2e6).sample_format == "pocket_raw16_real3"


# -- end to end: a generated B3I snippet re-encoded in the peers' formats -------------------

@pytest.fixture(scope="module")
def snippet(if_files):
    """0.1 s of the default scenario at 2.5 MHz (complex baseband, 4-bit in iq_int8; the
    session's factory)."""
    sidecar = if_files(0.1).metadata
    meta = json.loads(sidecar.read_text())
    return IfSource.from_sidecar(sidecar).read(0, meta["n_samples"]), meta


def encode_pocket_raw8(x, meta):
    sigma_lsb = meta["agc"]["gain_lsb"]  # stored LSB per noise sigma

    def code(v):  # 2-bit quantizer: sign and |v| >= sigma (near optimal for 2 bits)
        return ((v < 0) << 1 | (np.abs(v) >= sigma_lsb)).astype(np.uint8)

    # RF channel 2 carries B3I (Q stored negated), channel 1 unrelated noise at an L1 LO
    nib2 = code(x.real) | code(-x.imag) << 2
    nib1 = np.random.default_rng(0).integers(0, 16, x.size, dtype=np.uint8)
    return ((nib1 | nib2 << 4).astype(np.uint8).tobytes(),
            tag_text("RAW8", fs_mhz="2.5", f_lo="1575.42,1268.52", iq="2,2", bits="2,2"))


def encode_signalsim_int4x2(x, meta):
    def nibble(v):  # sign bit 3, magnitude |v| (the values become +-(2|v| + 1))
        return ((v < 0) << 3 | np.minimum(np.abs(v), 7).astype(np.uint8)).astype(np.uint8)

    return ((nibble(x.real) << 4 | nibble(x.imag)).astype(np.uint8).tobytes(),
            tag_text("INT4X2", fs_mhz="2.500000", f_lo="1268.520000", iq="1", bits="4",
                     prog="IFDataGen", SCALE="1.0"))


def encode_pocket_int8x2(x, meta):
    iq = np.stack([x.real, -x.imag], axis=1).astype(np.int8)  # Q negated on disk
    return iq.tobytes(), tag_text("INT8X2", fs_mhz="2.5", iq="2", bits="8")


ENCODERS = {"pocket_raw8_iq2": encode_pocket_raw8, "iq_int4_sm": encode_signalsim_int4x2,
            "iq_int8": encode_pocket_int8x2}


@pytest.mark.parametrize("fmt", sorted(ENCODERS))
def test_generated_snippet_acquired_with_flags_from_the_tag(tmp_path, snippet, fmt):
    x, meta = snippet
    p = write(tmp_path, *ENCODERS[fmt](x, meta))
    src = open_source(p)  # no options: all from x.bin.tag
    assert (src.format.name, src.if_hz, src.sampling_rate_hz) == (fmt, 0.0, 2.5e6)
    truth = {s["prn"]: s for s in meta["satellites"]}
    res = {r.prn: r for r in acquire_source(src, prns=[*truth, 1, 40])}
    for prn, t in truth.items():
        r = res[prn]
        dcode = (r.code_phase_chips - t["code_phase_chips"] + 5115) % 10230 - 5115
        # a wrong Q sign would mirror the Doppler: several satellites are > 1 kHz off zero
        assert r.detected and abs(r.doppler_hz - t["doppler_hz"]) < 100.0, (r, t)
        assert abs(dcode) < 0.5, (r, t)
    assert not res[1].detected and not res[40].detected


def test_run_cli_on_tagged_file_needs_no_flags(tmp_path, snippet, capsys):
    x, meta = snippet
    p = write(tmp_path, *encode_pocket_raw8(x, meta))
    prns = ",".join(f"C{s['prn']:02d}" for s in meta["satellites"][:3])
    # a snippet is too short for a fix: exit 1 (docs/errors.md), channels still printed
    assert main(["run", str(p), "--no-progress", "--prn", prns, "--out",
                 str(tmp_path / "run")]) == 1
    out = capsys.readouterr().out
    assert all(f"C{s['prn']:02d}" in out for s in meta["satellites"][:3]), out
