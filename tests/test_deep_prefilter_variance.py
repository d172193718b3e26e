"""The deep pre-filter's stated output variances against Monte Carlo truth errors.

``scripts/check_prefilter.py`` is the full check (45, 40, 35, 30 dB-Hz, 200 channels); this
runs its Monte Carlo at two C/N0 with fewer channels. The stated variances are the ``R`` of
every deep filter (paper 004 eq 34): the design covariance ``P`` stated before (frequency
variance 4.5-6.3 times the true one) fails the band.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

_SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "check_prefilter.py"
_spec = importlib.util.spec_from_file_location("check_prefilter", _SCRIPT)
check_prefilter = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(check_prefilter)

#: stated / MC variance accepted: 100 channels x 100 intervals, frequency errors correlated
#: over a few intervals, so the MC variance has a few per cent of spread
BAND = (0.75, 1.33)


@pytest.mark.parametrize("cn0_dbhz", [40.0, 30.0])
def test_prefilter_stated_variances_match_monte_carlo_errors(cn0_dbhz):
    r = check_prefilter.monte_carlo(cn0_dbhz, channels=100, intervals=150, seed=3)
    ratio_tau = r["stated_tau"] / r["var_tau"]
    ratio_f = r["stated_f"] / r["var_f"]
    assert BAND[0] < ratio_tau < BAND[1]
    assert BAND[0] < ratio_f < BAND[1]
    # the design covariance (what reached R before) is off by more than the band allows
    assert not BAND[0] < r["design_f"] / r["var_f"] < BAND[1]
