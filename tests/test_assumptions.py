"""What the filter assumes kept apart from the truth (issue 14): the assumptions file and
``[assume]``, the truth oscillator in the generated files, the separation of the two worlds,
a large heading error, bad inputs."""

import copy
import dataclasses
import json
import math
import tomllib

import numpy as np
import pytest

from sdr_di.cli import main
from sdr_di.constants import F_B3I
from sdr_di.coupling.config import IntegrationConfig
from sdr_di.integration.filter_setup import clock_model
from sdr_di.errors import AssumptionsError, ScenarioError
from sdr_di.integration.assumptions import (
    apply_to_deep,
    apply_to_lc,
    deep_beliefs,
    parse_assumptions,
    resolve_assumptions,
)
from sdr_di.integration.loose import LcSettings, run_loose
from sdr_di.sim.lc_inputs import make_inputs
from sdr_di.io.imu_files import read_truth
from sdr_di.scenario import DEFAULT_SCENARIO
from sdr_di.scenario.schema import parse_scenario
from sdr_di.sim.generate import generate_files, make_generator, simulate_truth

FULL = {
    "imu": {"grade": "tactical", "gyro_bias_deg_h": 2.0, "bias_time_s": 600.0},
    "oscillator": {"preset": "ocxo"},
    "measurement_noise": {"policy": "fixed", "sigma_range_m": 3.0, "sigma_rate_mps": 0.2},
    "initial_covariance": {"att_deg": [1.0, 1.0, 25.0], "clock_drift_mps": 0.5},
    "initial_errors": {"att_deg": [0.0, 0.0, 20.0], "pos_m": [3.0, -2.0, 5.0]},
}


def _raw(**tables):
    raw = tomllib.loads(DEFAULT_SCENARIO.read_text())
    raw.update(copy.deepcopy(tables))
    return raw


def _scenario(raw, duration=0.02, fs=2.5e6):
    sc = parse_scenario(raw, source=DEFAULT_SCENARIO, base_dir=DEFAULT_SCENARIO.parent)
    return sc.with_overrides(duration_s=duration, sampling_rate_hz=fs)


# -- the assumptions mapping ------------------------------------------------------------------
def test_apply_to_deep_sets_every_belief():
    a = parse_assumptions(FULL, "a.toml")
    assert a.changes_q
    cfg = apply_to_deep(IntegrationConfig(), a)
    assert cfg.imu.gyro_bias_deg_h == 2.0 and cfg.imu.accel_bias_mg == 1.0  # tactical grade
    assert cfg.bias_time_s == 600.0 and cfg.clock.preset == "ocxo"
    assert (cfg.noise_policy, cfg.sigma_range_m, cfg.sigma_rate_mps) == ("fixed", 3.0, 0.2)
    assert cfg.init_att_err_deg == (0.0, 0.0, 20.0) and cfg.p0_att_deg == (1.0, 1.0, 25.0)
    assert cfg.p0_pos_m == (3.0, 2.0, 5.0) and cfg.p0_clock == (None, 0.5)
    # the clock Q follows the assumed oscillator (mapped flicker), not the default TCXO
    assert not np.allclose(clock_model(cfg.clock).Q(0.02), clock_model("tcxo").Q(0.02))
    rec = deep_beliefs(cfg)
    json.dumps(rec)
    assert rec["given"]["source"] == "a.toml" and rec["oscillator"]["preset"] == "ocxo"
    # an injected error without a P0 is believed: the sigma is at least the error
    cfg2 = apply_to_deep(IntegrationConfig(), parse_assumptions(
        {"initial_errors": {"att_deg": [0, 0, -15]}}, "b"))
    assert cfg2.p0_att_deg == (0.05, 0.05, 15.0)


def test_apply_to_lc_overrides_lc_keys():
    a = parse_assumptions({k: v for k, v in FULL.items() if k not in (
        "oscillator", "measurement_noise")} | {"initial_covariance": {"att_deg": [1, 1, 25]},
                                               "measurement_noise": {
        "policy": "fixed", "sigma_pos_h_m": 4.0, "sigma_pos_v_m": 6.0, "sigma_vel_mps": 0.1}},
        "a.toml")
    st, imu = apply_to_lc(LcSettings(init_att_err_arcmin=(3, 3, 10)), a)
    assert st.init_att_err_arcmin == (0.0, 0.0, 1200.0) and st.p0_sigma_att_arcmin[2] == 1500
    assert st.assumed_r_sigmas == (4.0, 6.0, 0.1) and st.bias_time_s == 600.0
    assert imu.gyro_bias_deg_h == 2.0


@pytest.mark.parametrize(("raw", "match"), [
    ({"imu": {"grade": "gimbal"}}, r"a\.toml \[imu\]\.grade: unknown IMU grade 'gimbal'"),
    ({"imu": {"gyro_misalignment_mrad": 1}}, (r"\[imu\]\.gyro_misalignment_mrad: not an "
                                             r"assumption \(the filter has no state for it")),
    ({"imu": {"gyro_bias_tau_s": 0}}, r"\[imu\]\.gyro_bias_tau_s: must be > 0"),
    ({"oscillator": {"preset": "rubidium"}}, (r"\[oscillator\]\.preset: unknown oscillator "
                                             r"preset 'rubidium'")),
    ({"oscillator": {"preset": "tcxo", "h_2": -1e-20}}, (r"\[oscillator\]\.h_2: h-parameters "
                                                        r"must be >= 0")),
    ({"oscillator": {"g_sensitivity_per_g": [1e-9, 0, 0]}}, (r"g_sensitivity_per_g: not an "
                                                             r"assumption")),
    ({"filter": {"name": "ekf"}}, r"unknown table\(s\) 'filter'"),
    ({"initial_errors": {"heading_deg": 20}}, r"\[initial_errors\]: unknown key 'heading_deg'"),
    ({"initial_covariance": {"vel_mps": [0.1, -0.1, 0.1]}}, (r"\[initial_covariance\]\.vel_mps"
                                                           r": standard deviations")),
    ({"measurement_noise": {"policy": "fixed"}}, r"policy 'fixed' needs"),
])
def test_bad_assumptions_name_the_key(raw, match):
    with pytest.raises(AssumptionsError, match=match):
        parse_assumptions(raw, "a.toml")


def test_cli_bad_inputs_are_one_line_errors(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text('[oscillator]\npreset = "tcxo"\nh0 = -2e-19\n')
    assert main(["lc", "--duration", "1", "--assume", str(bad), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "[oscillator].h0: h-parameters must be >= 0" in err
    good = tmp_path / "osc.toml"
    good.write_text('[oscillator]\npreset = "ocxo"\n')
    # lc has no clock measurement: an assumed oscillator is refused, naming the table
    assert main(["lc", "--duration", "1", "--assume", str(good), "--out", str(tmp_path)]) == 2
    assert "[oscillator]: lc has no clock measurement" in capsys.readouterr().err
    # a command that cannot use assumptions: scalar run, generate
    (tmp_path / "x.bin").write_bytes(b"\0" * 100)
    assert main(["run", str(tmp_path / "x.bin"), "--fs", "2.5e6", "--assume", str(good)]) == 2
    assert "--assume" in capsys.readouterr().err
    assert main(["generate", "--assume", str(good)]) == 2
    assert "unrecognized arguments: --assume" in capsys.readouterr().err
    assert not list(tmp_path.glob("*lc*"))


def test_scenario_assume_table_and_file_precedence(tmp_path):
    sc = _scenario(_raw(assume={"initial_errors": {"att_deg": [0, 0, 10]}}))
    assert resolve_assumptions(sc).init_errors["att_deg"] == (0.0, 0.0, 10.0)
    f = tmp_path / "a.toml"
    f.write_text("[initial_errors]\natt_deg = [0, 0, 30]\n")
    a = resolve_assumptions(sc, f)  # the file replaces the table as a whole
    assert a.init_errors["att_deg"] == (0.0, 0.0, 30.0) and a.source == str(f)
    with pytest.raises(AssumptionsError, match=r"\[assume\] \[imu\]: unknown key 'x'"):
        resolve_assumptions(_scenario(_raw(assume={"imu": {"x": 1}})))
    with pytest.raises(ScenarioError, match=r"\[assume\] must be a table"):
        _scenario(_raw(assume=3))


# -- separation of the two worlds --------------------------------------------------------------
def _files(sc, d):
    paths = generate_files(sc, d, progress=False)
    return {k: p.read_bytes() for k, p in paths.items()}


def test_assumptions_alone_change_no_generated_file(tmp_path):
    base = _files(_scenario(_raw()), tmp_path / "a")
    other = _files(_scenario(_raw(assume=FULL)), tmp_path / "b")
    assert base == other  # IF, IMU, truth and sidecar (hash included) byte-identical
    assert _scenario(_raw()).hash == _scenario(_raw(assume=FULL)).hash


def test_truth_imu_alone_changes_the_imu_file_not_the_filter_q(tmp_path):
    base = _files(_scenario(_raw()), tmp_path / "a")
    raw = _raw()
    raw["imu"] = {"grade": "tactical"}
    other = _files(_scenario(raw), tmp_path / "b")
    assert base["imu"] != other["imu"] and base["if"] == other["if"]
    # the filter's Q: the same assumptions over both truths give the same Q; other
    # assumptions over the same truth another Q (lc: the Q each predict used)
    a = parse_assumptions({"imu": {"grade": "mems"}}, "a")
    a2 = parse_assumptions({"imu": {"grade": "navigation"}}, "a2")
    q = []
    for r, asm in ((_raw(), a), (raw, a), (_raw(), a2)):
        sc = _scenario(r, duration=3.0)
        truth, imu, _ = make_inputs(sc)
        st, filter_imu = apply_to_lc(LcSettings(), asm)
        q.append((run_loose(truth, imu, filter_imu, st, seed=1).q_diag, imu.f_b))
    np.testing.assert_array_equal(q[0][0], q[1][0])
    assert not np.array_equal(q[0][1], q[1][1])          # the IMU data differ
    assert not np.allclose(q[0][0], q[2][0])              # other beliefs, other Q


# -- the truth oscillator in the generator -----------------------------------------------------
def test_oscillator_moves_carrier_and_code_and_is_in_the_truth_file(tmp_path):
    osc = {"preset": "tcxo", "g_sensitivity_per_g": [0.0, 2e-9, 1e-9]}
    sc0 = _scenario(_raw(), duration=0.2)
    sc1 = _scenario(_raw(oscillator=osc), duration=0.2)
    assert sc0.hash != sc1.hash  # the oscillator is truth: part of the generated set's identity
    truth = simulate_truth(sc1)
    g0, g1 = make_generator(sc0, truth), make_generator(sc1, truth)
    assert g0.clock_truth is None and g1.clock_truth is not None
    j = np.arange(0, 200, 10, dtype=float)
    s, t, b = g1.node_times(j)
    np.testing.assert_allclose(s - t, b, rtol=0, atol=1e-15)       # receiver = true + bias
    _, _, b0 = g0.node_times(j)
    db = b - b0
    assert np.abs(db).max() > 1e-11   # g-sensitivity alone: 1e-9 x 1 g x 0.2 s = 2e-10 s
    st0, st1 = g0.node_state(0, 199), g1.node_state(0, 199)
    # carrier phase moves by -f_B3I db, code phase by -10.23e6 db chips (node 100)
    _, _, bb = g1.node_times(np.array([100.0]))
    _, _, bb0 = g0.node_times(np.array([100.0]))
    dph = (st1["ph0"][:, 100] - st0["ph0"][:, 100] + 0.5) % 1.0 - 0.5
    expect = (-F_B3I * (bb - bb0)[0] + 0.5) % 1.0 - 0.5
    np.testing.assert_allclose(dph, expect, atol=2e-3)
    dchip = st1["chip0"][:, 100] - st0["chip0"][:, 100]
    np.testing.assert_allclose(dchip, -10.23e6 * (bb - bb0)[0], atol=1e-6)
    paths = generate_files(sc1, tmp_path, progress=False)
    tr, _, _ = read_truth(paths["truth"])
    np.testing.assert_allclose(tr.clock_bias_s, g1.clock_truth.bias_s, rtol=0, atol=1e-20)
    meta = json.loads(paths["metadata"].read_text())
    assert meta["oscillator"]["preset"] == "tcxo" and "assume" not in json.dumps(meta)


# -- a large heading error: the nonlinear model matters ----------------------------------------
def _heading_errors(name, heading_deg, sc, truth, imu, model):
    st = dataclasses.replace(LcSettings(filter=name), init_att_err_arcmin=(
        0.0, 0.0, heading_deg * 60), p0_sigma_att_arcmin=(60.0, 60.0, max(
        abs(heading_deg), 1.0) * 60))
    return run_loose(truth, imu, model, st, seed=sc.seed).att_err[:, 2]


def test_large_heading_error_separates_ekf_and_ukf():
    sc = _scenario(_raw(), duration=12.0)
    truth, imu, model = make_inputs(sc)
    big = [_heading_errors(f, 20.0, sc, truth, imu, model) for f in ("ekf", "ukf")]
    small = [_heading_errors(f, 0.5, sc, truth, imu, model) for f in ("ekf", "ukf")]
    d_big = np.abs(big[0] - big[1]).max()
    d_small = np.abs(small[0] - small[1]).max()
    assert d_big > 0.2                 # deg: the linearization error of the EKF shows
    assert d_small < 0.05 * d_big      # and it is a large-angle effect
    assert math.isfinite(d_big)


# -- deep mode end to end ----------------------------------------------------------------------
@pytest.mark.slow
def test_deep_run_with_assumptions_records_both_worlds(tmp_path, capsys):
    """``run --mode deep --assume``: a 20 deg heading error injected at the alignment shows
    in the first rows and is pulled in; fixed R; the summary holds the truth (oscillator from
    the sidecar) and the assumptions."""
    sc = _scenario(_raw(oscillator={"preset": "tcxo"}), duration=20.0)
    paths = generate_files(sc, tmp_path / "gen", progress=False)
    f = tmp_path / "a.toml"
    f.write_text("[initial_errors]\natt_deg = [0.0, 0.0, 20.0]\n"
                 "[measurement_noise]\npolicy = \"fixed\"\nsigma_range_m = 2.0\n"
                 "sigma_rate_mps = 0.1\n[oscillator]\npreset = \"ocxo\"\n")
    out = tmp_path / "run"
    rc = main(["run", str(paths["if"]), "--mode", "deep", "--filter", "ukf", "--assume",
               str(f), "--no-progress", "--out", str(out)])
    assert rc == 0, capsys.readouterr()
    summ = json.loads((out / "default_deep_ukf_summary.json").read_text())
    assert summ["truth"]["oscillator"]["preset"] == "tcxo"
    a = summ["assumptions"]
    assert a["oscillator"]["preset"] == "ocxo" and a["given"]["source"] == str(f)
    assert a["initial_errors"]["att_deg"] == [0.0, 0.0, 20.0]
    assert a["initial_covariance"]["att_deg"][2] == 20.0
    assert a["measurement_noise"] == {"policy": "fixed", "sigma_range_m": 2.0,
                                      "sigma_rate_mps": 0.1}
    rows = np.genfromtxt(out / "default_deep_ukf.csv", delimiter=",", names=True, skip_header=1)
    head = np.abs(rows["att_err_u_deg"])
    assert head[0] > 5.0               # the injected error is there after the first update
    assert head[-1] < 0.5 * head[0]    # and the filter pulls it in


def test_fixed_noise_source_replaces_r_only():
    from sdr_di.integration.assumptions import FixedNoiseSource
    from sdr_di.integration.loop import Measurements

    class Stub:
        n_channels = 3

        def measure(self, loop, iv):
            return Measurements(z=np.arange(6.0), R=np.eye(6) * 7.0, geometry=(1, 2),
                                used=np.ones(3, bool))

        measure_launched = measure        # deep with the NCOs one interval ahead

    src = FixedNoiseSource(Stub(), 2.0, 0.1)
    for m in (src.measure(None, None), src.measure_launched(None, None)):
        np.testing.assert_allclose(np.diag(m.R), [4.0] * 3 + [0.01] * 3, rtol=1e-12)
        np.testing.assert_array_equal(m.z, np.arange(6.0))
        assert src.n_channels == 3 and m.geometry == (1, 2)
