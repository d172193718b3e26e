"""Deep-receiver experiments of issue 6 (``count-change``, ``outage``, ``weak-signal``).

The two end-to-end tests run the real experiment (scenario -> generated IF at 2.5 MHz ->
scalar start-up -> hand-over -> vector loop) at reduced size, once per module
(module-scoped fixtures, one generated file each), and check the behaviour issue 6 asks for:
``ff-aukf`` runs through every count change of 7-6-5-4-5-6-7 with position error below 5 m,
and after a 5 s blockage of every satellite each channel rejoins the measurement vector within
1 s without an acquisition search. The schedule starts at 14 s: the hand-over from scalar
tracking happens at about 12.2 s of the default scenario.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from sdr_di.errors import ExperimentError
from sdr_di.experiments import count_change, outage, weak_signal
from sdr_di.studies.aggregate import single_stats
from sdr_di.experiments.registry import get_experiment, parse_params

FS = 2.5e6


# ---- count-change ----------------------------------------------------------------------------
CC_PARAMS = {"filters": "ff-aukf", "counts": "7,6,5,4,5,6,7", "t_start_s": 14.0,
             "segment_s": 1.5, "sampling_rate_hz": FS}


@pytest.fixture(scope="module")
def cc(tmp_path_factory):
    out = tmp_path_factory.mktemp("count_change")
    params = parse_params(get_experiment("count-change"), overrides=CC_PARAMS)
    return count_change.run(params, 0, out), out


def test_count_change_ff_aukf_runs_through_every_count_change(cc):
    fig, _out = cc
    f = "ff-aukf"
    assert f"{f}.error" not in fig
    assert fig[f"{f}.completed"] == 1
    assert fig[f"{f}.handover_s"] < CC_PARAMS["t_start_s"]
    assert fig[f"{f}.through_all"] == 1
    assert fig[f"{f}.pos_m_max"] < 5.0
    counts = [int(c) for c in CC_PARAMS["counts"].split(",")]
    for i, c in enumerate(counts):
        assert fig[f"seg{i}.count"] == c
        assert math.isfinite(fig[f"{f}.seg{i}.pos_m_rmse"])
        assert fig[f"{f}.seg{i}.pos_m_max"] < 5.0, f"segment {i} ({c} satellites)"
    assert fig[f"{f}.acq_after_handover"] == 0


def test_count_change_blockage_reaches_the_measurement_vector(cc):
    """The schedule is real: in every segment the loop used the scheduled number of
    channels most of the time (the median), down to 4."""
    fig, out = cc
    with open(out / "errors_ff-aukf.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    t = np.array([float(r["t_s"]) for r in rows])
    n_used = np.array([int(float(r["n_used"])) for r in rows])
    sched = np.array([int(float(r["scheduled_count"])) for r in rows])
    for i, c in enumerate(int(x) for x in CC_PARAMS["counts"].split(",")):
        t0 = fig[f"seg{i}.t0_s"]
        sel = (t >= t0) & (t < t0 + CC_PARAMS["segment_s"])
        assert sel.sum() >= 5
        assert np.all(sched[sel] == c)
        assert np.median(n_used[sel]) == c, f"segment {i}: n_used {n_used[sel].tolist()}"
    assert 0.5 < fig["ff-aukf.count_match"] <= 1.0
    assert (out / "error_norms.png").stat().st_size > 0
    assert (out / "satellite_count.png").stat().st_size > 0


def test_count_change_tables_from_one_run(cc):
    fig, _ = cc
    tabs = count_change.tables(single_stats(fig))
    (row,) = tabs["filters"]
    assert row["filter"] == "ff-aukf" and row["through_all"] == 1
    assert row["pos_m_max"] == pytest.approx(fig["ff-aukf.pos_m_max"])
    assert [r["count"] for r in tabs["segments"]] == [7, 6, 5, 4, 5, 6, 7]


def test_count_change_schedule_blocks_the_lowest_satellites_first():
    segs, outs = count_change.schedule([1, 2, 3, 4, 5], [5, 4, 3, 4, 5], 10.0, 2.0, 25.0)
    assert segs == [(10.0, 12.0, 5), (12.0, 14.0, 4), (14.0, 16.0, 3), (16.0, 18.0, 4),
                    (18.0, 25.0, 5)]
    assert outs == [{"prn": 4, "start_s": 14.0, "end_s": 16.0, "blockage": True},
                    {"prn": 5, "start_s": 12.0, "end_s": 18.0, "blockage": True}]
    with pytest.raises(ExperimentError, match="simulates 5 satellites"):
        count_change.schedule([1, 2, 3, 4, 5], [6, 5], 10.0, 2.0, 25.0)


@pytest.mark.parametrize("pair, match", [
    ("counts=7,x", "comma list"), ("counts=7,0", ">= 1"), ("filters=kalman", "unknown filter"),
    ("segment_s=0", "segment_s"), ("duration_s=20", "ends before"),
])
def test_count_change_bad_params(pair, match):
    with pytest.raises(ExperimentError, match=match):
        parse_params(get_experiment("count-change"), [pair])


# ---- outage ----------------------------------------------------------------------------------
OUT_PARAMS = {"filters": "ff-aukf", "outages": "5", "t_first_s": 14.0, "gap_s": 4.0,
              "sampling_rate_hz": FS}


@pytest.fixture(scope="module")
def out_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("outage")
    params = parse_params(get_experiment("outage"), overrides=OUT_PARAMS)
    return outage.run(params, 0, out), out


def test_outage_every_channel_rejoins_within_1s_without_acquisition(out_run):
    fig, _out = out_run
    p = "ff-aukf.o0."
    assert fig["ff-aukf.completed"] == 1
    assert fig["ff-aukf.handover_s"] < OUT_PARAMS["t_first_s"]
    assert fig["o0.duration_s"] == 5.0
    assert fig[p + "all_left"] == 1          # the loop saw the blockage
    rejoin = {k: v for k, v in fig.items() if k.startswith(p + "rejoin_s.C")}
    assert len(rejoin) == 7
    assert all(0.0 <= v <= 1.0 for v in rejoin.values()), rejoin
    assert fig[p + "all_rejoined"] == 1 and fig[p + "n_rejoined"] == 7
    assert fig["ff-aukf.acq_after_handover"] == 0
    assert fig[p + "used_after"] > 0.9


def test_outage_error_growth_is_measured_during_the_blockage(out_run):
    fig, out = out_run
    p = "ff-aukf.o0."
    for key in ("pos_m_start", "pos_m_max", "pos_m_rmse_after", "vel_mps_max"):
        assert math.isfinite(fig[p + key]), key
    assert fig[p + "pos_growth_m"] == pytest.approx(fig[p + "pos_m_max"] - fig[p + "pos_m_start"])
    with open(out / "errors_ff-aukf.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    t = np.array([float(r["t_s"]) for r in rows])
    pos = np.array([[float(r[f"pos_err_{a}_m"]) for a in "enu"] for r in rows])
    inside = (t >= 14.0) & (t < 19.0)
    assert np.linalg.norm(pos[inside], axis=1).max() == pytest.approx(fig[p + "pos_m_max"])
    (row,) = outage.tables(single_stats(fig))["outages"]
    assert row["all_rejoined"] == 1 and row["duration_s"] == 5.0
    assert (out / "channels_ff-aukf.png").stat().st_size > 0


def test_rejoin_times():
    t = np.arange(0.0, 3.0, 0.1)
    used = np.zeros((t.size, 3), bool)
    used[t >= 1.2, 0] = True
    used[t >= 1.95, 1] = True
    used[(t >= 0.5) & (t < 0.8), 2] = True      # used before the return only
    r = outage.rejoin_times(t, used, 1.0, 2.5)
    assert r[0] == pytest.approx(0.2) and r[1] == pytest.approx(1.0) and math.isnan(r[2])
    wins, dur = outage.outage_windows([5.0, 10.0], 15.0, 15.0)
    assert wins == [(15.0, 20.0), (35.0, 45.0)] and dur == 60.0


# ---- weak-signal (cheap parts; the sweep itself is a full run, see docs/experiments.md) --------
def test_weak_signal_levels_and_threshold():
    p = dict(weak_signal.default_params)
    assert weak_signal.levels(p) == [40.0, 37.5, 35.0, 32.5, 30.0, 27.5, 25.0, 22.5, 20.0,
                                     17.5, 15.0]
    assert weak_signal.levels({**p, "levels": "30,40,35"}) == [40.0, 35.0, 30.0]
    assert weak_signal.threshold({40.0: True, 35.0: True, 30.0: False, 25.0: True}) == 35.0
    assert math.isnan(weak_signal.threshold({40.0: False, 35.0: True}))


@pytest.mark.parametrize("pair, match", [
    ("modes=vector", "modes"), ("levels=45", "cannot be made"), ("keep_fraction=1.5", "0 <"),
    ("filter=nope", "unknown filter"), ("settle_s=20", "shorter than hold_s"),
])
def test_weak_signal_bad_params(pair, match):
    with pytest.raises(ExperimentError, match=match):
        parse_params(get_experiment("weak-signal"), [pair])


def test_weak_signal_step_is_an_attenuation_window():
    """The C/N0 step uses the schema's attenuation window: amplitude factor 10^(-dB/20)
    from the step on, 1 before."""
    from sdr_di.experiments._deep import base_scenario, with_outages
    from sdr_di.sim.generate import make_generator

    p = {**weak_signal.default_params, "sampling_rate_hz": FS}
    sc = base_scenario({**p, "cn0_dbhz": 40.0}, 0, 4.0)
    sc = with_outages(sc, [{"prn": "all", "start_s": 2.0, "end_s": 5.0,
                            "attenuation_db": 12.5}])
    gen = make_generator(sc)
    f = gen.outage_factor(gen.sats[0].prn, np.array([1.9, 2.0, 3.9]))
    assert f == pytest.approx([1.0, 10 ** (-12.5 / 20), 10 ** (-12.5 / 20)])
    assert Path(sc.satellites.ephemeris).is_file()


@pytest.mark.slow
def test_weak_signal_deep_holds_25_dbhz_where_scalar_tracking_fails(tmp_path):
    """Reduced sweep, one level: 40 dB-Hz until 14 s, then 25 dB-Hz for 6 s (2.5 MHz).
    The deep receiver keeps every channel with position error below 10 m; the scalar
    receiver, whose threshold on this scenario is 30 dB-Hz (docs/experiments.md), does not
    hold the level: the gap issue 6 asks for (at least 5 dB) seen at one level."""
    params = parse_params(get_experiment("weak-signal"), overrides={
        "levels": "25", "t_step_s": 14.0, "hold_s": 6.0, "settle_s": 1.0,
        "sampling_rate_hz": FS, "plots": False})
    fig = weak_signal.run(params, 0, tmp_path)
    assert "L25.deep.error" not in fig
    assert fig["L25.deep.handover_s"] < 14.0
    assert fig["L25.deep.keep_min"] >= 0.95 and fig["L25.deep.all_kept_last"] == 1
    assert fig["L25.deep.pos_m_max"] < 10.0
    assert fig["L25.deep.pass"] == 1
    assert fig["L25.scalar.pass"] == 0
    assert fig["L25.scalar.keep_min"] < 0.5
    assert fig["deep.threshold_dbhz"] == 25.0 and math.isnan(fig["scalar.threshold_dbhz"])


def test_weak_signal_pass_criteria():
    p = dict(weak_signal.default_params)
    kept = np.ones((40, 3), bool)
    err = np.full(40, 2.0)
    valid = np.ones(40, bool)
    assert weak_signal._judge(kept, err, valid, p)["pass"] == 1
    k = kept.copy()
    k[:3, 1] = False                                   # 92.5 % < 95 %
    j = weak_signal._judge(k, err, valid, p)
    assert j["pass"] == 0 and j["keep_min"] == pytest.approx(37 / 40)
    k = kept.copy()
    k[-1, 2] = False                                   # lost at the end
    assert weak_signal._judge(k, err, valid, p)["pass"] == 0
    e = err.copy()
    e[20] = 10.5                                       # one epoch over 10 m
    assert weak_signal._judge(kept, e, valid, p)["pass"] == 0
    v = valid.copy()
    v[5] = False                                       # an epoch without a fix
    assert weak_signal._judge(kept, err, v, p)["pass"] == 0
