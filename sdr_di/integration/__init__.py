"""INS/GNSS integration: measurement models, loosely coupled runner, noise schedules, metrics.

``measurements``  deep/tight pseudorange + rate model (paper 004 eq 6-12), loose position /
                  velocity model (papers 000/003 eq 13-14)
``noise``         simulated GNSS solution noise with scheduled variance windows
``metrics``       attitude / velocity / position errors, RMSE = sqrt(mean ||e||^2), max
``loose``         closed-loop loosely coupled run (``sdr-di lc``)
``loop``          the integration loop every coupling mode on IF data shares (INS, filter,
                  feedback, rows); a mode supplies its measurement source
``gnss_epochs``   the scalar receiver's epochs recorded for loose and tight, their common
                  measurement source (time tags, INS interpolation, channel columns)
``loose_fixes``   loose mode's source: WLS position/velocity fixes, R from their formal
                  covariances (``sdr-di run --mode loose``; ``lc`` is the simulated one)
``tight_ranges``  tight mode's source: pseudoranges and rates into paper 004 eq 6-12
``loop_process``  loose and tight mode's loop in a child process behind the receiver
``receiver``      the receiver of every integrated mode: scalar start-up, hand-over, then
                  the loop with deep's, loose's or tight's source (docs/coupling.md)
``run_integrated`` files in, solution and summary out (``sdr-di run --mode deep|loose|tight``)

The process model is :class:`sdr_di.ins.error_model.InsErrorModel`.
"""

from .loose import LcResult, LcSettings, load_lc_scenario, run_loose
from ..coupling.measurements import (
                           LooseMeasurementModel,
                           RangeRateMeasurementModel,
                           loose_measurement,
                           predicted_observables,
)
from .metrics import nav_errors, rmse_max, summarize
from .noise import GnssNoise, NoiseWindow

__all__ = [
                           "GnssNoise",
                           "LcResult",
                           "LcSettings",
                           "LooseMeasurementModel",
                           "NoiseWindow",
                           "RangeRateMeasurementModel",
                           "load_lc_scenario",
                           "loose_measurement",
                           "nav_errors",
                           "predicted_observables",
                           "rmse_max",
                           "run_loose",

                           "summarize",
]
