"""sdr-di: BeiDou B3I / INS deeply integrated software-receiver simulator.

Subpackages follow the data flow (see ``docs/`` and DESIGN):

``scenario``  motion scenario files (TOML) and their validation
``orbits``    broadcast ephemerides (RINEX 3), satellite orbits/clocks, SP3, atmosphere
``signal``    B3I ranging codes, NH code, BCH, D1/D2 navigation messages
``sim``       trajectory truth, IMU model, per-satellite signal geometry, IF generator
``io``        IF sample formats, metadata sidecar, atomic file writing
``ins``       strapdown INS mechanization (ENU, Right-Front-Up body)
"""

__version__ = "0.1.0"
