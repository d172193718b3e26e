"""Inputs of the loosely coupled simulation (``sdr-di lc``, the ``noise-mismatch``
experiment): the scenario's truth trajectory and a measured IMU record, then the run.

Here, in the generator's package, rather than in :mod:`sdr_di.integration.loose`: the
integration filters run on given truth and IMU records and never import the generator.
"""

from __future__ import annotations

import numpy as np

from ..ins.imu import ImuErrorModel
from ..integration.loose import LcResult, LcSettings, run_loose
from ..scenario.schema import Scenario
from .generate import simulate_truth

__all__ = ["make_inputs", "run_loose_scenario"]


def make_inputs(sc: Scenario, settings: LcSettings | None = None):
    """Truth and measured IMU of a scenario (seeded from the scenario)."""
    settings = settings or LcSettings()
    truth = simulate_truth(sc)
    model = ImuErrorModel.from_spec(sc.imu, draw=settings.imu_draw)
    rng = np.random.default_rng(np.random.SeedSequence([sc.seed, 0x1A0]))
    return truth, model.apply(truth, rng), model


def run_loose_scenario(sc: Scenario, settings: LcSettings,
                       duration_s: float | None = None) -> LcResult:
    """Simulate truth + IMU from a scenario and run :func:`run_loose` (GNSS seed = scenario)."""
    if duration_s is not None:
        sc = sc.with_overrides(duration_s=duration_s)
    truth, imu, model = make_inputs(sc, settings)
    return run_loose(truth, imu, model, settings, seed=sc.seed)
