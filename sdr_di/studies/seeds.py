"""The seeds of a campaign's or a study's runs: one rule (:func:`run_seed`).

Apart from the campaign machinery so that a study specification (its ``[tuning]`` seeds) is
checked without importing the runner, its outputs or a plotting module.
"""

from __future__ import annotations

import numpy as np

__all__ = ["run_seed"]


def run_seed(base_seed: int, index: int) -> int:
    """Seed of run ``index`` of a campaign with ``base_seed`` (deterministic, independent)."""
    ss = np.random.SeedSequence(int(base_seed), spawn_key=(int(index),))
    return int(ss.generate_state(1, np.uint32)[0])
