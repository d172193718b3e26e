"""Deep integration's own parts: per-channel pre-filters, INS-aided NCO commands, the
vector-tracking measurement source.

``vector_tracking``  deep mode's measurement source in the integration loop (NCOs,
                     correlators, pre-filters, channel management, NCO feedback, navigation
                     data)
``nco``              predicted ranges and NCO commands from the INS
``prefilter``        per-channel pre-filters (``_numba_prefilter`` kernel)
``bit_power``        C/N0 from bit-synchronous prompt sums
``navdecode``        navigation message decoding after the hand-over

The receiver that runs every coupling mode (scalar start-up, hand-over, the integration
loop) is :mod:`sdr_di.integration.receiver`; its file runner is
:mod:`sdr_di.integration.run_integrated`. Their old names here (``sdr_di.deep.vector_loop``,
``sdr_di.deep.run_deep``, ``sdr_di.deep.DeepReceiver`` ...) still import, with a
:class:`DeprecationWarning`, until the next release.
"""

from .._deprecated import alias_modules, forwarding_getattr
from .nco import NcoCommand, RangePrediction, nco_commands, predict_ranges
from .prefilter import PreFilterBank, discriminator_variances

alias_modules(__name__, {"vector_loop": "sdr_di.integration.receiver",
                         "run_deep": "sdr_di.integration.run_integrated"})

__getattr__ = forwarding_getattr(__name__, {
    "MODES": "sdr_di.integration.receiver",
    "HandoverError": "sdr_di.integration.receiver",
    "IntegrationConfig": "sdr_di.integration.receiver",
    "DeepConfig": "sdr_di.integration.receiver:IntegrationConfig",
    "DeepReceiver": "sdr_di.integration.receiver:IntegratedReceiver",
    "DeepResult": "sdr_di.integration.receiver:IntegrationResult"})

__all__ = [
    "NcoCommand",
    "PreFilterBank",
    "RangePrediction",
    "discriminator_variances",
    "nco_commands",
    "predict_ranges",
]
