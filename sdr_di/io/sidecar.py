"""Metadata sidecar (JSON) describing an IF file: everything needed to read it back.

The sidecar of ``run.bin`` is ``run.json``. Keys (schema ``sdr-di-if/1``):

``schema``             ``"sdr-di-if/1"``
``if_file``            IF file name, relative to the sidecar
``sampling_rate_hz``   sample rate [Hz]
``if_hz``              intermediate frequency of the carrier [Hz] (0 for baseband)
``carrier_hz``         RF carrier the IF corresponds to (1268.52e6 for B3I)
``sample_format``      name in :mod:`sdr_di.io.sample_formats`
``quantization_bits``  effective bits of each component
``spectrum_inverted``  false (I + jQ non-inverted)
``n_samples``          samples (complex or real) in the file
``start``              ``{"week": BDT week, "sow": BDT seconds of week, "utc": ISO, "bdt": ISO}``
                       receiver-clock time of sample 0
``duration_s``         n_samples / sampling_rate_hz
``scenario``           ``{"name", "hash", "seed"}``
``satellites``         list of ``{"prn", "nav": "D1"|"D2", "cn0_dbhz", "elevation_deg",
                       "azimuth_deg", "doppler_hz", "code_phase_chips"}`` at t = 0
``imu_file``, ``truth_file``, ``ephemeris_file``   companion files
``generator``          ``{"name": "sdr-di", "version"}``
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from ..errors import SampleFormatError
from .atomic import atomic_open

SCHEMA = "sdr-di-if/1"


def write_sidecar(path: str | Path, meta: dict[str, Any]) -> Path:
    """Write the sidecar atomically; returns its path."""
    path = Path(path)
    meta = {"schema": SCHEMA, **meta}
    with atomic_open(path, "w") as fh:
        json.dump(meta, fh, indent=2, sort_keys=False)
        fh.write("\n")
    return path


def read_sidecar(path: str | Path) -> dict[str, Any]:
    """Read and check a sidecar.

    Raises
    ------
    SampleFormatError
        Missing file, not JSON, wrong schema or missing required key.
    """
    path = Path(path)
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise SampleFormatError(f"sidecar {path}: cannot read ({exc.strerror or exc})") from None
    except json.JSONDecodeError as exc:
        raise SampleFormatError(f"sidecar {path}: not JSON ({exc})") from None
    if meta.get("schema") != SCHEMA:
        raise SampleFormatError(f"sidecar {path}: schema {meta.get('schema')!r}, expected {SCHEMA!r}")
    for key in ("if_file", "sampling_rate_hz", "if_hz", "sample_format", "n_samples", "start"):
        if key not in meta:
            raise SampleFormatError(f"sidecar {path}: missing key {key!r}")
    return meta
