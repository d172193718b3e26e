"""Loose and tight coupling on the scalar receiver's own measurements (issue 13 items 2-3).

One generated default-scenario file (25 s at 2.5 MHz, in this test only) in which the four
lowest of the seven satellites are blocked from 16 s to 22 s, so the receiver has 7, then 3,
then 7 satellites. Both modes run through the CLI (``sdr-di run --mode loose|tight``, EKF):

* end to end: outputs under their names with deep's columns, hand-over at the same time
  as deep's rule gives, and a position RMSE vs the truth over the 7-satellite span after the
  hand-over below 1 m (measured: loose 0.36 m, tight 0.36 m);
* with 3 satellites tight keeps updating with 3 channels while loose gets no fix and coasts;
  tight's position error stays below a bound derived in
  :func:`test_tight_stays_bounded_with_three_satellites_while_loose_coasts`.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from sdr_di.cli import main
from sdr_di.integration.consistency import SD_COLUMNS
from sdr_di.integration.run_integrated import SOLUTION_COLUMNS

BLOCK = (16.0, 22.0)          # 4 of 7 satellites blocked [s]
COL = {c: i for i, c in enumerate(SOLUTION_COLUMNS)}


class _Runs(dict):
    """The generated file's paths (``runs["paths"]``) and each mode's CLI run, made when a
    test first asks for it (``runs[mode]``: rows of the CSV and the summary), so that the
    suite's slowest item is the generation or one run, not the generation and both runs.
    The CLI's receivers keep their scalar run (``keep_start``, which changes nothing else):
    :meth:`kept` gives a mode's receiver and result, for
    :func:`test_a_loop_over_a_kept_scalar_run_gives_the_rows_of_its_own_run`."""

    def __init__(self, folder, paths) -> None:
        super().__init__(paths=paths)
        self.folder = folder
        self._kept: dict = {}

    def __missing__(self, mode: str):
        from sdr_di.integration.receiver import IntegratedReceiver

        real_run = IntegratedReceiver.run

        def keeping(rx, *args, **kw):
            res = real_run(rx, *args, **{**kw, "keep_start": True})
            self._kept[rx.config.mode] = (rx, res)
            return res

        d = self.folder
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(IntegratedReceiver, "run", keeping)
            rc = main(["run", str(self["paths"]["if"]), "--mode", mode, "--filter", "ekf",
                       "--no-progress", "--out", str(d / mode)])
        assert rc == 0
        self[mode] = (np.loadtxt(d / mode / f"default_{mode}.csv", delimiter=",", skiprows=2),
                      json.loads((d / mode / f"default_{mode}_summary.json").read_text()))
        return self[mode]

    def kept(self, mode: str):
        self[mode]                                   # noqa: B018 - made if not yet
        return self._kept[mode]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    from sdr_di.experiments._deep import ranked_prns, with_outages
    from sdr_di.scenario import DEFAULT_SCENARIO, load_scenario
    from sdr_di.sim.generate import generate_files

    d = tmp_path_factory.mktemp("coupling")
    sc = load_scenario(DEFAULT_SCENARIO).with_overrides(duration_s=25.0, sampling_rate_hz=2.5e6)
    prns = ranked_prns(sc)
    assert len(prns) == 7
    sc = with_outages(sc, [{"prn": p, "start_s": BLOCK[0], "end_s": BLOCK[1], "blockage": True}
                           for p in prns[3:]])
    return _Runs(d, generate_files(sc, d, progress=False))


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["loose", "tight"])
def test_loose_and_tight_end_to_end(runs, mode):
    rows, summ = runs[mode]
    assert summ["mode"] == mode and summ["filter"] == "ekf"
    assert rows.shape[1] == len(SOLUTION_COLUMNS)
    t = rows[:, COL["t_s"]]
    assert np.all(np.diff(t) == pytest.approx(0.2))                    # 5 Hz output
    assert 10.0 < summ["handover_s"] < BLOCK[0] - 2.0
    seven = t < BLOCK[0]
    assert seven.sum() >= 10
    assert np.all(rows[seven, COL["n_used"]] == 7)
    pe = rows[:, [COL["pos_err_e_m"], COL["pos_err_n_m"], COL["pos_err_u_m"]]]
    rmse = math.sqrt(np.mean(np.sum(pe[seven] ** 2, axis=1)))
    assert rmse < 1.0, rmse
    ve = rows[:, [COL["vel_err_e"], COL["vel_err_n"], COL["vel_err_u"]]]
    assert math.sqrt(np.mean(np.sum(ve[seven] ** 2, axis=1))) < 0.1
    # BDT column: receiver time minus the clock bias / c (clock columns finite)
    assert np.all(np.isfinite(rows[:, COL["clock_bias_m"]]))
    assert np.all(np.isfinite(rows[:, COL["clock_drift_mps"]]))
    # formal 1-sigma of the corrected solution (ENU) and the consistency entry (issue 25)
    sd = rows[:, [COL[c] for c in SD_COLUMNS]]
    assert np.all(np.isfinite(sd)) and np.all(sd > 0)
    c = summ["consistency"]
    blocks = {"loose": ("vel", "pos"), "tight": ("range", "rate")}[mode]
    assert set(c) == {"band_rule", *(f"nis_{b}" for b in blocks), "nees_pos", "nees_vel",
                      "nees_att"}
    for k, e in c.items():
        if k != "band_rule":
            assert e["expected"] == 1.0 and e["value"] > 0 and e["band"][0] < 1 < e["band"][1]


@pytest.mark.slow
def test_tight_stays_bounded_with_three_satellites_while_loose_coasts(runs):
    """With 3 satellites tight's position error stays below ``e0 + b_a T^2 / 2``.

    Three pseudoranges fix three of the four combinations of position and clock bias; the
    fourth (position along ``d = U^-1 1`` with the clock moving by 1 m per ``|d|`` m) is held
    only by the INS, since the filter's TCXO clock model lets the clock wander. So tight's
    error can grow no faster than the INS coasting error along one direction: from ``e0``,
    its error at the blockage start, by at most ``b_a T^2 / 2`` over ``T`` = 6 s with
    ``b_a`` the accelerometer bias spec (4 mg, paper 004 Table 4), i.e. 0.71 m, if the
    filter had learned nothing of the bias. Loose meanwhile has no fix (3 satellites) and
    no update. Measured: tight at most 0.24 m in the blockage (EKF), loose coasting to 0.24 m
    (in a 10 s blockage of a 28 s file: 0.2 and 0.8 m).
    """
    loose, _ = runs["loose"]
    tight, _ = runs["tight"]
    t = tight[:, COL["t_s"]]
    blk = (t > BLOCK[0] + 0.3) & (t < BLOCK[1])          # after the channels' loss of lock
    assert blk.sum() >= 27                              # 5 Hz over 5.7 s
    assert np.all(tight[blk, COL["n_used"]] == 3)        # tight keeps updating with 3
    assert np.all(loose[blk, COL["n_used"]] == 0)        # loose: no fix, coasting
    pe = np.linalg.norm(tight[:, [COL["pos_err_e_m"], COL["pos_err_n_m"],
                                  COL["pos_err_u_m"]]], axis=1)
    e0 = pe[np.searchsorted(t, BLOCK[0])]
    b_a = 4e-3 * 9.80665
    bound = e0 + 0.5 * b_a * (BLOCK[1] - BLOCK[0]) ** 2
    assert pe[blk].max() < bound, (pe[blk].max(), bound)
    # both back on 7 after the blockage
    after = t > BLOCK[1] + 1.0
    assert after.any() and np.all(tight[after, COL["n_used"]] == 7)


@pytest.mark.slow
def test_a_loop_over_a_kept_scalar_run_gives_the_rows_of_its_own_run(runs):
    """Loose and tight share the scalar receiver's run (``ScalarRecord``: no feedback reaches
    it): tight run over the epochs the CLI's tight run kept equals that run to the bit, and
    loose run over those epochs equals the CLI's loose run to the CSV's 12 digits (every
    column: errors, states, formal sigmas, channel columns, NIS)."""
    from sdr_di.integration.receiver import (IntegratedReceiver, IntegrationConfig,
                                             ScalarRecord, StartMismatchError)
    from sdr_di.integration.run_integrated import write_solution_csv
    from sdr_di.io.imu_files import read_imu, read_truth
    from sdr_di.receiver.run_scalar import open_source, search_assistance

    paths = runs["paths"]
    src = open_source(paths["if"])
    imu = read_imu(paths["imu"])
    truth = read_truth(paths["truth"])[0]
    first, a = runs.kept("tight")
    rec = first.scalar_record
    assert isinstance(rec, ScalarRecord) and first.deep_start is None
    # what `sdr-di run` gave the receiver (a record is taken with the navigation data it was
    # made with: the same object)
    kw = dict(nav=rec.nav, truth=truth, assist=search_assistance(src, None, True))
    again = IntegratedReceiver(IntegrationConfig(filter="ekf", mode="tight"))
    b = again.run(open_source(paths["if"]), imu, start=rec, **kw)
    assert again.profile["scalar"] < 0.1 * first.profile["scalar"]
    assert b.handover_s == a.handover_s and b.prns == a.prns
    for name in ("t", "llh", "v_n", "att", "pos_err", "sd", "nees", "cn0_dbhz", "used",
                 "n_used", "nis"):
        assert np.array_equal(getattr(a, name), getattr(b, name), equal_nan=True), name
    loose = IntegratedReceiver(IntegrationConfig(filter="ekf", mode="loose")).run(
        src, imu, start=rec, **kw)
    rows, _ = runs["loose"]
    csv = write_solution_csv(paths["if"].parent / "replayed_loose.csv", loose)
    assert np.array_equal(np.loadtxt(csv, delimiter=",", skiprows=2), rows, equal_nan=True)
    # refused: another GNSS rate, or deep mode
    for cfg in (IntegrationConfig(filter="ekf", mode="loose", gnss_rate_hz=10.0),
                IntegrationConfig(filter="ekf")):
        with pytest.raises(StartMismatchError):
            IntegratedReceiver(cfg).run(src, imu, start=rec, **kw)


# ---- the sources without IF data (fast) -------------------------------------------------------
def _enu_to_ecef_cov(llh, D):
    from sdr_di.frames import C_e_n

    C = C_e_n(llh[0], llh[1])
    return C.T @ D @ C


def test_fix_covariance_is_the_formal_covariance_in_enu_and_neu():
    import types

    from sdr_di.integration.loose_fixes import fix_covariance

    llh = np.array([math.radians(40.0), math.radians(116.0), 100.0])
    cov = np.zeros((4, 4))
    cov[:3, :3] = _enu_to_ecef_cov(llh, np.diag([1.0, 4.0, 9.0]))        # E, N, U [m^2]
    cov[3, 3] = 25.0
    cov_v = np.zeros((4, 4))
    cov_v[:3, :3] = _enu_to_ecef_cov(llh, np.diag([0.01, 0.04, 0.09]))
    sol = types.SimpleNamespace(llh=llh, cov=cov, cov_v=cov_v)
    R = fix_covariance(sol)
    np.testing.assert_allclose(R, np.diag([0.01, 0.04, 0.09, 4.0, 1.0, 9.0]), atol=1e-9)


def _epoch(sample, sow, fix_sow=None):
    import types

    obs = types.SimpleNamespace(week=755, sow=sow, prn=np.array([27]), cn0_dbhz=np.array([40.0]))
    sol = types.SimpleNamespace(valid=fix_sow is not None, week=755, sow=fix_sow)
    return types.SimpleNamespace(sample=sample, obs=obs, sol=sol, nav={}, iono=None, sat=None)


def test_epochs_are_placed_by_their_bdt_and_the_ins_interpolated():
    """An epoch goes to the interval whose IMU span holds its BDT (receiver time minus the
    clock bias / c: loose the fix's own, tight the filter's), not its receiver time."""
    import types

    from sdr_di.constants import C_LIGHT
    from sdr_di.integration.gnss_epochs import ScalarEpochSource
    from sdr_di.integration.loop import Interval
    from sdr_di.integration.loose_fixes import LooseFixSource

    imu_t = np.arange(0, 2.0001, 0.005)
    sow0 = 1000.0
    fs = 1000.0
    # receiver time 1.000 s; the clock runs 12 ms ahead of BDT: BDT 0.988 s
    b = 0.012 * C_LIGHT
    ep = _epoch(1000, sow0 + 1.0, fix_sow=sow0 + 0.988)
    ivs = [Interval(i0, i0 + 4, round(imu_t[i0] * fs), round(imu_t[i0 + 4] * fs))
           for i0 in range(0, 396, 4)]                     # 20 ms intervals
    loop = types.SimpleNamespace(clock_bias_m=b)
    for cls in (LooseFixSource, ScalarEpochSource):
        src = cls([ep], [27], imu_t, (755, sow0), fs, {})
        got = [iv for iv in ivs if (setattr(iv, "clock_bias_m", b) or True)
               and src._take_epoch(loop, iv) is ep]
        assert len(got) == 1
        assert imu_t[got[0].i0] < 0.988 <= imu_t[got[0].i1] + 1e-12, cls
    nav = types.SimpleNamespace
    iv = Interval(0, 4, 0, 20, nav0=nav(llh=np.zeros(3), v_n=np.zeros(3)),
                  nav1=nav(llh=np.array([1.0, 2.0, 3.0]), v_n=np.array([4.0, 0.0, 0.0])))
    llh, v = ScalarEpochSource([], [27], imu_t, (755, sow0), fs, {}).ins_at(iv, 0.015)
    np.testing.assert_allclose(llh, [0.75, 1.5, 2.25])
    np.testing.assert_allclose(v, [3.0, 0.0, 0.0])


#: Static receiver of the synthetic tight set-ups [rad, rad, m].
_LLH0 = np.array([math.radians(40.0), math.radians(116.0), 100.0])


def _static_tight_setup(dur=8.0, d_north_m=0.0, v_east_mps=0.0, clock_bias_m=0.0, p0=None,
                        bad_epoch_s=None, bad_rate_mps=1.5, bad_channels=(0, 1), cn0=45.0,
                        background=False, iono_change_s=None, filter_name="ekf", **src_kw):
    """A static receiver at :data:`_LLH0` with five satellites, observables exact (the PVT's
    forward model at the truth), 5 Hz, through :class:`TightRangeSource` in the integration
    loop with an EKF. The INS starts ``d_north_m`` north of the truth moving ``v_east_mps``
    east, the filter's clock at ``clock_bias_m`` (truth 0); ``p0`` is the initial variance
    diagonal (NaN entries: the IMU spec's bias variances; default: tight around the truth).
    Optionally one corrupted epoch: ``bad_rate_mps`` added to the rates of ``bad_channels``
    at ``bad_epoch_s``, their C/N0 set to ``cn0``. ``background``: as loose and tight mode
    run it, the loop on a second thread (``BackgroundLoop``) waits for the epochs that
    another thread records, with a column for an extra channel (PRN 40) that is never
    seen and dropped at the end (``keep_columns``); ``background="process"``: the loop in a
    child process (``LoopProcess``) fed by the recorder. ``iono_change_s``: the epochs carry
    a Klobuchar object, another one (equal values) from that time on. Returns the loop's
    columns and the source."""
    import types

    from sdr_di.constants import OMEGA_E
    from sdr_di.filters import make_filter
    from sdr_di.frames import C_e_n, llh_to_ecef
    from sdr_di.ins.error_model import InsErrorModel, process_noise
    from sdr_di.ins.gravity import normal_gravity
    from sdr_di.ins.imu import ImuErrorModel
    from sdr_di.ins.mechanization import StrapdownINS
    from sdr_di.integration.gnss_epochs import GnssEpoch
    from sdr_di.integration.loop import IntegrationLoop
    from sdr_di.coupling.measurements import RangeRateMeasurementModel
    from sdr_di.integration.tight_ranges import TightRangeSource
    from sdr_di.receiver.observables import Observables
    from sdr_di.receiver.pvt import SatelliteStates, modelled_observables

    rate, fs, sow0, week = 200.0, 1000.0, 369000.0, 755
    llh0 = _LLH0
    r0 = llh_to_ecef(*llh0)
    n = round(dur * rate) + 1
    lat = llh0[0]
    imu = types.SimpleNamespace(
        t=np.arange(n) / rate, rate_hz=rate,
        f_b=np.tile([0.0, 0.0, float(normal_gravity(lat, llh0[2]))], (n, 1)),
        w_ib_b=np.tile([0.0, OMEGA_E * math.cos(lat), OMEGA_E * math.sin(lat)], (n, 1)))
    C_n_e = C_e_n(llh0[0], llh0[1]).T
    dirs = []
    for az, el in ((10, 70), (100, 40), (190, 35), (280, 50), (45, 20)):
        a, e = math.radians(az), math.radians(el)
        dirs.append(C_n_e @ [math.sin(a) * math.cos(e), math.cos(a) * math.cos(e), math.sin(e)])
    ns = len(dirs)
    sat = SatelliteStates(np.ones(ns, bool), r0 + 2.2e7 * np.array(dirs), np.zeros((ns, 3)),
                          np.zeros(ns), np.zeros(ns), ())
    from sdr_di.deep.vector_tracking import SampleClock
    from sdr_di.orbits.ephemeris import Klobuchar

    klob = [Klobuchar(alpha=(0.0,) * 4, beta=(72000.0, 0.0, 0.0, 0.0)) for _ in range(2)]
    epochs = []
    for k in range(0, round(dur * fs), 200):                  # 5 Hz
        P, D, _, _ = modelled_observables(sat, np.arange(ns), r0, np.zeros(3), 0.0, 0.0,
                                          sow0 + k / fs, None)
        c = np.full(ns, 45.0)
        if bad_epoch_s is not None and k == round(bad_epoch_s * fs):
            D = D.copy()
            D[list(bad_channels)] += bad_rate_mps
            c[list(bad_channels)] = cn0
        obs = Observables(sample_index=k, week=week, sow=sow0 + k / fs,
                          prn=np.arange(1, ns + 1), t_tx_week=np.full(ns, week),
                          t_tx_sow=np.full(ns, sow0), pseudorange_m=P,
                          pseudorange_rate_mps=D, doppler_hz=np.zeros(ns),
                          carrier_phase_m=np.zeros(ns), cn0_dbhz=c)
        iono = None if iono_change_s is None else klob[int(k >= iono_change_s * fs)]
        epochs.append(GnssEpoch(k, obs, sat, iono, None, {}))
    ins = StrapdownINS(llh0 + [d_north_m / 6.37e6, 0.0, 0.0], np.array([v_east_mps, 0.0, 0.0]),
                       att=np.zeros(3))
    ins.set_previous_increments(imu.f_b[0], imu.w_ib_b[0], 1.0 / rate)
    T = 4 / rate
    spec = ImuErrorModel()
    Q = process_noise(T, gyro_random_walk_si=spec.gyro_random_walk_si,
                      accel_random_walk_si=spec.accel_random_walk_si,
                      gyro_bias_si=spec.gyro_bias_si, accel_bias_si=spec.accel_bias_si)
    biases = np.r_[[spec.gyro_bias_si ** 2] * 3, [spec.accel_bias_si ** 2] * 3]
    if p0 is None:
        p0 = np.r_[[1e-3 ** 2] * 3, [0.01] * 3, (1 / 6.4e6) ** 2, (1 / 6.4e6) ** 2, 1.0,
                   biases, 1.0, 0.01]
    p0 = np.where(np.isnan(p0), np.r_[np.zeros(9), biases, 0.0, 0.0], p0)
    process, model = InsErrorModel(), RangeRateMeasurementModel()
    kf = make_filter(filter_name, process, model, np.zeros(17), np.diag(p0), Q, None, dt=T)
    loop = IntegrationLoop(
        imu=imu, t_if=imu.t, i_start=0, k_start=0, n_per=4, fs=fs, stop=10 ** 9, margin=0,
        ins=ins, clock_bias_m=clock_bias_m, clock_drift_mps=0.0, kf=kf, process=process,
        set_geometry=model.set_geometry,     # sow0 + k / fs, picklable for the process
        sow_of_sample=SampleClock(week, sow0, 0.0, 0.0, fs).sow, output_every=1)
    if not background or background == "built":
        src = TightRangeSource(epochs, list(range(1, ns + 1)), imu.t, (week, sow0), fs, {},
                               **src_kw)
        if background == "built":          # not run: (loop, source, epochs)
            return loop, src, epochs
        loop.run(src)
        return loop.columns(ns), src
    import threading
    import time

    from sdr_di.integration.gnss_epochs import GnssEpochRecorder
    from sdr_di.integration.loop import BackgroundLoop

    rec = GnssEpochRecorder(None, None)
    src = TightRangeSource(rec, list(range(1, ns + 1)) + [40], imu.t, (week, sow0), fs, {},
                           **src_kw)

    def produce():
        for ep in epochs:
            time.sleep(0.1)               # slower than the loop: it catches up and waits
            rec.append(ep)
        rec.close()

    producer = threading.Thread(target=produce)
    if background == "process":
        from sdr_di.integration.loop_process import LoopProcess

        run = LoopProcess(loop, src, src, rec)
        producer.start()
        run.join()
        loop, src = run.loop, run.epoch_source
        assert run.cpu_s > 0.0
    else:
        producer.start()
        BackgroundLoop(loop, src).join()
    producer.join()
    src.keep_columns(range(1, ns + 1), loop.rows)
    return loop.columns(ns), src


def test_tight_source_pulls_an_ins_error_in_through_the_loop():
    """Static receiver, five satellites, observables from the PVT's own forward model at the
    truth (so only the INS error is seen): the tight source in the unchanged integration
    loop pulls a 20 m north / 0.5 m/s east INS error and a 30 m clock error in."""
    wide = np.r_[[1e-3 ** 2] * 3, [1.0] * 3, (30 / 6.4e6) ** 2, (30 / 6.4e6) ** 2, 900.0,
                 [np.nan] * 6, 2500.0, 1.0]
    cols, _ = _static_tight_setup(dur=12.0, d_north_m=20.0, v_east_mps=0.5, clock_bias_m=30.0,
                                  p0=wide)
    assert np.all(cols["n"][9:] == 5)                # the first epoch in (0.18, 0.2] s
    assert np.all(np.isnan(cols["nis"][:9]))        # no update before the first epoch
    assert np.isfinite(cols["nis"]).sum() >= 55      # then one per epoch (5 Hz, 12 s)
    north_m = (cols["llh"][:, 0] - _LLH0[0]) * 6.37e6
    assert north_m[8] > 15.0                         # before the first update
    assert abs(north_m[-1]) < 0.5
    assert np.linalg.norm(cols["v"][-1]) < 0.05
    assert abs(cols["b"][-1]) < 0.5                  # truth clock bias 0


@pytest.mark.parametrize("cn0", [45.0, math.nan])
def test_tight_gate_keeps_a_lost_channels_rate_out(cn0):
    """At a tunnel entry the scalar receiver still reports channels that have lost the signal
    (their lock detectors lag by a few hundred ms): their rates are noise. One epoch 4 s in
    with 1.5 m/s on two of five rates (C/N0 still 45 dB-Hz: only the innovation gate can
    catch it; NaN: the C/N0 screen) must not reach the INS: with the gate and the screen
    the velocity stays within 0.02 m/s of the truth (static, exact observables); without
    them (``gate_alpha=0``, ``min_cn0_dbhz=None``) the one update pulls it off by ~0.1 m/s
    or more, the failure seen at the tunnel entry of the outage experiment."""
    cols, src = _static_tight_setup(bad_epoch_s=4.0, cn0=cn0)
    v = np.linalg.norm(cols["v"], axis=1)
    assert v.max() < 0.02, v.max()
    assert (src.n_screened if math.isnan(cn0) else src.n_gated) == 2
    off, _ = _static_tight_setup(bad_epoch_s=4.0, cn0=cn0, gate_alpha=0.0,
                                 min_cn0_dbhz=None)
    assert np.linalg.norm(off["v"], axis=1).max() > 0.05
    _, src0 = _static_tight_setup()
    assert src0.n_gated == 0 and src0.n_screened == 0     # nothing good rejected


def _flat_columns(cols: dict) -> dict:
    """The loop's columns with the nested ``updates`` arrays as ``updates.<key>``."""
    flat = {}
    for k, v in cols.items():
        if isinstance(v, dict):
            flat.update({f"{k}.{kk}": vv for kk, vv in v.items()})
        else:
            flat[k] = v
    return flat


def test_loop_behind_the_receiver_gives_the_rows_of_a_loop_after_it():
    """Loose and tight mode run the loop on a second thread while the scalar receiver still
    records epochs: the loop waits for each epoch it needs, so its rows are those of a loop
    run over the finished list, bit for bit (with a corrupted epoch, so the gate acts)."""
    seq, s_seq = _static_tight_setup(dur=4.0, bad_epoch_s=2.0)
    bg, s_bg = _static_tight_setup(dur=4.0, bad_epoch_s=2.0, background=True)
    assert s_bg.prns == s_seq.prns and s_bg.n_gated == s_seq.n_gated == 2
    a, b = _flat_columns(seq), _flat_columns(bg)
    assert a.keys() == b.keys()
    for k in a:
        assert a[k].shape == b[k].shape, k
        assert np.array_equal(a[k], b[k], equal_nan=True), k


def test_loop_in_a_child_process_gives_the_rows_of_the_loop_on_a_thread():
    """Loose and tight mode run the loop in a child process fed epoch by epoch: its rows,
    gate counts and navigation record are those of the loop run over the finished list,
    bit for bit; two Klobuchar objects with the same values are two models there as here
    (the source marks a change by identity, which the feed keeps)."""
    seq, s_seq = _static_tight_setup(dur=3.0, bad_epoch_s=2.0, iono_change_s=1.0)
    pr, s_pr = _static_tight_setup(dur=3.0, bad_epoch_s=2.0, iono_change_s=1.0,
                                   background="process")
    assert len(s_seq.navigation["ionosphere"]) == 2
    assert s_pr.navigation == s_seq.navigation
    assert (s_pr.prns, s_pr.n_gated, s_pr.n_screened) == (s_seq.prns, s_seq.n_gated,
                                                           s_seq.n_screened)
    a, b = _flat_columns(seq), _flat_columns(pr)
    assert a.keys() == b.keys()
    for k in a:
        assert a[k].shape == b[k].shape, k
        assert np.array_equal(a[k], b[k], equal_nan=True), k


def test_loop_process_hands_back_the_loops_exception():
    """An exception of the loop in its child process is raised by ``join`` in the parent,
    the same type and text as on a thread (a loop without a process model)."""
    from sdr_di.integration.gnss_epochs import GnssEpochRecorder
    from sdr_di.integration.loop import BackgroundLoop
    from sdr_di.integration.loop_process import LoopProcess

    def broken(run):
        loop, src, epochs = _static_tight_setup(dur=1.0, background="built")
        loop.process = None
        rec = GnssEpochRecorder(None, None)
        for ep in epochs:
            rec.append(ep)
        rec.close()
        src.attach_epochs(rec.epochs, rec.wait_for)
        return run(loop, src, rec)

    with pytest.raises(AttributeError) as on_thread:
        broken(lambda loop, src, rec: BackgroundLoop(loop, src).join())
    with pytest.raises(AttributeError) as in_child:
        broken(lambda loop, src, rec: LoopProcess(loop, src, src, rec).join())
    assert str(in_child.value) == str(on_thread.value)


def test_loop_process_compiles_the_rules_kernels_outside_their_timed_hooks():
    """ff-aukf in the loop's child process: its numba kernels are new to the child's
    interpreter and are loaded before the loop runs, so that the rule's adaptation time
    (a reported figure, paper 004's) holds its hooks' time only, not numba's start-up
    (0.15 s from a warm cache, 0.5-0.8 s and more from a cold one, in the first hook)."""
    seq, _ = _static_tight_setup(dur=2.0, filter_name="ff-aukf")
    loop, src, epochs = _static_tight_setup(dur=2.0, filter_name="ff-aukf",
                                            background="built")
    from sdr_di.integration.gnss_epochs import GnssEpochRecorder
    from sdr_di.integration.loop_process import LoopProcess

    rec = GnssEpochRecorder(None, None)
    src.attach_epochs(rec.epochs, rec.wait_for)
    run = LoopProcess(loop, src, src, rec)
    for ep in epochs:
        rec.append(ep)
    rec.close()
    run.join()
    assert run.loop.kf.rule is not None and run.loop.kf.adaptation_time_s < 0.05
    cols = run.loop.columns(src.n_channels)
    a, b = _flat_columns(seq), _flat_columns(cols)
    for k in a:
        assert np.array_equal(a[k], b[k], equal_nan=True), k


def test_a_dead_loop_process_is_replaced_by_the_loop_here():
    """A child that dies without a result (here: exits at once) is reported by a warning
    and the loop runs in the parent over the recorded epochs: the rows of a sequential
    run."""
    import subprocess
    import sys
    import types

    from sdr_di.integration.gnss_epochs import GnssEpochRecorder
    from sdr_di.integration.loop_process import LoopProcess

    seq, _ = _static_tight_setup(dur=2.0)
    loop, src, epochs = _static_tight_setup(dur=2.0, background="built")
    rec = GnssEpochRecorder(None, None)
    src.attach_epochs(rec.epochs, rec.wait_for)
    dead = types.SimpleNamespace(proc=subprocess.Popen(
        [sys.executable, "-c", "import sys; sys.exit(3)"], stdin=subprocess.PIPE,
        stdout=subprocess.PIPE))
    run = LoopProcess(loop, src, src, rec, child=dead)
    for ep in epochs:
        rec.append(ep)
    rec.close()
    with pytest.warns(RuntimeWarning, match="exit status 3"):
        run.join()
    cols = run.loop.columns(src.n_channels)
    a, b = _flat_columns(seq), _flat_columns(cols)
    for k in a:
        assert np.array_equal(a[k], b[k], equal_nan=True), k


def test_fixed_noise_source_pickles_for_the_loop_process():
    """The ``[measurement_noise] policy = "fixed"`` wrapper goes to the loop's child process
    with its source (its attribute delegation must not recurse while unpickling)."""
    import pickle

    from sdr_di.integration.assumptions import FixedNoiseSource

    loop, src, _ = _static_tight_setup(dur=1.0, background="built")
    _, w = pickle.loads(pickle.dumps((loop, FixedNoiseSource(src, 2.0, 0.1))))
    assert w._sig == (2.0, 0.1) and w.prns == src.prns and w.n_channels == src.n_channels


def test_run_modules_leave_the_slow_imports_out():
    """``sdr-di run --mode loose|tight|deep`` and the loop's child process import neither
    ``scipy.stats`` (the gate's quantile) nor ``scipy.optimize`` (ML-R's SQP, imported
    when that filter first solves): ~0.6 s and ~0.15 s of CPU at every run's start."""
    import subprocess
    import sys

    code = ("import sys, sdr_di.integration.run_integrated, sdr_di.integration.loop_process; "
            "print(sorted(m for m in ('scipy.stats', 'scipy.optimize') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "[]"


def test_gate_quantile_is_scipys_chi2_ppf():
    """The gate's chi-square quantile (computed without importing scipy.stats) is the value
    ``scipy.stats.chi2.ppf`` gives, bit for bit."""
    from scipy.stats import chi2

    from sdr_di.integration.gnss_epochs import _chi2_quantile

    for p in (1 - 1e-4, 1 - 1e-2, 0.5):
        for dof in (1, 2, 6, 14):
            assert _chi2_quantile(p, dof) == float(chi2.ppf(p, dof))


def test_loose_gate_drops_a_fix_outside_its_innovation_covariance_and_recovers():
    """Loose: a fix whose NIS ``y^T S^-1 y`` exceeds the 6-dof quantile at 1 - 1e-4 (27.9) is
    dropped; one within it is kept; after ``gate_reset_epochs`` gated epochs in a row the
    next is taken ungated (an INS drifted beyond its ``P`` must not lock itself out)."""
    import types

    from sdr_di.integration.loop import Measurements
    from sdr_di.integration.loose_fixes import LooseFixSource
    from sdr_di.coupling.measurements import LooseMeasurementModel

    llh = np.array([math.radians(40.0), math.radians(116.0), 100.0])
    model = LooseMeasurementModel(llh)
    P = np.diag(np.r_[[1e-6] * 3, [0.01] * 3, [(1 / 6.4e6) ** 2] * 2, 1.0, [1e-10] * 8])
    kf = types.SimpleNamespace(P=P, x=np.zeros(17), measurement_model=model)
    loop = types.SimpleNamespace(kf=kf, set_geometry=model.set_epoch)
    R = np.diag([0.01] * 3 + [1.0] * 3)            # S = 0.02 (m/s)^2, 2 m^2 on the diagonal
    src = LooseFixSource([], [27], np.arange(3.0), (755, 0.0), 1000.0, {})
    assert src.gate_limit(6) == pytest.approx(27.86, abs=0.01)

    def m(z):
        return Measurements(z=np.asarray(z, float), R=R, geometry=(llh,),
                            used=np.ones(1, bool))

    good = m([0.2, -0.2, 0.1, 1.5, -1.5, 2.0])      # NIS about 9
    assert src._gated(loop, None, None, good).z is not None
    bad = m([0.8, 0.0, 0.0, 0.0, 0.0, 0.0])         # NIS 32 (a lost channel's velocity)
    for _ in range(src.gate_reset_epochs):
        assert src._gated(loop, None, None, bad).z is None
    assert src.n_gated == src.gate_reset_epochs
    assert src._gated(loop, None, None, bad).z is not None      # recovery
    assert src._gated(loop, None, None, bad).z is None          # the count restarts
