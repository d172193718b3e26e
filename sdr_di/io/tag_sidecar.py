"""Peers' ``.tag`` sidecars (PocketSDR, SignalSim): read them and derive the reader's options.

The tag of ``x.bin`` is ``x.bin.tag`` (the whole file name plus ``.tag``). It is a text file of
``KEY = VALUE`` lines; the keys this module reads:

========  ===================================================================================
``PROG``  writing program: ``Pocket SDR`` (PocketSDR ``sdr_tag_write``), ``IFDataGen``
          (SignalSim ``CreateTagFile``); decides what ``INT8X2`` means (below)
``FMT``   layout name: PocketSDR ``INT8``, ``INT8X2``, ``RAW8``, ``RAW16``, ``RAW16I``,
          ``RAW32``, ``CS8``, ``CS16``; SignalSim ``INT2X2``, ``INT4X2``, ``INT8X2``
``F_S``   sampling rate [MHz]
``F_LO``  local-oscillator frequency [MHz], a comma list with one value per RF channel for
          the multi-channel ``RAW*`` layouts; the B3I IF is ``1268.52 MHz - F_LO``
          (0: not set)
``IQ``    per RF channel: PocketSDR 1 = real, 2 = I/Q; SignalSim writes 1 for its I/Q
          formats, so the ``FMT`` name decides except for the channels of ``RAW*``
``BITS``  per RF channel: bits per component
========  ===================================================================================

``TIME`` is ignored: SignalSim writes the wall-clock time of the generation and PocketSDR the
host clock when its receiver started, neither a time of the samples (give
``--start-week/--start-sow`` for a time hint). ``SCALE`` (SignalSim) and unknown keys are
ignored. Blank lines are skipped; any other line without ``=``, a repeated key, a missing
required key, a number that does not parse or is out of range, an unknown ``FMT``, or an RF
channel outside the ``F_LO`` list raises :class:`~sdr_di.errors.SampleFormatError` in one
line naming the tag file and the key.

``FMT`` to sample format (:mod:`sdr_di.io.sample_formats`):

* ``INT8`` -> ``real_int8``; ``CS8`` -> ``iq_int8``; ``CS16`` -> ``iq_int16``;
* ``INT8X2`` -> ``iq_int8``; written by PocketSDR it has Q negated (read with the spectrum
  inverted), by SignalSim it does not. ``PROG`` decides (``Pocket...`` or ``IFDataGen``);
  without a known ``PROG``, ``IQ = 2`` means PocketSDR and ``IQ = 1`` SignalSim;
* ``INT4X2`` -> ``iq_int4_sm``;
* ``RAW8``/``RAW16``/``RAW32`` -> ``pocket_raw{8,16,32}_{iq2,real2,real3}`` from the chosen
  channel's ``IQ`` and ``BITS`` (I/Q channels are 2-bit; real ones 2 or 3 bits);
  ``RAW16I`` -> ``pocket_raw16i_real2``;
* ``INT2X2`` (SignalSim 2-bit) is refused: its writer (``QuantSamplesIQ2`` in
  ``IFdataGen.cpp``) never stores the bytes it packs, so such files carry no signal.

RF channel: ``rf_channel`` (``--rfch``, 1-based) or, by default, the channel whose ``F_LO`` is
nearest the B3I carrier. For real samples a negative IF (LO above the carrier) becomes
``|IF|`` with the spectrum inverted.
"""

from __future__ import annotations

import dataclasses
import math
import os
from pathlib import Path

from ..constants import F_B3I
from ..errors import SampleFormatError
from .sample_formats import get_format

__all__ = ["Tag", "TagSource", "read_tag", "tag_path", "tag_source"]

_MAX_TAG_BYTES = 65536

# peer FMT -> (registry format, RF channels); RAW* formats are completed per channel
_SINGLE = {"INT8": "real_int8", "INT8X2": "iq_int8", "CS8": "iq_int8", "CS16": "iq_int16",
           "INT4X2": "iq_int4_sm"}
_RAW = {"RAW8": ("pocket_raw8", 2), "RAW16": ("pocket_raw16", 4),
        "RAW32": ("pocket_raw32", 8), "RAW16I": ("pocket_raw16i", 8)}
_REFUSED = {"INT2X2": "SignalSim's 2-bit writer (QuantSamplesIQ2 in IFdataGen.cpp) never "
                      "stores the bytes it packs, so INT2X2 files carry no signal"}


@dataclasses.dataclass(frozen=True)
class Tag:
    """Contents of a ``.tag`` file (values as written, frequencies converted to Hz).

    Attributes
    ----------
    path : Path
        The tag file.
    prog : str or None
        ``PROG``.
    fmt : str
        ``FMT``.
    fs_hz : float
        ``F_S`` [Hz].
    f_lo_hz : tuple of float
        ``F_LO`` per RF channel [Hz].
    iq : tuple of int or None
        ``IQ`` per RF channel.
    bits : tuple of int or None
        ``BITS`` per RF channel.
    """

    path: Path
    prog: str | None
    fmt: str
    fs_hz: float
    f_lo_hz: tuple[float, ...]
    iq: tuple[int, ...] | None
    bits: tuple[int, ...] | None


@dataclasses.dataclass(frozen=True)
class TagSource:
    """Reader options derived from a tag (and the explicit overrides), for one RF channel.

    Attributes
    ----------
    sample_format : str
        Registry name.
    sampling_rate_hz, if_hz : float
        Sample rate and IF [Hz] as :class:`~sdr_di.receiver.ifreader.IfSource` takes them.
    spectrum_inverted : bool
        Read with the spectrum inverted (PocketSDR ``INT8X2`` Q negation, real samples with
        a negative IF, or ``--inverted``).
    rf_channel : int or None
        RF channel (1-based) for multi-channel formats, else None.
    peer : str
        ``"PocketSDR"`` or ``"SignalSim"``.
    """

    sample_format: str
    sampling_rate_hz: float
    if_hz: float
    spectrum_inverted: bool
    rf_channel: int | None
    peer: str


def tag_path(if_path: str | os.PathLike) -> Path:
    """``x.bin`` -> ``x.bin.tag``."""
    p = Path(if_path)
    return p.with_name(p.name + ".tag")


def _numbers(path: Path, key: str, text: str, kind: type) -> tuple:
    vals = []
    for item in text.split(","):
        item = item.strip()
        try:
            v = kind(item)
        except ValueError:
            raise SampleFormatError(f"tag {path}: {key} = {text!r}: {item!r} is not "
                                    f"{'an integer' if kind is int else 'a number'}") from None
        if kind is float and not math.isfinite(v):
            raise SampleFormatError(f"tag {path}: {key} = {text!r}: not a finite number")
        vals.append(v)
    return tuple(vals)


def read_tag(path: str | os.PathLike) -> Tag:
    """Read and check a ``.tag`` file (syntax and numbers; meaning in :func:`tag_source`).

    Raises
    ------
    SampleFormatError
        Unreadable or non-text file, a line without ``=``, a repeated key, missing ``FMT``,
        ``F_S`` or ``F_LO``, a value that does not parse, ``F_S <= 0`` or ``F_LO < 0``.
    """
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            raw = fh.read(_MAX_TAG_BYTES + 1)
    except OSError as exc:
        raise SampleFormatError(f"tag {path}: cannot read ({exc.strerror or exc})") from None
    if len(raw) > _MAX_TAG_BYTES:
        raise SampleFormatError(f"tag {path}: larger than {_MAX_TAG_BYTES} bytes, not a tag file")
    try:
        text = raw.decode("ascii")
    except UnicodeDecodeError:
        raise SampleFormatError(f"tag {path}: not an ASCII text file") from None
    fields: dict[str, str] = {}
    for no, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        key, sep, value = line.partition("=")
        key = key.strip().upper()
        if not sep or not key:
            raise SampleFormatError(f"tag {path}: line {no} {line.strip()[:40]!r} is not "
                                    "KEY = VALUE")
        if key in fields:
            raise SampleFormatError(f"tag {path}: key {key} given twice")
        fields[key] = value.strip()
    for key in ("FMT", "F_S", "F_LO"):
        if not fields.get(key):
            raise SampleFormatError(f"tag {path}: missing key {key}")
    (fs_mhz,) = _single(path, "F_S", _numbers(path, "F_S", fields["F_S"], float))
    if fs_mhz <= 0.0:
        raise SampleFormatError(f"tag {path}: F_S = {fields['F_S']} MHz is not positive")
    f_lo = _numbers(path, "F_LO", fields["F_LO"], float)
    if any(f < 0.0 for f in f_lo):
        raise SampleFormatError(f"tag {path}: F_LO = {fields['F_LO']} MHz has a negative value")
    iq = _numbers(path, "IQ", fields["IQ"], int) if fields.get("IQ") else None
    bits = _numbers(path, "BITS", fields["BITS"], int) if fields.get("BITS") else None
    return Tag(path, fields.get("PROG") or None, fields["FMT"].upper(), fs_mhz * 1e6,
               tuple(f * 1e6 for f in f_lo), iq, bits)


def _single(path: Path, key: str, vals: tuple) -> tuple:
    if len(vals) != 1:
        raise SampleFormatError(f"tag {path}: {key} has {len(vals)} values, expected 1")
    return vals


def _int8x2_peer(tag: Tag) -> str:
    prog = (tag.prog or "").strip().lower()
    if prog.startswith("pocket"):
        return "PocketSDR"
    if prog == "ifdatagen":
        return "SignalSim"
    if tag.iq is not None and tag.iq[0] in (1, 2):
        return "PocketSDR" if tag.iq[0] == 2 else "SignalSim"
    raise SampleFormatError(
        f"tag {tag.path}: FMT = INT8X2 with PROG = {tag.prog!r} and no IQ: cannot tell "
        "PocketSDR's (Q negated) from SignalSim's (Q as is); give --format iq_int8 "
        "(with --inverted for PocketSDR)")


def tag_source(tag: Tag, rf_channel: int | None = None, *, sample_format: str | None = None,
               sampling_rate_hz: float | None = None, if_hz: float | None = None,
               spectrum_inverted: bool = False, carrier_hz: float = F_B3I) -> TagSource:
    """Reader options for one RF channel of a tagged file, explicit options overriding.

    Parameters
    ----------
    tag : Tag
        From :func:`read_tag`.
    rf_channel : int, optional
        RF channel, 1-based (``--rfch``); default the channel whose ``F_LO`` is nearest
        ``carrier_hz``.
    sample_format : str, optional
        Replaces the format the tag's ``FMT``/``IQ``/``BITS`` give, and with it PocketSDR's
        ``INT8X2`` Q negation.
    sampling_rate_hz : float, optional
        Replaces ``F_S`` [Hz].
    if_hz : float, optional
        Replaces ``carrier_hz - F_LO`` [Hz] (and the inversion a negative real IF implies).
    spectrum_inverted : bool, optional
        ``--inverted``: the spectrum is inverted, whatever the tag implies (the tag can
        only add an inversion: PocketSDR ``INT8X2``, or real samples below the LO).
    carrier_hz : float, optional
        RF carrier [Hz] (B3I).

    Raises
    ------
    SampleFormatError
        Unknown or refused ``FMT``, ``F_LO``/``IQ``/``BITS`` lists of the wrong length or
        values, ``rf_channel`` outside the ``F_LO`` list, the carrier outside the recorded
        band (``|IF| >= F_S/2``).
    """
    path, fmt = tag.path, tag.fmt
    if fmt in _REFUSED:
        raise SampleFormatError(f"tag {path}: FMT = {fmt} not supported: {_REFUSED[fmt]}")
    if fmt in _SINGLE:
        name, n_ch = _SINGLE[fmt], 1
        peer = _int8x2_peer(tag) if fmt == "INT8X2" else (
            "SignalSim" if fmt == "INT4X2" else "PocketSDR")
    elif fmt in _RAW:
        name, n_ch = _RAW[fmt]
        peer = "PocketSDR"
    else:
        known = ", ".join(sorted({*_SINGLE, *_RAW, *_REFUSED}))
        raise SampleFormatError(f"tag {path}: FMT = {fmt} unknown (known: {known})")
    if len(tag.f_lo_hz) != n_ch:
        raise SampleFormatError(f"tag {path}: F_LO has {len(tag.f_lo_hz)} value(s), {fmt} has "
                                f"{n_ch} RF channel(s)")
    if rf_channel is None:
        ch = min(range(n_ch), key=lambda k: abs(carrier_hz - tag.f_lo_hz[k])) + 1
    else:
        ch = rf_channel
        if isinstance(ch, bool) or not isinstance(ch, int) or not 1 <= ch <= n_ch:
            lo = ",".join(f"{f * 1e-6:g}" for f in tag.f_lo_hz)
            raise SampleFormatError(f"tag {path}: --rfch {rf_channel} outside the {n_ch} RF "
                                    f"channel(s) of {fmt} (F_LO = {lo} MHz)")
    if fmt in _RAW:
        for key, vals in (("IQ", tag.iq), ("BITS", tag.bits)):
            if vals is None:
                raise SampleFormatError(f"tag {path}: missing key {key} (needed for {fmt})")
            if len(vals) != n_ch:
                raise SampleFormatError(f"tag {path}: {key} has {len(vals)} value(s), {fmt} "
                                        f"has {n_ch} RF channels")
        iq, bits = tag.iq[ch - 1], tag.bits[ch - 1]
        kind = {(2, 2): "iq2", (1, 2): "real2", (1, 3): "real3"}.get((iq, bits))
        if fmt == "RAW16I":
            kind = "real2" if (iq, bits) == (1, 2) else None
        if kind is None:
            raise SampleFormatError(f"tag {path}: IQ = {iq}, BITS = {bits} of RF channel {ch} "
                                    f"not a {fmt} layout (I/Q 2-bit, real 2- or 3-bit)")
        name = f"{name}_{kind}"
    q_negated = fmt == "INT8X2" and peer == "PocketSDR"
    if sample_format is not None:
        name, q_negated = get_format(sample_format).name, False
    fmt_obj = get_format(name)
    fs = float(tag.fs_hz if sampling_rate_hz is None else sampling_rate_hz)
    inverted = bool(spectrum_inverted) or (q_negated and fmt_obj.is_complex)
    if if_hz is None:
        f_lo = tag.f_lo_hz[ch - 1]
        fif = carrier_hz - f_lo
        if not fmt_obj.is_complex and fif < 0.0:
            fif, inverted = -fif, True
        if abs(fif) >= fs / 2.0:
            raise SampleFormatError(
                f"tag {path}: F_LO = {f_lo * 1e-6:g} MHz (RF channel {ch}) puts the carrier "
                f"{carrier_hz * 1e-6:g} MHz at IF {(carrier_hz - f_lo) * 1e-6:g} MHz, outside "
                f"the band +-{fs / 2e6:g} MHz of F_S; give --if (or --rfch)")
    else:
        fif = float(if_hz)
    return TagSource(name, fs, fif, inverted, ch if fmt_obj.n_rf_channels > 1 else None, peer)
