"""Output sets a kill cannot mix (issue 12 item 3).

A generated set (``NAME.bin``, ``NAME_imu.csv``, ``NAME_truth.csv``, ``NAME.json``) is written
under ``.part`` names and renamed sidecar last; the sidecar records each member's size and
digest; every reader refuses a set whose members do not match; a failed or killed run never
touches an earlier complete set.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from sdr_di.errors import FileSetError, OutputError
from sdr_di.io import atomic
from sdr_di.io.atomic import OutputSet
from sdr_di.io.sidecar import check_member, file_fingerprint, read_sidecar
from sdr_di.receiver.ifreader import IfSource
from sdr_di.scenario import DEFAULT_SCENARIO, load_scenario
from sdr_di.sim.generate import generate_files

NAMES = ["s.bin", "s.json", "s_imu.csv", "s_truth.csv"]


def _small(duration_s: float = 0.02):
    return load_scenario(DEFAULT_SCENARIO).with_overrides(duration_s=duration_s,
                                                          sampling_rate_hz=2.5e6)


@pytest.fixture(scope="module")
def complete_set(if_files) -> Path:
    """The folder of a complete 0.02 s set (``s.*``; the session's factory: the tests copy it
    before they change it)."""
    return if_files(0.02, name="s").if_file.parent


def _contents(d: Path) -> dict[str, str]:
    """SHA-256 of each file by name: equal exactly when the bytes are (a failed comparison
    then prints 64 characters per file, not a diff of 80 MB of samples)."""
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(d.iterdir()) if p.is_file()}


def _copy(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    return dst


# -- the sidecar's record -------------------------------------------------------------------

def test_sidecar_records_every_member(complete_set):
    meta = read_sidecar(complete_set / "s.json")
    assert sorted(meta["files"]) == ["s.bin", "s_imu.csv", "s_truth.csv"]
    for name, rec in meta["files"].items():
        assert rec == file_fingerprint(complete_set / name)
        assert rec["size"] == (complete_set / name).stat().st_size


def test_fingerprint_sees_both_ends_and_the_size(tmp_path):
    big = tmp_path / "big"
    data = bytearray(os.urandom(3 << 20))
    big.write_bytes(data)
    ref = file_fingerprint(big)
    for pos in (0, len(data) - 1):
        changed = bytearray(data)
        changed[pos] ^= 1
        big.write_bytes(changed)
        assert file_fingerprint(big)["sha256_first_last_mib"] != ref["sha256_first_last_mib"]
    big.write_bytes(data + b"\0")
    assert file_fingerprint(big)["size"] == ref["size"] + 1


# -- readers refuse a mixed set ---------------------------------------------------------------

def test_new_bin_beside_old_sidecar_is_refused(complete_set, if_files, tmp_path):
    d = _copy(complete_set, tmp_path / "mixed")
    longer = if_files(0.04, name="s").if_file
    shutil.copy(longer, d / "s.bin")  # the new 0.04 s .bin, the old 0.02 s sidecar
    with pytest.raises(FileSetError, match=r"s\.json: s\.bin is not the file .* mixed"):
        IfSource.from_sidecar(d / "s.json")


def test_same_size_other_content_is_refused(complete_set, if_files, tmp_path):
    d = _copy(complete_set, tmp_path / "mixed")
    shutil.copy(if_files(0.02, seed=7, name="s").if_file, d / "s.bin")
    with pytest.raises(FileSetError, match="same size, different content"):
        IfSource.from_sidecar(d / "s.json")


def test_deep_mode_refuses_a_mixed_imu_and_uses_the_given_sidecar(complete_set, tmp_path):
    from sdr_di.integration.run_integrated import companion_files

    d = _copy(complete_set, tmp_path / "set")
    # a sidecar under another name, in another folder, naming the set's files: deep mode must
    # take the companions from it, not from a JSON beside the .bin
    other = tmp_path / "elsewhere"
    other.mkdir()
    meta = json.loads((d / "s.json").read_text())
    for key in ("if_file", "imu_file", "truth_file"):
        meta[key] = str(d / meta[key])
    meta["files"] = {str(d / k): v for k, v in meta["files"].items()}
    (other / "mine.json").write_text(json.dumps(meta))
    (d / "s.json").write_text(json.dumps({**meta, "imu_file": "nope.csv"}))
    src = IfSource.from_sidecar(other / "mine.json")
    assert companion_files(src)["imu"] == d / "s_imu.csv"
    with open(d / "s_imu.csv", "a") as fh:
        fh.write("\n")
    with pytest.raises(FileSetError, match=r"s_imu\.csv is not the file"):
        companion_files(src)
    # an IMU given on the command line replaces the sidecar's: its own file is not checked
    assert companion_files(src, skip=("imu",))["imu"] is None


def test_hand_written_sidecar_without_record_still_reads(complete_set, tmp_path):
    d = _copy(complete_set, tmp_path / "old")
    meta = json.loads((d / "s.json").read_text())
    del meta["files"]
    (d / "s.json").write_text(json.dumps(meta))
    assert IfSource.from_sidecar(d / "s.json").n_samples == meta["n_samples"]
    assert check_member(d / "s.json", meta, "imu_file") == d / "s_imu.csv"


# -- failures leave an earlier set alone --------------------------------------------------

def test_failure_while_writing_keeps_the_earlier_set(complete_set, tmp_path, monkeypatch):
    import sdr_di.sim.generate as gen

    d = _copy(complete_set, tmp_path / "set")
    before = _contents(d)

    def full(*a, **k):
        raise OutputError("s_truth.csv: write failed (No space left on device)")

    monkeypatch.setattr(gen, "write_truth", full)
    with pytest.raises(OutputError, match="No space"):
        generate_files(_small(0.04), d, name="s", progress=False)
    assert _contents(d) == before  # nothing deleted, nothing new, no .part left


def test_interrupt_between_renames_leaves_a_set_readers_refuse(complete_set, tmp_path,
                                                               monkeypatch):
    d = _copy(complete_set, tmp_path / "set")
    real = os.replace
    calls = []

    def replace_then_die(src, dst):
        if len(calls) == 1:  # .bin renamed, then the process "dies"
            raise KeyboardInterrupt
        calls.append(dst)
        return real(src, dst)

    monkeypatch.setattr(atomic.os, "replace", replace_then_die)
    with pytest.raises(KeyboardInterrupt):
        generate_files(_small(0.04), d, name="s", progress=False)
    assert [Path(c).name for c in calls] == ["s.bin"]
    assert sorted(p.name for p in d.iterdir()) == NAMES  # the .part files are gone
    with pytest.raises(FileSetError, match=r"s\.bin is not the file"):
        IfSource.from_sidecar(d / "s.json")


def test_output_set_renames_in_order_and_discards_on_error(tmp_path, monkeypatch):
    order = []
    real = os.replace
    monkeypatch.setattr(atomic.os, "replace", lambda s, t: (order.append(Path(t).name),
                                                            real(s, t)))
    with OutputSet() as files:
        for name in ("a.bin", "b.csv", "c.json"):
            with files.open(tmp_path / name, "w") as fh:
                fh.write(name)
        assert sorted(p.name for p in tmp_path.iterdir()) == [
            "a.bin.part", "b.csv.part", "c.json.part"]
        files.commit()
    assert order == ["a.bin", "b.csv", "c.json"]
    with pytest.raises(RuntimeError), OutputSet() as files:
        with files.open(tmp_path / "a.bin", "w") as fh:
            fh.write("new")
        raise RuntimeError
    assert (tmp_path / "a.bin").read_text() == "a.bin"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.bin", "b.csv", "c.json"]


# -- a real kill / Ctrl-C during a re-generation ------------------------------------------------

def _start_generation(out: Path) -> subprocess.Popen:
    # long enough (10 MHz, 12 s: 240 MB if it ran to the end) that the signal, sent once the
    # .bin.part has bytes, always lands while it is being written, even on a fast idle machine
    # (at 4 s a generation could finish before the signal arrived); killed early, it writes
    # only a few MB
    return subprocess.Popen(
        [sys.executable, "-m", "sdr_di.cli", "generate", "--no-progress", "--duration", "12",
         "--fs", "10e6", "--out", str(out), "--name", "s"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        # a terminal's Ctrl-C, whatever disposition the test process left to its children
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))


def _wait_for_part(proc: subprocess.Popen, part: Path, timeout_s: float = 120.0) -> None:
    t0 = time.monotonic()
    while not (part.exists() and part.stat().st_size > 0):
        if proc.poll() is not None:
            pytest.fail(f"generation ended before writing: {proc.stderr.read()}")
        if time.monotonic() - t0 > timeout_s:
            proc.kill()
            pytest.fail("generation did not start writing")
        time.sleep(0.02)


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGINT], ids=["SIGKILL", "SIGINT"])
def test_killed_regeneration_keeps_the_earlier_set(complete_set, tmp_path, sig):
    d = _copy(complete_set, tmp_path / "set")
    before = _contents(d)
    proc = _start_generation(d)
    _wait_for_part(proc, d / "s.bin.part")
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    finals = {k: v for k, v in _contents(d).items() if not k.endswith(".part")}
    assert finals == before
    assert IfSource.from_sidecar(d / "s.json").n_samples == 50_000
    if sig == signal.SIGINT:
        assert proc.returncode == 130
        assert err.strip().splitlines() == ["sdr-di: interrupted"], err
        assert sorted(_contents(d)) == NAMES  # the .part files were removed
