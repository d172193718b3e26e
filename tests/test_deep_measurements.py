"""Deep mode's measurement architectures (issue 45): the cascaded pre-filters
(``prefilter``), pre-filters with an information reset (``reset``) and the discriminator
outputs (``discriminator``): choice from the CLI, a study spec and the configuration, their
kernels against plain references, the whiteness criterion of the default, and a GEO channel
in the vector loop of each."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from sdr_di.cli import _DEEP_MEASUREMENTS, main
from sdr_di.constants import CHIP_RATE_B3I, F_B3I
from sdr_di.deep._numba_discriminators import interval_discriminators
from sdr_di.deep.architectures import block_ms, make_measurement_bank
from sdr_di.deep.discriminators import DiscriminatorBank, interval_discriminators_numpy
from sdr_di.deep.prefilter import PreFilterBank, ResetPreFilterBank
from sdr_di.experiments.measurement_errors import (meets_criterion, simulate_open_loop,
                                                   whiteness_figures)
from sdr_di.coupling.config import DEEP_MEASUREMENTS, IntegrationConfig

BETA = CHIP_RATE_B3I / F_B3I


def test_cli_choices_are_the_configuration_s_architectures():
    assert _DEEP_MEASUREMENTS == DEEP_MEASUREMENTS


def test_configuration_refuses_settings_that_do_not_fit():
    assert IntegrationConfig().deep_measurements == "prefilter"
    assert IntegrationConfig(deep_measurements="reset").fusion_intervals == 10
    assert IntegrationConfig(deep_measurements="reset", fusion_rate_hz=50.0).fusion_intervals == 1
    assert IntegrationConfig(deep_measurements="discriminator").fusion_intervals == 1
    for kw, msg in (({"deep_measurements": "centralised"}, "must be one of"),
                    ({"fusion_rate_hz": 5.0}, "needs deep_measurements 'reset'"),
                    ({"deep_measurements": "reset", "fusion_rate_hz": 7.0}, "divided by a whole"),
                    ({"deep_measurements": "reset", "nco_latency": 1}, "nco_latency"),
                    ({"mode": "tight", "deep_measurements": "reset"}, "deep mode only"),
                    ({"mode": "loose", "fusion_rate_hz": 5.0}, "deep mode only")):
        with pytest.raises(ValueError, match=msg):
            IntegrationConfig(**kw)
    # reset and discriminator fused every interval cut at most half an interval
    assert block_ms("prefilter", 20, 50.0) == 20
    assert block_ms("discriminator", 20, 50.0) == 10
    assert block_ms("discriminator", 20, 100.0) == 5
    assert block_ms("reset", 20, 50.0, 10) == 20
    with pytest.raises(ValueError, match="do not apply"):
        make_measurement_bank("discriminator", 2, 0.5, F_B3I, None, {"s_f": 1.0})


@pytest.mark.parametrize("m", [1, 2, 3, 10])
def test_discriminator_kernel_equals_the_numpy_reference(m):
    rng = np.random.default_rng(m)
    E, P, L = (rng.normal(size=m) + 1j * rng.normal(size=m) + 3.0 for _ in range(3))
    t = rng.uniform(1e-3, 1e-2, m)
    r_tau, r_phi = rng.uniform(1e-4, 1e-2, m), rng.uniform(1e-3, 0.1, m)
    got = interval_discriminators(E, P, L, t, 0.5, r_tau, r_phi, 1e4)
    ref = interval_discriminators_numpy(E, P, L, t, 0.5, r_tau, r_phi, 1e4)
    np.testing.assert_allclose(got, ref, rtol=1e-10, atol=1e-12)


def _blocks(tau: float, f: float, T: np.ndarray, phi0: float = 0.3, bits=None):
    """Noise-free E, P, L of contiguous blocks (triangle correlation, d = 0.5)."""
    t0 = np.concatenate([[0.0], np.cumsum(T)[:-1]])
    tc = t0 + T / 2
    amp = T * 1e3 * (1.0 if bits is None else np.asarray(bits))
    tau_c = tau + BETA * f * tc
    ph = amp * np.exp(1j * (phi0 + 2 * math.pi * f * tc))
    return [ph * np.maximum(1 - np.abs(tau_c - o), 0.0) for o in (0.5, 0.0, -0.5)]


def test_discriminators_measure_code_and_frequency_through_bit_flips():
    """Noise-free blocks with a code offset, a frequency error and data-bit sign changes:
    the code at the blocks' weighted centre and the frequency (phase slope modulo pi)."""
    T = np.array([0.007, 0.010, 0.003])
    bank = DiscriminatorBank(1)
    E, P, L = _blocks(0.05, 3.0, T, bits=[1, -1, -1])
    bank.process(0, E, P, L, T, 1e4)
    dtau, df, v_tau, v_f = bank.outputs(0)
    assert df == pytest.approx(3.0, abs=1e-9)
    assert dtau == pytest.approx(0.05 + BETA * 3.0 * 0.01, abs=2e-4)
    assert v_tau == pytest.approx(0.5 / (2 * 1e4 * T.sum()), rel=0.1)   # d / (2 C/N0 T)
    assert 0 < v_f < 10.0
    bank.shift(0, 0.01, 1.0)                     # NCOs moved after the correlations
    assert bank.outputs(0)[:2] == pytest.approx((dtau - 0.01, 2.0))
    bank.process(0, E[:1], P[:1], L[:1], T[:1], 1e4)     # one block: no frequency
    assert bank.outputs(0)[3] == pytest.approx(100.0 ** 2) and bank.nis_p[0] == 1.0


def test_reset_outputs_only_the_window_s_information():
    """The reset bank's output is the window's equivalent measurement: the same whatever
    prior it was restarted from (its information is taken out again), while the cascade's
    output depends on what it carried."""
    rng = np.random.default_rng(5)
    T = np.full(20, 0.01)
    E, P, L = _blocks(0.02, 0.4, T)
    noise = [0.3 * (rng.normal(size=T.size) + 1j * rng.normal(size=T.size)) for _ in range(3)]
    E, P, L = (a + n for a, n in zip((E, P, L), noise))
    outs = []
    for prior_mean, prior in ((0.0, (0.05, 0.5)), (0.3, (0.02, 0.2)), (-0.2, None)):
        bank = ResetPreFilterBank(1)
        bank.x[0] = (0.01, 0.0, prior_mean)
        bank.decorrelate(0, prior=prior)
        for k in range(2):                       # two 100 ms intervals of one window
            bank.process(0, E[10 * k:10 * k + 10], P[10 * k:10 * k + 10],
                         L[10 * k:10 * k + 10], T[:10], 1e4)
        outs.append(bank.outputs(0))
    outs = np.array(outs)
    sd = np.sqrt(outs[0, 2:])
    assert np.all(np.abs(outs[:, :2] - outs[0, :2]) < 0.05 * sd), outs
    assert np.allclose(outs[:, 2:], outs[0, 2:], rtol=0.02)
    # over one 20 ms interval the same holds for the reset bank, while the cascade carries
    # what it had into its output
    for cls in (ResetPreFilterBank, PreFilterBank):
        out = []
        for prior_mean in (0.0, 0.3):
            bank = cls(1)
            bank.reset(0, dtau=0.01, df=prior_mean, sigma_f=0.2)
            bank.process(0, E[:2], P[:2], L[:2], T[:2], 1e4)
            out.append(bank.outputs(0))
        moved = abs(out[1][1] - out[0][1]) / math.sqrt(out[0][3])
        assert (moved > 0.5) if cls is PreFilterBank else (moved < 0.05), (cls, out)


def test_reset_measurements_are_white_and_the_cascade_s_rates_are_not():
    """Issue 45 item 2's criterion (|lag 1| <= 0.15, the per-term mean square of sums of 25
    normalized errors within [0.7, 1.4]), code and rate, at 40 and 30 dB-Hz, open loop:
    met by the information-reset pre-filters, not by the cascade's rates (whose consecutive
    errors cancel: sums of 25 about 0.27 at 40 dB-Hz). (The discriminators' rates at
    30 dB-Hz are at the edge, 1.32-1.40: their short blocks at bit edges understate the
    phase noise by about 20 %; docs/deep.md.)"""
    for cn0 in (40.0, 30.0):
        r = simulate_open_loop("reset", cn0, channels=50, fusions=100, seed=3)
        for name, e in (("code", r.code), ("rate", r.rate)):
            f = whiteness_figures(e)
            assert meets_criterion(f), (cn0, name, f)
        r = simulate_open_loop("prefilter", cn0, channels=50, fusions=200, seed=3)
        f = whiteness_figures(r.rate)
        assert not meets_criterion(f), (cn0, f)
        assert f["sum25"] < 0.7


@pytest.fixture(scope="module")
def geo_file(if_files):
    """The folder of 20 s at 2.5 MHz of the default scenario with the GEO satellite C05 (D2,
    2 ms bits) in place of C32 (``g.bin``...; the session's factory: the runs write
    elsewhere)."""
    return if_files(20.0, name="g",
                    prns=("C05", "C08", "C10", "C13", "C27", "C28", "C30")).if_file.parent


def test_each_architecture_tracks_a_geo_channel_in_the_vector_loop(geo_file, tmp_path,
                                                                   capsys):
    """``run --mode deep --deep-measurements A`` (``reset`` through ``sdr_di.run``) on a
    file with a GEO satellite: the
    architecture is in the summary (and named in the solution's header unless it is the
    cascade), every channel, C05 included, stays in the measurement vector, and the errors
    against the truth stay small (measured: position 0.65-0.67 m, velocity 0.008 (cascade),
    0.011 (reset) and 0.086 m/s (discriminator))."""
    import sdr_di

    for arch, vel_max in (("prefilter", 0.03), ("reset", 0.03), ("discriminator", 0.2)):
        out = tmp_path / f"run_{arch}"
        if arch == "reset":             # the API door
            res = sdr_di.run(geo_file / "g.bin", mode="deep", deep_measurements=arch, out=out)
            assert res.details.result.deep_measurements == arch
        else:
            rc = main(["run", str(geo_file / "g.bin"), "--mode", "deep", "--no-progress",
                       "--deep-measurements", arch, "--out", str(out)])
            assert rc == 0, capsys.readouterr().out
        s = json.loads((out / "g_deep_summary.json").read_text())
        assert s["deep_measurements"] == arch
        assert s["fusion_rate_hz"] == (5.0 if arch == "reset" else 50.0)
        assert 5 in s["prns"] and s["channels_always_used"] is True
        assert s["metrics"]["pos_m_rmse"] < 1.5 and s["metrics"]["vel_mps_rmse"] < vel_max
        head = (out / "g_deep.csv").read_text().splitlines()[0]
        assert ("measurements" in head) == (arch != "prefilter"), head


def test_a_geo_channel_is_tracked_and_used_in_scalar_and_tight(geo_file, tmp_path, capsys):
    """Issue 46 item 3 beside the deep test above: on the same file the scalar receiver
    tracks C05 (D2, 2 ms bits), writes its observations and fixes with all seven
    satellites, and tight mode keeps C05's range and rate in its measurement vector on
    every update (measured: 39 of 99 scalar epochs with 7 satellites; tight position RMSE
    0.70 m, velocity 0.017 m/s)."""
    out = tmp_path / "scalar"
    assert main(["run", str(geo_file / "g.bin"), "--no-progress", "--out", str(out)]) == 0
    obs = (out / "g_obs.rnx").read_text()
    assert "C05 " in obs.split("END OF HEADER")[1], "no C05 observation"
    rows = [ln.split(",") for ln in (out / "g_pvt.csv").read_text().splitlines()
            if ln and not ln.startswith("#")]
    n_sats = [int(r[rows[0].index("n_sats")]) for r in rows[1:]]
    assert n_sats.count(7) >= 20, n_sats
    out = tmp_path / "tight"
    assert main(["run", str(geo_file / "g.bin"), "--mode", "tight", "--no-progress",
                 "--out", str(out)]) == 0
    s = json.loads((out / "g_tight_summary.json").read_text())
    assert 5 in s["prns"] and s["used_fraction"][s["prns"].index(5)] == 1.0, s["prns"]
    assert s["metrics"]["pos_m_rmse"] < 1.5 and s["metrics"]["vel_mps_rmse"] < 0.05
    capsys.readouterr()


def test_architecture_is_a_study_factor():
    """A study spec crosses cells with ``deep_measurements`` (the experiment parameter the
    run hands to the receiver); a value that is not an architecture is refused."""
    from sdr_di.errors import StudyError
    from sdr_di.studies.spec import parse_study

    raw = {"study": {"name": "arch", "filters": ["ekf"], "runs": 2},
           "base": {"duration_s": 20.0, "sampling_rate_hz": 2.5e6},
           "cells": [{"name": "open-sky"}],
           "factorial": {"deep_measurements": ["prefilter", "reset", "discriminator"]}}
    spec = parse_study(raw)
    assert sorted(c.params["deep_measurements"] for c in spec.cells) == sorted(
        DEEP_MEASUREMENTS)
    raw["factorial"]["deep_measurements"] = ["prefilter", "centralised"]
    with pytest.raises(StudyError, match="deep_measurements"):
        parse_study(raw)
    # or a filter entry's suffix, so that architectures pair on the same files and start-up
    from sdr_di.experiments.variants import variant_list

    vs = variant_list("compare", "ekf,ekf@reset,ff-aukf@discriminator,ekf@tight")
    assert [(v.label, v.coupling, v.architecture) for v in vs] == [
        ("ekf", "deep", None), ("ekf@reset", "deep", "reset"),
        ("ff-aukf@discriminator", "deep", "discriminator"), ("ekf@tight", "tight", None)]
    del raw["factorial"]
    raw["study"]["filters"] = ["ekf", "ekf@reset", "ekf@centralised"]
    with pytest.raises(StudyError, match="centralised"):
        parse_study(raw)
