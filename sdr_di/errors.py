"""Exception hierarchy.

Every bad input raises a subclass of :class:`SdrDiError` naming the input and what is wrong;
the CLI prints ``error: <message>`` on one line and exits with status 2.
"""


class SdrDiError(Exception):
    """Base class of all sdr-di input and processing errors."""


class ScenarioError(SdrDiError):
    """Malformed or impossible scenario file."""


class EphemerisError(SdrDiError):
    """Unreadable, unsupported or non-BDS navigation file, or no usable record."""


class UnknownPrnError(SdrDiError):
    """A PRN outside 1..63 was requested."""


class NoEphemerisError(EphemerisError):
    """A requested PRN has no healthy record valid at the requested time."""


class OutputError(SdrDiError):
    """An output could not be written (directory not writable, disk full...)."""


class NavMessageError(SdrDiError):
    """A navigation message could not be encoded or decoded (parity, preamble...)."""


class SampleFormatError(SdrDiError):
    """Unknown or inconsistent IF sample format."""


class ImuDataError(SdrDiError):
    """IMU data with NaN, gaps or non-monotonic time."""
