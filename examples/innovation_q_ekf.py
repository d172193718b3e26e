"""A custom integration filter: an EKF that inflates ``Q`` when its innovations are too large.

Run it from the repository root (the current folder is searched for the module)::

    sdr-di run FILE.bin --mode deep --filter examples.innovation_q_ekf:InnovationQEKF:gain=2
    sdr-di study examples/custom_filter_study.toml --out out/custom

Rule: the mean normalized innovation squared per measurement, ``NIS / m``, over the last
``window`` updates is 1 for a consistent filter. Its excess over 1 scales the nominal ``Q``:
``Q = Q0 (1 + gain * max(mean NIS/m - 1, 0))``, at most ``max_scale`` times ``Q0``.
"""

from collections import deque

import numpy as np

from sdr_di.filters import EKF


class InnovationQEKF(EKF):
    """EKF with innovation-based ``Q`` inflation (module notes); options ``gain``,
    ``window``, ``max_scale`` (``--filter ...:gain=2:window=20``)."""

    def __init__(self, process_model, measurement_model, x0, P0, Q0, R0=None, *,
                 gain: float = 1.0, window: int = 10, max_scale: float = 10.0, **kwargs):
        super().__init__(process_model, measurement_model, x0, P0, Q0, R0, **kwargs)
        self.Q0 = self.Q.copy()
        self.gain, self.max_scale = float(gain), float(max_scale)
        self.nis_per_m = deque(maxlen=int(window))

    def update(self, z, R=None, measurement_model=None):
        super().update(z, R, measurement_model)
        if self.y.size:
            self.nis_per_m.append(self.nis / self.y.size)
            excess = max(float(np.mean(self.nis_per_m)) - 1.0, 0.0)
            self.Q = self.Q0 * min(1.0 + self.gain * excess, self.max_scale)
