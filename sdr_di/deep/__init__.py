"""Deep integration: per-channel pre-filters, INS-aided NCO commands, the vector loop.

``vector_loop``      :class:`DeepReceiver`: scalar start-up, hand-over, the integration loop,
                     in any coupling mode (``DeepConfig.mode``: deep, loose, tight;
                     docs/coupling.md)
``vector_tracking``  deep mode's measurement source in that loop (NCOs, correlators,
                     pre-filters, channel management, NCO feedback, navigation data)
``nco``              predicted ranges and NCO commands from the INS
``prefilter``        per-channel pre-filters (``_numba_prefilter`` kernel)
``bit_power``        C/N0 from bit-synchronous prompt sums
``navdecode``        navigation message decoding after the hand-over
``run_deep``         files in, solution and summary out (``sdr-di run --mode deep|loose|tight``)
"""

from .nco import NcoCommand, RangePrediction, nco_commands, predict_ranges
from .prefilter import PreFilterBank, discriminator_variances
from .vector_loop import (
    MODES,
    DeepConfig,
    DeepReceiver,
    DeepResult,
    HandoverError,
    IntegrationConfig,
)

__all__ = [
    "MODES",
    "DeepConfig",
    "DeepReceiver",
    "DeepResult",
    "HandoverError",
    "IntegrationConfig",
    "NcoCommand",
    "PreFilterBank",
    "RangePrediction",
    "discriminator_variances",
    "nco_commands",
    "predict_ranges",
]
