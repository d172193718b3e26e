"""Receiver oscillator: power-law frequency noise, the presets table, Allan variance.

One table (:data:`CLOCK_PRESETS`) serves both worlds: the truth oscillator the generator
applies to the IF (:mod:`sdr_di.sim.oscillator`, scenario ``[oscillator]``) and the clock the
integration filter assumes (:class:`~sdr_di.ins.error_model.ClockModel`, assumptions
``[oscillator]``, ``IntegrationConfig.clock``). It lives here, below ``sim/`` and ``ins/``, so that
neither imports the other.

Model (IEEE Std 1139; Barnes et al. 1971): the fractional frequency ``y = dx/dt`` of the
oscillator (``x``: time deviation = receiver clock bias [s]) has the one-sided power spectral
density ``S_y(f) = h0 + h_-1 / f + h_-2 / f^2`` (white FM, flicker FM, random-walk FM; the
phase-noise terms h1, h2 are below a navigation receiver's interest and left out). Its Allan
variance is::

    sigma_y^2(tau) = h0 / (2 tau) + 2 ln2 h_-1 + (2 pi^2 / 3) h_-2 tau

Presets (Brown and Hwang, *Introduction to Random Signals and Applied Kalman Filtering*,
table of typical h-parameters of timing standards): TCXO h0 = 2e-19 s, h_-1 = 7e-21,
h_-2 = 2e-20 1/s; OCXO 8e-20, 2e-21, 4e-23; ``ideal`` all zero. The g-sensitivity
(fractional frequency per g of specific force, body Right-Front-Up axes) is not part of a
preset: it is given per axis in the scenario (0 by default); a filter has no state for it.

The two-state clock of the filter (:class:`~sdr_di.ins.error_model.ClockModel`, paper 004
eq 4: white FM into the bias, random-walk FM into the drift) has no flicker term. Decision:
:func:`two_state_coefficients` *maps* ``h_-1`` into the other two terms with the tangent
envelope ``h_-1`` contributes to neither less than its Allan variance at any ``tau``: by
``tau_m / tau + tau / tau_m >= 2`` the flat ``2 ln2 h_-1`` is bounded by
``ln2 h_-1 (tau_m / tau + tau / tau_m)``, so::

    h0'  = h0  + 2 ln2 h_-1 tau_m
    h_-2' = h_-2 + 3 ln2 h_-1 / (2 pi^2 tau_m)

with ``tau_m = sqrt(3 h0 / (4 pi^2 h_-2))``, the ``tau`` at which the white and random-walk
terms are equal (where the flicker floor shows); the envelope touches the true Allan
variance there and lies above it elsewhere (a conservative ``Q``). The alternative, the
three-term ``Q`` of Van Dierendonck et al. (1984), is not used: it is not a covariance of
any state-space process and can be indefinite for short intervals.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

__all__ = [
    "CLOCK_PRESETS",
    "G0",
    "OscillatorSpec",
    "allan_variance",
    "oscillator_from_table",
    "overlapping_allan_variance",
    "two_state_coefficients",
]

#: Standard gravity [m/s^2]: the "g" of a g-sensitivity.
G0 = 9.80665


@dataclasses.dataclass(frozen=True)
class OscillatorSpec:
    """A receiver oscillator (module notes).

    Attributes
    ----------
    h0 : float
        White frequency noise [s] (``S_y = h0``).
    h_1 : float
        Flicker frequency noise [-] (``S_y = h_-1 / f``).
    h_2 : float
        Random-walk frequency noise [1/s] (``S_y = h_-2 / f^2``).
    g_sensitivity_per_g : tuple of 3 floats
        Fractional frequency change per g of specific force along the body axes (Right,
        Front, Up) [1/g].
    preset : str or None
        Name of the preset it came from (None: given term by term).
    """

    h0: float = 0.0
    h_1: float = 0.0
    h_2: float = 0.0
    g_sensitivity_per_g: tuple = (0.0, 0.0, 0.0)
    preset: str | None = None

    @property
    def is_ideal(self) -> bool:
        """No noise and no g-sensitivity: the clock is the deterministic ``[receiver_clock]``."""
        return self.h0 == 0 and self.h_1 == 0 and self.h_2 == 0 and not any(
            self.g_sensitivity_per_g)

    def allan_variance(self, tau) -> np.ndarray:
        """Allan variance ``sigma_y^2(tau)`` [-] at averaging times ``tau`` [s]."""
        return allan_variance(self.h0, self.h_1, self.h_2, tau)

    def as_dict(self) -> dict:
        """Plain form for summaries and sidecars."""
        return {"preset": self.preset, "h0": self.h0, "h_1": self.h_1, "h_2": self.h_2,
                "g_sensitivity_per_g": list(self.g_sensitivity_per_g)}


#: Oscillator presets (module notes; Brown and Hwang). One table for truth and filter.
CLOCK_PRESETS: dict[str, OscillatorSpec] = {
    "ideal": OscillatorSpec(0.0, 0.0, 0.0, preset="ideal"),
    "tcxo": OscillatorSpec(2e-19, 7e-21, 2e-20, preset="tcxo"),
    "ocxo": OscillatorSpec(8e-20, 2e-21, 4e-23, preset="ocxo"),
}


def allan_variance(h0: float, h_1: float, h_2: float, tau) -> np.ndarray:
    """Power-law Allan variance (module notes) at ``tau`` [s]."""
    tau = np.asarray(tau, float)
    return h0 / (2.0 * tau) + 2.0 * math.log(2.0) * h_1 + (2.0 * math.pi**2 / 3.0) * h_2 * tau


def two_state_coefficients(h0: float, h_1: float, h_2: float) -> tuple[float, float]:
    """``(h0', h_-2')`` of the two-state clock model that bound the power-law oscillator's
    Allan variance from above (module notes: the flicker term mapped by its tangent envelope).

    Without flicker the coefficients are returned unchanged. With flicker but no white or no
    random-walk term ``tau_m`` is 1 s.
    """
    if h_1 <= 0.0:
        return h0, h_2
    tau_m = math.sqrt(3.0 * h0 / (4.0 * math.pi**2 * h_2)) if h0 > 0 and h_2 > 0 else 1.0
    ln2 = math.log(2.0)
    return (h0 + 2.0 * ln2 * h_1 * tau_m,
            h_2 + 3.0 * ln2 * h_1 / (2.0 * math.pi**2 * tau_m))


def overlapping_allan_variance(x: np.ndarray, tau0: float, m: int) -> float:
    """Overlapping Allan variance at ``tau = m tau0`` from phase (time-deviation) samples.

    ``sigma^2 = sum (x[i+2m] - 2 x[i+m] + x[i])^2 / (2 (N - 2m) tau^2)`` over the
    ``N - 2m`` overlapping second differences of the ``N`` phase samples ``x`` [s] spaced
    ``tau0`` [s] (NIST SP 1065, eq 14).
    """
    x = np.asarray(x, float)
    n = x.size
    if m < 1 or n < 2 * m + 1:
        raise ValueError(f"overlapping Allan variance: m = {m} needs at least {2 * m + 1} "
                         f"phase samples, got {n}")
    d = x[2 * m:] - 2.0 * x[m:-m] + x[:-2 * m]
    tau = m * tau0
    return float(np.sum(d * d) / (2.0 * d.size * tau * tau))


# ------------------------------------------------------------------------------------------
def oscillator_from_table(table: Mapping[str, Any], where: str, error: type[Exception], *,
                          allow_g: bool = True) -> OscillatorSpec:
    """Oscillator of a TOML table: ``preset`` (``ideal``, ``tcxo``, ``ocxo``; default
    ``ideal``) and/or the terms ``h0``, ``h_1`` (h_-1), ``h_2`` (h_-2), which override the
    preset's; ``g_sensitivity_per_g = [x, y, z]`` (body Right-Front-Up, 1/g) when
    ``allow_g``.

    Raises
    ------
    error
        (The caller's :class:`~sdr_di.errors.SdrDiError` subclass) an unknown key or preset,
        a negative or non-finite h-parameter, a malformed g-sensitivity; the message names
        ``where`` and the key.
    """
    if not isinstance(table, Mapping):
        raise error(f"{where}: expected a table")
    known = {"preset", "h0", "h_1", "h_2"} | ({"g_sensitivity_per_g"} if allow_g else set())
    extra = sorted(set(table) - known)
    if extra:
        raise error(f"{where}: unknown key(s) {', '.join(map(repr, extra))}; valid: "
                    f"{', '.join(sorted(known))}")
    name = table.get("preset", "ideal")
    if not isinstance(name, str) or name not in CLOCK_PRESETS:
        raise error(f"{where}.preset: unknown oscillator preset {name!r}; valid: "
                    f"{', '.join(CLOCK_PRESETS)}")
    base = CLOCK_PRESETS[name]
    kw: dict[str, Any] = {}
    for key in ("h0", "h_1", "h_2"):
        if key in table:
            v = table[key]
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise error(f"{where}.{key}: expected a finite number, got {v!r}")
            if v < 0:
                raise error(f"{where}.{key}: h-parameters must be >= 0, got {v:g}")
            kw[key] = float(v)
    if "g_sensitivity_per_g" in table:
        v = table["g_sensitivity_per_g"]
        if (not isinstance(v, list) or len(v) != 3 or not all(
                isinstance(a, (int, float)) and not isinstance(a, bool) and math.isfinite(a)
                for a in v)):
            raise error(f"{where}.g_sensitivity_per_g: expected 3 finite numbers [1/g] (body "
                        f"Right, Front, Up), got {v!r}")
        if any(abs(a) > 1e-6 for a in v):
            raise error(f"{where}.g_sensitivity_per_g: {v!r} is above 1e-6 per g (1 ppm/g; "
                        "quartz oscillators are 1e-10 to 1e-8 per g)")
        kw["g_sensitivity_per_g"] = tuple(float(a) for a in v)
    preset = name if not ({"h0", "h_1", "h_2"} & set(kw)) else (
        f"{name} (modified)" if "preset" in table else None)
    return dataclasses.replace(base, preset=preset, **kw)
