"""``sdr-di run --mode scalar`` end to end on generated files, and its bad-input handling.

The files are generated at a low sample rate (2.5-4 MHz instead of 25 MHz) to keep the suite
fast; the full-rate figures come from ``scripts/check_scalar.py`` (closing notes).
"""

import csv
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from sdr_di.cli import main
from sdr_di.constants import LAMBDA_B3I
from sdr_di.io.solution_files import read_solution_csv
from sdr_di.orbits.rinex_nav import load_nav
from sdr_di.receiver.accuracy import solution_vs_truth
from sdr_di.receiver.loops import pll_doppler_noise_hz
from sdr_di.receiver.run_scalar import open_source, run_scalar
from sdr_di.receiver.scalar import ScalarReceiver
from sdr_di.receiver.tracking import TrackingConfig
from sdr_di.signal.fields import PARAMS

DUR = "37"  # one D1 frame (subframes 1-3 at 30-48 s would need 48 s; 18 s is enough for
            # satellites whose first subframe is caught) plus margin


def _gen(out: Path, *args) -> Path:
    assert main(["generate", "--no-progress", "--duration", DUR, "--out", str(out), *args]) == 0
    return out


@pytest.fixture(scope="module")
def complex_file(if_files):
    """The folder of a 37 s default-scenario set at 2.5 MHz (complex; the session's factory:
    shared, the run writes elsewhere)."""
    return if_files(float(DUR)).if_file.parent


def _velocity_rmse_bound(pvt_csv: Path, channels_csv: Path) -> float:
    """What the velocity RMSE of a run may reach from thermal noise [m/s].

    The velocity comes from the carrier loops' Doppler (D1 satellites: 10 ms coherent PLL
    updates at ``track_pll_bw_hz``), whose thermal noise at the weakest channel's C/N0 is
    :func:`~sdr_di.receiver.loops.pll_doppler_noise_hz` (0.022 m/s at 40 dB-Hz). Independent
    equal errors on the satellites map to the velocity's 3D RMS through PDOP (exactly with 4
    satellites, whatever the weights; the foreign file of this test, default seed, has the
    ephemerides of only 4 satellites for 90 of its 94 fixes, PDOP ~4.8): expected
    RMSE = sigma_rate x RMS(PDOP), ~0.107 m/s here, so a fixed 0.1 m/s fails about every
    other noise realization. The factor 1.3 covers the spread of an RMSE over ~90 fixes
    0.2 s apart (the Doppler noise decorrelates within ~0.05 s; relative standard deviation
    about 1/sqrt(2 x 90) = 7.5 %, so 1.3 is 4 of them); a carrier problem (a half-cycle
    jump moves one fix by ~3 m/s) or a noisier loop still exceeds it.

    Limitation: with more than 4 satellites the PVT's elevation weights are not the equal
    thermal noise's optimal ones and the RMSE exceeds sigma_rate x PDOP (other seeds of this
    file, 5-6 satellites: 1.08-1.29 times), so the bound only suits 4-satellite runs (the
    assertion below checks that it applies; the 2.5 MHz complex file has 5 satellites and
    keeps its fixed 0.1 m/s).
    """
    with open(channels_csv) as f:
        cn0 = min(float(r["cn0_dbhz"]) for r in csv.DictReader(f))
    cfg = TrackingConfig()
    sigma_rate = LAMBDA_B3I * pll_doppler_noise_hz(cn0, cfg.coherent_ms_d1 * 1e-3,
                                                   cfg.track_pll_bw_hz)
    sol = read_solution_csv(pvt_csv)
    fix = np.asarray(sol["status"]) == "fix"
    pdop = np.asarray(sol["pdop"], float)[fix]
    assert np.mean(np.asarray(sol["n_sats"], float)[fix] == 4) > 0.9, "bound for 4 satellites"
    return 1.3 * sigma_rate * float(np.sqrt(np.mean(pdop ** 2)))


def _prns(d: Path) -> list[int]:
    meta = json.loads((d / "default.json").read_text())
    return [s["prn"] for s in meta["satellites"]]


def test_scalar_run_tracks_decodes_and_fixes(complex_file, tmp_path):
    d = complex_file
    rx = ScalarReceiver(log=False)
    res = run_scalar(open_source(d / "default.bin"), tmp_path / "run", prns=_prns(d) + [1, 40],
                     progress=False, receiver=rx)
    # every simulated satellite acquired: Doppler within 100 Hz, code phase within 0.5 chip
    # of the generator's truth (at the file's first sample)
    truth = {s["prn"]: s for s in json.loads((d / "default.json").read_text())["satellites"]}
    acq = {r.prn: r for r in rx.acquisition_results}
    for p, t in truth.items():
        r = acq[p]
        dcode = (r.code_phase_chips - t["code_phase_chips"] + 5115) % 10230 - 5115
        assert r.detected and abs(r.doppler_hz - t["doppler_hz"]) < 100.0, (r, t)
        assert abs(dcode) < 0.5, (r, t)
    assert not acq[1].detected and not acq[40].detected
    # every simulated satellite tracked for the whole file (never lost), absent PRNs not
    states = {r["prn"]: r["state"] for r in res.channels}
    assert all(states.get(p) == "TRACK" for p in _prns(d)), states
    assert 1 not in states and 40 not in states
    for p in _prns(d):
        c = rx.channels[p]
        assert c.n_acquisitions == 1, c.transitions
        assert all(st.name in ("PULL_IN", "TRACK") for _, st in c.transitions), c.transitions
    # decoded ephemerides equal the RINEX records within the ICD LSB
    nav = load_nav(Path(json.loads((d / "default.json").read_text())["ephemeris_file"]))
    assert len(rx.ephemerides) >= 4
    for prn, eph in rx.ephemerides.items():
        ref = nav.select(prn, eph.week, eph.toe)
        assert ref.toe == eph.toe
        for name, p in PARAMS.items():
            if hasattr(ref, name) and name not in ("prn", "week"):
                lsb = p.lsb * (np.pi if p.semicircles else 1.0)
                assert abs(getattr(eph, name) - getattr(ref, name)) <= 0.5 * lsb + 1e-15, name
    acc = solution_vs_truth(res.files["pvt"], d / "default_truth.csv")
    assert acc["n_fixes"] > 50
    assert acc["pos_rmse_m"] < 3.0, acc
    assert acc["vel_rmse_mps"] < 0.1, acc


def test_foreign_real_int16_file_with_options(tmp_path, capsys):
    """A real-IF int16 file at another rate, read with command-line options only.

    The start time is given as a rough hint (25 s off), as a user of a recording would: it
    only lets the receiver accept the first decoded subframe instead of waiting for two.
    """
    d = _gen(tmp_path, "--fs", "4e6", "--if", "1.02e6", "--format", "real_int16", "--bits", "12")
    (d / "default.json").rename(d / "hidden.json")  # the receiver gets only the options
    rc = main(["run", str(d / "default.bin"), "--fs", "4e6", "--if", "1.02e6", "--format",
               "short", "--start-week", "755", "--start-sow", str(start_sow(d) - 25.0),
               "--out", str(d / "run"), "--no-progress", "--prn",
               ",".join(str(p) for p in _prns_from(d / "hidden.json"))])
    out = capsys.readouterr().out
    assert rc == 0, out
    acc = solution_vs_truth(d / "run" / "default_pvt.csv", d / "default_truth.csv")
    bound = _velocity_rmse_bound(d / "run" / "default_pvt.csv", d / "run" / "default_channels.csv")
    assert acc["n_fixes"] > 50 and acc["pos_rmse_m"] < 3.0, acc
    assert acc["vel_rmse_mps"] < bound, (acc, bound)


def start_sow(d: Path) -> float:
    return json.loads((d / "hidden.json").read_text())["start"]["sow"]


def _prns_from(sidecar: Path) -> list[int]:
    return [s["prn"] for s in json.loads(sidecar.read_text())["satellites"]]


def _expect(capsys, args, pattern, out_dir: Path, status: int = 2):
    rc = main(["run", *args, "--out", str(out_dir), "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == status and len(err) == 1 and err[0].startswith("sdr-di: error: "), err
    assert re.search(pattern, err[0]), err[0]
    assert not out_dir.exists() or not any(out_dir.iterdir())


def test_bad_inputs(if_files, tmp_path, capsys):
    out = tmp_path / "out"
    empty = tmp_path / "empty.bin"
    empty.write_bytes(b"")
    _expect(capsys, [str(empty), "--fs", "25e6", "--format", "ibyte"], "empty", out)
    _expect(capsys, [str(tmp_path / "none.bin")], "no such file", out)
    _expect(capsys, [str(empty), "--fs", "25e6", "--format", "int3"], "unknown sample format", out)
    # truncated: the sidecar promises more samples than the file has (the set's size record
    # catches it first: a file that is not the one the sidecar was written with)
    g = shutil.copytree(if_files(0.1).if_file.parent, tmp_path / "g")  # changed below
    data = (g / "default.bin").read_bytes()
    (g / "default.bin").write_bytes(data[: len(data) // 2])
    _expect(capsys, [str(g / "default.bin")], "shorter|truncated|not the file this sidecar",
            out)
    (g / "default.bin").write_bytes(data)
    _expect(capsys, [str(g / "default.bin"), "--prn", "C21,C77"], "C77", out)


def test_no_satellite_found(if_files, tmp_path, capsys):
    f = if_files(0.3, cn0_dbhz=0.0).if_file
    # a run without a fix: exit 1 (docs/errors.md), and no empty output folder left
    _expect(capsys, [str(f), "--prn", "C10,C27"], "no satellite found",
            tmp_path / "out", status=1)
    assert not (tmp_path / "out").exists()
