"""A run that cannot be right says so; messages name what the user typed; no leftovers
(issue 28 items 1-3).

Small files only: one 1 s, 2.5 MHz generated set shared by the module (``short_set``).
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest

from sdr_di.cli import main


@pytest.fixture(scope="module")
def short_set(if_files) -> Path:
    """A 1 s generated set at 2.5 MHz (iq_int8): ``s.bin`` with its sidecar and companions
    (the session's factory; the tests copy a file before they change it)."""
    return if_files(1.0, name="s").if_file.parent


def _run(capsys, argv: list[str]) -> tuple[int, list[str]]:
    rc = main(argv)
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    return rc, err


# -- item 3: no leftovers --------------------------------------------------------------------

def test_failed_deep_run_leaves_no_folder_and_says_what_length_it_needs(short_set, tmp_path,
                                                                       capsys):
    out = tmp_path / "a" / "run"          # two levels that do not exist yet
    rc, err = _run(capsys, ["run", str(short_set / "s.bin"), "--mode", "deep",
                            "--no-progress", "--out", str(out)])
    assert rc == 1 and len(err) == 1 and err[0].startswith("sdr-di: error: "), err
    assert "no hand-over" in err[0] and "too short for the hand-over" in err[0], err[0]
    m = re.search(r"needs about (\d+) s", err[0])
    assert m and int(m.group(1)) == 12, err[0]      # two D1 subframes of 6 s
    assert not (tmp_path / "a").exists()


# -- item 1: flags against the sidecar --------------------------------------------------------

def test_flags_that_contradict_the_sidecar_are_exit_2_naming_both(short_set, tmp_path, capsys):
    out = tmp_path / "o"
    rc, err = _run(capsys, ["run", str(short_set / "s.bin"), "--fs", "2.5e6", "--if", "0",
                            "--format", "real_int8", "--no-progress", "--out", str(out)])
    assert rc == 2 and len(err) == 1 and err[0].startswith("sdr-di: error: "), err
    assert "--format real_int8" in err[0] and "the sidecar iq_int8" in err[0], err[0]
    assert "--ignore-sidecar" in err[0] and not out.exists()
    rc, err = _run(capsys, ["acquire", str(short_set / "s.bin"), "--fs", "5e6", "--format",
                            "iq_int8", "--out", str(out)])
    assert rc == 2 and "--fs 5e+06 Hz, the sidecar 2.5e+06 Hz" in err[0], err


def test_ignore_sidecar_lets_contradicting_flags_through(short_set, tmp_path, capsys):
    rc, err = _run(capsys, ["acquire", str(short_set / "s.bin"), "--fs", "2.5e6", "--if", "0",
                            "--format", "real_int8", "--ignore-sidecar", "--noncoherent", "10",
                            "--out", str(tmp_path / "a")])
    assert rc == 0, err
    assert (tmp_path / "a" / "s_acquisition.csv").is_file()
    # what it finds is no satellites: one warning line says so (item 1, acquire)
    assert len(err) == 1 and err[0].startswith("sdr-di: warning: ") and \
        "at 0 Hz Doppler" in err[0] and "the sample format (--format)" in err[0], err


def test_truncated_file_with_flags_is_caught_by_its_sidecar(short_set, tmp_path, capsys):
    d = tmp_path / "t"
    d.mkdir()
    shutil.copy(short_set / "s.json", d / "s.json")
    (d / "s.bin").write_bytes((short_set / "s.bin").read_bytes()[:100_000])
    rc, err = _run(capsys, ["run", str(d / "s.bin"), "--fs", "2.5e6", "--format", "iq_int8",
                            "--no-progress", "--out", str(tmp_path / "o")])
    assert rc == 2 and "100000 bytes, the sidecar records" in err[0], err


def test_format_check_message_names_the_cli_switch(short_set, tmp_path, capsys):
    f = tmp_path / "foreign.bin"
    shutil.copy(short_set / "s.bin", f)
    argv = ["acquire", str(f), "--fs", "2.5e6", "--format", "iq_int16", "--noncoherent", "10",
            "--out", str(tmp_path / "a")]
    rc, err = _run(capsys, argv)
    assert rc == 2 and len(err) == 1, err
    assert err[0].endswith("(--no-format-check reads it anyway)") and "check_format" not in \
        err[0], err[0]
    assert main([*argv, "--no-format-check"]) == 0


# -- item 2: messages name what the user typed -------------------------------------------------

@pytest.mark.parametrize("flags,expected", [
    (["--fs", "4.5e6", "--if", "20e6", "--format", "real_int16"], "--if: must be <= 2.25e+06"),
    (["--cn0", "-500"], "--cn0: must be >= 0, got -500"),
    (["--bits", "20"], "--bits: must be in [1, 16], got 20"),
    (["--duration", "-5"], "--duration: must be > 0, got -5"),
    (["--prn", "C99"], "--prn: unknown BDS PRN"),
    (["--format", "real_int16"], "--format: real samples need an IF > 0: give --if"),
])
def test_generate_flag_errors_name_the_flag(tmp_path, capsys, flags, expected):
    rc, err = _run(capsys, ["generate", "--no-progress", "--duration", "0.02", *flags,
                            "--out", str(tmp_path / "o")])
    assert rc == 2 and len(err) == 1, err
    assert err[0].startswith(f"sdr-di: error: {expected}"), err[0]
    assert "default.toml: [" not in err[0] and not (tmp_path / "o").exists()


def test_warnings_are_one_line(short_set, tmp_path, capsys):
    f = tmp_path / "odd.bin"
    f.write_bytes((short_set / "s.bin").read_bytes()[:200_001])    # a partial sample at the end
    rc, err = _run(capsys, ["acquire", str(f), "--fs", "2.5e6", "--format", "iq_int8",
                            "--noncoherent", "10", "--out", str(tmp_path / "a")])
    assert rc == 0, err
    assert err == [f"sdr-di: warning: IF file {f}: size 200001 bytes is not a whole number of "
                   "iq_int8 samples (2 bytes each); ignoring the 1 trailing byte(s) of a "
                   "partial sample"], err


# -- item 1: detections real signals cannot give; a run without a fix -------------------------

def _res(prn: int, doppler_hz: float, detected: bool = True):
    from sdr_di.receiver.acquisition import AcquisitionResult

    return AcquisitionResult(prn=prn, detected=detected, code_phase_chips=0.0,
                             code_phase_samples=0.0, doppler_hz=doppler_hz,
                             doppler_coarse_hz=doppler_hz, cn0_dbhz=40.0, peak_metric=100.0,
                             threshold=60.0, pfa=1e-3, noise_power=1.0, doppler_refined=True)


def test_implausible_detections_patterns():
    from sdr_di.receiver.acquisition import MAX_IN_VIEW, implausible_detections

    real = [_res(8, -77.7), _res(10, -1032.0), _res(13, 141.9), _res(27, 71.8),
            _res(28, -1697.6), _res(30, 1858.7), _res(32, 2532.4)]
    assert implausible_detections(real) == (None, [])
    # GEOs share a Doppler near zero: plausible
    assert implausible_detections([*real, _res(1, 0.2), _res(2, -0.1), _res(3, 0.3),
                                   _res(4, 5.0)])[0] is None
    problem, prns = implausible_detections([*real, _res(14, 0.0), _res(15, -0.0),
                                            _res(17, 0.4)])
    assert "3 PRNs that are not GEOs detected at 0 Hz" in problem and prns == []
    problem, prns = implausible_detections(
        [_res(p, 1000.0 + 97.0 * p) for p in range(6, 6 + MAX_IN_VIEW + 1)])
    assert f"{MAX_IN_VIEW + 1} PRNs detected" in problem and prns == []
    problem, prns = implausible_detections([*real, _res(14, 512.0), _res(15, 515.0),
                                            _res(17, 518.0), _res(19, 509.0),
                                            _res(20, 515.0, detected=False)])
    assert "4 PRNs that are not GEOs detected within 10 Hz" in problem
    assert prns == [14, 15, 17, 19]
    assert implausible_detections([*real, _res(14, 512.0), _res(15, 515.0),
                                   _res(17, 520.0)])[0] is None        # three: can happen


def test_wrong_format_run_stops_with_a_diagnosis(short_set, tmp_path, capsys):
    """The issue's case: an iq_int8 file read as real_int8 (its sidecar ignored). Before:
    exit 0 after tracking the whole file, channels at exactly 0 Hz, 0 epochs with a fix."""
    out = tmp_path / "o"
    rc, err = _run(capsys, ["run", str(short_set / "s.bin"), "--fs", "2.5e6", "--if", "0",
                            "--format", "real_int8", "--ignore-sidecar", "--no-progress",
                            "--out", str(out)])
    assert rc == 1 and len(err) == 1 and err[0].startswith("sdr-di: error: "), err
    assert "at 0 Hz Doppler" in err[0] and "the sample format (--format)" in err[0], err[0]
    assert not out.exists()


def test_study_cell_with_an_unknown_scenario_key_is_refused_before_any_run(tmp_path, capsys):
    spec = tmp_path / "typo.toml"
    spec.write_text('[study]\nname = "t"\nfilters = ["ekf", "ff-aukf"]\nruns = 1\n'
                    '[base]\nduration_s = 4.0\n[[cells]]\nname = "baseline"\n'
                    '[[cells]]\nname = "imu-typo"\n'
                    'truth = { "imu.accel_random_walk_mps_sqrthz" = 0.5 }\n')
    out = tmp_path / "st"
    rc, err = _run(capsys, ["study", str(spec), "--out", str(out)])
    assert rc == 2 and len(err) == 1, err
    assert err[0].startswith(f"sdr-di: error: study {spec}: cell 'imu-typo': truth [imu]: "
                             "unknown key(s) 'accel_random_walk_mps_sqrthz'"), err[0]
    assert not out.exists()           # no run of the good cell either


def test_scalar_run_without_a_fix_is_exit_1_with_the_likely_causes(short_set, tmp_path,
                                                                   capsys):
    """1 s of signal: satellites tracked, no navigation data, no fix. Before: exit 0."""
    out = tmp_path / "o"
    rc, err = _run(capsys, ["run", str(short_set / "s.bin"), "--no-progress", "--out",
                            str(out)])
    assert rc == 1 and len(err) == 1 and err[0].startswith("sdr-di: error: no fix in "), err
    causes = ["the sample format", "the IF sign", "the sample rate", "the start time"]
    at = [err[0].index(c) for c in causes]
    assert at == sorted(at), err[0]                       # in that order
    assert (out / "s_pvt.csv").is_file() and (out / "s_channels.csv").is_file()  # kept
