"""Observables and PVT on generator-consistent synthetic channel observations.

The observations are built from the IF generator's own geometry (default scenario): the
transmit time of the code received at receiver-clock time ``sow + s`` is
``sow + s - D_code(s)`` and the Doppler is ``-f_B3I dD_carr/ds`` (receiver-clock seconds), so
they are exact up to float rounding and the solver must give the truth.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from sdr_di.constants import C_LIGHT, F_B3I, LAMBDA_B3I
from sdr_di.frames import C_e_n, ecef_to_llh, llh_to_ecef
from sdr_di.receiver import pvt
from sdr_di.receiver.observables import (
    ObservableBuilder,
    Observables,
    ReceiverTime,
    form_observables,
)
from sdr_di.scenario import DEFAULT_SCENARIO, load_scenario
from sdr_di.sim.generate import make_generator
from sdr_di.sim.geometry import satellite_delays

from sdr_di.receiver.tracking import ChannelObservation


def _chan(prn, k, week, sow, dop=0.0, phase=0.0, cn0=45.0, code_lock=True, carrier_lock=True,
          time_valid=True):
    return ChannelObservation(prn=prn, sample_index=k, t_tx_week=week, t_tx_sow=sow,
                              doppler_hz=dop, carrier_phase_cycles=phase, cn0_dbhz=cn0,
                              code_lock=code_lock, carrier_lock=carrier_lock,
                              time_valid=time_valid)


# --- synthetic, generator-consistent observations -------------------------------------------
@dataclasses.dataclass
class Synth:
    chans: list
    obs_exact: Observables      # pseudoranges c * D_code without float-sow rounding
    t_true: float               # true time since the start of the receive instant [s]
    bias_s: float               # receiver clock bias at that instant [s]
    drift: float                # [s/s]


class World:
    def __init__(self):
        self.sc = load_scenario(DEFAULT_SCENARIO)
        self.gen = make_generator(self.sc)
        self.fs = self.gen.fs
        self.eph = {s.prn: s.eph for s in self.gen.sats}
        self.iono = self.gen.iono

    def delays(self, s, b0, drift, iono, tropo):
        t = (s - b0) / (1.0 + drift)
        b = b0 + drift * t
        d = [satellite_delays(sat.eph, self.gen.path, np.array([t]), self.sc.sow,
                              np.array([b]), iono, tropo) for sat in self.gen.sats]
        return (np.array([x.d_code[0] for x in d]), np.array([x.d_carr[0] for x in d]), t, b)

    def synth(self, k, b0=0.0, drift=0.0, iono="default", tropo=True, cn0=45.0) -> Synth:
        iono = self.iono if iono == "default" else iono
        s = k / self.fs
        dc, dcarr, t, b = self.delays(s, b0, drift, iono, tropo)
        h = 1e-3
        _, dp, _, _ = self.delays(s + h, b0, drift, iono, tropo)
        _, dm, _, _ = self.delays(s - h, b0, drift, iono, tropo)
        dop = -F_B3I * (dp - dm) / (2 * h)
        phase = -F_B3I * dcarr           # integrated Doppler (+ arbitrary constant 0)
        sc = self.sc
        chans = [_chan(sat.prn, k, sc.week, sc.sow + s - dc[i], dop[i], phase[i], cn0)
                 for i, sat in enumerate(self.gen.sats)]
        obs = form_observables(chans, ReceiverTime.from_sample_zero(self.fs, sc.week, sc.sow))
        obs_exact = dataclasses.replace(obs, pseudorange_m=C_LIGHT * dc)
        return Synth(chans, obs_exact, t, b, drift)

    def truth(self, sol):
        """Truth ECEF position/velocity at the fix's BDT time."""
        dt = (sol.week - self.sc.week) * 604800.0 + sol.sow - self.sc.sow
        r, v = self.gen.path(np.array([dt]))
        return r[0], v[0]


@pytest.fixture(scope="module")
def world():
    return World()


EPOCHS_S = (0.0, 22.4, 41.0)   # straight, first circle, second circle


# --- observables ---------------------------------------------------------------------------
def test_receiver_time_first_fix_trick_and_sample_count():
    rt = ReceiverTime(25e6)
    chans = [_chan(7, 1000, 755, 360000.0), _chan(8, 1000, 755, 360000.01),
             _chan(9, 1000, 755, 359999.995)]
    obs = form_observables(chans, rt)
    assert rt.initialized and rt.k0 == 1000
    assert obs.sow == pytest.approx(360000.01 + 0.075, abs=1e-12)
    np.testing.assert_allclose(obs.pseudorange_m,
                               C_LIGHT * (360000.085 - np.array([360000.0, 360000.01, 359999.995])),
                               atol=0.02)   # float sow: ulp 5.8e-11 s = 1.7 cm
    # afterwards: t_rx advances with the sample count only (no re-initialisation)
    later = [_chan(7, 1000 + 25_000_000, 755, 360001.0)]
    obs2 = form_observables(later, rt)
    assert obs2.sow == pytest.approx(360001.085, abs=1e-12)
    assert obs2.pseudorange_m[0] == pytest.approx(0.085 * C_LIGHT, abs=0.02)


def test_observables_week_crossing_and_channel_selection():
    rt = ReceiverTime(1e6)
    rt.set(0, 756, 0.010)
    chans = [_chan(7, 0, 755, 604799.94, dop=1000.0, phase=5.0),
             _chan(8, 0, 756, 0.0, dop=-250.0, carrier_lock=False),
             _chan(9, 0, 756, 0.0, code_lock=False),
             _chan(10, 0, 756, 0.0, time_valid=False),
             _chan(11, 0, 756, 0.0, dop=float("nan"))]
    obs = form_observables(chans, rt)
    assert obs.prn.tolist() == [7, 8, 11]
    assert obs.pseudorange_m[0] == pytest.approx(0.07 * C_LIGHT, abs=0.05)  # sow ulp
    assert obs.pseudorange_m[1] == pytest.approx(0.01 * C_LIGHT, abs=0.05)
    # approaching satellite (positive Doppler): range decreasing, negative rate
    assert obs.pseudorange_rate_mps[0] == pytest.approx(-1000.0 * LAMBDA_B3I)
    assert obs.pseudorange_rate_mps[1] == pytest.approx(250.0 * LAMBDA_B3I)
    assert math.isnan(obs.pseudorange_rate_mps[2])
    assert obs.carrier_phase_m[0] == pytest.approx(-5.0 * LAMBDA_B3I)
    assert math.isnan(obs.carrier_phase_m[1])          # no carrier lock: no phase
    strict = form_observables(chans, rt, require_carrier_lock_for_rate=True)
    assert math.isnan(strict.pseudorange_rate_mps[1])
    with pytest.raises(ValueError, match="different samples"):
        form_observables([_chan(7, 0, 756, 0.0), _chan(8, 1, 756, 0.0)], rt)
    with pytest.raises(ValueError, match="more than one"):
        form_observables([_chan(7, 0, 756, 0.0), _chan(7, 0, 756, 0.0)], rt)


def test_unknown_transmit_week_is_resolved():
    # receiver time known: nearest week to t_rx (here across the week boundary)
    rt = ReceiverTime(1e6)
    rt.set(0, 756, 0.010)
    obs = form_observables([_chan(7, 0, None, 604799.94), _chan(8, 0, None, 0.0)], rt)
    assert obs.t_tx_week.tolist() == [755, 756] and obs.unknown_week == ()
    assert obs.pseudorange_m[0] == pytest.approx(0.07 * C_LIGHT, abs=0.05)
    # not initialised: from a channel that knows its week
    rt = ReceiverTime(1e6)
    obs = form_observables([_chan(7, 0, None, 604799.94), _chan(8, 0, 756, 0.0)], rt)
    assert obs.t_tx_week.tolist() == [755, 756] and rt.initialized
    # nobody knows: left out, reported; the PVT says why
    rt = ReceiverTime(1e6)
    obs = form_observables([_chan(7, 0, None, 1000.0), _chan(8, 0, None, 1000.01)], rt)
    assert obs.n == 0 and obs.unknown_week == (7, 8) and not rt.initialized
    sol = pvt.solve(obs, {}, None)
    assert sol.status is pvt.PvtStatus.TOO_FEW_SATELLITES and "week unknown" in sol.message
    # a rough time hint (days off) is enough
    rt = ReceiverTime(1e6, time_hint=(755, 604000.0 - 3 * 86400))
    obs = form_observables([_chan(7, 0, None, 604799.94), _chan(8, 0, None, 5.0)], rt)
    assert obs.t_tx_week.tolist() == [755, 756]


def test_engine_without_weeks_uses_ephemeris_hint(world):
    syn = world.synth(round(3.0 * world.fs))
    chans = [dataclasses.replace(c, t_tx_week=None) for c in syn.chans]
    sol = pvt.PvtEngine(world.fs, world.eph, world.iono).process(chans)
    assert sol.valid and sol.week == world.sc.week
    r, _ = world.truth(sol)
    assert np.linalg.norm(sol.r_e - r) < 0.1


def test_generator_carrier_phase_and_doppler_are_consistent(world):
    """carrier_phase_m differences over time match the integrated pseudorange rate."""
    k1, k2 = int(5.0 * world.fs), int(5.2 * world.fs)
    a = form_observables(world.synth(k1).chans, ReceiverTime.from_sample_zero(world.fs, 0, 0))
    b = form_observables(world.synth(k2).chans, ReceiverTime.from_sample_zero(world.fs, 0, 0))
    dphi = b.carrier_phase_m - a.carrier_phase_m
    mean_rate = 0.5 * (a.pseudorange_rate_mps + b.pseudorange_rate_mps)
    np.testing.assert_allclose(dphi, mean_rate * 0.2, atol=2e-3)


# --- PVT on exact observations -----------------------------------------------------------
@pytest.mark.parametrize("t_s", EPOCHS_S)
def test_exact_observations_reproduce_truth(world, t_s):
    syn = world.synth(round(t_s * world.fs))
    sol = pvt.solve(syn.obs_exact, world.eph, world.iono)
    assert sol.status is pvt.PvtStatus.FIX and sol.valid, sol.message
    assert sol.velocity_status is pvt.PvtStatus.FIX
    r, v = world.truth(sol)
    assert np.linalg.norm(sol.r_e - r) < 0.01
    assert np.linalg.norm(sol.v_e - v) < 1e-3
    assert abs(sol.clock_bias_m) < 0.01 and abs(sol.clock_drift_mps) < 1e-3
    assert sol.n_sats == 7 and np.abs(sol.residuals).max() < 1e-3
    # derived fields
    np.testing.assert_allclose(sol.llh, ecef_to_llh(sol.r_e))
    np.testing.assert_allclose(sol.v_n, C_e_n(sol.llh[0], sol.llh[1]) @ sol.v_e)
    assert sol.sow - world.sc.sow == pytest.approx(syn.t_true, abs=1e-9)


@pytest.mark.parametrize("t_s", EPOCHS_S)
def test_full_chain_from_channel_observations(world, t_s):
    """ChannelObservation -> observables -> PVT. t_tx arrives as float sow (ulp 5.8e-11 s at
    3.6e5 s = 1.7 cm of range), so the residuals sit at the mm level and, with this
    constellation's PDOP of about 6, the position at the few-cm level."""
    syn = world.synth(round(t_s * world.fs))
    builder = ObservableBuilder(world.fs, ReceiverTime.from_sample_zero(
        world.fs, world.sc.week, world.sc.sow))
    sol = pvt.solve(builder(syn.chans), world.eph, world.iono)
    assert sol.valid, sol.message
    r, v = world.truth(sol)
    assert np.abs(sol.residuals).max() < 0.01
    assert np.linalg.norm(sol.r_e - r) < 0.01 * sol.dops.pdop * 2
    assert np.linalg.norm(sol.v_e - v) < 1e-3


def test_first_fix_clock_trick_absorbs_time_error(world):
    """Auto-initialised receiver time: position still exact, bias = c * (t_rx - t_true)."""
    k = round(12.0 * world.fs)
    syn = world.synth(k)
    engine = pvt.PvtEngine(world.fs, world.eph, world.iono)
    sol = engine.process(syn.chans)
    assert sol.valid, sol.message
    rx_minus_true = (sol.rx_sow - world.sc.sow) - syn.t_true
    assert 1e-3 < abs(rx_minus_true) < 0.1           # the nominal 75 ms guess was off
    assert sol.clock_bias_m == pytest.approx(C_LIGHT * rx_minus_true, abs=0.1)
    r, v = world.truth(sol)
    assert np.linalg.norm(sol.r_e - r) < 0.1
    assert np.linalg.norm(sol.v_e - v) < 1e-3
    # next epoch: time from the sample count, bias reported (not steered), unchanged
    k2 = k + round(0.2 * world.fs)
    sol2 = engine.process(world.synth(k2).chans)
    assert sol2.valid
    assert sol2.rx_sow - sol.rx_sow == pytest.approx(0.2, abs=1e-9)
    assert sol2.clock_bias_m == pytest.approx(sol.clock_bias_m, abs=0.1)
    r2, _ = world.truth(sol2)
    assert np.linalg.norm(sol2.r_e - r2) < 0.1


@pytest.mark.parametrize("b0,drift", [(2.5e-4, 0.0), (-3.0e-3, 1.0e-7), (1.0e-4, -4.0e-7)])
def test_clock_bias_and_drift_recovered(world, b0, drift):
    syn = world.synth(round(30.0 * world.fs), b0=b0, drift=drift)
    sol = pvt.solve(syn.obs_exact, world.eph, world.iono)
    assert sol.valid
    assert sol.clock_bias_m == pytest.approx(C_LIGHT * syn.bias_s, abs=0.01)
    assert sol.clock_drift_mps == pytest.approx(C_LIGHT * drift, abs=1e-3)
    r, v = world.truth(sol)
    assert np.linalg.norm(sol.r_e - r) < 0.01
    assert np.linalg.norm(sol.v_e - v) < 1e-3


# --- noise, weights, DOP -------------------------------------------------------------------
def _monte_carlo(world, cfg, sig_pr, sig_rate, n=300, seed=1):
    syn = world.synth(round(10.0 * world.fs))
    sat = pvt.satellite_states(syn.obs_exact, world.eph)
    ref = pvt.solve(syn.obs_exact, world.eph, world.iono, config=cfg)
    r, v = world.truth(ref)
    rng = np.random.default_rng(seed)
    dpos, dvel, mah = [], [], []
    for _ in range(n):
        obs = dataclasses.replace(
            syn.obs_exact,
            pseudorange_m=syn.obs_exact.pseudorange_m + sig_pr * rng.standard_normal(7),
            pseudorange_rate_mps=(syn.obs_exact.pseudorange_rate_mps
                                  + sig_rate * rng.standard_normal(7)))
        sol = pvt.solve_position(obs, world.eph, world.iono, x0=ref, config=cfg, sat=sat)
        sol = pvt.solve_velocity(obs, world.eph, sol, world.iono, cfg, sat=sat)
        assert sol.valid and sol.velocity_valid
        dpos.append(sol.r_e - r)
        dvel.append(sol.v_e - v)
        x = np.r_[sol.r_e - r, sol.clock_bias_m]
        mah.append(x @ np.linalg.solve(sol.cov, x))
    return ref, np.array(dpos), np.array(dvel), np.array(mah)


def test_noise_errors_consistent_with_dop(world):
    cfg = pvt.PvtConfig(weighting="equal", sigma_pr_m=1.0, sigma_rate_mps=0.05)
    ref, dpos, dvel, _ = _monte_carlo(world, cfg, 1.0, 0.05)
    pdop = ref.dops.pdop
    ms_pos = np.mean(np.sum(dpos**2, axis=1))
    ms_vel = np.mean(np.sum(dvel**2, axis=1))
    assert ms_pos / (pdop * 1.0) ** 2 == pytest.approx(1.0, abs=0.25)
    assert ms_vel / (pdop * 0.05) ** 2 == pytest.approx(1.0, abs=0.25)
    # horizontal / vertical split too (ENU)
    C = C_e_n(ref.llh[0], ref.llh[1])
    enu = dpos @ C.T
    assert np.mean(np.sum(enu[:, :2]**2, axis=1)) / ref.dops.hdop**2 == pytest.approx(1, abs=0.3)
    assert np.mean(enu[:, 2]**2) / ref.dops.vdop**2 == pytest.approx(1, abs=0.3)
    assert abs(np.mean(dpos, axis=0)).max() < 4 * pdop / math.sqrt(len(dpos))


def test_default_weights_formal_covariance_consistent(world):
    """Noise drawn with the weight model's own sigmas: Mahalanobis distance ~ chi2(4)."""
    cfg = pvt.PvtConfig()
    syn = world.synth(round(10.0 * world.fs))
    ref = pvt.solve(syn.obs_exact, world.eph, world.iono, config=cfg)
    # per-satellite sigmas of the model at the reference C/N0 (45): 1 m / sin(el)
    order = [int(np.flatnonzero(syn.obs_exact.prn == p)[0]) for p in ref.prns]
    sig = np.empty(7)
    sig[order] = 1.0 / np.sin(ref.elevation)
    rng = np.random.default_rng(7)
    sat = pvt.satellite_states(syn.obs_exact, world.eph)
    r, _ = world.truth(ref)
    mah = []
    for _ in range(300):
        obs = dataclasses.replace(syn.obs_exact, pseudorange_m=syn.obs_exact.pseudorange_m
                                  + sig * rng.standard_normal(7))
        sol = pvt.solve_position(obs, world.eph, world.iono, x0=ref, config=cfg, sat=sat)
        x = np.r_[sol.r_e - r, sol.clock_bias_m - C_LIGHT * syn.bias_s]
        mah.append(x @ np.linalg.solve(sol.cov, x))
    assert np.mean(mah) == pytest.approx(4.0, abs=0.8)


def test_velocity_formal_covariance_consistent(world):
    """Rate noise drawn with the weight model's sigmas (0.05 m/s / sin(el) at 45 dB-Hz):
    the Mahalanobis distance of (v, d) under ``cov_v`` averages 4 (chi-square, 4 dof)."""
    cfg = pvt.PvtConfig()
    syn = world.synth(round(10.0 * world.fs))
    ref = pvt.solve(syn.obs_exact, world.eph, world.iono, config=cfg)
    assert ref.cov_v.shape == (4, 4) and np.all(np.isfinite(ref.cov_v))
    order = [int(np.flatnonzero(syn.obs_exact.prn == p)[0]) for p in ref.prns]
    sig = np.empty(7)
    sig[order] = 0.05 / np.sin(ref.elevation)
    rng = np.random.default_rng(11)
    sat = pvt.satellite_states(syn.obs_exact, world.eph)
    _, v_true = world.truth(ref)
    mah = []
    for _ in range(300):
        obs = dataclasses.replace(syn.obs_exact, pseudorange_rate_mps=(
            syn.obs_exact.pseudorange_rate_mps + sig * rng.standard_normal(7)))
        sol = pvt.solve_velocity(obs, world.eph, ref, world.iono, cfg, sat=sat)
        x = np.r_[sol.v_e - v_true, sol.clock_drift_mps]
        mah.append(x @ np.linalg.solve(sol.cov_v, x))
    assert np.mean(mah) == pytest.approx(4.0, abs=0.8)


def test_satellite_states_equal_each_record_evaluated_alone(world):
    """satellite_states evaluates the satellites of a week in one stacked call per pass;
    every row equals the record's own three-pass evaluation bit for bit, with a satellite
    timed in the previous week and one without an ephemeris in the same epoch."""
    from sdr_di.orbits.broadcast import sat_pos_vel_clock

    obs = world.synth(round(22.4 * world.fs)).obs_exact
    wk = obs.t_tx_week.copy()
    sow = obs.t_tx_sow.copy()
    wk[1] -= 1                       # the same instant, counted from the previous week
    sow[1] += 604800.0
    obs = dataclasses.replace(obs, t_tx_week=wk, t_tx_sow=sow)
    ephs = {p: e for p, e in world.eph.items() if p != int(obs.prn[2])}
    sat = pvt.satellite_states(obs, ephs)
    assert sat.missing == (int(obs.prn[2]),) and not sat.ok[2] and sat.ok.sum() == obs.n - 1
    for i in np.flatnonzero(sat.ok):
        eph, w, t_sv = ephs[int(obs.prn[i])], int(wk[i]), float(sow[i])
        _, _, d0, _ = sat_pos_vel_clock(eph, t_sv, week=w)
        _, _, d1, _ = sat_pos_vel_clock(eph, t_sv - d0[0], week=w)
        r, v, d, dd = sat_pos_vel_clock(eph, t_sv - d1[0], week=w)
        assert np.array_equal(sat.r_e[i], r[0]) and np.array_equal(sat.v_e[i], v[0])
        assert sat.dt_sv[i] == d[0] and sat.ddt_sv[i] == dd[0]
    assert np.all(np.isnan(sat.r_e[2]))


@pytest.mark.parametrize("t_s", EPOCHS_S)
def test_modelled_observables_are_the_generator_observables(world, t_s):
    """The PVT's models run forwards from the true state and clock give the exact
    pseudoranges and rates (the tight coupling's predictions)."""
    b0, drift = 2.5e-4, 1.0e-7
    syn = world.synth(round(t_s * world.fs), b0=b0, drift=drift)
    obs = syn.obs_exact
    sat = pvt.satellite_states(obs, world.eph)
    r, v = world.gen.path(np.array([syn.t_true]))
    idx = np.arange(obs.n)
    P, D, U, el = pvt.modelled_observables(sat, idx, r[0], v[0], C_LIGHT * syn.bias_s,
                                           C_LIGHT * drift, world.sc.sow + syn.t_true,
                                           world.iono)
    np.testing.assert_allclose(P, obs.pseudorange_m, atol=0.01)
    np.testing.assert_allclose(D, obs.pseudorange_rate_mps, atol=1e-3)
    np.testing.assert_allclose(np.linalg.norm(U, axis=1), 1.0)
    assert np.all(el > 0)
    # and it is the model the WLS solves: at the fix, measured minus modelled = residuals
    sol = pvt.solve(obs, world.eph, world.iono)
    k = [int(np.flatnonzero(obs.prn == p)[0]) for p in sol.prns]
    P2, D2, _, _ = pvt.modelled_observables(sat, k, sol.r_e, sol.v_e, sol.clock_bias_m,
                                            sol.clock_drift_mps, sol.sow, world.iono)
    np.testing.assert_allclose(obs.pseudorange_m[k] - P2, sol.residuals, atol=1e-6)
    np.testing.assert_allclose(obs.pseudorange_rate_mps[k] - D2, sol.rate_residuals,
                               atol=1e-6)


def test_cn0_lowers_weight(world):
    """A 20 dB weaker satellite with a 30 m error moves the fix much less when weighted."""
    syn = world.synth(round(10.0 * world.fs))
    obs = syn.obs_exact
    pr = obs.pseudorange_m.copy()
    pr[2] += 30.0
    cn0 = np.full(7, 45.0)
    cn0[2] = 25.0
    bad = dataclasses.replace(obs, pseudorange_m=pr, cn0_dbhz=cn0)
    r, _ = world.truth(pvt.solve(obs, world.eph, world.iono))
    cfg_hi = pvt.PvtConfig(max_residual_rms_m=1e9)
    e_w = np.linalg.norm(pvt.solve(bad, world.eph, world.iono, config=cfg_hi).r_e - r)
    e_eq = np.linalg.norm(pvt.solve(bad, world.eph, world.iono,
                                    config=dataclasses.replace(cfg_hi, weighting="equal")).r_e - r)
    assert e_w < 0.2 * e_eq


def test_dops_hand_computed_geometry():
    """Zenith + four horizon satellites at azimuths 0/90/180/270 from (0 N, 0 E):
    HDOP = 1, VDOP = sqrt(5/4), TDOP = 1/2, PDOP = 3/2, GDOP = sqrt(5/2)."""
    r = llh_to_ecef(0.0, 0.0, 0.0)
    d = 2.0e7
    # at lat = lon = 0: East = +Y, North = +Z, Up = +X
    dirs = np.array([[1, 0, 0], [0, 0, 1], [0, 1, 0], [0, 0, -1], [0, -1, 0]], float)
    dops, _ = pvt.compute_dops(r, r + d * dirs)
    assert dops.hdop == pytest.approx(1.0)
    assert dops.vdop == pytest.approx(math.sqrt(1.25))
    assert dops.tdop == pytest.approx(0.5)
    assert dops.pdop == pytest.approx(1.5)
    assert dops.gdop == pytest.approx(math.sqrt(2.5))
    bad, Qb = pvt.compute_dops(r, r + d * dirs[:3])
    assert Qb is None and math.isnan(bad.gdop)


# --- the corrections are applied ----------------------------------------------------------
@pytest.mark.parametrize("switch", ["ionosphere", "troposphere"])
def test_atmosphere_corrections_are_applied(world, switch):
    syn = world.synth(round(10.0 * world.fs))
    on = pvt.solve(syn.obs_exact, world.eph, world.iono)
    off = pvt.solve(syn.obs_exact, world.eph, world.iono,
                    config=pvt.PvtConfig(**{switch: False}))
    r, _ = world.truth(on)
    assert np.linalg.norm(on.r_e - r) < 0.01
    assert np.linalg.norm(off.r_e - r) > 1.0          # metre-level without the correction
    assert np.abs(off.residuals).max() > 0.05


def test_generator_without_atmosphere_matches_solver_without(world):
    syn = world.synth(round(10.0 * world.fs), iono=None, tropo=False)
    cfg = pvt.PvtConfig(ionosphere=False, troposphere=False)
    sol = pvt.solve(syn.obs_exact, world.eph, None, config=cfg)
    r, v = world.truth(sol)
    assert np.linalg.norm(sol.r_e - r) < 0.01 and np.linalg.norm(sol.v_e - v) < 1e-3
    # and with corrections on the model no longer matches
    sol2 = pvt.solve(syn.obs_exact, world.eph, world.iono)
    assert np.linalg.norm(sol2.r_e - r) > 1.0


def test_sagnac_and_satellite_clock_matter(world, monkeypatch):
    """Sanity of the test itself: breaking Sagnac or the satellite clock spoils the fix."""
    syn = world.synth(round(10.0 * world.fs))
    ok = pvt.solve(syn.obs_exact, world.eph, world.iono)
    r, _ = world.truth(ok)
    monkeypatch.setattr(pvt, "OMEGA_E", 0.0)
    no_sagnac = pvt.solve(syn.obs_exact, world.eph, world.iono)
    assert np.linalg.norm(no_sagnac.r_e - r) > 1.0
    monkeypatch.undo()
    sat = pvt.satellite_states(syn.obs_exact, world.eph)
    sat_bad = dataclasses.replace(sat, dt_sv=sat.dt_sv + 1e-8 * np.arange(7))
    bad = pvt.solve_position(syn.obs_exact, world.eph, world.iono, sat=sat_bad)
    assert np.linalg.norm(bad.r_e - r) > 1.0


# --- sanity / status -----------------------------------------------------------------------
def test_too_few_satellites_is_a_status_not_an_exception(world):
    syn = world.synth(round(10.0 * world.fs))
    three = syn.obs_exact.select(np.arange(3))
    sol = pvt.solve(three, world.eph, world.iono)
    assert sol.status is pvt.PvtStatus.TOO_FEW_SATELLITES and not sol.valid
    assert "need 4" in sol.message
    assert np.all(np.isnan(sol.r_e)) and np.all(np.isnan(sol.v_e))
    assert sol.sow == three.sow                        # receiver time still reported
    # no ephemeris for most satellites
    eph4 = {p: world.eph[p] for p in list(world.eph)[:3]}
    sol = pvt.solve(syn.obs_exact, eph4, world.iono)
    assert sol.status is pvt.PvtStatus.TOO_FEW_SATELLITES and "no ephemeris" in sol.message
    # elevation mask leaves fewer than four
    sol = pvt.solve(syn.obs_exact, world.eph, world.iono,
                    config=pvt.PvtConfig(elevation_mask_deg=68.0))
    assert sol.status is pvt.PvtStatus.TOO_FEW_SATELLITES and "mask" in sol.message
    # nothing tracked at all
    rt = ReceiverTime(world.fs)
    empty = form_observables([_chan(7, 0, 755, 360000.0, code_lock=False)], rt)
    assert empty.n == 0 and not rt.initialized
    sol = pvt.solve(empty, world.eph, world.iono)
    assert sol.status is pvt.PvtStatus.TOO_FEW_SATELLITES


def test_elevation_mask_drops_low_satellites(world):
    syn = world.synth(round(10.0 * world.fs))
    full = pvt.solve(syn.obs_exact, world.eph, world.iono)
    mask = float(np.sort(np.degrees(full.elevation))[1]) + 0.5   # drop the two lowest
    sol = pvt.solve(syn.obs_exact, world.eph, world.iono,
                    config=pvt.PvtConfig(elevation_mask_deg=mask))
    assert sol.valid and sol.n_sats == 5
    assert np.all(np.degrees(sol.elevation) >= mask)
    r, _ = world.truth(sol)
    assert np.linalg.norm(sol.r_e - r) < 0.01


def test_large_residual_flagged(world):
    syn = world.synth(round(10.0 * world.fs))
    pr = syn.obs_exact.pseudorange_m.copy()
    pr[3] += 500.0
    sol = pvt.solve(dataclasses.replace(syn.obs_exact, pseudorange_m=pr), world.eph, world.iono)
    assert sol.status is pvt.PvtStatus.LARGE_RESIDUALS and not sol.valid
    assert np.all(np.isfinite(sol.r_e))               # filled in for diagnosis
    rate = syn.obs_exact.pseudorange_rate_mps.copy()
    rate[1] += 50.0
    sol = pvt.solve(dataclasses.replace(syn.obs_exact, pseudorange_rate_mps=rate), world.eph,
                    world.iono)
    assert sol.valid and sol.velocity_status is pvt.PvtStatus.LARGE_RESIDUALS


def test_navdata_with_select_is_accepted(world):
    from sdr_di.orbits.rinex_nav import load_nav

    nav = load_nav(world.sc.satellites.ephemeris)
    syn = world.synth(round(10.0 * world.fs))
    a = pvt.solve(syn.obs_exact, nav, world.iono)
    # the same records looked up by hand (at 06:30 BDT the start lies halfway between two
    # toes, so the generator's record of t = 0 need not be the one nearest t = 10 s)
    week, sow = int(syn.obs_exact.t_tx_week[0]), float(syn.obs_exact.t_tx_sow[0])
    b = pvt.solve(syn.obs_exact, {p: nav.select(p, week, sow) for p in world.eph}, world.iono)
    assert a.valid and np.linalg.norm(a.r_e - b.r_e) < 1e-6


def test_initial_guess_forms(world):
    syn = world.synth(round(10.0 * world.fs))
    ref = pvt.solve(syn.obs_exact, world.eph, world.iono)
    for x0 in (ref, ref.r_e, np.r_[ref.r_e, ref.clock_bias_m], None):
        sol = pvt.solve(syn.obs_exact, world.eph, world.iono, x0=x0)
        assert np.linalg.norm(sol.r_e - ref.r_e) < 1e-4
    with pytest.raises(ValueError, match="x0"):
        pvt.solve(syn.obs_exact, world.eph, world.iono, x0=[1.0, 2.0])
    with pytest.raises(ValueError, match="weighting"):
        pvt.PvtConfig(weighting="snr")


def test_range_norms_are_numpys_norm_bit_for_bit():
    """``pvt._norms`` (the range model's row norms without ``np.linalg.norm``'s argument
    handling) gives its values exactly, so the Sagnac iteration's ranges are unchanged."""
    rng = np.random.default_rng(9)
    for n in (1, 3, 7, 15):
        d = rng.normal(size=(n, 3)) * 10 ** rng.uniform(0, 8, size=(n, 1))
        assert np.array_equal(pvt._norms(d), np.linalg.norm(d, axis=-1))
