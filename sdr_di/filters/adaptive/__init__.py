"""Adaptive rules: small pluggable pieces around a core filter, one module per paper rule.

=====================  ==========================  ==============================  ==========
rule (registry names)  module                      paper / equations               core
=====================  ==========================  ==============================  ==========
``ff-aukf``            :mod:`.ff_aukf`             004 eq 26-39, Table 2           UKF
``rae-aukf``           :mod:`.rae_aukf`            004 baseline (Sage window)      UKF
``ml-q-ukf``           :mod:`.ml_q`                000 eq 47/49, sec. 3.3          UKF
``sage-husa-ukf``      :mod:`.sage_husa`           001 eq 30-33                    UKF
``q-scaling-ekf/ukf``  :mod:`.q_scaling`           002 eq 16-22                    EKF, UKF
``ml-r-ckf``           :mod:`.ml_r`                003 eq 35-38 (SLSQP)            CKF
=====================  ==========================  ==============================  ==========

Change of the measurement count ``N_k`` (each module's docstring has the details):

* ``ff-aukf``: robust by design -- state-sized ``Q`` window and per-channel residual powers.
* ``rae-aukf``: cannot average vectors of different length -- flushes its windows and does
  not adapt until they refill (the limitation paper 004 states).
* ``ml-q-ukf``: unaffected (state-sized window).
* ``sage-husa-ukf``: ``r``/``R`` statistics restart; ``q``/``Q`` continue.
* ``q-scaling``: continues, per-measurement innovation power in the window.
* ``ml-r-ckf``: window and parameters restart.
"""

from .base import AdaptiveRule, default_q_floor
from .ff_aukf import ForgettingFactorAUKF, forgetting_weights
from .ml_q import MLProcessNoiseUKF
from .ml_r import MLMeasurementNoiseCKF
from .q_scaling import ProcessNoiseScaling
from .rae_aukf import SageWindowAUKF
from .sage_husa import SageHusaUKF

__all__ = [
           "AdaptiveRule",
           "ForgettingFactorAUKF",
           "MLMeasurementNoiseCKF",
           "MLProcessNoiseUKF",
           "ProcessNoiseScaling",
           "SageHusaUKF",
           "SageWindowAUKF",
           "default_q_floor",
           "forgetting_weights",
]
