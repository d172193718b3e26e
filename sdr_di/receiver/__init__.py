"""Software receiver front end on recorded IF.

Modules
-------
:mod:`~sdr_di.receiver.ifreader`
    :class:`IfSource`: chunked, memory-mapped reading of every sample format of
    :mod:`sdr_di.io.sample_formats`, from a sidecar or explicit options.
:mod:`~sdr_di.receiver.correlator`
    Multi-channel early/prompt/late correlators with externally driven code and carrier NCOs
    (numba kernel in :mod:`~sdr_di.receiver._numba_correlate_bits`).
:mod:`~sdr_di.receiver.acquisition`
    Parallel code-phase search (FFT) over a Doppler grid, CFAR threshold from a false-alarm
    probability, fine Doppler / code refinement and C/N0 estimate.
"""

from .acquisition import AcquisitionResult, acquire, acquire_source, detection_threshold
from .correlator import CorrelationResult, Correlator, correlate
from .ifreader import IfFileWarning, IfSource

__all__ = ["AcquisitionResult", "CorrelationResult", "Correlator", "IfFileWarning", "IfSource",
           "acquire", "acquire_source", "correlate", "detection_threshold"]
