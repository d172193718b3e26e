"""The report of one run (``sdr-di report RUN_DIR``, :mod:`sdr_di.report`): verdicts of the
consistency table against the chi-square band, a run without a reference, an ``lc`` run.

The deep and scalar pages on real runs are checked where those runs are made
(``test_deep_iono_take_up.py``, ``test_scalar_like_others.py``), and the README tour's folder
(scalar, deep, loose, tight) in ``test_readme_tour.py``.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.stats import chi2

from sdr_di.cli import main
from sdr_di.report import consistency_rows, render_run_report, verdict
from sdr_di.report.consistency_table import consistency_table_html


def _band(n: float, dof: int) -> tuple[float, float]:
    k = n * dof
    return chi2.ppf(0.025, k) / k, chi2.ppf(0.975, k) / k


def test_verdicts_of_a_hand_made_summary_against_the_chi_square_band():
    cons = {"band_rule": "hand-made",
            "nees_pos": {"value": 0.2, "n": 50},
            "nees_vel": {"value": 3.0, "n": 50},
            "nees_att": {"value": 1.0, "n": 50},
            "nis_code": {"value": 1.0, "n": 200, "n_eff": 120.0, "dof": 7}}
    rows = {r["key"]: r for r in consistency_rows(cons)}
    assert rows["nees_pos"]["verdict"] == "pessimistic"
    assert rows["nees_vel"]["verdict"] == "overconfident"
    assert rows["nees_att"]["verdict"] == "consistent"
    assert rows["nis_code"]["verdict"] == "consistent"
    lo, hi = _band(50, 3)                       # NEES: 3 dof per sample, n samples
    assert (rows["nees_pos"]["low"], rows["nees_pos"]["high"]) == pytest.approx((lo, hi))
    lo, hi = _band(120.0, 7)                    # NIS: the effective count, the block's dof
    assert (rows["nis_code"]["low"], rows["nis_code"]["high"]) == pytest.approx((lo, hi))
    # at the band's edges the verdict turns
    assert verdict(lo * 0.999, (lo, hi)) == "pessimistic"
    assert verdict(hi * 1.001, (lo, hi)) == "overconfident"
    assert verdict(None, (lo, hi)) == "no samples"
    # a band given in the summary wins over the computed one
    r = consistency_rows({"nees_pos": {"value": 0.2, "n": 50, "band": [0.1, 0.3]}})[0]
    assert r["verdict"] == "consistent" and (r["low"], r["high"]) == (0.1, 0.3)
    page = consistency_table_html(cons, "t")
    assert page.count("pessimistic:") == 1 and page.count("overconfident:") == 1
    assert page.count("consistent:") == 2


def _no_truth_run(folder, filter_name: str = "my_filters:ScaledQEKF"):
    """A deep run's files as the run writes them, from a result without a reference (a
    foreign IF file): error columns NaN, no NEES; one channel's C/N0 drops and it leaves
    the measurement vector for 2 s."""
    from sdr_di.integration.receiver import IntegrationResult
    from sdr_di.integration.run_integrated import (write_channel_series, write_solution_csv,
                                                   write_nis_series)

    t = 12.4 + 0.2 * np.arange(40)
    n, prns = t.size, (8, 10, 13, 27)
    llh = np.column_stack([np.radians(40.0) + 1e-7 * np.arange(n), np.full(n, np.radians(116)),
                           np.full(n, 100.0)])
    cn0 = np.full((n, 4), 40.0)
    used = np.ones((n, 4), bool)
    drop = (t > 16) & (t < 18)
    cn0[drop, 1] = 25.0
    used[drop, 1] = False
    nan3 = np.full((n, 3), math.nan)
    tu = 12.4 + 0.02 * np.arange(400)
    res = IntegrationResult(
        t=t, week=755, sow=369000 + t, llh=llh, v_n=np.tile([0.0, 20.0, 0.0], (n, 1)),
        att=np.zeros((n, 3)), clock_bias_m=np.zeros(n), clock_drift_mps=np.zeros(n),
        n_used=used.sum(axis=1), att_err=nan3, vel_err=nan3, pos_err=nan3, prns=prns,
        used=used, cn0_dbhz=cn0, nis=np.ones(n), handover_s=12.2, filter_name=filter_name,
        adaptation_s=0.0, profile={}, mode="deep", sd=np.full((n, 9), 0.5),
        nees=np.full((n, 3), math.nan),
        updates={"t": tu, "nis": np.random.default_rng(1).chisquare(4, (400, 2)) / 4,
                 "dof": np.full(400, 4)})
    folder.mkdir(parents=True, exist_ok=True)
    write_solution_csv(folder / "rec_deep.csv", res)
    write_channel_series(folder / "rec_deep_channels.csv", res)
    write_nis_series(folder / "rec_deep_nis.csv", res)
    cons = res.consistency()
    (folder / "rec_deep_summary.json").write_text(json.dumps(
        {"mode": "deep", "filter": filter_name, "handover_s": 12.2, "prns": list(prns),
         "rows": n, "metrics": {"n": 0}, "consistency": cons, "warnings": []}))
    return folder


def test_a_run_without_truth_leaves_the_error_figures_out_and_says_why(tmp_path):
    d = _no_truth_run(tmp_path / "rec_run")
    page = render_run_report(d).read_text()
    for name in ("pos-error", "vel-error", "att-error"):
        assert f"rec_deep-{name}" not in page
        assert not (d / f"rec_deep_{name}.png").exists()
    assert "no reference trajectory (truth) for this run" in page
    for name in ("nis", "trajectory", "channels", "sats-used"):   # what needs no truth
        assert f'id="rec_deep-{name}"' in page, name
    assert 'id="rec_deep-consistency"' in page and "no samples" in page   # NEES rows
    assert "filter my_filters:ScaledQEKF" in page                          # a plugin's run
    # drawn once; a second report reuses the PNGs (drawn only when missing or stale)
    mtime = (d / "rec_deep_nis.png").stat().st_mtime_ns
    render_run_report(d)
    assert (d / "rec_deep_nis.png").stat().st_mtime_ns == mtime
    (d / "rec_deep_nis.png").unlink()
    assert main(["report", str(d)]) == 0 and (d / "rec_deep_nis.png").is_file()


def test_lc_report_has_the_error_nis_and_consistency_figures(tmp_path, capsys):
    assert main(["lc", "--duration", "20", "--out", str(tmp_path)]) == 0
    assert main(["report", str(tmp_path)]) == 0
    page = (tmp_path / "report.html").read_text()
    for name in ("pos-error", "vel-error", "att-error", "nis"):
        assert f'id="default_lc_ekf-{name}"' in page, name
    assert 'id="default_lc_ekf-consistency"' in page
    assert "lc writes errors only (no position rows)" in page
    assert page.count("<img") == 4


def test_report_of_a_folder_that_is_not_a_run_is_one_line_exit_2(tmp_path, capsys):
    (tmp_path / "x_summary.json").write_text("[1, 2]")
    assert main(["report", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("sdr-di: error: report ") and "JSON object" \
        in err[0]


def test_ratio_axes_read_as_plain_decimals():
    """The study's ratio axes: log over a wide span, linear near 1, never ``10^x`` labels."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from sdr_di.experiments.plotting import ratio_axis

    def labels(values):
        fig = Figure()
        ax = fig.subplots()
        ax.plot(range(len(values)), values, "o")
        ratio_axis(ax, values)
        FigureCanvasAgg(fig).draw()
        out = [t.get_text() for t in ax.get_yticklabels() + ax.get_yticklabels(minor=True)
               if t.get_text()]
        return ax.get_yscale(), out

    scale, wide = labels([0.3, 1.0, 3.0])
    assert scale == "log" and {"0.5", "1", "2"} <= set(wide), wide
    scale, near = labels([0.95, 0.995, 1.04])          # a ratio near 1: many labels, linear
    assert scale == "linear" and len(near) >= 4, near
    for lab in wide + near:
        assert lab.replace(".", "", 1).replace("-", "", 1).isdigit(), lab


def test_study_summary_shows_nees_and_nis_beside_the_rmse(tmp_path):
    """A hand-made study folder: NEES beside each RMSE (the ensemble's with band and
    verdict when cells.csv has them), the NIS per block after the comparison columns."""
    import csv

    from sdr_di.studies.study_report import render_study_report

    (tmp_path / "study.json").write_text(json.dumps(
        {"name": "s", "baseline": "ekf", "filters": ["ekf", "ukf"], "runs": 4,
         "cells": [{"name": "c"}], "status": "done", "interval": "log_ratio"}))
    base = {"cell": "c", "n_ok": "4", "n_runs": "4", "nis_code": "1.02", "nis_rate": "0.97",
            "nis_vel": "", "nis_pos": ""}
    rows = []
    for f, nees in (("ekf", 3.0), ("ukf", 1.05)):
        r = {**base, "filter": f}
        for q in ("pos", "vel", "att"):
            r.update({f"{q}_rmse_mean": "0.5", f"{q}_best": "0", f"{q}_ratio": "0.9",
                      f"{q}_ratio_ci_low": "0.8", f"{q}_ratio_ci_high": "1.0",
                      f"{q}_wins": "3", f"{q}_sign_p_holm": "0.3", f"nees_{q}": str(nees)})
        rows.append(r)
    rows[0].update({"anees_pos": "3.0", "anees_pos_lo": "0.8", "anees_pos_hi": "1.25"})
    with open(tmp_path / "cells.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    page = render_study_report(tmp_path).read_text()
    summary = page[page.index("Summary per cell"):page.index("Plots")]
    for q in ("pos", "vel", "att"):
        assert f"<th>{q} RMSE</th><th>{q} NEES</th>" in summary
    assert "<th>NIS code</th><th>NIS rate</th>" in summary and "NIS vel" not in summary
    assert "3 [0.8, 1.25] <span class='v-reversed'>&#10007; overconfident</span>" in summary
    assert "<td>1.05</td>" in summary
