"""Deep integration: per-channel pre-filters, INS-aided NCO commands, the vector loop."""

from .nco import NcoCommand, RangePrediction, nco_commands, predict_ranges
from .prefilter import PreFilterBank, discriminator_variances
from .vector_loop import DeepConfig, DeepReceiver, DeepResult, HandoverError

__all__ = [
    "DeepConfig",
    "DeepReceiver",
    "DeepResult",
    "HandoverError",
    "NcoCommand",
    "PreFilterBank",
    "RangePrediction",
    "discriminator_variances",
    "nco_commands",
    "predict_ranges",
]
