"""Chunked, memory-mapped reader of IF sample files (every format of the sample registry).

:class:`IfSource` opens a headerless IF file described by a ``sdr-di-if/1`` sidecar
(:meth:`IfSource.from_sidecar`) or by explicit options (foreign recordings: GNSS-SDR,
GNU Radio, rtl_sdr-style files...). Layouts come from :mod:`sdr_di.io.sample_formats`, the one
registry shared with the generator; this module only adds the reader-side conversions.

Reading
-------
Each :meth:`IfSource.read` maps just the byte range it needs with :class:`numpy.memmap`,
converts it to ``complex64`` (I/Q formats) or ``float32`` (real formats) and drops the map, so
the resident memory is bounded by the requested block whatever the file length (a single
whole-file map would keep every touched page resident while it lives). Values are the stored
integers (no scaling): a 4-bit ``iq_int8`` file gives I and Q in -7..7.

Byte-coded layouts (``iq_int4``, SignalSim ``iq_int4_sm``, PocketSDR ``pocket_raw*``) are
unpacked per block through one 256-entry table per (format, RF channel), built from the
registry's :func:`~sdr_di.io.sample_formats.byte_layout`: a vectorised gather, no per-sample
Python. Their values are the peers' odd levels (``+-1, +-3`` for 2 bits, ``+-1..+-15`` for
SignalSim's 4 bits). The multi-channel PocketSDR layouts are read one RF channel at a time
(``rf_channel``, 1-based); only that channel's byte of each sample is decoded.

Spectrum inversion (``spectrum_inverted=True``)
    * complex formats: the samples are conjugated, so the returned stream is non-inverted and
      ``if_hz`` is the IF of that corrected stream (a satellite with Doppler ``fd`` appears at
      ``if_hz + fd``); on disk it sits at ``-(if_hz + fd)``.
    * real formats: conjugation does nothing, so the spectrum is mirrored about ``fs/4``
      instead by multiplying sample ``k`` (file index) by ``(-1)**k``: a component at ``f``
      moves to ``fs/2 - f``. The declared ``if_hz`` is where the carrier sits in the recorded
      (inverted) spectrum, as front-end data sheets give it; the reader reports the IF of the
      corrected stream, ``IfSource.if_hz = fs/2 - declared``, and keeps the declared value in
      ``IfSource.declared_if_hz``. Correlators and acquisition must use ``IfSource.if_hz``.

What is checked (each failure raises :class:`~sdr_di.errors.SampleFormatError` with one line
naming the file)
----------------------------------------------------------------------------------------------
* unknown sample format name (the registry's error, prefixed with the file);
* missing file (also a sidecar whose ``if_file`` does not exist), unreadable file, empty file,
  file shorter than one sample;
* file holding fewer samples than the sidecar's ``n_samples`` (truncated copy or recording);
* a trailing partial sample (file size not a multiple of the sample size) is **not** an error:
  a :class:`IfFileWarning` names the number of trailing bytes, and only whole samples are read
  (front ends stopped mid-buffer produce such files; the lost fraction of a sample is
  harmless). A file longer than the sidecar's ``n_samples`` also warns and is read up to
  ``n_samples``;
* sampling rate not positive/finite; IF outside the Nyquist band (|IF| < fs/2 for complex,
  0 <= IF <= fs/2 for real);
* a heuristic check of the declared layout on up to three 64 KiB windows of the file
  (start, middle, end; ``check_format=False`` skips it). It looks at how the bytes split into
  the declared containers and flags only patterns that genuine data of the declared format
  cannot produce:

  - 16-bit declared (``iq_int16``/``real_int16``) on 8-bit data: the low byte of each word is
    a narrow, peaked distribution (circular mean of the low byte > 0.2, i.e. not the uniform
    low byte of wide 16-bit data), the high byte has the same spread as the low byte, and the
    high byte is not the sign extension of the low byte (< 60 %; genuine 16-bit data narrow
    enough to have a peaked low byte has |v| < 128 on > 80 % of words);
  - 8-bit declared (``iq_int8``/``real_int8``) on 16-bit little-endian data: the odd byte is
    the sign extension of the even byte on > 90 % of pairs with less than half its spread
    (narrow 16-bit data), or the even bytes are flat (circular mean < 0.05) while the odd
    bytes are peaked (> 0.3) (wide 16-bit data); genuine I/Q components or consecutive real
    samples share one distribution (same spread, sign extension on < 40 % of pairs);
  - 8-bit declared on packed 4-bit ``iq_int4`` data: the same test as the first on the two
    nibbles of each byte;
  - ``iq_int4`` declared on 8-bit data with small values: the high nibble is the sign
    extension of the low nibble on > 90 % of bytes, with less than half its spread;
  - an integer format declared on float32 data (``gr_complex``): >= 99 % of the 4-byte words
    read as float32 are finite with magnitude in [1e-10, 1e10];
  - ``gr_complex`` declared on integer data: > 1 % non-finite words, or < 90 % of the nonzero
    words with magnitude in [1e-20, 1e20].

  Windows with fewer than 4096 byte pairs, or nearly all-zero data, are not judged.
  **Not detected**: I/Q versus real of the same container (``iq_int8`` vs ``real_int8``...:
  identical byte statistics), big-endian 16-bit data, offset-binary (unsigned) samples,
  8-bit data whose noise spans more than about +-100 LSB declared as 16-bit, wrong sampling
  rate or IF (acquisition finds nothing, or finds satellites at wrong Doppler/code rates).
  The peers' layouts (``iq_int4_sm``, ``pocket_raw*``) are not judged beyond the float32
  test: every byte value is a valid sample there.
"""

from __future__ import annotations

import collections
import functools
import math
import os
import threading
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from ..constants import F_B3I, SECONDS_PER_WEEK
from ..errors import FormatCheckError, SampleFormatError  # noqa: F401  (FormatCheckError: its old home)
from ..io.sample_formats import SampleFormat, byte_layout, get_format
from ..io.page_cache import aligned_empty, open_uncached, pread_uncached, release_read_behind
from ..paths import note_input
from ..io.sidecar import check_member, member_path, read_sidecar

__all__ = ["FormatCheckError", "IfFileWarning", "IfSource", "check_format_statistics"]




class IfFileWarning(UserWarning):
    """Suspicious but readable IF file (partial trailing sample, longer than declared)."""



@functools.cache
def _byte_tables(name: str, rf_channel: int) -> tuple[int, np.ndarray, np.ndarray] | None:
    """Reader tables of a byte-coded format (the registry's :func:`byte_layout`).

    Returns the byte index of the channel inside a sample, a 256-entry table to the
    :meth:`IfSource.read` values (complex64 or float32) and a 256-entry table for
    :meth:`IfSource.read_stored` (int8, or int16 holding an int8 (I, Q) pair in memory
    order); None for plain containers.
    """
    layout = byte_layout(get_format(name), rf_channel)
    if layout is None:
        return None
    byte, table = layout
    # stored values as one 1-D table of whole samples (an (I, Q) int8 pair read as one int16):
    # a 1-D gather is several times faster than indexing rows of a 2-D table
    pairs = np.ascontiguousarray(table.astype(np.int8))
    pairs = pairs.view(np.int16)[:, 0] if pairs.shape[1] == 2 else pairs[:, 0]
    if table.shape[1] == 2:
        values = (table[:, 0].astype(np.float32)
                  + 1j * table[:, 1].astype(np.float32)).astype(np.complex64)
    else:
        values = table[:, 0].astype(np.float32)
    return byte, values, pairs

_CHECK_WINDOW_BYTES = 65536
#: Values per block of the read-ahead's sums of squares (:meth:`IfSource.read_stored_power`;
#: a block's sum of 8-bit squares stays below 2**31).
_POWER_BLOCK = 65536
_CHECK_MIN_PAIRS = 4096
#: Power blocks per piece of a read-ahead (:class:`_ReadAhead`): 1 MiB of 8-bit values.
_PIECE_BLOCKS = 16
#: Longest wait of the read-ahead thread for the split kernel calls to end, per piece [s].
_SPLIT_WAIT_S = 0.02


class IfSource:
    """A recorded IF sample stream, read in blocks through short-lived memory maps.

    Parameters
    ----------
    path : str or Path
        Headerless IF file.
    sampling_rate_hz : float
        Sample rate ``fs`` [Hz].
    if_hz : float
        Intermediate frequency of the carrier [Hz] (0 for complex baseband). For a real
        format with ``spectrum_inverted`` this is where the carrier sits in the recorded
        spectrum; see the module notes.
    sample_format : str
        Name or alias in :mod:`sdr_di.io.sample_formats`.
    spectrum_inverted : bool, optional
        The front end inverts the spectrum (high-side LO...). Corrected on reading.
    start_week, start_sow : int, float, optional
        BDT week and seconds of week of sample 0 (receiver clock), when known.
    n_samples : int, optional
        Expected number of samples (the sidecar's): a shorter file is an error, a longer one
        warns and is read up to ``n_samples``.
    check_format : bool, optional
        Run the layout heuristic (module notes) when opening. Default True.
    carrier_hz : float, optional
        RF carrier the IF corresponds to [Hz], for code-Doppler scaling. Default B3I.
    meta : dict, optional
        The sidecar contents, kept as :attr:`meta`.
    rf_channel : int, optional
        RF channel to read, 1-based (PocketSDR ``-RFCH`` numbering), for formats that
        interleave several (``pocket_raw*``); required for them, and must be 1 or None for
        single-channel formats.

    Raises
    ------
    SampleFormatError
        See the module notes.
    """

    def __init__(self, path: str | os.PathLike, sampling_rate_hz: float, if_hz: float,
                 sample_format: str, spectrum_inverted: bool = False,
                 start_week: int | None = None, start_sow: float | None = None, *,
                 n_samples: int | None = None, check_format: bool = True,
                 carrier_hz: float = F_B3I, meta: dict[str, Any] | None = None,
                 rf_channel: int | None = None):
        self.path = Path(path)
        try:
            self.format: SampleFormat = get_format(sample_format)
        except SampleFormatError as exc:
            raise SampleFormatError(f"IF file {self.path}: {exc}") from None
        n_ch = self.format.n_rf_channels
        if rf_channel is None and n_ch > 1:
            raise SampleFormatError(f"IF file {self.path}: {self.format.name} interleaves {n_ch} "
                                    f"RF channels; choose one with --rfch (1-{n_ch})")
        ch = 1 if rf_channel is None else rf_channel
        if (isinstance(ch, bool) or not isinstance(ch, (int, np.integer))
                or not 1 <= ch <= n_ch):
            raise SampleFormatError(f"IF file {self.path}: RF channel {rf_channel!r} outside "
                                    f"1..{n_ch} of {self.format.name}")
        self.rf_channel = int(ch)
        self._tables = _byte_tables(self.format.name, self.rf_channel)
        fs = float(sampling_rate_hz)
        if not (math.isfinite(fs) and fs > 0.0):
            raise SampleFormatError(f"IF file {self.path}: sampling rate {sampling_rate_hz!r} Hz "
                                    "is not a positive number")
        fif = float(if_hz)
        if self.format.is_complex:
            ok = math.isfinite(fif) and abs(fif) < fs / 2.0
            band = f"|IF| < fs/2 = {fs / 2:g} Hz"
        else:
            ok = math.isfinite(fif) and 0.0 <= fif <= fs / 2.0
            band = f"0 <= IF <= fs/2 = {fs / 2:g} Hz for real samples"
        if not ok:
            raise SampleFormatError(f"IF file {self.path}: IF {if_hz!r} Hz outside {band}")
        self.sampling_rate_hz = fs
        self.declared_if_hz = fif
        self.spectrum_inverted = bool(spectrum_inverted)
        self._mirror = self.spectrum_inverted and not self.format.is_complex
        self.if_hz = fs / 2.0 - fif if self._mirror else fif
        self.start_week = None if start_week is None else int(start_week)
        self.start_sow = None if start_sow is None else float(start_sow)
        self.carrier_hz = float(carrier_hz)
        self.meta = meta
        #: Read the next chunk in a background thread (:meth:`read_stored` notes).
        self.read_ahead = True
        #: Let the read-ahead read past the page cache (``O_DIRECT``; :meth:`_read_stored_into`);
        #: cleared by the first read the file system refuses.
        self.uncached = True
        self._pool = None
        self._ahead: tuple | None = None
        #: ``(first sample, stored values)`` of the last read, for the next read-ahead to
        #: copy its first samples from (:meth:`_after_read`); dropped once used.
        self._held: tuple | None = None
        # the end of the last read, and the overlaps the caller's last 8 reads asked for
        # again (samples): the read-ahead starts twice the largest before the end
        self._prev_end: int | None = None
        self._overlaps: collections.deque[int] = collections.deque(maxlen=8)

        try:
            size = self.path.stat().st_size
        except FileNotFoundError:
            raise SampleFormatError(f"IF file {self.path}: not found") from None
        except OSError as exc:
            raise SampleFormatError(f"IF file {self.path}: cannot stat ({exc.strerror or exc})"
                                    ) from None
        if not self.path.is_file():
            raise SampleFormatError(f"IF file {self.path}: not a regular file")
        if not os.access(self.path, os.R_OK):
            raise SampleFormatError(f"IF file {self.path}: not readable")
        note_input(self.path, what="IF file")
        bps = self.format.bytes_per_sample
        if size == 0:
            raise SampleFormatError(f"IF file {self.path}: empty file")
        whole, rest = divmod(size, bps)
        if whole == 0:
            raise SampleFormatError(f"IF file {self.path}: {size} bytes, shorter than one "
                                    f"{self.format.name} sample ({bps} bytes)")
        if n_samples is not None:
            n_samples = int(n_samples)
            if whole < n_samples:
                raise SampleFormatError(
                    f"IF file {self.path}: holds {whole} samples, the sidecar says {n_samples} "
                    f"(truncated file: {n_samples - whole} samples missing)")
            if whole > n_samples:
                warnings.warn(f"IF file {self.path}: holds {whole} samples, more than the "
                              f"sidecar's {n_samples}; reading the first {n_samples}",
                              IfFileWarning, stacklevel=2)
                whole = n_samples
        self._n = int(whole)
        if check_format:
            problem = check_format_statistics(self.path, self.format, self._n)
            if problem:
                raise FormatCheckError(f"IF file {self.path}: declared {self.format.name} but "
                                       f"{problem}", "pass check_format=False to read anyway")
        if rest:  # after the format check: a refused file gets one line
            warnings.warn(f"IF file {self.path}: size {size} bytes is not a whole number of "
                          f"{self.format.name} samples ({bps} bytes each); ignoring the "
                          f"{rest} trailing byte(s) of a partial sample", IfFileWarning,
                          stacklevel=2)

    # -- construction from a sidecar ---------------------------------------------------------
    @classmethod
    def from_sidecar(cls, path: str | os.PathLike, check_format: bool = True) -> IfSource:
        """Open the IF file described by a ``sdr-di-if/1`` sidecar.

        Parameters
        ----------
        path : str or Path
            The sidecar JSON; its ``if_file`` is relative to the sidecar's folder.
        check_format : bool, optional
            Run the layout heuristic.

        Raises
        ------
        SampleFormatError
            Unreadable or malformed sidecar, missing IF file, truncated IF file, unknown or
            implausible format.
        """
        path = Path(path)
        meta = read_sidecar(path)
        note_input(path, what="sidecar")
        if_path = member_path(path, meta, "if_file")
        if not if_path.exists():
            raise SampleFormatError(f"sidecar {path}: IF file {if_path} not found")
        check_member(path, meta, "if_file")  # size and digest recorded by the generator
        start = meta.get("start") or {}
        src = cls(if_path, meta["sampling_rate_hz"], meta["if_hz"], meta["sample_format"],
                  spectrum_inverted=bool(meta.get("spectrum_inverted", False)),
                  start_week=start.get("week"), start_sow=start.get("sow"),
                  n_samples=meta["n_samples"], check_format=check_format,
                  carrier_hz=float(meta.get("carrier_hz", F_B3I)), meta=meta)
        src.sidecar_path = path  # its companions (IMU, truth) are relative to it
        return src

    # -- properties ---------------------------------------------------------------------------
    @property
    def n_samples(self) -> int:
        """Whole samples readable from the file."""
        return self._n

    @property
    def duration_s(self) -> float:
        """File duration ``n_samples / fs`` [s]."""
        return self._n / self.sampling_rate_hz

    @property
    def is_complex(self) -> bool:
        """True for I/Q formats (``read`` returns complex64), False for real (float32)."""
        return self.format.is_complex

    @property
    def dtype(self) -> np.dtype:
        """Element type of the blocks returned by :meth:`read`."""
        return np.dtype(np.complex64 if self.format.is_complex else np.float32)

    def sample_time(self, k: float) -> tuple[int, float]:
        """BDT (week, seconds of week) of sample ``k`` on the receiver clock.

        Raises
        ------
        SampleFormatError
            The start time is unknown.
        """
        if self.start_week is None or self.start_sow is None:
            raise SampleFormatError(f"IF file {self.path}: start time unknown")
        sow = self.start_sow + k / self.sampling_rate_hz
        dw = math.floor(sow / SECONDS_PER_WEEK)
        return self.start_week + dw, sow - dw * SECONDS_PER_WEEK

    def __repr__(self) -> str:
        return (f"IfSource({str(self.path)!r}, fs={self.sampling_rate_hz:g} Hz, "
                f"if={self.if_hz:g} Hz, format={self.format.name}, n={self._n}, "
                f"inverted={self.spectrum_inverted})")

    # -- reading -----------------------------------------------------------------------------
    def _convert(self, raw: np.ndarray) -> np.ndarray:
        """Raw bytes of whole samples -> complex64 / float32 values (a fresh array)."""
        fmt = self.format
        if self._tables is not None:
            byte, values, _ = self._tables
            bps = fmt.bytes_per_sample
            return values[raw[byte::bps] if bps > 1 else raw]
        if fmt.name == "gr_complex":
            return raw.view(np.dtype("<f4")).astype(np.float32).view(np.complex64)
        vals = raw.view(fmt.dtype).astype(np.float32)
        if fmt.is_complex:
            return vals.view(np.complex64)
        return vals

    def read(self, start_sample: int, n: int) -> np.ndarray:
        """Read ``n`` samples starting at sample ``start_sample``.

        Parameters
        ----------
        start_sample : int
            Index of the first sample (0-based, file order).
        n : int
            Number of samples; ``start_sample + n`` must not exceed :attr:`n_samples`.

        Returns
        -------
        numpy.ndarray
            ``complex64`` (I + jQ) for I/Q formats, ``float32`` for real formats, shape
            ``(n,)``, stored integer values, spectrum inversion corrected. A fresh array (not a
            view of the map).

        Raises
        ------
        ValueError
            Range outside the file.
        """
        start_sample = int(start_sample)
        n = int(n)
        if start_sample < 0 or n < 0 or start_sample + n > self._n:
            raise ValueError(f"IF file {self.path}: samples [{start_sample}, {start_sample + n})"
                             f" outside [0, {self._n})")
        if n == 0:
            return np.empty(0, self.dtype)
        bps = self.format.bytes_per_sample
        raw = np.memmap(self.path, dtype=np.uint8, mode="r", offset=start_sample * bps,
                        shape=(n * bps,))
        try:
            out = self._convert(raw)
        finally:
            mm = getattr(raw, "_mmap", None)
            del raw
            if mm is not None:
                try:
                    mm.close()
                except BufferError:  # pragma: no cover - a view still alive
                    pass
        if self.spectrum_inverted:
            if self.format.is_complex:
                np.conjugate(out, out=out)
            else:
                out[(1 - start_sample % 2)::2] *= -1.0
        return out

    def read_stored(self, start_sample: int, n: int) -> tuple[np.ndarray, int]:
        """Read ``n`` samples as stored integers, without conversion to float.

        For the receiver's correlator kernel, which converts the values itself. Values are
        those :meth:`read` returns (same scale), in the smallest exact type.

        Parameters
        ----------
        start_sample, n : int
            As in :meth:`read`.

        Returns
        -------
        values : numpy.ndarray
            1-D, ``n * n_comp`` values: ``int8`` (``iq_int8``, ``real_int8``, the byte-coded
            layouts unpacked), ``int16`` (``iq_int16``, ``real_int16``) or ``float32``
            (``gr_complex``, and every format when the spectrum is inverted: then the
            :meth:`read` values, corrected); I and Q interleaved for I/Q formats. A fresh
            array (or a slice of a fresh read-ahead buffer that nothing else refers to).
        n_comp : int
            2 for I/Q formats, 1 for real ones.

        Raises
        ------
        ValueError
            Range outside the file.

        Notes
        -----
        **Read-ahead** (:attr:`read_ahead`, default True): after each call, a background
        thread reads the next ``n + b`` samples from ``b`` before this call's end, the
        range the receivers' sequential chunk reads ask for next: they re-read an overlap of
        up to two coherent blocks, and ``b`` is twice the largest overlap of the last 8 calls
        (``n / 2`` at most, and before any overlap was seen). The samples of that range the
        last read already holds (its last ``b``, and the samples its read-ahead read past
        the range asked for) are copied from its values before they are returned, and only
        the rest is read from the file: on the 40 s 25 MHz default file the receivers ask
        for 1.12 times the file (chunks of 100 or 200 ms that overlap by 10 ms); the file
        was read 1.35 times with every read-ahead read whole (scalar and deep alike,
        measured 2026-12-04) and 1.5 times with ``b = n / 2``. A later call inside that
        range is served from it, so the file read overlaps the caller's work (the read
        releases the GIL, as do the correlator kernels); any other call reads
        synchronously and drops it. The read-ahead goes a piece at a time, while no split
        kernel call keeps both cores busy, and the call that needs the values reads the
        pieces not yet taken itself (:class:`_ReadAhead`). The values are the same either
        way.
        """
        n_comp = 2 if self.format.is_complex else 1
        if self.spectrum_inverted:
            return self.read(start_sample, n).view(np.float32), n_comp
        start_sample = int(start_sample)
        n = int(n)
        if start_sample < 0 or n < 0 or start_sample + n > self._n:
            raise ValueError(f"IF file {self.path}: samples [{start_sample}, {start_sample + n})"
                             f" outside [0, {self._n})")
        out = self._take_ahead(start_sample, n, n_comp)
        if out is None:
            out = self._read_stored_now(start_sample, n, n_comp)
            self._held = (start_sample, out)
        self._after_read(start_sample, n, n_comp)
        return out, n_comp

    def _after_read(self, start_sample: int, n: int, n_comp: int) -> None:
        """Schedule the read-ahead after a read of ``[start_sample, start_sample + n)``; the
        values held from it (:attr:`_held`) that the read-ahead's range starts with are
        copied in rather than read again (:meth:`read_stored` notes)."""
        end = start_sample + n
        held, self._held = self._held, None
        if self._prev_end is not None and start_sample <= self._prev_end:
            self._overlaps.append(self._prev_end - start_sample)
        self._prev_end = end
        if self.read_ahead and n > 0 and end < self._n:
            back = min(n // 2, 2 * max(self._overlaps)) if self._overlaps else n // 2
            a0 = end - back
            m = min(n + back, self._n - a0)
            head = None
            if held is not None:
                h0, vals = held
                h1 = min(h0 + vals.size // n_comp, a0 + m)
                if h0 <= a0 < h1:
                    head = vals[(a0 - h0) * n_comp:(h1 - h0) * n_comp]
            self._schedule_ahead(a0, m, n_comp, head)

    def read_stored_power(self, start_sample: int, n: int) -> tuple[np.ndarray, int, float]:
        """:meth:`read_stored` and the mean power per sample of the values it returns
        (``sum(values**2) / n`` [stored units^2], :func:`~sdr_di.receiver.
        _numba_correlate_bits.mean_power`'s value, bit for bit).

        For 8-bit values served from the read-ahead, the read-ahead thread has summed the
        squares over blocks of :data:`_POWER_BLOCK` values; only the partial blocks at the
        ends are summed here. The sums are integers below 2**53 and so exact in any order:
        the value is the same as summing here. Other formats are summed here.
        """
        from ._numba_correlate_bits import block_sum_squares, mean_power

        n_comp = 2 if self.format.is_complex else 1
        hit = None
        if not self.spectrum_inverted:
            hit = self._take_ahead(int(start_sample), int(n), n_comp, with_power=True)
        if hit is None:
            x, n_comp = self.read_stored(start_sample, n)
            return x, n_comp, float(mean_power(x, n_comp))
        x, sums, i0 = hit
        self._after_read(int(start_sample), int(n), n_comp)
        i1 = i0 + x.size
        b0 = -(-i0 // _POWER_BLOCK)
        b1 = i1 // _POWER_BLOCK
        if sums is None or b1 <= b0:
            return x, n_comp, float(mean_power(x, n_comp))
        edge = np.zeros(2)
        head, tail = x[:b0 * _POWER_BLOCK - i0], x[b1 * _POWER_BLOCK - i0:]
        block_sum_squares(head, max(head.size, 1), edge[:1])
        block_sum_squares(tail, max(tail.size, 1), edge[1:])
        total = float(np.sum(sums[b0:b1])) + float(edge[0]) + float(edge[1])
        m = x.size // n_comp
        return x, n_comp, (total / m if m > 0 else 0.0)

    def _file_dtype(self) -> np.dtype:
        """The dtype of the values in the file, for the formats read without a byte table."""
        return np.dtype("<f4") if self.format.name == "gr_complex" else np.dtype(
            self.format.dtype)

    def _stored_dtype(self) -> np.dtype:
        """The dtype :meth:`read_stored` returns (native byte order)."""
        if self._tables is not None:
            return np.dtype(np.int8)
        return self._file_dtype().newbyteorder("=")

    def _read_stored_into(self, out: np.ndarray, start_sample: int, n: int,
                          n_comp: int) -> None:
        """:meth:`_read_stored_now` of a checked range into ``out`` (``n * n_comp`` values
        of :meth:`_stored_dtype`): formats stored as they are served are read straight
        into it, the others converted and copied.

        A straight read bypasses the page cache where the file system allows it
        (:attr:`uncached`; :func:`~sdr_di.io.page_cache.pread_uncached`: ``O_DIRECT``, the
        disk's data straight into ``out`` when its address is aligned with the file offset,
        as :class:`_ReadAhead`'s buffers are). On the 2-core VM that took 0.58 s of system
        time off a scalar run of the 40 s default file (1.07-1.26 s against 1.55-1.94 s, six
        interleaved pairs). Where it is refused, it reads through the cache
        (``os.preadv``) and the pages it leaves 64 MiB behind leave the cache
        (:func:`~sdr_di.io.page_cache.release_read_behind`): on the same VM a 2 GB file
        read from disk cost 4.4 s of system time into fresh cache pages, 0.3 s with them
        released and reused (as much as reading it from the cache)."""
        fmt = self.format
        bps = fmt.bytes_per_sample
        if self._tables is not None or not hasattr(os, "preadv") or \
                not self._file_dtype().isnative:
            out[:] = self._read_stored_now(start_sample, n, n_comp)
            return
        if self.uncached:
            fd = open_uncached(self.path)
            if fd is not None:
                try:
                    got = pread_uncached(fd, out.view(np.uint8), start_sample * bps)
                except OSError:       # (EINVAL: no uncached reads on this file system)
                    got = None
                finally:
                    os.close(fd)
                if got == n * bps:
                    return
                if got is not None:
                    raise SampleFormatError(
                        f"IF file {self.path}: short read at sample {start_sample}")
            self.uncached = False
        view = memoryview(out).cast("B")
        fd = os.open(self.path, os.O_RDONLY)
        try:
            done, want, off = 0, n * bps, start_sample * bps
            while done < want:
                got = os.preadv(fd, [view[done:want]], off + done)
                if got <= 0:
                    raise SampleFormatError(
                        f"IF file {self.path}: short read at sample {start_sample}")
                done += got
            release_read_behind(fd, off, want)
        finally:
            os.close(fd)

    def _read_stored_now(self, start_sample: int, n: int, n_comp: int) -> np.ndarray:
        """:meth:`read_stored` of a checked range, read now (a fresh array)."""
        fmt = self.format
        if n == 0:
            return np.empty(0, self._stored_dtype())
        # one read() into a fresh array: cheaper than mapping the range and copying it
        # (no page faults on a new mapping per chunk)
        bps = fmt.bytes_per_sample
        with open(self.path, "rb") as fh:            # (offsets from its start)
            if self._tables is not None:
                byte, _, pairs = self._tables
                raw = np.fromfile(fh, dtype=np.uint8, count=n * bps, offset=start_sample * bps)
                if bps > 1:
                    raw = raw[byte::bps]
                out = pairs[raw].view(np.int8)
            else:
                dt = self._file_dtype()
                out = np.fromfile(fh, dtype=dt, count=n * bps // dt.itemsize,
                                  offset=start_sample * bps)
                if not out.dtype.isnative:
                    out = out.astype(out.dtype.newbyteorder("="))
            release_read_behind(fh.fileno(), start_sample * bps, n * bps)
        if out.size != n * n_comp:
            raise SampleFormatError(f"IF file {self.path}: short read at sample {start_sample}")
        return out

    def _schedule_ahead(self, start_sample: int, n: int, n_comp: int,
                        head: np.ndarray | None = None) -> None:
        """Start reading ``[start_sample, start_sample + n)`` in the background
        (:class:`_ReadAhead`); ``head``, the stored values of its first samples, already
        read, is copied in (here, before the caller can change them) instead."""
        if self._pool is None:
            from concurrent.futures import ThreadPoolExecutor

            self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="if-read-ahead")
        job = _ReadAhead(self, start_sample, n, n_comp)
        if head is not None and 0 < head.size <= job.values.size \
                and head.dtype == job.values.dtype and head.size % n_comp == 0:
            job.values[:head.size] = head
            job.copied = head.size // n_comp
        if job.sums is not None:
            _compile_here()
        self._pool.submit(job.run)
        self._ahead = (start_sample, n, job)

    def _take_ahead(self, start_sample: int, n: int, n_comp: int, with_power: bool = False):
        """The requested range from the pending read-ahead, or None (which is dropped).
        ``with_power``: ``(values, block sums of squares or None, index of the first value
        in the read-ahead buffer)`` instead of the values."""
        ahead, self._ahead = self._ahead, None
        if ahead is None:
            return None
        a0, m, job = ahead
        if not (a0 <= start_sample and start_sample + n <= a0 + m):
            job.cancel()
            return None
        try:
            buf, sums = job.result()
        except Exception:  # noqa: BLE001 - read again in the caller's thread, which raises
            return None
        self._held = (a0, buf)           # (the next read-ahead's head: _after_read)
        i = (start_sample - a0) * n_comp
        if with_power:
            return buf[i:i + n * n_comp], sums, i
        return buf[i:i + n * n_comp]

    def __getstate__(self) -> dict:
        st = dict(self.__dict__)
        st["_pool"] = None
        st["_ahead"] = None
        st["_held"] = None
        return st

    def chunks(self, n_per_chunk: int, start: int = 0,
               stop: int | None = None) -> Iterator[tuple[int, np.ndarray]]:
        """Iterate over consecutive blocks of the file.

        Parameters
        ----------
        n_per_chunk : int
            Samples per block (> 0); the last block may be shorter.
        start : int, optional
            First sample.
        stop : int, optional
            One past the last sample (default: end of file).

        Yields
        ------
        (int, numpy.ndarray)
            Index of the block's first sample and the block (as :meth:`read`). The blocks
            cover ``[start, stop)`` exactly, without overlap.
        """
        n_per_chunk = int(n_per_chunk)
        if n_per_chunk <= 0:
            raise ValueError(f"n_per_chunk must be positive, got {n_per_chunk}")
        stop = self._n if stop is None else min(int(stop), self._n)
        k = int(start)
        if k < 0:
            raise ValueError(f"start must be >= 0, got {start}")
        while k < stop:
            m = min(n_per_chunk, stop - k)
            yield k, self.read(k, m)
            k += m




# -- layout heuristic ------------------------------------------------------------------------

def _compile_here() -> None:
    """Compile (or load from numba's cache) the read-ahead thread's kernel on this thread.

    Numba collects its compiler's warnings with :class:`warnings.catch_warnings`, which
    swaps process-wide state: compiling on the read-ahead thread while this thread is
    inside its own ``catch_warnings`` (the deep run's navigation-data warnings, a test's
    ``pytest.warns``) can take this thread's warnings away. It happened in a clean-clone
    test run, whose numba cache starts empty: an ``IfFileWarning`` was not seen."""
    from ._numba_correlate_bits import block_sum_squares

    block_sum_squares(np.zeros(1, np.int8), 1, np.empty(1))


class _ReadAhead:
    """One read-ahead of ``[start, start + n)`` of an :class:`IfSource`, in pieces of
    :data:`_PIECE_BLOCKS` power blocks, with their block sums of squares when the values are
    8-bit (:meth:`IfSource.read_stored_power`).

    A read through the page cache costs CPU (the copy, the cache's pages), so the read-ahead
    thread (:meth:`run`) then reads a piece only while no split kernel call runs
    (:func:`~sdr_di.receiver.threads.wait_for_split_calls`, at most
    :data:`_SPLIT_WAIT_S` per piece): during one, both cores are busy with the calling
    thread and the kernel worker the caller waits for, and a read there delayed the worker.
    On the 2-core machine (40 s default file, deep run, interleaved runs, 2026-12-04) the
    main thread's waits on the kernel worker were 0.79-1.17 s per run with each chunk read
    at once, whenever asked, and 0.53-0.81 s with the pieces held back (0.38-0.70 s with the
    read thread at the idle scheduling class instead, which can stall the caller on a loaded
    machine: a starved thread may hold the GIL). The caller that needs the values
    (:meth:`result`) reads the pieces not yet taken itself, so it waits for no more than the
    pieces being read, and nothing is starved when the kernels never stop (several
    receivers in threads of one process).

    An uncached read (:attr:`IfSource.uncached`) costs next to no CPU (the disk's data go
    straight into the buffer) and is not held back. Held back, it left the caller more
    pieces to read itself, at the disk's pace: the deep loop's read stage took 0.61-0.76 s
    per 40 s run, against 0.36-0.38 s with reads through the cache, and 0.15-0.26 s not
    held back (three interleaved sets, 2026-12-04).
    """

    def __init__(self, src: IfSource, start: int, n: int, n_comp: int) -> None:
        self.src, self.start, self.n_comp = src, start, n_comp
        dt = src._stored_dtype()    # (aligned with the file: its reads go straight into it)
        self.values = aligned_empty(n * n_comp * dt.itemsize,
                                    start * src.format.bytes_per_sample).view(dt)
        self.sums = np.empty(-(-self.values.size // _POWER_BLOCK)) \
            if self.values.dtype == np.int8 else None
        step = _PIECE_BLOCKS * _POWER_BLOCK // n_comp          # samples per piece
        self.pieces = [(a, min(a + step, n)) for a in range(0, n, step)]
        self.copied = 0                  # leading samples copied in, not to read
        self._next = 0                   # first piece not taken
        self._busy = 0                   # pieces being read
        self._stop = False
        self._error: BaseException | None = None
        self._cond = threading.Condition()

    def _left(self) -> bool:
        return not self._stop and self._error is None and self._next < len(self.pieces)

    def _take(self) -> int | None:
        with self._cond:
            if not self._left():
                return None
            self._busy += 1
            self._next += 1
            return self._next - 1

    def _read(self, i: int) -> None:
        from ._numba_correlate_bits import block_sum_squares

        try:
            a, b = self.pieces[i]
            v0, v1 = a * self.n_comp, b * self.n_comp
            r0 = max(a, self.copied)
            if r0 < b:
                self.src._read_stored_into(self.values[r0 * self.n_comp:v1], self.start + r0,
                                           b - r0, self.n_comp)
            if self.sums is not None:    # v0 is a multiple of the block
                block_sum_squares(self.values[v0:v1], _POWER_BLOCK,
                                  self.sums[v0 // _POWER_BLOCK:-(-v1 // _POWER_BLOCK)])
        except BaseException as e:  # noqa: BLE001 - re-raised by result()
            with self._cond:
                self._error = self._error or e
        finally:
            with self._cond:
                self._busy -= 1
                self._cond.notify_all()

    def run(self) -> None:
        """The read-ahead thread's work (class notes)."""
        from .threads import wait_for_split_calls

        while self._left():            # (taken by the caller: not waited for)
            if not self.src.uncached:
                wait_for_split_calls(_SPLIT_WAIT_S)   # (class notes)
            i = self._take()
            if i is None:
                return
            self._read(i)

    def result(self) -> tuple[np.ndarray, np.ndarray | None]:
        """The values and their block sums (None unless 8-bit): the pieces not yet taken
        are read here, the ones being read waited for; a read's exception is raised."""
        while (i := self._take()) is not None:
            self._read(i)
        with self._cond:
            self._cond.wait_for(lambda: self._busy == 0)
        if self._error is not None:
            raise self._error
        return self.values, self.sums

    def cancel(self) -> None:
        """Read no more pieces (the values are not needed)."""
        with self._cond:
            self._stop = True


def _circ_mean(lo_u: np.ndarray, period: int) -> float:
    """|mean(exp(2 pi j lo / period))|: 0 for a flat distribution, ~1 when peaked near 0."""
    ang = lo_u.astype(np.float64) * (2.0 * np.pi / period)
    return float(np.hypot(np.mean(np.cos(ang)), np.mean(np.sin(ang))))


def _split_stats(hi: np.ndarray, lo_u: np.ndarray, width: int) -> dict[str, float]:
    """Statistics of (signed high part, unsigned low part) of containers split in two."""
    period = 1 << width
    lo_s = np.where(lo_u >= period // 2, lo_u.astype(np.int32) - period, lo_u.astype(np.int32))
    ext = np.where(lo_s < 0, -1, 0)
    hi = hi.astype(np.int32)
    s_lo = float(np.std(lo_s))
    s_hi = float(np.std(hi))
    return {
        "r_lo": _circ_mean(lo_u, period),
        "r_hi": _circ_mean(hi & (period - 1), period),
        "ext": float(np.mean(hi == ext)),
        "ratio": s_hi / s_lo if s_lo > 0 else math.inf,
        "s_lo": s_lo,
        "nonzero": float(np.mean((lo_s != 0) | (hi != 0))),
    }


def _narrow_pairs_in_wide(st: dict[str, float]) -> bool:
    """Containers declared wide that hold pairs of narrow values."""
    return (st["nonzero"] > 0.3 and st["r_lo"] > 0.2 and st["ext"] < 0.6
            and 0.5 < st["ratio"] < 2.0)


def _wide_in_narrow(st: dict[str, float]) -> bool:
    """Pairs of narrow containers that are the halves of wide values."""
    if st["nonzero"] < 0.5 or st["s_lo"] < 0.5:
        return False
    return ((st["ext"] > 0.9 and st["ratio"] < 0.5)
            or (st["r_lo"] < 0.05 and st["r_hi"] > 0.3))


def _float_like(b: np.ndarray) -> bool:
    n = (b.size // 4) * 4
    if n < 4 * _CHECK_MIN_PAIRS // 2:
        return False
    with np.errstate(invalid="ignore", over="ignore"):
        v = b[:n].view(np.dtype("<f4")).astype(np.float64)
        a = np.abs(v)
        ok = np.isfinite(v) & (a >= 1e-10) & (a <= 1e10)
    return float(np.mean(ok)) >= 0.99


#: Longest repetition period looked for by :func:`content_problem` [bytes]: a sampled
#: signal with receiver noise never repeats exactly; a file that does is a test pattern, a
#: copied block or not samples at all.
MAX_PERIOD_BYTES = 4096


def content_problem(b: np.ndarray) -> str | None:
    """What makes the bytes ``b`` (the start of an IF file) no recording of any format, or
    None: text (printable ASCII with line breaks), one value throughout, or a pattern that
    repeats exactly with a period of at most :data:`MAX_PERIOD_BYTES` bytes (issue 49 item 8:
    a text file read as ``iq_int8`` gave two satellites "detected")."""
    n = b.size
    if n < 2 * _CHECK_MIN_PAIRS:
        return None
    printable = (b >= 32) & (b <= 126) | (b == 9) | (b == 10) | (b == 13)
    if printable.mean() > 0.99 and np.any(b == 10):
        return "its bytes are text (printable characters and line breaks), not samples"
    if np.all(b == b[0]):
        return f"every byte is {int(b[0]):#04x}: the file holds no signal"
    m = min(n // 2, _CHECK_MIN_PAIRS)
    for p in np.nonzero(b[1:MAX_PERIOD_BYTES + 1] == b[0])[0] + 1:
        p = int(p)
        if p + m <= n and np.array_equal(b[p:], b[:n - p]):
            return (f"its bytes repeat exactly every {p} bytes: a pattern, not a recording "
                    "with receiver noise")
    return None


def check_format_statistics(path: str | os.PathLike, fmt: SampleFormat | str,
                            n_samples: int | None = None) -> str | None:
    """Heuristic check that the bytes of an IF file fit the declared layout.

    Parameters
    ----------
    path : str or Path
        IF file.
    fmt : SampleFormat or str
        Declared format.
    n_samples : int, optional
        Whole samples to consider (default: from the file size).

    Returns
    -------
    str or None
        A short description of the implausibility, or None when nothing is flagged (including
        when there is too little or too uniform data to judge). See the module notes for what
        is and is not detected.
    """
    if isinstance(fmt, str):
        fmt = get_format(fmt)
    path = Path(path)
    bps = fmt.bytes_per_sample
    if n_samples is None:
        n_samples = path.stat().st_size // bps
    total = n_samples * bps
    win = min(total, _CHECK_WINDOW_BYTES)
    win -= win % 8  # whole samples of every format and whole float32 pairs
    if win < 2 * _CHECK_MIN_PAIRS:
        return None
    starts = sorted({0, ((total - win) // 2) // 8 * 8, (total - win) // 8 * 8})
    parts = []
    with open(path, "rb") as fh:
        for s in starts:
            fh.seek(s)
            parts.append(np.frombuffer(fh.read(win), dtype=np.uint8))
    problem = content_problem(parts[0])
    if problem:
        return problem
    b = np.concatenate(parts)
    name = fmt.name
    if name == "gr_complex":
        with np.errstate(invalid="ignore", over="ignore"):
            v = b.view(np.dtype("<f4")).astype(np.float64)
            fin = np.isfinite(v)
            a = np.abs(v)
            nz = fin & (a > 0)
            plaus = nz & (a >= 1e-20) & (a <= 1e20)
        if np.mean(~fin) > 0.01 or (np.any(nz) and plaus.sum() < 0.9 * nz.sum()):
            return ("the words are not plausible float32 values (NaN/Inf or extreme "
                    "exponents): the file looks like integer samples")
        return None
    if _float_like(b):
        return "the data look like float32 samples (gr_complex)"
    if name in ("iq_int16", "real_int16"):
        w = b.view(np.dtype("<i2")).astype(np.int32)
        st = _split_stats(w >> 8, w & 0xFF, 8)
        if _narrow_pairs_in_wide(st):
            return ("the low and high bytes of each 16-bit word look like two independent "
                    "8-bit samples: the file looks like 8-bit samples (iq_int8/real_int8)")
        return None
    if name in ("iq_int8", "real_int8"):
        st = _split_stats(b[1::2].view(np.int8), b[0::2], 8)
        if _wide_in_narrow(st):
            return ("odd bytes behave as the high bytes of the even ones: the file looks "
                    "like 16-bit little-endian samples (iq_int16/real_int16)")
        st4 = _split_stats(b.view(np.int8) >> 4, b & 0xF, 4)
        if _narrow_pairs_in_wide(st4):
            return ("the two nibbles of each byte look like independent 4-bit values: the "
                    "file looks like packed 4-bit I/Q (iq_int4)")
        return None
    if name == "iq_int4":
        st = _split_stats(b.view(np.int8) >> 4, b & 0xF, 4)
        if _wide_in_narrow(st):
            return ("the high nibble is the sign extension of the low nibble: the file looks "
                    "like 8-bit samples with small values (iq_int8/real_int8)")
        return None
    return None
