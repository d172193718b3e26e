"""Deep on a file whose assistance has no ionosphere lines: the hand-over does not wait for
subframe 1 (``IntegrationConfig.iono_wait_s`` = 0 by default) and the rows before the model is
taken up are flagged (``iono`` column, ``docs/deep.md``)."""

import gzip
import json
import re
from types import SimpleNamespace

import numpy as np
import pytest

from sdr_di.cli import main
from sdr_di.integration.run_integrated import SOLUTION_COLUMNS, iono_in_force, iono_take_up_s
from sdr_di.integration.receiver import IntegrationConfig
from sdr_di.scenario import REPO_ROOT

RINEX = REPO_ROOT / "ephemeris" / "ESBC00DNK_R_20201770000_01D_MN.rnx.gz"


def test_iono_flag_follows_the_history():
    t = np.arange(10.0, 14.01, 0.2)
    deep = SimpleNamespace(t=t, navigation={"ionosphere": {"history": [
        {"t_s": 10.0, "model": "none", "source": None},
        {"t_s": 12.4, "model": "klobuchar", "source": "broadcast"}]}})
    on = iono_in_force(deep)
    assert np.all(on[t < 12.39] == 0) and np.all(on[t > 12.39] == 1)
    assert iono_take_up_s(deep) == pytest.approx(12.4)
    loose = SimpleNamespace(t=t, navigation={"ionosphere": [{"t_s": 10.0,
                                                               "model": "klobuchar"}]})
    assert np.all(iono_in_force(loose) == 1) and iono_take_up_s(loose) is None
    assert IntegrationConfig().iono_wait_s == 0.0


@pytest.fixture(scope="module")
def late_file(tmp_path_factory):
    """Default scenario from 06:30:20 BDT (subframe 1 at +10..+16 s), 18 s at 2.5 MHz."""
    out = tmp_path_factory.mktemp("late")
    text = (REPO_ROOT / "signals" / "default.toml").read_text()
    text = text.replace('start = "2020-06-25T06:30:00"', 'start = "2020-06-25T06:30:20"')
    text = text.replace('"../ephemeris/', f'"{REPO_ROOT / "ephemeris"}/')
    (out / "late.toml").write_text(text)
    assert main(["generate", "--scenario", str(out / "late.toml"), "--duration", "18",
                 "--fs", "2.5e6", "--out", str(out), "--no-progress"]) == 0
    nav = out / "no_iono.rnx"
    with gzip.open(RINEX, "rt") as fh:
        nav.write_text("".join(ln for ln in fh if "IONOSPHERIC CORR" not in ln))
    return out


def test_deep_hands_over_without_waiting_and_flags_the_rows(late_file, capsys):
    out = late_file / "run"
    rc = main(["run", str(late_file / "default.bin"), "--mode", "deep", "--filter", "ekf",
               "--ephemeris", str(late_file / "no_iono.rnx"), "--out", str(out),
               "--no-progress", "--plots"])
    cap = capsys.readouterr()
    assert rc == 0, cap.err
    assert cap.err.count("sdr-di: warning:") == 1 and "without ionosphere" in cap.err
    rows = np.loadtxt(out / "default_deep.csv", delimiter=",", skiprows=2)
    t, iono = rows[:, 0], rows[:, SOLUTION_COLUMNS.index("iono")]
    summ = json.loads((out / "default_deep_summary.json").read_text())
    nav_change = rows[:, SOLUTION_COLUMNS.index("nav_change")].astype(int)
    assert t[0] < 15.0                # before subframe 1 ends: no wait for the ionosphere
    assert iono[0] == 0 and iono[-1] == 1           # taken up when subframe 1 is decoded
    k = int(np.argmax(iono))
    assert np.all(iono[:k] == 0) and np.all(iono[k:] == 1)
    assert nav_change[k] & 2 and summ["iono_from_s"] == pytest.approx(t[k])
    assert summ["metrics_after_iono"]["n"] == t.size - k
    assert "after the ionosphere take-up" in cap.out
    # the run's figures, and `sdr-di report RUN_DIR` on an integrated run
    names = ("pos-error", "vel-error", "att-error", "nis", "trajectory", "channels",
             "innovations", "sats-used")
    assert sorted(p.name for p in out.glob("*.png")) == sorted(
        f"default_deep_{n}.png" for n in names)
    assert main(["report", str(out)]) == 0
    page = (out / "report.html").read_text()
    assert "deep, filter ekf" in page and page.count("<img") == len(names)
    for n in names:
        assert f'id="default_deep-{n}"' in page, n
    assert 'id="default_deep-consistency"' in page
    assert page.count("<td class=") == 5              # nis_code, nis_rate, 3 NEES verdicts


def test_integrated_progress_bar_reports_the_start_up_and_ends_at_100(late_file, capsys):
    from sdr_di.integration.run_integrated import run_integrated
    from sdr_di.receiver.run_scalar import open_source

    run_integrated(open_source(late_file / "default.bin"), late_file / "bar",
             config=IntegrationConfig(filter="ekf", mode="loose"), duration_s=12.0, progress=True)
    err = capsys.readouterr().err.replace("\r", "\n").splitlines()
    bars = [ln for ln in err if ln.startswith("run loose")]
    assert "scalar start-up: acquisition" in bars[0], bars[0]
    # Each new stage is drawn at its first report whatever tqdm's refresh interval drops
    # (a fast machine skipped the 5.1 s report): the start-up with its channels, then the
    # filter's stage from the hand-over on (the ephemerides, decoded after +10 s of file).
    assert any("scalar start-up, 7 tracked" in b for b in bars), bars
    first = next(b for b in bars if "WLS fixes of 7" in b)
    assert 10.0 < float(re.search(r" ([0-9.]+)/12\.0 s", first).group(1)) < 12.0, first
    assert "WLS fixes of" in bars[-1] and "in the vector" not in bars[-1], bars[-1]
    assert "100%" in bars[-1] and "12.0/12.0 s" in bars[-1], bars[-1]


def test_an_all_zero_decoded_klobuchar_set_does_not_displace_one_in_force():
    """SignalSim with a RINEX file without BDS ionosphere lines broadcasts a zero set while
    its signal carries the GPS set's delays: the zero set must not replace the assistance
    set; with nothing in force it is taken (Klobuchar's night-time constant)."""
    from sdr_di.orbits.ephemeris import Klobuchar
    from sdr_di.orbits.rinex_nav import load_nav
    from sdr_di.receiver.navdata import BROADCAST, NavDataInForce
    from sdr_di.receiver.navdata import RINEX as FROM_RINEX

    zero = Klobuchar((0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0))
    nd = NavDataInForce(load_nav(RINEX))
    assert nd.iono_source == FROM_RINEX
    assert not nd.offer_klobuchar(zero, 20.0) and nd.iono_source == FROM_RINEX
    bare = NavDataInForce(None)
    assert bare.offer_klobuchar(zero, 20.0) and bare.iono_source == BROADCAST
    real = Klobuchar((1e-8, 0.0, 0.0, 0.0), (9e4, 0.0, 0.0, 0.0))
    assert bare.offer_klobuchar(real, 26.0) and bare.klobuchar == real
    assert not bare.offer_klobuchar(zero, 50.0) and bare.klobuchar == real
