"""BeiDou B3I ranging codes and the D1 Neumann-Hoffman secondary code.

BDS-SIS-ICD-B3I-1.0 section 4.3: the B3I ranging code of each PRN is the modulo-2 sum of two
13-stage maximal-length sequences, truncated to 10230 chips (1 ms at 10.23 Mcps):

* G1(X) = 1 + X + X^3 + X^4 + X^13, initial phase all ones, **reset to its initial phase every
  8190 chips** (so chips 8190..10229 repeat G1 chips 0..2039);
* G2(X) = 1 + X + X^5 + X^6 + X^7 + X^9 + X^10 + X^12 + X^13, never reset; its initial phase
  selects the PRN (table shipped in ``data/BDS_B3I_G2_initial_phases.csv``, stage 1 first).

Both generators are Fibonacci shift registers: stage k feeds stage k+1, the feedback (modulo-2
sum of the stages named by the polynomial exponents) enters stage 1, the output is stage 13.

Chip polarity convention (used everywhere in the project: codes, NH code, data bits)
------------------------------------------------------------------------------------
Logic bit 0 -> signal level +1, logic bit 1 -> signal level -1, so the modulo-2 sum of bits is
the product of levels. :func:`b3i_code_bits` returns logic bits, :func:`b3i_code` the levels.
"""

from __future__ import annotations

import csv
import functools
import importlib.resources

import numpy as np

from ..constants import CODE_LENGTH_B3I, GEO_PRNS, check_prn

__all__ = [
    "G1_TAPS",
    "G2_TAPS",
    "G1_RESET_PERIOD",
    "NH20",
    "NH20_BITS",
    "NH20_STRING",
    "b3i_code",
    "b3i_code_bits",
    "g2_initial_phase",
    "lfsr13",
    "nav_type",
    "reference_table",
]

#: Stages (polynomial exponents) summed into the G1 feedback.
G1_TAPS = (1, 3, 4, 13)
#: Stages (polynomial exponents) summed into the G2 feedback.
G2_TAPS = (1, 5, 6, 7, 9, 10, 12, 13)
#: G1 is reset to all ones every this many chips.
G1_RESET_PERIOD = 8190

#: D1 NH secondary code as logic bits, first bit first (1 bit per 1-ms code period).
NH20_STRING = "00000100110101001110"
#: NH code logic bits (uint8 0/1, read-only).
NH20_BITS = np.frombuffer(NH20_STRING.encode("ascii"), dtype=np.uint8) - ord("0")
NH20_BITS.setflags(write=False)
#: NH code levels (int8 +/-1, bit 0 -> +1, read-only).
NH20 = (1 - 2 * NH20_BITS.astype(np.int8)).astype(np.int8)
NH20.setflags(write=False)

_DATA = "data"
_G2_CSV = "BDS_B3I_G2_initial_phases.csv"


@functools.lru_cache(maxsize=1)
def reference_table() -> tuple[dict[str, str], ...]:
    """Rows of the shipped G2 initial-phase table (one dict per PRN 1..63, CSV column names)."""
    text = importlib.resources.files(__package__).joinpath(_DATA, _G2_CSV).read_text("ascii")
    rows = tuple(csv.DictReader(text.splitlines()))
    if [int(r["prn"]) for r in rows] != list(range(1, 64)):
        raise RuntimeError(f"{_G2_CSV}: expected PRN rows 1..63")
    return rows


def g2_initial_phase(prn: int) -> tuple[int, ...]:
    """G2 initial register contents of ``prn`` as 13 bits, stage 1 first."""
    row = reference_table()[check_prn(prn) - 1]
    return tuple(int(c) for c in row["g2_initial_phase_stage1_to_stage13"])


def lfsr13(state: tuple[int, ...], taps: tuple[int, ...], n: int, reset: int | None = None) -> np.ndarray:
    """Output of a 13-stage Fibonacci LFSR.

    Parameters
    ----------
    state : tuple of int
        Initial contents, stage 1 first (13 values 0/1).
    taps : tuple of int
        Stages (1..13) summed modulo 2 into the feedback that enters stage 1.
    n : int
        Number of output chips (stage 13 is the output).
    reset : int, optional
        Reload ``state`` every ``reset`` chips.

    Returns
    -------
    numpy.ndarray
        uint8 0/1 chips, length ``n``.

    Notes
    -----
    The chips are read from the register's cycle through the all-ones state
    (:func:`_cycle`, one pass of at most 8191 steps per tap set and process), at the
    position of ``state`` on it; a state off that cycle (a tap set that is not maximal)
    is stepped chip by chip (:func:`_lfsr13_steps`). The same chips either way: the
    register is deterministic; stepping each PRN's 10230 chips in Python cost about 5 ms
    per code at a run's start.
    """
    # Integer register: bit (13 - k) holds stage k, so stage 13 is bit 0 (the output) and a
    # shift toward higher stages is a right shift with the feedback entering at bit 12.
    init = 0
    for k, b in enumerate(state, start=1):
        init |= (int(b) & 1) << (13 - k)
    mask = 0
    for t in taps:
        mask |= 1 << (13 - t)
    chips, pos = _cycle(mask)
    if pos[init] < 0:
        return _lfsr13_steps(init, mask, n, reset)
    i = np.arange(n, dtype=np.int64)
    if reset is not None:
        i %= reset
    return chips[(i + pos[init]) % chips.size]


def _lfsr13_steps(init: int, mask: int, n: int, reset: int | None = None) -> np.ndarray:
    """:func:`lfsr13` chip by chip from register ``init`` with feedback mask ``mask``."""
    out = np.empty(n, dtype=np.uint8)
    s = init
    for i in range(n):
        if reset is not None and i % reset == 0:
            s = init
        out[i] = s & 1
        fb = (s & mask).bit_count() & 1
        s = (s >> 1) | (fb << 12)
    return out


@functools.lru_cache(maxsize=8)
def _cycle(mask: int) -> tuple[np.ndarray, np.ndarray]:
    """The output chips of one period of the register with feedback mask ``mask`` from the
    all-ones state (uint8, read-only), and each 13-bit state's step on that period (int64
    (8192,), -1 for a state not on it)."""
    ones = (1 << 13) - 1
    pos = np.full(1 << 13, -1, dtype=np.int64)
    chips = []
    s = ones
    for i in range(1 << 13):
        pos[s] = i
        chips.append(s & 1)
        fb = (s & mask).bit_count() & 1
        s = (s >> 1) | (fb << 12)
        if s == ones:
            break
    else:                                  # a tail into a cycle without all ones: no table
        pos[:] = -1
    out = np.array(chips, dtype=np.uint8)
    out.setflags(write=False)
    pos.setflags(write=False)
    return out, pos


@functools.lru_cache(maxsize=1)
def _g1() -> np.ndarray:
    return lfsr13((1,) * 13, G1_TAPS, CODE_LENGTH_B3I, reset=G1_RESET_PERIOD)


@functools.lru_cache(maxsize=64)
def b3i_code_bits(prn: int) -> np.ndarray:
    """B3I ranging code of ``prn`` as logic chips (G1 xor G2).

    Parameters
    ----------
    prn : int
        Satellite PRN, 1..63.

    Returns
    -------
    numpy.ndarray
        Read-only uint8 array of 10230 chips, values 0/1, first transmitted chip first.

    Raises
    ------
    UnknownPrnError
        ``prn`` outside 1..63.
    """
    p = check_prn(prn)
    g2 = lfsr13(g2_initial_phase(p), G2_TAPS, CODE_LENGTH_B3I)
    code = np.bitwise_xor(_g1(), g2)
    code.setflags(write=False)
    return code


@functools.lru_cache(maxsize=64)
def b3i_code(prn: int) -> np.ndarray:
    """B3I ranging code of ``prn`` as signal levels (logic 0 -> +1, logic 1 -> -1).

    Returns
    -------
    numpy.ndarray
        Read-only int8 array of 10230 chips, values +1/-1.
    """
    code = (1 - 2 * b3i_code_bits(prn).astype(np.int8)).astype(np.int8)
    code.setflags(write=False)
    return code


def nav_type(prn: int) -> str:
    """Navigation message type broadcast on B3I by ``prn``: ``'D2'`` for GEO (PRN 1-5, 59-63),
    ``'D1'`` otherwise (MEO/IGSO, with the NH20 secondary code)."""
    return "D2" if check_prn(prn) in GEO_PRNS else "D1"
