"""Multipath replicas of the satellites' signals (issue 15 item 3; ``docs/impairments.md``).

A replica of satellite ``s`` is a copy of its direct signal, ``alpha`` times its amplitude,
``delay_chips`` later in code *and* data (the whole signal is delayed), with a carrier phase
``phase`` above the direct one at the start and a carrier Doppler ``doppler_offset_hz`` above
it (the phase grows by ``2 pi f_d t``)::

    r(t) = alpha A d(t - tau) c(t - tau) exp(j (phi(t) + phase + 2 pi f_d t)),
    tau = delay_chips / 10.23 MHz.

With ``reflector = "ground"`` and ``antenna_height_m = h`` the replica is the reflection off a
horizontal ground plane under the antenna (an image antenna ``h`` below it): excess delay
``tau(t) = 2 h sin(el(t)) / c`` from the satellite's elevation at each node, carrier phase
``-2 pi f_B3I tau + pi + phase`` (the reflection's sign change; ``phase_deg`` adds to it),
so the delay rate gives the replica's Doppler offset ``-f_B3I dtau/dt`` by itself
(Braasch 1996; Kaplan and Hegarty 2017, ch. 9). ``alpha`` is the reflection's amplitude.

The generator synthesizes each replica as one more row of the kernel's satellite arrays
(:func:`replica_rows`): the direct row's code phase less ``delay_chips``, the same code, the
satellite's own symbols, so the kernel needs nothing new and a replica costs what a
satellite costs. The relative carrier phase is given directly (the carrier delay
``-f_B3I tau`` of a real reflection is one part of it), as in the classic two-ray
analyses of DLL multipath error (Braasch, in Parkinson and Spilker 1996, ch. 14; van Nee
1993).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..constants import C_LIGHT
from ..scenario.impairments import Multipath


@dataclasses.dataclass(frozen=True)
class SignalRow:
    """One row of the kernel's satellite arrays: satellite ``k`` (index in the generator's
    list), direct (``alpha`` 1, the rest 0) or a replica."""

    k: int
    alpha: float = 1.0
    delay_chips: float = 0.0
    phase_cycles: float = 0.0
    doppler_hz: float = 0.0
    #: Ground reflector: antenna height [m] (0: the fixed replica above).
    height_m: float = 0.0

    def ground_delay_s(self, el_rad: np.ndarray) -> np.ndarray:
        """Excess path delay [s] of the ground reflection at elevations ``el_rad``:
        ``2 h sin(el) / c`` (an image antenna ``h`` below the ground plane)."""
        return 2.0 * self.height_m * np.sin(el_rad) / C_LIGHT


def replica_rows(prns: list[int], multipath: tuple[Multipath, ...]) -> list[SignalRow]:
    """Rows of the replicas of satellites ``prns`` (in order of the ``[[multipath]]`` tables;
    ``prn`` None applies to every satellite). A table naming a PRN that is not simulated
    adds nothing."""
    rows = []
    for mp in multipath:
        for k, prn in enumerate(prns):
            if mp.prn is None or mp.prn == prn:
                if mp.antenna_height_m is not None:  # ground: + 180 deg at reflection
                    rows.append(SignalRow(k, mp.alpha, 0.0, mp.phase_deg / 360.0 + 0.5, 0.0,
                                          mp.antenna_height_m))
                else:
                    rows.append(SignalRow(k, mp.alpha, mp.delay_chips, mp.phase_deg / 360.0,
                                          mp.doppler_offset_hz))
    return rows
