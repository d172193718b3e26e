"""IF sample formats: one registry used by the generator (writer) and the receiver (reader).

=============  =======  ============================================================
name           complex  layout on disk
=============  =======  ============================================================
``iq_int8``    yes      interleaved signed 8-bit I, Q, I, Q ... (GNU Radio/GNSS-SDR
                        ``ibyte``, ``rtl_sdr``-style but signed). Alias ``ibyte``.
``real_int8``  no       signed 8-bit real samples. Alias ``byte``.
``iq_int16``   yes      interleaved little-endian signed 16-bit I, Q. Alias ``ishort``.
``real_int16`` no       little-endian signed 16-bit real samples. Alias ``short``.
``iq_int4``    yes      one byte per complex sample: I in the high nibble, Q in the low
                        nibble, each a two's-complement 4-bit value (-8..7).
``gr_complex`` yes      interleaved little-endian float32 I, Q (GNU Radio
                        ``gr_complex``; read only).
=============  =======  ============================================================

Quantized values are integers on a symmetric mid-tread grid ``-L..L`` with
``L = 2**(bits-1) - 1`` (1-bit: ``-1, +1``), stored as plain integers in the container, so a
4-bit file in ``iq_int8`` holds values -7..7. Spectrum is not inverted: I + jQ is the complex
baseband (or IF) signal ``exp(+j 2 pi f t)`` for a positive frequency ``f``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..errors import SampleFormatError


@dataclasses.dataclass(frozen=True)
class SampleFormat:
    """Description of one on-disk sample layout.

    Attributes
    ----------
    name : str
        Canonical name.
    is_complex : bool
        True for I/Q formats.
    dtype : numpy.dtype
        Container element type (per component, or per packed byte for ``iq_int4``).
    bytes_per_sample : int
        Bytes per (complex or real) sample on disk.
    max_bits : int
        Widest quantization the container holds.
    writable : bool
        True when the generator can write it.
    """

    name: str
    is_complex: bool
    dtype: np.dtype
    bytes_per_sample: int
    max_bits: int
    writable: bool = True


FORMATS: dict[str, SampleFormat] = {
    f.name: f
    for f in (
        SampleFormat("iq_int8", True, np.dtype(np.int8), 2, 8),
        SampleFormat("real_int8", False, np.dtype(np.int8), 1, 8),
        SampleFormat("iq_int16", True, np.dtype("<i2"), 4, 16),
        SampleFormat("real_int16", False, np.dtype("<i2"), 2, 16),
        SampleFormat("iq_int4", True, np.dtype(np.uint8), 1, 4),
        SampleFormat("gr_complex", True, np.dtype("<f4"), 8, 32, writable=False),
    )
}

ALIASES = {"ibyte": "iq_int8", "byte": "real_int8", "ishort": "iq_int16",
           "short": "real_int16", "cs8": "iq_int8", "cs16": "iq_int16", "cf32": "gr_complex"}


def get_format(name: str) -> SampleFormat:
    """Look up a sample format by name or alias.

    Raises
    ------
    SampleFormatError
        Unknown name.
    """
    key = ALIASES.get(name, name)
    try:
        return FORMATS[key]
    except KeyError:
        names = ", ".join(sorted(set(FORMATS) | set(ALIASES)))
        raise SampleFormatError(f"unknown sample format {name!r} (known: {names})") from None


def quantizer_levels(bits: int) -> int:
    """Largest magnitude ``L`` of the symmetric mid-tread quantizer for ``bits`` bits."""
    if bits < 1:
        raise SampleFormatError(f"quantization bits must be >= 1, got {bits}")
    return 1 if bits == 1 else 2 ** (bits - 1) - 1


def pack_iq_int4(i: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Pack integer I and Q in -8..7 into one byte each: (I << 4) | (Q & 0xF)."""
    return ((i.astype(np.int16) & 0xF) << 4 | (q.astype(np.int16) & 0xF)).astype(np.uint8)


def unpack_iq_int4(packed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`pack_iq_int4`: signed I and Q (int8) from packed bytes."""
    b = packed.astype(np.int16)
    i = (b >> 4) & 0xF
    q = b & 0xF
    i = np.where(i >= 8, i - 16, i).astype(np.int8)
    q = np.where(q >= 8, q - 16, q).astype(np.int8)
    return i, q
