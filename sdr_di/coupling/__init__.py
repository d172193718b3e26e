"""What every coupling mode shares with the integration loop, below both: the receiver's
settings (:mod:`.config`: :class:`~sdr_di.coupling.config.IntegrationConfig`), the filter
interval and a mode's measurements and interface (:mod:`.interval`), and the measurement
models of ranges and rates and of loose fixes (:mod:`.measurements`).

Layers (``tests/test_package_layout.py``): deep mode's measurement source
(:mod:`sdr_di.deep`) and the integration loop and receiver (:mod:`sdr_di.integration`) both
import this package; it imports neither. Nothing is imported here: name the module.
"""
