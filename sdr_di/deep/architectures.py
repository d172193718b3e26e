"""Deep mode's measurement architectures: what each channel hands the integration filter
(``IntegrationConfig.deep_measurements``; docs/deep.md, *Measurement architectures*).

=================  =====================================================================
``prefilter``      paper 004's cascade: per-channel pre-filters carried from interval to
                   interval (:class:`~sdr_di.deep.prefilter.PreFilterBank`); blocks of up
                   to ``coherent_ms`` (20 ms)
``reset``          the same pre-filters restarted from an uninformative prior every
                   interval (information reset, :class:`~sdr_di.deep.prefilter.
                   ResetPreFilterBank`)
``discriminator``  the interval's code and frequency discriminator outputs, no state
                   (:class:`~sdr_di.deep.discriminators.DiscriminatorBank`)
=================  =====================================================================

``discriminator``, and ``reset`` fused every interval, take their frequency from the phases
of the interval's own blocks, so they cut blocks of at most half an interval
(:func:`block_ms`): 10 ms at the default 50 Hz. ``reset`` fuses at 5 Hz by default
(``IntegrationConfig.fusion_rate_hz``): its pre-filters run over the 10 intervals between
fusions with the cascade's blocks.
"""

from __future__ import annotations

from ..ins.imu import ImuErrorModel
from .discriminators import DiscriminatorBank
from .prefilter import PreFilterBank, ResetPreFilterBank, model_process_noise

__all__ = ["block_ms", "make_measurement_bank"]

#: Block lengths [ms] that divide a 20 ms D1 data bit (blocks never cross a bit edge).
_DIVISORS_OF_20 = (20, 10, 5, 4, 2, 1)


def block_ms(architecture: str, coherent_ms: int, filter_rate_hz: float,
             fusion_intervals: int = 1) -> int:
    """Longest coherent block [ms] of ``architecture``: ``coherent_ms`` for the cascade and
    for ``reset`` fused less often than every interval; otherwise (``reset`` fused every
    interval, ``discriminator``) the longest divisor of 20 ms that is at most
    ``coherent_ms`` and half an interval (two blocks or more per interval, for the
    frequency)."""
    if architecture == "prefilter" or fusion_intervals > 1:
        return int(coherent_ms)
    half_ms = 500.0 / float(filter_rate_hz)
    return next(d for d in _DIVISORS_OF_20 if d <= min(coherent_ms, half_ms) or d == 1)


def make_measurement_bank(architecture: str, n: int, spacing: float, carrier_hz: float,
                          imu: ImuErrorModel | None, prefilter: dict | None = None):
    """The measurement bank of ``n`` channels for ``architecture`` (module table).

    Parameters
    ----------
    architecture : str
        ``"prefilter"``, ``"reset"`` or ``"discriminator"``.
    n : int
        Channels.
    spacing : float
        Early/late offset d [chips].
    carrier_hz : float
        Carrier frequency [Hz].
    imu : ImuErrorModel or None
        The assumed IMU, for the noise model's frequency random walk
        (:func:`~sdr_di.deep.prefilter.model_process_noise`).
    prefilter : dict, optional
        Keyword arguments of the bank (``IntegrationConfig.prefilter``); a discriminator
        bank takes ``sigma_f_none`` only.
    """
    kw = dict(prefilter or {})
    if architecture == "discriminator":
        unknown = set(kw) - {"sigma_f_none"}
        if unknown:
            raise ValueError(f"deep_measurements 'discriminator' carries no pre-filter: "
                             f"settings {', '.join(sorted(unknown))} do not apply")
        return DiscriminatorBank(n, spacing, carrier_hz, **kw)
    s_f_model, q_phi_model = model_process_noise(imu, carrier_hz)
    kw = {"s_f_model": s_f_model, "q_phi_model": q_phi_model, **kw}
    if architecture == "reset":
        return ResetPreFilterBank(n, spacing, carrier_hz, **kw)
    if architecture == "prefilter":
        return PreFilterBank(n, spacing, carrier_hz, **kw)
    raise ValueError(f"unknown deep_measurements {architecture!r}")
