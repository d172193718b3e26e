"""sdr-di: BeiDou B3I / INS deeply integrated software-receiver simulator.

Subpackages follow the data flow (``docs/index.md`` is the map of the documentation):

``scenario``  motion scenario files (TOML) and their validation
``orbits``    broadcast ephemerides (RINEX 3), satellite orbits/clocks, SP3, atmosphere
``signal``    B3I ranging codes, NH code, BCH, D1/D2 navigation messages
``sim``       trajectory truth, IMU model, per-satellite signal geometry, IF generator
``io``        IF sample formats, metadata sidecar, atomic file writing
``ins``       strapdown INS mechanization (ENU, Right-Front-Up body)
``filters``   the integration filters (EKF, UKF, CKF) and their adaptive rules
``receiver``  acquisition, tracking loops, observables, PVT (scalar mode)
``integration`` the integration loop and the receiver of deep, loose and tight modes
``deep``      deep mode's own parts: vector tracking, pre-filters, NCO commands
``experiments`` robustness experiments (one seeded run each)
``studies``   running experiments: campaigns, studies, paired statistics, reports

The public API is :func:`generate`, :func:`run` and :func:`study` (:mod:`sdr_di.api`); they
mirror the ``sdr-di`` commands. Their options objects (:class:`RunOptions`,
:class:`GenerateOptions`, :class:`StudyOptions`, :mod:`sdr_di.options`) own the rules between
options; :func:`run_with`, :func:`generate_with` and :func:`study_with` take them. Every bad
input raises a subclass of :class:`SdrDiError` (:mod:`sdr_di.errors`), exported here; those
of a bad value are also ``ValueError``. Everything else is internal and may move between
releases.
"""

from .api import (
    GeneratedFiles,
    RunResult,
    generate,
    generate_with,
    run,
    run_with,
    study,
    study_with,
)
from .errors import (
    AcquisitionError,
    AssumptionsError,
    CampaignError,
    CovarianceError,
    EphemerisError,
    ExperimentError,
    FileSetError,
    FilterError,
    FormatCheckError,
    HandoverError,
    ImplausibleAcquisition,
    ImuDataError,
    LoopProcessError,
    NavMessageError,
    NoEphemerisError,
    NoSatelliteError,
    OptionsError,
    OutputError,
    PluginError,
    RunFailed,
    SampleFormatError,
    ScenarioError,
    SdrDiError,
    SidecarError,
    SolutionFileError,
    StudyError,
    UnknownPrnError,
)
from .options import GenerateOptions, RunOptions, StudyOptions

__version__ = "0.2.0"

#: The public API, its options objects, and every exception class of :mod:`sdr_di.errors`.
__all__ = ["GenerateOptions", "GeneratedFiles", "RunOptions", "RunResult", "StudyOptions",
           "__version__", "generate", "generate_with", "run", "run_with", "study", "study_with",
           "AcquisitionError", "AssumptionsError", "CampaignError", "CovarianceError",
           "EphemerisError", "ExperimentError", "FileSetError", "FilterError", "FormatCheckError",
           "HandoverError", "ImplausibleAcquisition", "ImuDataError", "LoopProcessError",
           "NavMessageError", "NoEphemerisError", "NoSatelliteError", "OptionsError",
           "OutputError", "PluginError", "RunFailed", "SampleFormatError", "ScenarioError", "SdrDiError",
           "SidecarError", "SolutionFileError", "StudyError", "UnknownPrnError"]
