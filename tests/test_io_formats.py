"""Sample formats, atomic output and the metadata sidecar."""

import errno
from pathlib import Path

import numpy as np
import pytest

from sdr_di.errors import OutputError, SampleFormatError
from sdr_di.io.atomic import atomic_open, ensure_output_dir
from sdr_di.io.sample_formats import (get_format, pack_iq_int4, quantizer_levels,
                                      unpack_iq_int4)
from sdr_di.io.sidecar import read_sidecar, write_sidecar


def test_int4_pack_round_trip():
    rng = np.random.default_rng(0)
    i = rng.integers(-8, 8, 1000).astype(np.int8)
    q = rng.integers(-8, 8, 1000).astype(np.int8)
    packed = pack_iq_int4(i, q)
    assert packed.dtype == np.uint8 and packed.shape == (1000,)
    i2, q2 = unpack_iq_int4(packed)
    np.testing.assert_array_equal(i, i2)
    np.testing.assert_array_equal(q, q2)
    # layout: I in the high nibble
    assert pack_iq_int4(np.array([1], np.int8), np.array([-1], np.int8))[0] == 0x1F


def test_format_registry():
    assert get_format("ibyte").name == "iq_int8" and get_format("iq_int8").is_complex
    assert get_format("real_int16").bytes_per_sample == 2
    assert quantizer_levels(4) == 7 and quantizer_levels(1) == 1 and quantizer_levels(8) == 127
    with pytest.raises(SampleFormatError, match="unknown sample format"):
        get_format("int3")


def test_atomic_open_keeps_nothing_on_failure(tmp_path: Path):
    final = tmp_path / "x.bin"
    with pytest.raises(OutputError, match="No space left"):
        with atomic_open(final) as fh:
            fh.write(b"abc")
            raise OSError(errno.ENOSPC, "No space left on device")
    assert not final.exists() and not list(tmp_path.iterdir())
    with atomic_open(final) as fh:
        fh.write(b"abc")
    assert final.read_bytes() == b"abc" and not (tmp_path / "x.bin.part").exists()


def test_output_dir_errors(tmp_path: Path):
    f = tmp_path / "file"
    f.write_text("x")
    with pytest.raises(OutputError, match="not a directory|cannot create"):
        ensure_output_dir(f)
    with pytest.raises(OutputError, match="cannot create|is not a directory"):
        ensure_output_dir(f / "sub")


def test_sidecar_round_trip_and_errors(tmp_path: Path):
    meta = {"if_file": "a.bin", "sampling_rate_hz": 25e6, "if_hz": 0.0,
            "sample_format": "iq_int8", "n_samples": 10, "start": {"week": 1, "sow": 2.0}}
    p = write_sidecar(tmp_path / "a.json", meta)
    assert read_sidecar(p)["sampling_rate_hz"] == 25e6
    (tmp_path / "b.json").write_text('{"schema": "other"}')
    with pytest.raises(SampleFormatError, match="schema"):
        read_sidecar(tmp_path / "b.json")
    (tmp_path / "c.json").write_text("{")
    with pytest.raises(SampleFormatError, match="not JSON"):
        read_sidecar(tmp_path / "c.json")
