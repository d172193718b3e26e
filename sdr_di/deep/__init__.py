"""Deep integration's own parts: per-channel pre-filters, INS-aided NCO commands, the
vector-tracking measurement source.

``vector_tracking``  deep mode's measurement source in the integration loop (NCOs,
                     correlators, pre-filters, channel management, NCO feedback, navigation
                     data)
``nco``              predicted ranges and NCO commands from the INS
``prefilter``        per-channel pre-filters (``_numba_prefilter`` kernel)
``bit_power``        C/N0 from bit-synchronous prompt sums (one channel, the plain form)
``channel_tests``    every channel's bit sums, noise rings, C/N0 and loss tests as arrays
                     (``_numba_channel_tests`` kernel, one call per pass)
``pass_epochs``      a pass's correlator outputs made ready for the channels (NH wipe-off,
                     noise values, coherent blocks, bit sums; ``_numba_pass_epochs`` kernel)
``navdecode``        navigation message decoding after the hand-over

The receiver that runs every coupling mode (scalar start-up, hand-over, the integration
loop) is :mod:`sdr_di.integration.receiver`; its file runner is
:mod:`sdr_di.integration.run_integrated` (their 0.1 names here were removed in 0.2.0:
CHANGELOG.md). Deep mode imports nothing of :mod:`sdr_di.integration`; what it shares with
the loop is :mod:`sdr_di.coupling`.
"""

from .nco import NcoCommand, RangePrediction, nco_commands, predict_ranges
from .prefilter import PreFilterBank, discriminator_variances

__all__ = [
    "NcoCommand",
    "PreFilterBank",
    "RangePrediction",
    "discriminator_variances",
    "nco_commands",
    "predict_ranges",
]
