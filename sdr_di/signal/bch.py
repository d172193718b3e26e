"""BCH(15,11,1) code of the BDS D1/D2 navigation messages (BDS-SIS-ICD-B3I-1.0 5.1.3).

Generator polynomial g(X) = X^4 + X + 1, systematic: a codeword is the 11 information bits
(first transmitted bit = most significant = coefficient of X^14) followed by the 4 parity bits,
the remainder of d(X) X^4 divided by g(X).

Error behaviour
---------------
The code is a cyclic Hamming code (minimum distance 3) and *perfect*: every one of the 15
non-zero syndromes is the syndrome of exactly one single-bit error, so every 15-bit word lies
within distance 1 of exactly one codeword. Consequently

* any single error is corrected (``n_corrected == 1``);
* a double (or any weight >= 2) error can never be detected by the code itself: the decoder
  reports one correction and returns the data of a *different* codeword (it is never returned
  as an error-free ``n_corrected == 0`` word, because a weight-2 pattern is not a codeword).

The navigation decoder therefore adds message-level checks (preamble, FraID range, SOW on the
subframe grid, FraID/page consistent with SOW, reserved page numbers) that catch most such
miscorrections; see :mod:`sdr_di.signal.navmsg`.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "BCH_GENERATOR",
    "bch_decode",
    "bch_decode_ints",
    "bch_encode",
    "bch_encode_ints",
    "bch_syndrome",
]

#: g(X) = X^4 + X + 1 as a bit mask (coefficient of X^k at bit k).
BCH_GENERATOR = 0b10011


def _poly_mod(value: int, nbits: int) -> int:
    """Remainder of the ``nbits``-bit polynomial ``value`` modulo g(X)."""
    r = value
    for i in range(nbits - 1, 3, -1):
        if (r >> i) & 1:
            r ^= BCH_GENERATOR << (i - 4)
    return r


def _syndromes(words: np.ndarray) -> np.ndarray:
    """``_poly_mod(w, 15)`` of every 15-bit word: the remainder is linear over GF(2), so it
    is the XOR of the remainders of the word's set bits (a numpy pass per bit instead of a
    Python call per word: the tables cost 33 ms of every process start that way)."""
    r = np.zeros(words.shape, np.int64)
    for pos in range(15):
        r ^= ((words >> pos) & 1) * _poly_mod(1 << pos, 15)
    return r


def _build_tables() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    data = np.arange(2048, dtype=np.int64)
    enc = ((data << 4) | _syndromes(data << 4)).astype(np.uint16)
    syndrome_to_flip = np.zeros(16, dtype=np.uint16)
    for pos in range(15):
        syndrome_to_flip[_poly_mod(1 << pos, 15)] = 1 << pos
    words = np.arange(1 << 15, dtype=np.int64)
    synd = _syndromes(words).astype(np.uint8)
    corrected = words ^ syndrome_to_flip[synd]
    dec_data = (corrected >> 4).astype(np.uint16)
    dec_nerr = (synd != 0).astype(np.uint8)
    return enc, dec_data, dec_nerr, synd


#: Lookup tables: encoder (2048 entries), decoder data / corrections / syndrome (32768 entries).
_ENC, _DEC_DATA, _DEC_NERR, _SYND = _build_tables()


def _bits_to_int(bits: np.ndarray) -> np.ndarray:
    """Rows of bits (MSB first) to integers."""
    n = bits.shape[-1]
    weights = (1 << np.arange(n - 1, -1, -1)).astype(np.int64)
    return (bits.astype(np.int64) * weights).sum(axis=-1)


def _int_to_bits(values: np.ndarray, n: int) -> np.ndarray:
    shifts = np.arange(n - 1, -1, -1)
    return ((np.asarray(values, dtype=np.int64)[..., None] >> shifts) & 1).astype(np.uint8)


def bch_encode_ints(data: np.ndarray | int) -> np.ndarray:
    """Encode 11-bit integers (bit 10 = first information bit) into 15-bit codeword integers."""
    d = np.asarray(data, dtype=np.int64)
    if np.any((d < 0) | (d > 2047)):
        raise ValueError("BCH(15,11) information words must be 11-bit integers 0..2047")
    return _ENC[d]


def bch_decode_ints(words: np.ndarray | int) -> tuple[np.ndarray, np.ndarray]:
    """Decode 15-bit codeword integers; returns (11-bit data integers, number of corrected bits)."""
    w = np.asarray(words, dtype=np.int64)
    if np.any((w < 0) | (w >= 1 << 15)):
        raise ValueError("BCH(15,11) words must be 15-bit integers")
    return _DEC_DATA[w], _DEC_NERR[w]


def bch_syndrome(cw15: np.ndarray) -> np.ndarray:
    """4-bit syndrome(s) of 15-bit word(s) given as bits (last axis), 0 for a codeword."""
    return _SYND[_bits_to_int(np.asarray(cw15))]


def bch_encode(data11: np.ndarray) -> np.ndarray:
    """Encode information bits into BCH(15,11) codewords.

    Parameters
    ----------
    data11 : array_like
        0/1 bits, shape (..., 11), first transmitted bit first.

    Returns
    -------
    numpy.ndarray
        uint8 codewords, shape (..., 15): the 11 information bits then the 4 parity bits.
    """
    d = np.asarray(data11)
    if d.shape[-1:] != (11,):
        raise ValueError(f"bch_encode expects 11 bits on the last axis, got shape {d.shape}")
    return _int_to_bits(bch_encode_ints(_bits_to_int(d & 1)), 15)


def bch_decode(cw15: np.ndarray) -> tuple[np.ndarray, np.ndarray | int]:
    """Decode BCH(15,11) codewords, correcting one bit error per codeword.

    Parameters
    ----------
    cw15 : array_like
        0/1 bits, shape (..., 15).

    Returns
    -------
    data11 : numpy.ndarray
        uint8 information bits, shape (..., 11).
    n_corrected : int or numpy.ndarray
        Bits corrected per codeword (0 or 1); a plain int for a single codeword. See the module
        docstring: a word with two or more errors is miscorrected and reported as 1.
    """
    c = np.asarray(cw15)
    if c.shape[-1:] != (15,):
        raise ValueError(f"bch_decode expects 15 bits on the last axis, got shape {c.shape}")
    data, nerr = bch_decode_ints(_bits_to_int(c & 1))
    bits = _int_to_bits(data, 11)
    if c.ndim == 1:
        return bits, int(nerr)
    return bits, nerr
