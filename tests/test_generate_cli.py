"""``sdr-di generate`` end to end: outputs, formats, reproducibility and every bad input."""

import errno
import gzip
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sdr_di.cli import main
from sdr_di.io.sample_formats import unpack_iq_int4
from sdr_di.io.sidecar import read_sidecar
from sdr_di.scenario import DEFAULT_SCENARIO

DUR = "0.02"


def run(args, capsys):
    rc = main(["generate", "--no-progress", "--duration", DUR, *args])
    return rc, capsys.readouterr()


def final_files(d: Path):
    return sorted(p.name for p in d.iterdir()) if d.exists() else []


def test_generate_writes_consistent_outputs(tmp_path, capsys):
    rc, _ = run(["--out", str(tmp_path)], capsys)
    assert rc == 0
    assert final_files(tmp_path) == ["default.bin", "default.json", "default_imu.csv",
                                     "default_truth.csv"]
    meta = read_sidecar(tmp_path / "default.json")
    assert meta["n_samples"] == 500_000 and meta["sampling_rate_hz"] == 25e6
    assert (tmp_path / "default.bin").stat().st_size == meta["n_samples"] * 2
    assert len(meta["satellites"]) == 7 and meta["start"]["week"] == 755
    assert meta["start"]["sow"] == 360000.0 + 2.5 * 3600
    x = np.fromfile(tmp_path / "default.bin", np.int8)
    assert x.min() >= -7 and x.max() <= 7  # 4-bit mid-tread grid
    # automatic gain: noise-dominated input at ~3 LSB RMS (Max step 0.3352 sigma)
    assert np.std(x) == pytest.approx(1 / 0.3352, rel=0.05)


def test_same_seed_same_bytes_other_seed_differs(tmp_path, capsys):
    for name, seed in (("a", "5"), ("b", "5"), ("c", "6")):
        assert run(["--out", str(tmp_path), "--name", name, "--seed", seed], capsys)[0] == 0
    a, b, c = ((tmp_path / f"{n}.bin").read_bytes() for n in "abc")
    assert a == b and a != c


@pytest.mark.parametrize("fmt, bits, extra, bps", [
    ("iq_int4", "4", [], 1),
    ("iq_int16", "12", [], 4),
    ("real_int16", "12", ["--fs", "20e6", "--if", "5e6"], 2),
    ("real_int8", "2", ["--fs", "20e6", "--if", "4.1e6"], 1),
])
def test_other_formats(tmp_path, capsys, fmt, bits, extra, bps):
    rc, err = run(["--out", str(tmp_path), "--format", fmt, "--bits", bits, *extra], capsys)
    assert rc == 0, err
    meta = read_sidecar(tmp_path / "default.json")
    assert meta["sample_format"] == fmt
    assert (tmp_path / "default.bin").stat().st_size == meta["n_samples"] * bps
    L = 2 ** (int(bits) - 1) - 1
    if fmt == "iq_int4":
        i, q = unpack_iq_int4(np.fromfile(tmp_path / "default.bin", np.uint8))
        assert max(abs(i).max(), abs(q).max()) <= L
    else:
        x = np.fromfile(tmp_path / "default.bin", np.int16 if "16" in fmt else np.int8)
        assert abs(x).max() <= L and abs(x).max() >= L // 2


def _expect_error(capsys, tmp_path, args, pattern, out=None):
    out = out or tmp_path / "out"
    rc, cap = run(["--out", str(out), *args], capsys)
    assert rc == 2
    lines = cap.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("sdr-di: error: "), cap.err
    assert re.search(pattern, lines[0]), lines[0]
    assert [f for f in final_files(out) if not f.endswith(".part")] == []
    assert [f for f in final_files(out) if f.endswith(".part")] == []


def test_malformed_scenario(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text(DEFAULT_SCENARIO.read_text().replace('duration_s = 60.0', 'duration_s = "x"'))
    _expect_error(capsys, tmp_path, ["--scenario", str(bad)], r"duration_s: expected a finite number")


def test_unknown_prn(tmp_path, capsys):
    _expect_error(capsys, tmp_path, ["--prn", "C10,C64"], r"unknown BDS PRN 'C64'")


def test_prn_without_ephemeris(tmp_path, capsys):
    _expect_error(capsys, tmp_path, ["--prn", "C10,C01"], r"C0?1|PRN 1")


def test_unreadable_and_non_bds_rinex(tmp_path, capsys):
    junk = tmp_path / "junk.rnx"
    junk.write_bytes(b"\x00\x01garbage" * 100)
    _expect_error(capsys, tmp_path, ["--ephemeris", str(junk)], r"junk\.rnx")
    gps = tmp_path / "gps.rnx"
    gps.write_text("     3.04           N: GNSS NAV DATA    G: GPS              RINEX VERSION / TYPE\n"
                   "                                                            END OF HEADER\n")
    _expect_error(capsys, tmp_path, ["--ephemeris", str(gps)], r"no BDS records")
    v5 = tmp_path / "v5.rnx.gz"
    with gzip.open(v5, "wt") as fh:
        fh.write("     5.00           NAVIGATION DATA     M                   RINEX VERSION / TYPE\n")
    _expect_error(capsys, tmp_path, ["--ephemeris", str(v5)], r"unsupported RINEX version 5\.00")


def test_output_directory_not_writable(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    rc, cap = run(["--out", str(blocker / "sub")], capsys)
    assert rc == 2 and "output directory" in cap.err and len(cap.err.strip().splitlines()) == 1


def test_disk_full_leaves_nothing(tmp_path, capsys, monkeypatch):
    import sdr_di.io.atomic as atomic

    class Full:
        def __init__(self, fh):
            self.fh, self.n = fh, 0

        def write(self, data):
            self.n += len(data)
            if self.n > 300_000:
                raise OSError(errno.ENOSPC, "No space left on device")
            return self.fh.write(data)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return self.fh.__exit__(*exc)

    real_open = open
    monkeypatch.setattr(atomic, "open", lambda *a, **k: Full(real_open(*a, **k)), raising=False)
    out = tmp_path / "out"
    _expect_error(capsys, tmp_path, [], r"No space left on device", out=out)


def test_console_script_exit_status(tmp_path):
    """The installed entry point reports errors in one line with status 2."""
    res = subprocess.run([sys.executable, "-m", "sdr_di.cli", "generate", "--prn", "C99",
                          "--out", str(tmp_path)], capture_output=True, text=True)
    assert res.returncode == 2 and res.stderr.count("\n") == 1 and "C99" in res.stderr


def test_console_script_is_console_main_and_exits_frozen(tmp_path):
    """The ``sdr-di`` script runs :func:`~sdr_di.cli.console_main`, which ends through
    ``exit_program``: the status of ``main``, the objects frozen out of the garbage
    collector before the interpreter's teardown (what saves its cycle search), and the
    output flushed."""
    import tomllib
    from pathlib import Path

    meta = tomllib.loads((Path(__file__).resolve().parents[1] / "pyproject.toml").read_text())
    assert meta["project"]["scripts"]["sdr-di"] == "sdr_di.cli:console_main"
    code = ("import atexit, gc, sys; from sdr_di import cli; "
            "atexit.register(lambda: print('frozen', gc.get_freeze_count() > 0)); "
            "cli.main = lambda: (print('ran', sys.argv[1:]), 3)[1]; cli.console_main()")
    res = subprocess.run([sys.executable, "-c", code, "x"], capture_output=True, text=True)
    assert res.returncode == 3
    assert res.stdout.split("\n")[:2] == ["ran ['x']", "frozen True"]


@pytest.mark.slow
def test_generated_message_switches_to_the_new_upload_and_the_receiver_takes_it(tmp_path):
    """A file across an upload (07:00 records on the air from 07:00:18): the message carries
    the new record from the 07:00:30 frame on, and the scalar receiver decodes and uses it."""
    import json

    from sdr_di.receiver.accuracy import solution_vs_truth
    from sdr_di.receiver.run_scalar import open_source, run_scalar
    from sdr_di.receiver.scalar import ScalarReceiver
    from sdr_di.scenario import REPO_ROOT

    text = (REPO_ROOT / "signals" / "default.toml").read_text()
    text = text.replace('"../ephemeris/', f'"{REPO_ROOT / "ephemeris"}/')
    text = text.replace('start = "2020-06-25T06:30:00"', 'start = "2020-06-25T07:00:10"')
    sc = tmp_path / "upload.toml"
    sc.write_text(text)
    out = tmp_path / "f"
    assert main(["generate", "--no-progress", "--scenario", str(sc), "--duration", "42",
                 "--fs", "2.5e6", "--out", str(out)]) == 0
    meta = json.loads((out / "default.json").read_text())
    switched = {s["prn"]: s["broadcast"] for s in meta["satellites"] if len(s["broadcast"]) > 1}
    assert switched, meta["satellites"]
    for recs in switched.values():
        assert recs[1]["from_s"] == pytest.approx(20.0) and recs[1]["toe"] > recs[0]["toe"]
    rx = ScalarReceiver(log=False)
    res = run_scalar(open_source(out / "default.bin"), tmp_path / "run", progress=False,
                     receiver=rx)
    taken = [p for p, recs in switched.items()
             if p in rx.ephemerides and rx.ephemerides[p].toe == recs[1]["toe"]]
    assert taken, {p: getattr(rx.ephemerides.get(p), "toe", None) for p in switched}
    acc = solution_vs_truth(res.files["pvt"], out / "default_truth.csv")
    assert acc["n_fixes"] >= 10 and acc["pos_rmse_m"] < 3.0, acc  # fixes from 38 s on
