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

Peers' formats (read only; the layouts and the source file of each fact are in
``docs/formats.md``):

=======================  =======  =====================================================
name                     complex  layout on disk
=======================  =======  =====================================================
``iq_int4_sm``           yes      SignalSim ``INT4X2``: one byte per complex sample, I in
                                  the high nibble, Q in the low nibble, each nibble
                                  sign-magnitude: bit 3 the sign (1: negative), bits 2-0
                                  the magnitude ``m``; value ``+-(2m + 1)`` (odd, -15..15).
``pocket_raw8_iq2``      yes      PocketSDR ``RAW8`` with 2-bit I/Q channels: one byte per
                                  sample time, RF channel 1 in bits 3-0, channel 2 in bits
                                  7-4; in a channel's nibble I is bits 1-0 and Q bits 3-2,
                                  each 2-bit code sign-magnitude (bit 1 the sign, bit 0 the
                                  magnitude: +1, +3, -1, -3 for codes 0..3), **Q negated**
                                  (codes 0..3 give Q = -1, -3, +1, +3).
``pocket_raw8_real2``    no       ``RAW8`` with 2-bit real channels: the I code of the
                                  channel's nibble (bits 1-0 / 5-4).
``pocket_raw8_real3``    no       ``RAW8`` with 3-bit real channels: in the channel's nibble
                                  bit 1 the sign, bit 0 and bit 3 the magnitude
                                  ``m = 2 b0 + b3``; value ``+-(2m + 1)``.
``pocket_raw16_*``       as raw8  PocketSDR ``RAW16``: 2 bytes per sample time, byte 0 holds
                                  channels 1-2, byte 1 channels 3-4 (nibbles as RAW8).
``pocket_raw32_*``       as raw8  PocketSDR ``RAW32``: 4 bytes, channels 1-8 (as RAW16).
``pocket_raw16i_real2``  no       PocketSDR ``RAW16I``: 2 bytes, 4 channels of 2-bit real
                                  codes per byte (channel ``k`` at bits ``2((k-1) % 4)``
                                  of byte ``(k-1) // 4``).
=======================  =======  =====================================================

PocketSDR ``INT8X2`` is ``iq_int8`` with Q negated: read it as ``iq_int8`` with the spectrum
inverted (conjugation is Q negation). Multi-channel formats carry ``n_rf_channels > 1``; a
reader picks one channel (1-based, PocketSDR's ``-RFCH`` numbering).

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
    n_rf_channels : int
        RF channels interleaved in each sample (PocketSDR ``RAW*``: 2, 4 or 8; else 1).
    peer : str
        Program whose files use the layout (``""`` for sdr-di's own formats).
    """

    name: str
    is_complex: bool
    dtype: np.dtype
    bytes_per_sample: int
    max_bits: int
    writable: bool = True
    n_rf_channels: int = 1
    peer: str = ""


FORMATS: dict[str, SampleFormat] = {
    f.name: f
    for f in (
        SampleFormat("iq_int8", True, np.dtype(np.int8), 2, 8),
        SampleFormat("real_int8", False, np.dtype(np.int8), 1, 8),
        SampleFormat("iq_int16", True, np.dtype("<i2"), 4, 16),
        SampleFormat("real_int16", False, np.dtype("<i2"), 2, 16),
        SampleFormat("iq_int4", True, np.dtype(np.uint8), 1, 4),
        SampleFormat("gr_complex", True, np.dtype("<f4"), 8, 32, writable=False),
        SampleFormat("iq_int4_sm", True, np.dtype(np.uint8), 1, 4, writable=False,
                     peer="SignalSim"),
        *(SampleFormat(f"pocket_{raw}_{kind}", kind == "iq2", np.dtype(np.uint8), nbytes,
                       3 if kind == "real3" else 2, writable=False, n_rf_channels=2 * nbytes,
                       peer="PocketSDR")
          for raw, nbytes in (("raw8", 1), ("raw16", 2), ("raw32", 4))
          for kind in ("iq2", "real2", "real3")),
        SampleFormat("pocket_raw16i_real2", False, np.dtype(np.uint8), 2, 2, writable=False,
                     n_rf_channels=8, peer="PocketSDR"),
    )
}

ALIASES = {"ibyte": "iq_int8", "byte": "real_int8", "ishort": "iq_int16",
           "short": "real_int16", "cs8": "iq_int8", "cs16": "iq_int16", "cf32": "gr_complex",
           "signalsim_int4x2": "iq_int4_sm"}


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


# -- byte-coded layouts (one 256-entry table per byte position) -------------------------------

def _sign_magnitude(sign: np.ndarray, m: np.ndarray) -> np.ndarray:
    """Odd-level sign-magnitude value ``+-(2m + 1)`` (sign 1: negative), as int8."""
    return ((1 - 2 * sign.astype(np.int16)) * (2 * m.astype(np.int16) + 1)).astype(np.int8)


def unpack_iq_int4_sm(packed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """SignalSim ``INT4X2`` bytes -> I, Q (int8, odd values -15..15).

    I is the high nibble, Q the low nibble; in each nibble bit 3 is the sign and bits 2-0
    the magnitude ``m``; the value is ``+-(2m + 1)`` (the writer truncates ``|x| * gain`` to
    ``m``, so ``2m + 1`` is the middle of the quantization interval, in half steps).
    """
    b = np.asarray(packed, dtype=np.uint8)
    hi, lo = b >> 4, b & 0xF
    return _sign_magnitude(hi >> 3, hi & 7), _sign_magnitude(lo >> 3, lo & 7)


def _pocket_2bit(code: np.ndarray) -> np.ndarray:
    """PocketSDR 2-bit code (bit 1 the sign, bit 0 the magnitude) -> +1, +3, -1, -3."""
    return _sign_magnitude((code >> 1) & 1, code & 1)


def _pocket_3bit(nibble: np.ndarray) -> np.ndarray:
    """PocketSDR 3-bit real code: bit 1 the sign, magnitude ``2 b0 + b3`` -> +-1..+-7."""
    return _sign_magnitude((nibble >> 1) & 1, 2 * (nibble & 1) + ((nibble >> 3) & 1))


def byte_layout(fmt: SampleFormat, rf_channel: int = 1) -> tuple[int, np.ndarray] | None:
    """Decoding table of a byte-coded format, for one RF channel.

    Parameters
    ----------
    fmt : SampleFormat
        The format.
    rf_channel : int, optional
        RF channel, 1-based (1 for single-channel formats).

    Returns
    -------
    (int, numpy.ndarray) or None
        The index of the byte holding the channel inside one sample, and a ``(256, n_comp)``
        int8 table from that byte's value to the channel's I, Q (or real) values; None for
        formats that are not byte-coded (plain integer and float containers).

    Raises
    ------
    SampleFormatError
        ``rf_channel`` outside ``1..fmt.n_rf_channels``.
    """
    if not 1 <= rf_channel <= fmt.n_rf_channels:
        raise SampleFormatError(f"RF channel {rf_channel} outside 1..{fmt.n_rf_channels} of "
                                f"{fmt.name}")
    b = np.arange(256, dtype=np.uint8)
    k = rf_channel - 1
    if fmt.name == "iq_int4":
        return 0, np.stack(unpack_iq_int4(b), axis=1)
    if fmt.name == "iq_int4_sm":
        return 0, np.stack(unpack_iq_int4_sm(b), axis=1)
    if fmt.name == "pocket_raw16i_real2":
        return k // 4, _pocket_2bit(b >> (2 * (k % 4)) & 3)[:, None]
    if fmt.name.startswith("pocket_raw"):
        nib = (b >> (4 * (k % 2))) & 0xF
        if fmt.name.endswith("_iq2"):
            table = np.stack([_pocket_2bit(nib & 3), -_pocket_2bit(nib >> 2)], axis=1)
        elif fmt.name.endswith("_real2"):
            table = _pocket_2bit(nib & 3)[:, None]
        else:
            table = _pocket_3bit(nib)[:, None]
        return k // 2, table.astype(np.int8)
    return None
