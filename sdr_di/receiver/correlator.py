"""Multi-channel early/prompt/late correlators driven by external code and carrier NCOs.

Each call correlates one *coherent interval* per channel over a block of samples (all
channels share the block; each has its own start and length inside it). The NCO frequencies
are constant over the interval and set from outside for every interval, as the scalar loops
or the deep-integration (vector) loop command them.

Conventions
-----------
* Code phase ``theta`` [chips]: the replica chip at sample ``k`` of the interval is
  ``code[floor(theta0 + k * f_code / fs) mod L]`` (``L = 10230`` for B3I). Early and late
  replicas are advanced / delayed by ``d`` chips (``spacing_chips``, default 0.5):
  ``E = sum x c(theta + d) w``, ``L = sum x c(theta - d) w``.
* Carrier phase ``phi`` [cycles]: ``w_k = exp(-j 2 pi (phi0 + k f_carr / fs))`` with
  ``f_carr = IF + Doppler`` [Hz]; a signal ``a c(theta) exp(+j 2 pi phi)`` gives
  ``P = a n`` (complex input) or ``P = a n / 2`` (real input) when the NCOs match.
* End states are computed, not accumulated: ``theta_end = theta0 + f_code n / fs`` and
  ``phi_end = phi0 + f_carr n / fs`` (float64, from the caller's unreduced start values), so a
  loop that chains intervals by feeding ``theta_end``/``phi_end`` back never drifts from the
  commanded NCO. Reduce them modulo the code length / one cycle when convenient; the kernel
  reduces internally.

Accuracy: float64 code phase recomputed from the interval start at every sample (no rounding
accumulates; code-phase error ~1e-12 chip), float64 carrier phase per 256-sample block,
float32 wipe-off products and sums within a block added in float64 (a rounding error of about
2e-7 of the sums' noise level; kernel module notes).

Kernel: :func:`~sdr_di.receiver._numba_correlate_bits.correlate_epl_bits` (replicas as bit
windows, :func:`bit_windows`), the same kernel the scalar receiver, acquisition and the deep
loop call on stored samples; complex samples reach it as their float view (no copy).
``int8`` samples at 11 MHz or more take its integer twin
(:mod:`~sdr_di.receiver._numba_correlate_int`: the rotation table rounded to integers at
scale 127, about 2e-5 dB of SNR; ``SDR_DI_CORRELATOR=float`` forces the float32 kernel).
:class:`Correlator` caches the bit windows of its table per PRN list; :func:`correlate_table`
packs them at each call (~0.1 ms for 7 channels).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence

import numba
import numpy as np

from ..constants import CODE_LENGTH_B3I
from ..errors import UnknownPrnError
from ._numba_correlate_bits import correlate_epl_bits, pack_bit_windows
from ._numba_correlate_blocks import rotation_tables

__all__ = ["CODE_PAD", "CorrelationResult", "Correlator", "bit_windows", "check_prn",
           "correlate", "correlate_epl_bits", "correlate_table", "padded_replicas"]

#: Chips of periodic padding on each side of the replica table (spacing must be < CODE_PAD - 1).
CODE_PAD = 8
#: Samples per carrier block (one cos/sin pair per block, one table product per sample).
CARRIER_BLOCK = 256


@dataclasses.dataclass(frozen=True)
class CorrelationResult:
    """Outputs of one correlation interval for ``n_ch`` channels.

    Attributes
    ----------
    early, prompt, late : numpy.ndarray
        complex128 (n_ch,): correlator sums (input units x samples).
    code_phase_end : numpy.ndarray
        float64 (n_ch,): code NCO phase after the interval, ``theta0 + f_code n / fs`` [chips].
    carrier_phase_end : numpy.ndarray
        float64 (n_ch,): carrier NCO phase after the interval, ``phi0 + f_carr n / fs``
        [cycles].
    n_samples : numpy.ndarray
        int64 (n_ch,): samples integrated.
    spacing_chips : float
        Early/late offset d [chips].
    """

    early: np.ndarray
    prompt: np.ndarray
    late: np.ndarray
    code_phase_end: np.ndarray
    carrier_phase_end: np.ndarray
    n_samples: np.ndarray
    spacing_chips: float


def padded_replicas(codes: np.ndarray, pad: int = CODE_PAD) -> np.ndarray:
    """Periodically padded float32 replica table for the kernel.

    Parameters
    ----------
    codes : numpy.ndarray
        (n_ch, L) or (L,) chips, +/-1 (any numeric type).
    pad : int
        Chips of padding on each side.

    Returns
    -------
    numpy.ndarray
        float32 (n_ch, L + 2 pad) with ``out[:, pad + i] = code[i mod L]`` for
        ``-pad <= i < L + pad``.
    """
    codes = np.atleast_2d(np.asarray(codes))
    length = codes.shape[1]
    idx = np.arange(-pad, length + pad) % length
    return np.ascontiguousarray(codes[:, idx], dtype=np.float32)


def bit_windows(table: np.ndarray) -> np.ndarray:
    """Bit windows of padded replica tables, for the receiver's bit-packed kernel.

    Parameters
    ----------
    table : numpy.ndarray
        (n_ch, W) or (W,) padded replicas from :func:`padded_replicas` (+/-1), ``W = L + 2 M``.

    Returns
    -------
    numpy.ndarray
        uint64 (n_ch, W + 64): bit ``b`` of entry ``j`` is 1 where table entry ``j + b`` is
        negative (entries past ``W - 1`` count as positive: no valid phase needs them, see
        :mod:`~sdr_di.receiver._numba_correlate_bits`).
    """
    neg = np.ascontiguousarray(np.atleast_2d(np.asarray(table)) < 0)
    out = np.empty((neg.shape[0], neg.shape[1] + 64), dtype=np.uint64)
    pack_bit_windows(neg, out)
    return out


def _as_channel_array(v, n_ch: int, dtype, name: str) -> np.ndarray:
    a = np.asarray(v, dtype=dtype)
    if a.ndim == 0:
        a = np.full(n_ch, a, dtype=dtype)
    if a.shape != (n_ch,):
        raise ValueError(f"{name}: expected a scalar or shape ({n_ch},), got {a.shape}")
    return np.ascontiguousarray(a)


def _prepare_samples(samples: np.ndarray) -> tuple[np.ndarray, int, int]:
    """Samples as the kernel reads them.

    Returns
    -------
    xs : numpy.ndarray
        1-D contiguous ``float32``/``float64``/``int8``/``int16`` components: the samples
        themselves (real) or the float view of ``complex64``/``complex128`` samples
        (interleaved I, Q; no copy when already contiguous). Other complex types convert to
        ``complex64``, other real types to ``float32``.
    n_comp : int
        Components per sample: 2 (complex) or 1 (real).
    n : int
        Samples.
    """
    x = np.asarray(samples)
    if x.ndim != 1:
        raise ValueError(f"samples must be 1-D, got shape {x.shape}")
    if np.iscomplexobj(x):
        if x.dtype not in (np.complex64, np.complex128):
            x = x.astype(np.complex64)
        x = np.ascontiguousarray(x)
        return x.view(np.float32 if x.dtype == np.complex64 else np.float64), 2, x.size
    if x.dtype not in (np.float32, np.float64, np.int8, np.int16):
        x = x.astype(np.float32)
    return np.ascontiguousarray(x), 1, x.size


def kernel_tasks(n_rows: int, n_max: int, threads: int | None = None) -> int:
    """Tasks per row of a correlator kernel call: enough for ``threads`` (default numba's
    current count) to share ``n_rows`` rows, at most one per 256-sample carrier block of the
    longest row (``n_max`` samples); 1 for one thread."""
    threads = numba.get_num_threads() if threads is None else int(threads)
    if threads <= 1 or n_rows == 0:
        return 1
    nblk = max(1, (n_max + CARRIER_BLOCK - 1) // CARRIER_BLOCK)
    want = max(1, math.ceil(4 * threads / n_rows))
    return int(min(want, nblk))


def carrier_rotation(dphi) -> tuple[np.ndarray, np.ndarray]:
    """Carrier rotation tables of the kernels: ``cos(2 pi m dphi)`` and ``-sin(2 pi m dphi)``
    for ``m = 0 .. CARRIER_BLOCK - 1``, one row per carrier step ``dphi`` [cycles/sample]
    (float32 (n, CARRIER_BLOCK) each, the kernels' product precision: computed in float64,
    the phase reduced to one cycle before the trig, then rounded)."""
    d = np.asarray(dphi, dtype=np.float64)
    shape = d.shape + (CARRIER_BLOCK,)
    rot_re = np.empty((d.size, CARRIER_BLOCK), np.float32)
    rot_im = np.empty((d.size, CARRIER_BLOCK), np.float32)
    rotation_tables(np.ascontiguousarray(d.reshape(-1)), rot_re, rot_im)
    return rot_re.reshape(shape), rot_im.reshape(shape)


def reduce_code_phase(theta, code_len: int) -> np.ndarray:
    """Code phases [chips] reduced to the kernels' ``[0, code_len)``."""
    t = np.mod(np.asarray(theta, dtype=np.float64), float(code_len))
    t[t >= code_len] = 0.0  # np.mod of a tiny negative can round up to L
    return t


def correlate_table(samples: np.ndarray, table: np.ndarray, code_len: int,
                    code_phase_chips, code_rate_cps, carrier_phase_cycles, carrier_freq_hz,
                    n_samples, sampling_rate_hz: float, spacing_chips: float = 0.5,
                    start_sample=0, pad: int = CODE_PAD) -> CorrelationResult:
    """Correlate with a prepared replica table (the fast path of :func:`correlate`).

    Parameters
    ----------
    samples : numpy.ndarray
        1-D block, complex or real (see :func:`correlate`).
    table : numpy.ndarray
        float32 (n_ch, code_len + 2 pad) from :func:`padded_replicas`, one row per channel.
    code_len : int
        Chips per code period L.
    code_phase_chips, code_rate_cps, carrier_phase_cycles, carrier_freq_hz, n_samples, \
sampling_rate_hz, spacing_chips, start_sample
        As in :func:`correlate` [chips, chips/s, cycles, Hz, samples, Hz, chips, samples].
    pad : int, optional
        Padding of ``table`` [chips].

    Returns
    -------
    CorrelationResult

    Raises
    ------
    ValueError
        Intervals outside the block, non-finite NCO values, non-positive code rate, spacing
        outside ``[0, pad - 1)``.

    Notes
    -----
    Packs the table's :func:`bit_windows` at each call (~0.1 ms for 7 rows); a caller with a
    fixed PRN list can use :class:`Correlator`, which keeps them.
    """
    table = np.atleast_2d(np.asarray(table))
    return _correlate_bits(samples, bit_windows(table), np.arange(table.shape[0]), code_len,
                           code_phase_chips, code_rate_cps, carrier_phase_cycles,
                           carrier_freq_hz, n_samples, sampling_rate_hz, spacing_chips,
                           start_sample, pad)


def _correlate_bits(samples: np.ndarray, bits: np.ndarray, tab_idx: np.ndarray, code_len: int,
                    code_phase_chips, code_rate_cps, carrier_phase_cycles, carrier_freq_hz,
                    n_samples, sampling_rate_hz: float, spacing_chips: float, start_sample,
                    pad: int) -> CorrelationResult:
    """:func:`correlate_table` on bit windows ``bits`` (uint64 (n_tab, code_len + 2 pad + 64),
    :func:`bit_windows`), channel ``c`` correlating with row ``tab_idx[c]`` (int, (n_ch,));
    other parameters and units as in :func:`correlate_table`."""
    x, n_comp, n_x = _prepare_samples(samples)
    tab_idx = np.ascontiguousarray(tab_idx, dtype=np.int64)
    n_ch = tab_idx.size
    if bits.ndim != 2 or bits.shape[1] < code_len + 2 * pad + 64:
        raise ValueError(f"replica table: expected {code_len + 2 * pad} entries per row "
                         f"(code_len + 2 pad), got {bits.shape[-1] - 64}")
    fs = float(sampling_rate_hz)
    if not fs > 0:
        raise ValueError(f"sampling rate must be positive, got {sampling_rate_hz}")
    d = float(spacing_chips)
    if not 0.0 <= d < pad - 1:
        raise ValueError(f"spacing_chips must be in [0, {pad - 1}), got {spacing_chips}")
    theta = _as_channel_array(code_phase_chips, n_ch, np.float64, "code_phase_chips")
    rate = _as_channel_array(code_rate_cps, n_ch, np.float64, "code_rate_cps")
    phi = _as_channel_array(carrier_phase_cycles, n_ch, np.float64, "carrier_phase_cycles")
    fc = _as_channel_array(carrier_freq_hz, n_ch, np.float64, "carrier_freq_hz")
    nsamp = _as_channel_array(n_samples, n_ch, np.int64, "n_samples")
    start = _as_channel_array(start_sample, n_ch, np.int64, "start_sample")
    for name, a in (("code_phase_chips", theta), ("code_rate_cps", rate),
                    ("carrier_phase_cycles", phi), ("carrier_freq_hz", fc)):
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name} must be finite")
    if np.any(nsamp < 0) or np.any(start < 0) or np.any(start + nsamp > n_x):
        raise ValueError(f"channel intervals [start, start + n) must lie inside the "
                         f"{n_x}-sample block")
    dchip = rate / fs
    if np.any(dchip <= 0) or np.any(dchip * CARRIER_BLOCK >= code_len):
        raise ValueError("code rate must be positive and below "
                         f"{code_len / CARRIER_BLOCK:g} chips per sample")
    dphi = fc / fs
    theta_r = reduce_code_phase(theta, code_len)
    phi_r = phi - np.floor(phi)
    rot_re, rot_im = carrier_rotation(dphi)
    out = np.empty((n_ch, 3, 2))
    if n_ch:
        n_sub = kernel_tasks(n_ch, int(nsamp.max()))
        correlate_epl_bits(x, n_comp, bits, tab_idx, pad, code_len, start, nsamp, theta_r,
                           dchip, phi_r, dphi, rot_re, rot_im, np.arange(n_ch, dtype=np.int64),
                           d, n_sub, out)
    res = out[..., 0] + 1j * out[..., 1]
    return CorrelationResult(
        early=res[:, 0].copy(), prompt=res[:, 1].copy(), late=res[:, 2].copy(),
        code_phase_end=theta + rate * nsamp / fs,
        carrier_phase_end=phi + fc * nsamp / fs,
        n_samples=nsamp, spacing_chips=d)


def correlate(samples: np.ndarray, codes: np.ndarray, code_phase_chips, code_rate_cps,
              carrier_phase_cycles, carrier_freq_hz, n_samples, sampling_rate_hz: float,
              spacing_chips: float = 0.5, start_sample=0) -> CorrelationResult:
    """Early/prompt/late correlation of ``n_ch`` channels over one block of samples.

    Parameters
    ----------
    samples : numpy.ndarray
        1-D block: complex64/complex128 (I + jQ) or float32/float64 (real IF).
    codes : numpy.ndarray
        (n_ch, L) ranging codes, +/-1 chips, one row per channel (or (L,) for one channel).
    code_phase_chips : float or array (n_ch,)
        Code NCO phase at each channel's first sample [chips], may be fractional, any value
        (reduced modulo L).
    code_rate_cps : float or array (n_ch,)
        Code NCO rate [chips/s], e.g. ``10.23e6 * (1 + doppler / 1268.52e6)``.
    carrier_phase_cycles : float or array (n_ch,)
        Carrier NCO phase at the first sample [cycles].
    carrier_freq_hz : float or array (n_ch,)
        Carrier NCO frequency, IF + Doppler [Hz] (may be negative).
    n_samples : int or array (n_ch,)
        Samples of each channel's interval.
    sampling_rate_hz : float
        Sample rate fs [Hz].
    spacing_chips : float, optional
        Early/late offset d [chips] (E at +d, L at -d). Default 0.5.
    start_sample : int or array (n_ch,), optional
        Index in ``samples`` of each channel's first sample. Default 0.

    Returns
    -------
    CorrelationResult
    """
    codes = np.atleast_2d(np.asarray(codes))
    return correlate_table(samples, padded_replicas(codes), codes.shape[1], code_phase_chips,
                           code_rate_cps, carrier_phase_cycles, carrier_freq_hz, n_samples,
                           sampling_rate_hz, spacing_chips, start_sample)


def check_prn(prn) -> int:
    """Return ``prn`` as an int, or raise :class:`~sdr_di.errors.UnknownPrnError`."""
    try:
        ok = not isinstance(prn, bool) and int(prn) == prn and 1 <= int(prn) <= 63
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise UnknownPrnError(f"PRN {prn!r} is not a BeiDou B3I PRN (1..63)")
    return int(prn)


def _default_code_source() -> Callable[[int], np.ndarray]:
    from ..signal.codes import b3i_code

    return b3i_code


class Correlator:
    """Correlator bank for a sample rate, with cached replica tables per PRN.

    The float table of the last PRN list and its bit windows (the kernel's replicas) are
    kept, so repeated calls with the same PRN list pack nothing.

    Parameters
    ----------
    sampling_rate_hz : float
        Sample rate fs [Hz].
    spacing_chips : float, optional
        Early/late offset d [chips]. Default 0.5.
    code_source : callable, optional
        ``prn -> +/-1 chips``; default :func:`sdr_di.signal.codes.b3i_code`.

    Examples
    --------
    >>> corr = Correlator(25e6)                                        # doctest: +SKIP
    >>> r = corr.correlate(block, [6, 9], theta0, 10.23e6, 0.0, fd, 25000)  # doctest: +SKIP
    >>> r.prompt                                                      # doctest: +SKIP
    """

    def __init__(self, sampling_rate_hz: float, spacing_chips: float = 0.5,
                 code_source: Callable[[int], np.ndarray] | None = None):
        self.sampling_rate_hz = float(sampling_rate_hz)
        self.spacing_chips = float(spacing_chips)
        self._code_source = code_source
        self._rows: dict[int, np.ndarray] = {}
        self._stack_key: tuple[int, ...] | None = None
        self._stack: np.ndarray | None = None
        self._bits: np.ndarray | None = None
        self.code_len: int | None = None

    def _row(self, prn: int) -> np.ndarray:
        row = self._rows.get(prn)
        if row is None:
            check_prn(prn)
            if self._code_source is None:
                self._code_source = _default_code_source()
            code = np.asarray(self._code_source(int(prn)))
            if self.code_len is None:
                self.code_len = code.size
            elif code.size != self.code_len:
                raise ValueError(f"code of PRN {prn} has {code.size} chips, expected "
                                 f"{self.code_len}")
            row = padded_replicas(code)[0]
            self._rows[prn] = row
        return row

    def table(self, prns: Sequence[int]) -> np.ndarray:
        """Padded replica table for the channels' PRNs (cached for a repeated PRN list)."""
        key = tuple(check_prn(p) for p in prns)
        if key != self._stack_key:
            rows = [self._row(p) for p in key]
            width = (self.code_len or CODE_LENGTH_B3I) + 2 * CODE_PAD
            self._stack = (np.stack(rows) if rows else np.empty((0, width), np.float32))
            self._stack_key = key
            self._bits = None
        return self._stack

    def _table_bits(self, prns: Sequence[int]) -> np.ndarray:
        """:func:`bit_windows` of :meth:`table` (packed once per PRN list, like the table)."""
        tab = self.table(prns)
        if self._bits is None:
            self._bits = bit_windows(tab)
        return self._bits

    def correlate(self, samples: np.ndarray, prns: Sequence[int], code_phase_chips,
                  code_rate_cps, carrier_phase_cycles, carrier_freq_hz, n_samples,
                  start_sample=0) -> CorrelationResult:
        """Correlate channels ``prns`` (one per entry, repeats allowed) over ``samples``.

        Parameters are those of :func:`correlate`, per channel; raises
        :class:`~sdr_di.errors.UnknownPrnError` for a PRN outside 1..63.
        """
        bits = self._table_bits(prns)
        return _correlate_bits(samples, bits, np.arange(bits.shape[0]),
                               self.code_len or CODE_LENGTH_B3I, code_phase_chips,
                               code_rate_cps, carrier_phase_cycles, carrier_freq_hz, n_samples,
                               self.sampling_rate_hz, self.spacing_chips, start_sample,
                               CODE_PAD)
