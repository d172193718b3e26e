"""The ``jamming`` experiment (issue 15's closing figure): a noise jammer ramped in J/S, the
J/S and effective C/N0 at which a mode loses its solution, checked against the C/N0 at which
the same receiver loses it without a jammer (the reference staircase of attenuations)."""

from __future__ import annotations

import argparse
import json
import math

import numpy as np
import pytest

from sdr_di.errors import SdrDiError
from sdr_di.experiments import jamming
from sdr_di.studies.commands import add_parsers
from sdr_di.sim.interference import effective_cn0_dbhz


def _cli(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="sdr-di")
    add_parsers(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    return args.func(args)


def test_loss_time_is_the_start_of_the_first_window_that_never_holds():
    t = np.arange(0.0, 10.0, 0.5)
    holds = np.ones(t.size, bool)
    holds[[6, 7]] = False          # 3.0-3.5 s: shorter than the 2 s window, not a loss
    holds[10:] = False             # from 5.0 s on
    assert jamming.loss_time(t, holds, 1.0, 2.0) == 5.0
    holds[14] = True               # 7.0 s holds once: the loss starts after it
    assert jamming.loss_time(t, holds, 1.0, 2.0) == 7.5
    assert math.isnan(jamming.loss_time(t, np.ones(t.size, bool), 1.0, 2.0))
    # a window that does not fit in the record is not a loss
    assert math.isnan(jamming.loss_time(t, t < 8.6, 1.0, 2.0))


def test_ramp_js():
    p = {**jamming.default_params, "t_on_s": 10.0, "ramp_s": 20.0, "js_start_db": 30.0,
         "js_stop_db": 50.0}
    js = jamming.js_at(p, [5.0, 10.0, 20.0, 30.0])
    assert math.isnan(js[0]) and list(js[1:]) == [30.0, 40.0, 50.0]


def test_scalar_loss_under_the_jammer_is_at_the_effective_cn0_of_the_reference(tmp_path,
                                                                                  capsys):
    """End to end through ``sdr-di robustness jamming`` (2.5 MHz, 16-bit, scalar only): the
    scalar receiver holds at the ramp's start, loses its solution on the ramp, and the
    sidecar's effective C/N0 at that J/S is within 1.5 dB of the C/N0 at which it loses
    the solution on the same seed without a jammer (C/N0 lowered along the same path by
    attenuation): the jammer costs what its effective C/N0 says, no more, no less."""
    out = tmp_path / "r"
    params = ["sampling_rate_hz=2.5e6", "modes=scalar", "bits=16", "t_on_s=5",
              "ramp_s=10", "js_start_db=25", "js_stop_db=45", "plots=false"]
    rc = _cli(["robustness", "jamming", "--seed", "1", "--out", str(out),
               *(x for p in params for x in ("--param", p))])
    assert rc == 0
    assert "scalar.js_loss_db" in capsys.readouterr().out
    fig = json.loads((out / "result.json").read_text())["figures"]
    assert fig["scalar.lost"] == 1
    assert fig["scalar.t_loss_s"] > 6.0          # it held after the jammer came on
    js = fig["scalar.js_loss_db"]
    assert 25.0 < js < 45.0
    assert fig["scalar.cn0_eff_loss_dbhz"] == pytest.approx(
        effective_cn0_dbhz(40.0, 40.0, [(js, fig["kappa_per_hz"])]))
    assert abs(fig["scalar.jam_minus_ref_db"]) <= 1.5, fig
    rows = (out / "loss_scalar.csv").read_text().splitlines()
    assert rows[0] == "t_s,js_db,cn0_eff_dbhz,n_kept,fix_valid,pos_err_m"
    assert (out / "thresholds.csv").is_file()


@pytest.mark.parametrize("pair, msg", [
    ("bits=5", "bits=5: expected one of 4, 8, 16"),
    ("js_stop_db=20", "js_stop_db=20.0: must exceed js_start_db"),
    ("jammer_bandwidth_hz=-1", "jammer_bandwidth_hz=-1.0: expected a number > 0"),
    ("js_stop_db=95", "jammer .*js_end_db: must be <= 90"),
    ("jammer_offset_hz=2e6", "jammer .*band .* outside the sampled band"),
    ("loss_window_s=30", "loss_window_s=30.0: must be shorter than ramp_s"),
    ("min_channels=0", "min_channels=0: expected an integer"),
    ("modes=scalar,vector", "modes='scalar,vector': expected a comma list"),
])
def test_bad_params_are_one_line_errors_before_any_work(tmp_path, pair, msg):
    out = tmp_path / "o"
    with pytest.raises(SdrDiError, match=msg) as info:
        _cli(["campaign", "jamming", "--runs", "2", "--out", str(out),
              "--param", "sampling_rate_hz=2.5e6", "--param", pair])
    assert "\n" not in str(info.value)
    assert not out.exists()
