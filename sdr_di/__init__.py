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

import os

# numba's ``omp`` layer keeps its worker threads spinning after each parallel region unless
# told otherwise; the generator's kernel (one region per chunk) then takes CPU from its own
# writer thread and from other processes (measured: `sdr-di generate` of the 60 s default
# file 13.0 -> 11.3 user CPU-s, docs/notes/speed.md). Read by libgomp when numba first
# loads it, so it must be set before any parallel kernel runs; a user's setting is kept.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from .api import GeneratedFiles, RunResult, generate, run, study

__version__ = "0.1.0"

__all__ = ["GeneratedFiles", "RunResult", "__version__", "generate", "run", "study"]
