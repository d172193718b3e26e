"""sdr-di: BeiDou B3I / INS deeply integrated software-receiver simulator.

Subpackages follow the data flow (see ``docs/`` and DESIGN):

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
mirror the ``sdr-di`` commands. Everything else is internal and may move between releases.
"""

from .api import GeneratedFiles, RunResult, generate, run, study

__version__ = "0.1.0"

__all__ = ["GeneratedFiles", "RunResult", "__version__", "generate", "run", "study"]
