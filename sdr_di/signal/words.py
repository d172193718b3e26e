"""Subframe word coding of the BDS D1/D2 messages: header, BCH(15,11) and interleaving.

BDS-SIS-ICD-B3I-1.0 section 5.1.3. A 300-bit subframe is 10 words of 30 bits.

* Word 1 carries 26 information bits: the first 15 (preamble 11100010010 and 4 Rev bits) are
  sent without coding, the next 11 (FraID and the 8 SOW MSBs) form one BCH(15,11) codeword.
* Words 2-10 carry 22 information bits each: bits 1-11 form codeword 1, bits 12-22 codeword 2,
  and the two 15-bit codewords are interleaved bit by bit, codeword 1 first:
  ``x1_1 x2_1 x1_2 x2_2 ... x1_11 x2_11 p1_1 p2_1 ... p1_4 p2_4``.

The information stream (224 bits) therefore reads: preamble 11, Rev 4, FraID 3, SOW 20
(8 MSBs in word 1, 12 LSBs leading word 2), then the 186-bit body described in
:mod:`sdr_di.signal.fields`.
"""

from __future__ import annotations

import numpy as np

from ..errors import NavMessageError
from .bch import bch_decode, bch_encode
from .fields import BODY_BITS, HEADER_BITS, INFO_BITS

__all__ = [
    "PREAMBLE",
    "SUBFRAME_BITS",
    "build_info",
    "decode_words",
    "encode_words",
    "parse_header",
]

#: The 11-bit preamble 11100010010 (uint8 0/1, read-only).
PREAMBLE = np.array([1, 1, 1, 0, 0, 0, 1, 0, 0, 1, 0], dtype=np.uint8)
PREAMBLE.setflags(write=False)
#: Bits per subframe.
SUBFRAME_BITS = 300

_INTERLEAVE = np.empty(30, dtype=np.intp)  # transmitted position -> index in concat(c1, c2)
_INTERLEAVE[0::2] = np.arange(15)
_INTERLEAVE[1::2] = 15 + np.arange(15)


def _int_bits(value: int, n: int) -> np.ndarray:
    return ((int(value) >> np.arange(n - 1, -1, -1)) & 1).astype(np.uint8)


def build_info(fraid: int, sow: int, body: np.ndarray, rev: int = 0) -> np.ndarray:
    """Assemble the 224 information bits of a subframe from FraID, SOW [s] and the 186-bit body."""
    if not 1 <= int(fraid) <= 5:
        raise NavMessageError(f"FraID {fraid} outside 1..5")
    if not 0 <= int(sow) < 604800:
        raise NavMessageError(f"SOW {sow} outside 0..604799")
    body = np.asarray(body, dtype=np.uint8)
    if body.shape != (BODY_BITS,):
        raise NavMessageError(f"subframe body must have {BODY_BITS} bits, got {body.shape}")
    return np.concatenate([PREAMBLE, _int_bits(rev, 4), _int_bits(fraid, 3), _int_bits(sow, 20), body])


def encode_words(info: np.ndarray) -> np.ndarray:
    """BCH-encode and interleave 224 information bits into the 300 transmitted bits."""
    info = np.asarray(info, dtype=np.uint8)
    if info.shape != (INFO_BITS,):
        raise NavMessageError(f"expected {INFO_BITS} information bits, got {info.shape}")
    out = np.empty(SUBFRAME_BITS, dtype=np.uint8)
    out[:15] = info[:15]
    out[15:30] = bch_encode(info[15:26])
    halves = info[26:].reshape(9, 2, 11)  # word, codeword, bit
    cws = bch_encode(halves).reshape(9, 30)  # concat(c1, c2) per word
    out[30:] = cws[:, _INTERLEAVE].reshape(-1)
    return out


def decode_words(bits300: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """De-interleave and BCH-decode a subframe.

    Returns
    -------
    info : numpy.ndarray
        224 corrected information bits (uint8).
    n_corrected : numpy.ndarray
        Corrected bits per word (10 values; words 2-10 can report up to 2, one per codeword).
    """
    b = np.asarray(bits300, dtype=np.uint8)
    if b.shape != (SUBFRAME_BITS,):
        raise NavMessageError(f"a subframe has {SUBFRAME_BITS} bits, got shape {b.shape}")
    info = np.empty(INFO_BITS, dtype=np.uint8)
    nc = np.zeros(10, dtype=np.int64)
    info[:15] = b[:15]
    info[15:26], nc[0] = bch_decode(b[15:30])
    words = b[30:].reshape(9, 30)
    cws = np.empty((9, 30), dtype=np.uint8)
    cws[:, _INTERLEAVE] = words
    data, n = bch_decode(cws.reshape(9, 2, 15))
    info[26:] = data.reshape(-1)
    nc[1:] = n.sum(axis=1)
    return info, nc


def parse_header(info: np.ndarray) -> tuple[bool, int, int, int]:
    """(preamble ok, Rev, FraID, SOW) from the information bits."""

    def val(a: int, b: int) -> int:
        v = 0
        for x in info[a:b]:
            v = (v << 1) | int(x)
        return v

    ok = bool(np.array_equal(info[:11], PREAMBLE))
    return ok, val(11, 15), val(15, 18), val(18, HEADER_BITS)
