"""The experiments across coupling modes (issue 13 item 4): variant labels, filter entries with
options, the mode parameter of count-change / outage / weak-signal, the shared per-variant
bookkeeping (:mod:`sdr_di.experiments.variants`), and the outage's time to a good solution.

The loose/tight end-to-end test needs the receiver's coupling modes (``IntegrationConfig.mode``);
it is skipped where the receiver has none.
"""

from __future__ import annotations

import csv
import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from sdr_di.errors import ExperimentError
from sdr_di.experiments import count_change, outage
from sdr_di.studies.aggregate import aggregate, single_stats
from sdr_di.experiments.entries import check_filter_entry
from sdr_di.experiments.filter_figures import filter_names_in
from sdr_di.experiments.registry import get_experiment, parse_params
from sdr_di.experiments.variants import (
    Variant,
    nan_figures,
    variant_label,
    variant_list,
    variant_rows,
    write_errors_csv,
)


def test_variant_labels_keep_deep_names_and_tag_the_other_couplings():
    vs = variant_list("x", "ekf,ff-aukf:q_states=nominal", "deep,tight,loose")
    assert [v.label for v in vs] == ["ekf", "ff-aukf:q_states=nominal", "ekf@tight",
                                     "ff-aukf:q_states=nominal@tight", "ekf@loose",
                                     "ff-aukf:q_states=nominal@loose"]
    assert vs[1].filter == "ff-aukf" and vs[1].options == {"q_states": "nominal"}
    assert variant_label("ukf", "deep") == "ukf"
    stats = {f"{v.label}.pos_m_rmse": {} for v in vs} | {"seg0.count": {}, "o0.start_s": {}}
    assert filter_names_in(stats) == [v.label for v in vs]


@pytest.mark.parametrize("spec, match", [
    ("kalman", "unknown filter"), ("ff-aukf:window", "not key=value"),
    ("ff-aukf:adapt_q=maybe", "true/false"), ("ekf@tight", "not allowed"),
])
def test_bad_filter_entries_are_one_line_errors(spec, match):
    with pytest.raises(ExperimentError, match=match):
        check_filter_entry("x", spec)


def test_filter_options_are_read_as_numbers_where_they_are_numbers():
    assert check_filter_entry("x", "ff-aukf:window=25:q_states=all") == (
        "ff-aukf", {"window": 25, "q_states": "all"})


@pytest.mark.parametrize("exp", ["count-change", "outage"])
def test_modes_parameter(exp):
    p = parse_params(get_experiment(exp), ["modes=loose,tight,deep"])
    assert p["modes"] == "loose,tight,deep"
    with pytest.raises(ExperimentError, match="modes"):
        parse_params(get_experiment(exp), ["modes=vector"])
    with pytest.raises(ExperimentError, match="modes"):
        parse_params(get_experiment(exp), ["modes=scalar"])   # scalar has no filter


def test_weak_signal_takes_every_mode_and_filter_options():
    p = parse_params(get_experiment("weak-signal"),
                     ["modes=scalar,loose,tight,deep", "filter=ff-aukf:q_states=nominal"])
    assert p["modes"] == "scalar,loose,tight,deep"


def test_count_change_schedule_below_four():
    prns = [27, 8, 13, 10, 30, 28, 32]
    segs, outs = count_change.schedule(prns, [7, 5, 3, 2, 3, 5, 7], 15.0, 10.0, 85.0)
    assert [c for *_, c in segs] == [7, 5, 3, 2, 3, 5, 7]
    blocked = {o["prn"]: (o["start_s"], o["end_s"]) for o in outs}
    assert blocked[32] == (25.0, 75.0) and blocked[28] == (25.0, 75.0)   # out from 5 on
    assert blocked[10] == (35.0, 65.0) and blocked[30] == (35.0, 65.0)   # out from 3 on
    assert blocked[13] == (45.0, 55.0)                                   # out at 2 only
    assert 27 not in blocked and 8 not in blocked


def test_first_good_solution_after_the_tunnel():
    t = np.arange(0.0, 10.0, 0.5)
    n_used = np.where(t >= 6.0, 5, 0)
    pos = np.where(t >= 7.0, 1.0, 30.0)
    assert outage.first_good_s(t, n_used, pos, 5.0, 10.0, 5.0) == pytest.approx(2.0)
    assert math.isnan(outage.first_good_s(t, n_used, pos, 5.0, 6.5, 5.0))
    # measurements alone are not enough: the position must be good too
    assert outage.first_good_s(t, n_used, np.full(t.size, 30.0), 5.0, 10.0, 5.0) != 1.0


def test_variant_rows_one_row_per_label_with_spread_over_runs():
    runs = [{"ekf.pos_m_rmse": 1.0, "ekf@tight.pos_m_rmse": 2.0, "n": 3},
            {"ekf.pos_m_rmse": 3.0, "ekf@tight.pos_m_rmse": 4.0, "n": 3}]
    rows = variant_rows(aggregate(runs), ("pos_m_rmse", "vel_mps_rmse"))
    assert [r["filter"] for r in rows] == ["ekf", "ekf@tight"]
    assert rows[0]["pos_m_rmse"] == 2.0 and rows[0]["pos_m_rmse_std"] == pytest.approx(
        math.sqrt(2.0))
    assert math.isnan(rows[1]["vel_mps_rmse"])
    one = variant_rows(single_stats(runs[0]), ("pos_m_rmse",), extra_col=1)
    assert "pos_m_rmse_std" not in one[0] and one[0]["extra_col"] == 1
    assert set(nan_figures("ekf@loose")) == {f"ekf@loose.{q}_{s}" for q in
                                             ("att_deg", "vel_mps", "pos_m")
                                             for s in ("rmse", "max")}
    assert "ekf.win_pos_m_max" in nan_figures("ekf", "win_")


def test_errors_csv_columns(tmp_path):
    @dataclasses.dataclass
    class R:
        t = np.array([0.0, 0.1])
        n_used = np.array([2, 1])
        prns = (8, 27)
        used = np.array([[True, True], [True, False]])
        cn0_dbhz = np.array([[40.0, 39.0], [41.0, 20.0]])
        att_err = np.zeros((2, 3))
        vel_err = np.ones((2, 3))
        pos_err = np.full((2, 3), 2.0)

    path = write_errors_csv(tmp_path / "e.csv", R(), {"scheduled_count": np.array([2, 1])})
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0])[:7] == ["t_s", "n_used", "used_C08", "used_C27", "cn0_C08", "cn0_C27",
                                 "scheduled_count"]
    assert rows[1]["used_C27"] == "0" and rows[1]["pos_err_u_m"] == "2"


def _has_modes() -> bool:
    from sdr_di.integration.receiver import IntegrationConfig

    return "mode" in {f.name for f in dataclasses.fields(IntegrationConfig)}


@pytest.mark.slow
@pytest.mark.skipif(not _has_modes(), reason="the receiver has no loose/tight coupling yet")
def test_count_change_three_satellites_tight_updates_loose_coasts(tmp_path):
    """7 -> 3 -> 7 satellites (2.5 MHz): with 3 in view the WLS fix (loose) is gone, so the
    filter gets no update, while tight keeps updating with 3 pseudoranges and rates."""
    params = parse_params(get_experiment("count-change"), overrides={
        "filters": "ekf", "modes": "tight,loose", "counts": "7,3,7", "t_start_s": 14.0,
        "segment_s": 4.0, "sampling_rate_hz": 2.5e6, "plots": False})
    fig = count_change.run(params, 0, Path(tmp_path))
    for label in ("ekf@tight", "ekf@loose"):
        assert fig[f"{label}.completed"] == 1, fig.get(f"{label}.error")
    # seg1 is the 3-satellite segment; its first second is the channels leaving
    assert fig["ekf@tight.seg1.updating"] > 0.9
    assert fig["ekf@loose.seg1.updating"] < 0.3
    # back on 7: tight updates throughout, loose gets its fixes back
    assert fig["ekf@tight.seg2.updating"] > 0.9 and fig["ekf@loose.seg2.updating"] > 0.5
    tabs = count_change.tables(single_stats(fig))
    assert {r["filter"] for r in tabs["filters"]} == {"ekf@tight", "ekf@loose"}
    assert (tmp_path / "errors_ekf@loose.csv").is_file()
    assert isinstance(Variant("ekf", "ekf", {}, "loose").label, str)
