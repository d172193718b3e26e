"""Truth atmosphere apart from the receiver's models (issue 46, item 4; ``[atmosphere]``).

The receiver removes the broadcast Klobuchar ionosphere and the Saastamoinen delay of a
standard atmosphere (:mod:`sdr_di.orbits.atmosphere`). With ``truth = "residuals"`` the
generator's delays differ from those models as a real sky does; the receiver never sees
this module (it lives in the generator).

Ionosphere: the Klobuchar delay scaled per satellite pass (one scenario = one pass of each
satellite) by a drawn factor plus a slow variation::

    I_true(t) = max(1 + k_s + g_s(t), 0) * I_Klobuchar(t)        on code (delay) and carrier
                                                                 (advance) alike

``k_s ~ N(0, iono_scale_sigma^2)`` per satellite, ``g_s`` a first-order Gauss-Markov process
of stationary 1-sigma ``iono_variation_sigma`` and correlation time ``iono_variation_tau_s``
starting from 0 at the scenario start. Why this model: the broadcast Klobuchar model removes
only about half of the real delay (RMS), and what it leaves is mostly a misjudged amplitude
of the whole local ionosphere seen along each line of sight, slowly changing over a pass
(travelling disturbances, the model's fixed daily shape), not white noise. Scaling the
model keeps the truth's geometry (obliquity, local time, pierce points) physical and the
residual proportional to the delay, so it vanishes where the delay does (night: 5 ns
floor) and grows at low elevations. Default ``iono_scale_sigma = 0.5``: a residual of 50 %
RMS of the model delay. An independent model (NeQuick, a global ionosphere map) would need
data this project does not ship.

Troposphere: the hydrostatic delay is the model's (the standard atmosphere's pressure is
close to the real one and its mapping near 1/sin E above 10 deg); the wet delay is not::

    T_true = T_Saastamoinen - ZWD_0 / sin E + ZWD_true(t) m_w(E)
    ZWD_true(t) = max(ZWD_0 + dz + gz(t), 0)
    m_w(E) = 1 / (sin E + 0.00035 / (tan E + 0.017))             (Chao 1974 wet mapping)

``ZWD_0`` the standard atmosphere's zenith wet delay at the receiver
(:func:`~sdr_di.orbits.atmosphere.saastamoinen_zenith_wet`, 0.086 m at sea level), ``dz ~
N(0, zwd_sigma_m^2)`` drawn once, ``gz`` Gauss-Markov (``zwd_variation_sigma_m``,
``zwd_variation_tau_s``) from 0. Default ``zwd_sigma_m = 0.05``: the few-centimetre zenith
error of blind (no meteorological data) tropospheric models such as UNB3m; the wet part is
where such models err, being the part the standard atmosphere cannot know.

Randomness: its own stream ``SeedSequence([seed, 0xA7305])``, drawn in a fixed order
(``k_s`` of the satellites in PRN order, ``dz``, then the ionospheric variations on the
1 s grid, one column per satellite in PRN order, then the wet variation; the grid starts
at -1 s, a margin for the clock bias, and the processes start from 0 at t = 0), so the files of a
scenario with the switch on are reproducible from the seed and the other streams (IMU,
noise, oscillator) are untouched. The slow processes are sampled every second and
interpolated linearly (their change in 1 s is far below a millimetre).
"""

from __future__ import annotations

import math

import numpy as np

from ..orbits.atmosphere import saastamoinen_zenith_wet
from ..scenario.schema import AtmosphereSpec

__all__ = ["AtmosphereTruth", "chao_wet_mapping"]

#: Grid of the slow processes [s].
GRID_S = 1.0


def chao_wet_mapping(el) -> np.ndarray:
    """Chao (1974) wet mapping function ``1 / (sin E + 0.00035 / (tan E + 0.017))`` [-] of
    elevation ``el`` [rad] (clipped at 1e-3 rad)."""
    el = np.maximum(np.asarray(el, float), 1e-3)
    return 1.0 / (np.sin(el) + 0.00035 / (np.tan(el) + 0.017))


def _gauss_markov_grid(w: np.ndarray, sigma: float, tau_s: float, dt: float) -> np.ndarray:
    """Gauss-Markov paths on the grid ``t_j = (j - 1) dt`` (rows = nodes), zero up to the
    node of ``t = 0`` (j = 1), driven from there by the unit white samples ``w[2:]``:
    ``p[j] = a p[j-1] + sigma sqrt(1 - a^2) w[j]``, ``a = exp(-dt / tau)``."""
    from scipy.signal import lfilter

    a = math.exp(-dt / tau_s)
    out = np.zeros_like(w)
    out[2:] = lfilter([sigma * math.sqrt(1.0 - a * a)], [1.0, -a], w[2:], axis=0)
    return out


class AtmosphereTruth:
    """The drawn atmosphere of one scenario run (module docstring).

    Parameters
    ----------
    spec : AtmosphereSpec
        ``[atmosphere]`` with ``truth = "residuals"``.
    prns : sequence of int
        The simulated satellites.
    duration_s : float
        Scenario length [s] (the grid covers it and a little more).
    seed : int
        The scenario seed.
    height_m : float
        Receiver height at the start [m] (the standard atmosphere's ``ZWD_0`` there).
    """

    def __init__(self, spec: AtmosphereSpec, prns, duration_s: float, seed: int,
                 height_m: float) -> None:
        self.spec = spec
        self.prns = tuple(sorted(int(p) for p in prns))
        rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0xA7305]))
        self.iono_scale = {p: float(spec.iono_scale_sigma * rng.standard_normal())
                           for p in self.prns}
        self.zwd_offset_m = float(spec.zwd_sigma_m * rng.standard_normal())
        self.zwd_model_m = float(saastamoinen_zenith_wet(height_m))
        n = int(math.ceil(duration_s / GRID_S)) + 3
        self.t_grid = (np.arange(n) - 1.0) * GRID_S          # from -1 s: clock-bias margin
        g = _gauss_markov_grid(rng.standard_normal((n, len(self.prns))),
                               spec.iono_variation_sigma, spec.iono_variation_tau_s, GRID_S)
        self.iono_variation = {p: g[:, j] for j, p in enumerate(self.prns)}
        self.zwd_variation_m = _gauss_markov_grid(
            rng.standard_normal((n, 1)), spec.zwd_variation_sigma_m, spec.zwd_variation_tau_s,
            GRID_S)[:, 0]

    def iono_factor(self, prn: int, t) -> np.ndarray:
        """``max(1 + k_s + g_s(t), 0)`` [-] at true times ``t`` [s since start]."""
        g = np.interp(np.asarray(t, float), self.t_grid, self.iono_variation[int(prn)])
        return np.maximum(1.0 + self.iono_scale[int(prn)] + g, 0.0)

    def zwd_m(self, t) -> np.ndarray:
        """True zenith wet delay ``ZWD_true(t)`` [m]."""
        z = np.interp(np.asarray(t, float), self.t_grid, self.zwd_variation_m)
        return np.maximum(self.zwd_model_m + self.zwd_offset_m + z, 0.0)

    def tropo_residual_m(self, t, el) -> np.ndarray:
        """``T_true - T_Saastamoinen`` [m] at true times ``t`` and elevations ``el`` [rad]
        (0 where ``el <= 0``, as the model)."""
        el = np.asarray(el, float)
        sin_el = np.sin(np.maximum(el, 1e-3))
        res = self.zwd_m(t) * chao_wet_mapping(el) - self.zwd_model_m / sin_el
        return np.where(el > 0.0, res, 0.0)

    def record(self) -> dict:
        """The draws for the sidecar (``atmosphere_truth``) and the truth file's header."""
        return {
            "truth": self.spec.truth,
            "model": {k: getattr(self.spec, k) for k in (
                "iono_scale_sigma", "iono_variation_sigma", "iono_variation_tau_s",
                "zwd_sigma_m", "zwd_variation_sigma_m", "zwd_variation_tau_s")},
            "iono_scale": {f"C{p:02d}": k for p, k in self.iono_scale.items()},
            "iono_variation_end": {f"C{p:02d}": float(v[-1])
                                   for p, v in self.iono_variation.items()},
            "zwd_model_m": self.zwd_model_m,
            "zwd_offset_m": self.zwd_offset_m,
            "zwd_variation_end_m": float(self.zwd_variation_m[-1]),
            "grid_s": GRID_S,
        }
