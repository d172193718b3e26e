"""Exception hierarchy.

Every bad input raises a subclass of :class:`SdrDiError` naming the input and what is wrong;
the CLI prints ``error: <message>`` on one line and exits with status 2. The public API
(``sdr_di.generate``, ``sdr_di.run``, ``sdr_di.study``) raises the same classes, exported from
``sdr_di``. Those of a bad value of an option or argument (:class:`OptionsError`,
:class:`FilterError`, :class:`AcquisitionError`, :class:`SolutionFileError`) are also
``ValueError``; the errors of a file's content (scenario, sidecar, IMU data, study spec)
are not, so that the numerical-failure handlers (``except ValueError``) never mistake one
for a failed computation.
"""


class SdrDiError(Exception):
    """Base class of all sdr-di input and processing errors."""


class OptionsError(SdrDiError, ValueError):
    """Options of a command (or arguments of the API function that mirrors it) out of range
    or that do not fit together: a bad mode, a number that must be positive, an option of
    another mode, a PLL bandwidth beyond the loop's stability limit. The message names the
    option as it was given (the CLI's flag, the API's argument)."""


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


class SidecarError(SampleFormatError):
    """Unreadable IF metadata sidecar: not a JSON object, wrong schema, a key missing or of the
    wrong type."""


class FileSetError(SidecarError):
    """A file of a generated set (IF, IMU, truth) is missing or is not the file its sidecar was
    written with (size or digest differ: a mixed set)."""


class FormatCheckError(SampleFormatError):
    """The layout heuristic says the bytes are not in the declared format (:mod:`sdr_di.receiver.ifreader` notes).

    ``str()`` ends with how to read the file anyway (``hint``); :attr:`finding` is the
    message without it, for a caller that names its own switch (the CLI's
    ``--no-format-check``).
    """

    def __init__(self, finding: str, hint: str):
        super().__init__(f"{finding} ({hint})")
        self.finding = finding


class SolutionFileError(SdrDiError, ValueError):
    """A solution file that cannot be read (wrong header, columns or values)."""


class ImuDataError(SdrDiError):
    """IMU data with NaN, gaps or non-monotonic time."""


class FilterError(SdrDiError, ValueError):
    """Bad filter input or configuration: unknown filter name, wrong-size ``z``/``R``/``Q``,
    non-finite values, non-positive-definite initial covariance, unknown option (a bad
    value: also a ``ValueError``)."""


class CovarianceError(FilterError):
    """A covariance matrix lost positive definiteness during a filter step.

    Attributes
    ----------
    filter_name : str
        Name of the filter (``"UKF"``, ``"ff-aukf"``...).
    step : str
        The step that failed (``"predict"``, ``"update"``).
    matrix : str
        Which matrix (``"P"`` state covariance, ``"S"`` innovation covariance...).
    min_eigenvalue : float
        Smallest eigenvalue of the offending (symmetrized) matrix.
    """

    def __init__(self, filter_name: str, step: str, matrix: str, min_eigenvalue: float,
                 epoch: int | None = None) -> None:
        self.filter_name = filter_name
        self.step = step
        self.matrix = matrix
        self.min_eigenvalue = float(min_eigenvalue)
        self.epoch = epoch
        where = f" at epoch {epoch}" if epoch is not None else ""
        super().__init__(
            f"{filter_name} {step}{where}: covariance {matrix} is not positive definite "
            f"(smallest eigenvalue {min_eigenvalue:.3e}); Cholesky factorization failed. "
            "Check Q/R/P scaling, or construct the filter with psd_fallback='clip' to clip "
            "eigenvalues instead of failing")


class PluginError(FilterError):
    """Code a user brought (a plugin filter) raised during a run: one line naming the
    plugin, the call and the exception. The run failed, not the input: exit status 1
    (:attr:`exit_status`); in a study only that filter's runs fail."""

    exit_status = 1


class AssumptionsError(SdrDiError):
    """Bad assumptions file or ``[assume]`` table (what the integration filter believes):
    unknown table, key or preset, negative sigma or h-parameter, or assumptions given to a
    command that cannot use them."""


class ExperimentError(SdrDiError):
    """Unknown experiment name, unknown parameter or a parameter value of the wrong kind."""


class CampaignError(SdrDiError):
    """Bad campaign configuration (``runs < 1``, bad worker count, unreachable scheduler) or a
    campaign in which no run completed."""


class AcquisitionError(SdrDiError, ValueError):
    """An acquisition that cannot run: a file shorter than one code period, or search
    parameters out of range (coherent or non-coherent length, Doppler range, pfa)."""


class StudyError(SdrDiError):
    """Bad study specification (unknown table or key, unknown filter, baseline or cell,
    a bad cell parameter) or an output folder that holds another study."""


class RunFailed(SdrDiError):
    """A run that went through but whose result cannot be right: no fix at all, or an
    acquisition that real signals cannot produce. The CLI prints its one-line diagnosis and
    exits with status 1 (:attr:`exit_status`), not 2: the inputs were readable, the result
    is what failed."""

    exit_status = 1


class NoSatelliteError(RunFailed):
    """Acquisition found no satellite in the IF file (a run without a fix: exit status 1)."""


class ImplausibleAcquisition(RunFailed):
    """A run's acquisition gave detections that real signals cannot give: the samples are
    read wrongly (the CLI's exit status 1)."""


class HandoverError(RunFailed):
    """The scalar start-up never reached a state the vector loop can take over (a run
    without a fix: exit status 1)."""


class LoopProcessError(SdrDiError):
    """The loop failed in its child process with an exception that does not pickle (its
    text)."""
