"""Numbers in the JSON files sdr-di writes: one rule for values that are not finite.

JSON (RFC 8259) has no NaN or infinity; Python's :mod:`json` would write the non-standard
``NaN``/``Infinity`` that strict readers (browsers, ``jq``, most other languages) refuse.
sdr-di writes every non-finite float as ``null`` ("no value": a metric without a reference,
a run that diverged, a statistic of fewer than two runs) in every file: run summaries, study
and campaign records, reports' data. A reader turns ``null`` back into NaN where it expects
a number (:func:`finite_or_nan`). (Study records before issue 48 wrote ``"nan"`` strings;
:func:`finite_or_nan` still reads them.)
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["finite_or_nan", "json_safe"]


def json_safe(obj: Any) -> Any:
    """``obj`` with every non-finite float as None (``null``), at any depth.

    Dicts (keys as text), lists, tuples and numpy arrays are walked; numpy scalars become
    Python numbers. Anything else is returned as is.

    Parameters
    ----------
    obj : object
        A value to be written with :func:`json.dump`.

    Returns
    -------
    object
        The same structure, strict-JSON safe.
    """
    if isinstance(obj, np.ndarray):
        return json_safe(obj.tolist())
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    return obj


def finite_or_nan(v: Any) -> Any:
    """A number read back from JSON: ``null`` (or an old ``"nan"``/``"inf"`` string) as the
    float it stood for (NaN for ``null``); anything else as is."""
    if v is None:
        return math.nan
    if v in ("nan", "inf", "-inf"):
        return float(v)
    return v
