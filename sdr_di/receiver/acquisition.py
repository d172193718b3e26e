"""B3I acquisition: parallel code-phase search (FFT) over a Doppler grid, CFAR detection.

Search
------
The block of ``K x M`` ms starting at the first sample is cut into ``K`` coherent blocks of
``M`` ms (``N_c = round(M fs / 1000)`` samples; default ``M = 1``, ``K = 20``). For every Doppler
bin ``fd`` (grid ``doppler_center_hz + i * step`` over ``+-doppler_range_hz``, default step
``1 / (2 T_c)`` = 500 Hz for 1 ms: worst straddle loss 0.9 dB) the carrier ``IF + fd`` is wiped
off, each block is transformed once (``scipy.fft``, shared by all PRNs), and for each PRN the
circular correlation with the replica is ``R_b(tau) = IFFT(X_b conj(C))``, all code delays
``tau`` (samples) at once. The replica FFT per PRN, sample rate and block length is cached.

Code Doppler (``fd / f_carrier`` of the chip rate, 4 ppm at 5 kHz) is handled two ways:
across blocks, the power of block ``b`` is shifted by ``round(b (N_c - M fs / 1000 / (1 +
fd / f_carrier)))`` samples before summation, the code phase that block ``b`` starts at (the code
drifts 0.8 chip over 20 ms at 5 kHz; where ``fs`` is not a multiple of 1 kHz the rounded
``N_c`` alone drifts up to half a sample per block); within a block the replica is
resampled at ``10.23e6 (1 + fd / f_carrier)`` chips/s for that bin when the smear over the block
exceeds 0.1 chip (coherent blocks longer than about 2 ms at 5 kHz), otherwise the nominal-rate
replica is used.

D1 signals carry the 1 kbps NH code (and 50 bps data), D2 signals 500 bps data: a bit can
flip between any two milliseconds, so 1 ms coherent blocks with non-coherent summation is the
safe default; ``M > 1`` gains sensitivity only on signals without transitions (or at the cost
of a random loss when a transition falls in a block).

Low sample rates (zero-stuffing)
--------------------------------
The FFT search has one code delay per sample. Below about 1.4 samples per chip the lags leave
holes of up to half a sample between them (a whole chip at 5 MHz: the correlation peak can be
missed entirely), so the block is zero-stuffed by ``u = ceil(10.23e6 / (0.7 fs))``
(:func:`acquisition_upsampling`; ``upsample`` overrides it) and searched at ``u fs``: the zero
samples add nothing to any correlation, the lags fall every ``1 / (u fs)`` (worst-case
misalignment 0.35 chip) and code phases still refer to the original samples. The refinement
runs on the original samples.

Statistic and threshold
-----------------------
``S(tau, fd) = sum_b |R_b(tau, fd)|^2``. With noise only, each ``R_b`` is circular complex
Gaussian with variance ``sigma2`` (``N_c E|x|^2`` for white noise), so ``S / sigma2`` follows
``Gamma(K, 1)`` (``2 S / sigma2`` is chi-square with ``2K`` degrees of freedom). ``sigma2`` is
estimated per PRN from the whole search grid as ``median(S) / median(Gamma(K, 1))`` (a signal
occupies a handful of the ~10^5-10^6 cells, so the median is unaffected; the estimate also holds
for coloured, quantized noise). The peak metric is ``T = max S / sigma2``. For a false-alarm
probability ``pfa`` over the whole search of one PRN with ``n_cells = n_doppler_bins x
n_code_delays`` cells treated as independent (conservative: neighbouring delays at 2.4
samples/chip are correlated), the per-cell probability is ``1 - (1 - pfa)**(1 / n_cells)`` and
the threshold is the matching upper quantile of ``Gamma(K, 1)`` (``scipy.special
.gammainccinv``). With the defaults (1 ms x 20, +-5 kHz, 25 MHz, pfa 1e-3: 525 000 cells)
the threshold is T = 58.4. Detection probability (non-central chi-square) at 40 dB-Hz: ~1.
At 35 dB-Hz: 0.8 with 1.2 dB of straddle losses (Doppler bin, code delay), but only ~0.2
when a D1 signal also loses the average 1.8 dB of NH transitions inside 1 ms blocks that are
not aligned with its code epochs; ``noncoherent=40`` (threshold 89.1) gives 0.87 in that worst
average case and ~1 otherwise (the tests use 40 at 35 dB-Hz).

Real inputs
-----------
Before the search the block is cleaned (``clean=True``,
:func:`~sdr_di.receiver.narrowband.remove_dc_and_lines`): the mean is subtracted and
narrowband lines are blanked in the block's spectrum. A DC offset or a CW line is coherent
energy that the code's 1 kHz line spectrum picks up for every PRN; without the cleaning a
DC offset of 3 LSB on 4-bit noise passes the threshold for most PRNs. With it, the statistic
keeps its Gamma(K, 1) distribution on DC offsets and clipped (1-2 bit) inputs: the test
suite checks the per-cell exceedance of the Gamma(K) quantile at p = 1e-2 over one search's
cells. A constant input has no power left after the mean removal: nothing is detected and
the result says so. Detections of three or more PRNs at one Doppler (refined Dopplers within
10 Hz, or one grid bin) get a note: a line that escaped the blanking, or an artefact, is far
more likely than satellites sharing a Doppler that closely.

Short files (:func:`acquire_source`): a file that ends before ``K`` blocks are read is
searched with the whole blocks it holds, down to one code period; the results carry the
``K`` used. The Doppler refinement needs at least 4 whole code periods after the code phase;
without them the Doppler is the interpolated grid value and ``doppler_refined`` is False.
:func:`detection_cn0_dbhz` gives the C/N0 at which a search of a given ``K`` and ``M``
detects with probability 0.9.

Refinement (detected PRNs)
--------------------------
1. Doppler and delay by parabolic interpolation of ``S`` over the neighbouring bins/delays.
2. Code phase: prompt power summed over 1 ms blocks on a 0.1-chip grid of +-0.4 chip around the
   estimate (the receiver's bit-window correlator kernel, E/P/L at 0.1 chip spacing on three
   offsets), parabolic interpolation of the maximum.
3. Doppler: the 1 ms prompts ``P_b`` are squared (removing NH/data signs) and the frequency of
   ``P_b^2`` is found by a zero-padded FFT and parabolic interpolation; the residual is half of
   it (unambiguous within +-250 Hz, the coarse grid leaves at most +-250 Hz before step 1).
   Step 2 is then repeated at the refined Doppler.
4. C/N0 = ``(mean |P_b|^2 - sigma_P^2) / sigma_P^2 / T`` with ``sigma_P^2 = sigma2 N / N_c``
   the noise variance of a 1 ms prompt (``N`` samples, ``T`` = 1 ms), in dB-Hz.
5. Doppler ambiguity (``coherent_ms = 1``): the frequency of the squared prompts (step 3) is
   exact modulo 500 Hz; at low C/N0 noise can put the coarse peak in a neighbouring 500 Hz bin,
   which a 1 ms PLL/FLL cannot pull in. The mean epoch-aligned 1 ms prompt power at ``fd`` and
   ``fd +- 500 Hz`` picks the right one (a 500 Hz error costs 3.9 dB of prompt power).

Code phase conventions (as the correlator): ``code_phase_chips`` is the code NCO phase to load
at the first sample of the block, ``theta0`` in ``[0, 10230)``: the received chip at sample
``k`` is ``floor(theta0 + k f_code / fs) mod 10230``. ``code_phase_samples`` is the (fractional)
sample index in the block where the first code period begins, the FFT correlation lag of the
peak (GNSS-SDR's "code phase in samples"): ``theta0 = -code_phase_samples f_code / fs mod 10230``.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import os
from collections import OrderedDict
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import scipy.fft
from scipy import special

from ..constants import CHIP_RATE_B3I, CODE_LENGTH_B3I, F_B3I, is_geo
from ..errors import AcquisitionError, ImplausibleAcquisition  # noqa: F401
from ..settings import passive_kernel_workers
from ._numba_acquire import accumulate_power
from ._numba_correlate_bits import correlate_epl_bits
from .correlator import (
    CODE_PAD,
    bit_windows,
    carrier_rotation,
    check_prn,
    kernel_tasks,
    padded_replicas,
    reduce_code_phase,
)
from .narrowband import remove_dc_and_lines

__all__ = ["AcquisitionResult", "AcquisitionWarning", "ImplausibleAcquisition",
           "acquire", "acquire_source", "acquisition_upsampling", "check_search",
           "default_doppler_step_hz", "detection_cn0_dbhz", "detection_threshold",
           "doppler_offsets", "implausible_detections", "LIKELY_CAUSES"]

#: Refined Dopplers closer than this are "the same Doppler" for the artefact note [Hz].
_SHARED_DOPPLER_HZ = 10.0
#: Whole code periods the Doppler refinement needs (squared-prompt FFT).
_MIN_REFINE_EPOCHS = 4
#: Most BDS satellites above the horizon at one place and time: every GEO (at most 10 PRNs),
#: every IGSO (about 10) and about a third of the 27 MEOs, all from the Asia-Pacific at best
#: (about 30); more detections than this are not satellites.
MAX_IN_VIEW = 30
#: A refined Doppler within this of 0 Hz is "at zero Doppler" [Hz]: a satellite that is not
#: a GEO passes through zero Doppler only at its highest elevation, for seconds.
_ZERO_DOPPLER_HZ = 1.0
#: Non-GEO detections at zero Doppler that real signals do not give (module notes).
_ZERO_DOPPLER_MIN = 3
#: Non-GEO detections within ``_SHARED_DOPPLER_HZ`` of each other that real signals do not
#: give (10 non-GEO satellites over +-3.6 kHz: 4 within 10 Hz has a probability near 1e-5).
_SHARED_DOPPLER_MIN = 4
#: The usual reasons of detections real signals cannot give, most likely first.
LIKELY_CAUSES = ("the sample format (--format), the IF and its sign (--if, --inverted), the "
                 "sample rate (--fs)")
_REPLICA_CACHE: OrderedDict[tuple, np.ndarray] = OrderedDict()
_REPLICA_CACHE_MAX = 256


@dataclasses.dataclass
class AcquisitionResult:
    """Acquisition outcome for one PRN (module notes give the conventions).

    Attributes
    ----------
    prn : int
    detected : bool
        ``peak_metric > threshold``.
    code_phase_chips : float
        Code phase at the first sample of the block [chips], in [0, 10230).
    code_phase_samples : float
        Sample index (fractional) where the first code period begins in the block.
    doppler_hz : float
        Carrier Doppler [Hz] (refined when detected), relative to the IF.
    doppler_coarse_hz : float
        Doppler bin of the peak [Hz].
    cn0_dbhz : float
        C/N0 estimate [dB-Hz] (NaN when not detected, with ``refine=False``, or when the
        measured power does not exceed the noise).
    peak_metric : float
        ``max S / sigma2`` (Gamma(K, 1) distributed with noise only).
    threshold : float
        Detection threshold on ``peak_metric`` for ``pfa``.
    pfa : float
        False-alarm probability over this PRN's search space.
    noise_power : float
        ``sigma2``: noise variance of one coherent correlation [input units^2 x samples^2].
    grid : numpy.ndarray or None
        ``S / sigma2`` (n_doppler, n_delays), when asked with ``keep_grid``.
    doppler_bins_hz : numpy.ndarray or None
        Doppler of the grid rows [Hz], when ``keep_grid``.
    coherent_ms, noncoherent : int
        M and K of the search that gave this result.
    doppler_refined : bool
        The Doppler was refined from the squared prompts (needs at least 4 whole code
        periods after the code phase; otherwise it is the interpolated grid value, within
        about a quarter of the bin spacing).
    notes : tuple of str
        Remarks for the user: ``doppler not refined (...)``, ``same Doppler as N other
        PRNs`` (several detections at one Doppler: a line or an artefact more likely than
        satellites), ``no signal power in the input``.
    lines_hz : numpy.ndarray or None
        Narrowband lines blanked in the input before the search [Hz] (module notes of
        :mod:`~sdr_di.receiver.narrowband`), the same for every PRN of one call.
    """

    prn: int
    detected: bool
    code_phase_chips: float
    code_phase_samples: float
    doppler_hz: float
    doppler_coarse_hz: float
    cn0_dbhz: float
    peak_metric: float
    threshold: float
    pfa: float
    noise_power: float
    grid: np.ndarray | None = None
    doppler_bins_hz: np.ndarray | None = None
    coherent_ms: int = 1
    noncoherent: int = 0
    doppler_refined: bool = False
    notes: tuple[str, ...] = ()
    lines_hz: np.ndarray | None = None

    def __repr__(self) -> str:
        return (f"AcquisitionResult(prn={self.prn}, detected={self.detected}, "
                f"code_phase_chips={self.code_phase_chips:.3f}, "
                f"doppler_hz={self.doppler_hz:.1f}, cn0_dbhz={self.cn0_dbhz:.1f}, "
                f"peak_metric={self.peak_metric:.1f}, threshold={self.threshold:.1f})")


def detection_threshold(pfa: float, n_cells: int, noncoherent: int) -> float:
    """Threshold on ``S / sigma2`` (Gamma(K, 1) under noise) for a search-wide ``pfa``.

    Parameters
    ----------
    pfa : float
        False-alarm probability over the ``n_cells`` cells of one PRN's search, in (0, 1).
    n_cells : int
        Cells searched (Doppler bins x code delays), treated as independent.
    noncoherent : int
        K, coherent blocks summed.
    """
    if not 0.0 < pfa < 1.0:
        raise ValueError(f"pfa must be in (0, 1), got {pfa}")
    p_cell = -math.expm1(math.log1p(-pfa) / n_cells)
    return float(special.gammainccinv(noncoherent, p_cell))


def detection_cn0_dbhz(threshold: float, noncoherent: int, coherent_ms: int = 1,
                       pd: float = 0.9) -> float:
    """C/N0 [dB-Hz] at which a search detects with probability ``pd`` (no losses).

    With a signal of coherent SNR ``snr = C/N0 M 1 ms`` per block, ``2 S / sigma2`` is
    non-central chi-square with ``2K`` degrees of freedom and non-centrality ``2 K snr``;
    the C/N0 that puts ``pd`` of it above ``2 threshold`` is solved for. Real searches lose
    about 1-3 dB more (Doppler-bin and code-lag straddle; NH or data transitions inside
    blocks that are not aligned with the code epochs).

    Parameters
    ----------
    threshold : float
        Threshold on ``S / sigma2`` (:func:`detection_threshold`).
    noncoherent : int
        K.
    coherent_ms : int
        M [ms].
    pd : float
        Detection probability, in (0, 1).
    """
    from scipy import optimize, stats

    k = int(noncoherent)

    def miss(snr_db: float) -> float:
        return float(stats.ncx2.sf(2.0 * threshold, 2 * k, 2 * k * 10.0 ** (snr_db / 10.0))) - pd

    snr_db = optimize.brentq(miss, -60.0, 60.0, xtol=1e-4)
    return snr_db - 10.0 * math.log10(int(coherent_ms) * 1e-3)


def default_doppler_step_hz(coherent_ms: int, sampling_rate_hz: float) -> float:
    """Default Doppler bin spacing [Hz]: ``1 / (2 T_c)`` with ``T_c`` the coherent block of
    ``round(M fs / 1000)`` samples (500 Hz for 1 ms; module notes)."""
    fs = float(sampling_rate_hz)
    return 1.0 / (2.0 * (round(int(coherent_ms) * fs * 1e-3) / fs))


def doppler_offsets(doppler_range_hz: float, step_hz: float) -> np.ndarray:
    """Doppler bins of a search relative to its centre [Hz]: ``step * (-n..n)`` with ``n``
    the fewest bins that cover ``+-doppler_range_hz``."""
    n_half = math.ceil(doppler_range_hz / step_hz - 1e-9)
    return step_hz * np.arange(-n_half, n_half + 1)


def acquisition_upsampling(sampling_rate_hz: float) -> int:
    """Zero-stuffing factor of the search at ``sampling_rate_hz`` [Hz] (module notes):
    ``ceil(10.23e6 / (0.7 fs))``, at least 1."""
    return max(1, math.ceil(CHIP_RATE_B3I / (0.7 * float(sampling_rate_hz)) - 1e-9))


def _default_code_source() -> Callable[[int], np.ndarray]:
    from ..signal.codes import b3i_code

    return b3i_code


def _replica_fft(code: np.ndarray, fs: float, n: int, chip_rate: float,
                 workers: int) -> np.ndarray:
    """conj(FFT) of ``n`` samples of the code at ``chip_rate`` starting at chip 0 (cached)."""
    key = (hashlib.sha1(np.ascontiguousarray(code, dtype=np.int8).tobytes()).digest(),
           float(fs), int(n), float(chip_rate))
    hit = _REPLICA_CACHE.get(key)
    if hit is not None:
        _REPLICA_CACHE.move_to_end(key)
        return hit
    length = code.size
    k = np.arange(n, dtype=np.float64)
    idx = np.floor(k * (chip_rate / fs)).astype(np.int64) % length
    rep = code[idx].astype(np.complex64)
    cf = np.conj(scipy.fft.fft(rep, workers=workers)).astype(np.complex64)
    _REPLICA_CACHE[key] = cf
    if len(_REPLICA_CACHE) > _REPLICA_CACHE_MAX:
        _REPLICA_CACHE.popitem(last=False)
    return cf


def _parabola(ym: float, y0: float, yp: float) -> float:
    """Offset of the vertex of the parabola through (-1, ym), (0, y0), (1, yp), in [-0.5, 0.5]."""
    den = ym - 2.0 * y0 + yp
    if den >= 0.0 or not math.isfinite(den):
        return 0.0
    return float(np.clip(0.5 * (ym - yp) / den, -0.5, 0.5))


def acquire(samples: np.ndarray, sampling_rate_hz: float, if_hz: float = 0.0,
            prns: Iterable[int] | None = None, *, coherent_ms: int = 1,
            noncoherent: int = 20, doppler_range_hz: float = 5000.0,
            doppler_step_hz: float | None = None, doppler_center_hz: float = 0.0,
            pfa: float = 1e-3, refine: bool = True, carrier_hz: float = F_B3I,
            code_source: Callable[[int], np.ndarray] | None = None,
            workers: int | None = None, prn_batch: int = 8,
            keep_grid: bool = False, upsample: int | None = None,
            clean: bool = True, shared_doppler_min: int = 3,
            doppler_centers: dict[int, float] | None = None) -> list[AcquisitionResult]:
    """Search PRNs in a block of IF samples.

    Parameters
    ----------
    samples : numpy.ndarray
        1-D complex (I/Q) or real samples, at least ``coherent_ms x noncoherent`` ms long;
        the first that many are used. Sample 0 is the reference of the code phase.
    sampling_rate_hz : float
        fs [Hz].
    if_hz : float, optional
        Intermediate frequency [Hz] (0 for complex baseband).
    prns : iterable of int, optional
        PRNs to search (default all 63); one outside 1..63 raises
        :class:`~sdr_di.errors.UnknownPrnError` before any work.
    coherent_ms : int, optional
        Coherent integration M [ms], an integer >= 1. Default 1 (safe with NH/data bits).
    noncoherent : int, optional
        K, coherent blocks summed non-coherently. Default 20.
    doppler_range_hz : float, optional
        Half-width of the Doppler search [Hz]. Default 5000.
    doppler_step_hz : float, optional
        Bin spacing [Hz]; default ``1 / (2 M 1 ms)``.
    doppler_center_hz : float, optional
        Centre of the Doppler search (e.g. predicted Doppler or clock drift) [Hz].
    doppler_centers : dict, optional
        ``{prn: centre [Hz]}``: per-PRN centres (assisted searches) overriding
        ``doppler_center_hz`` for those PRNs; every PRN keeps the half-width and step. Bins
        that several PRNs' grids share are transformed once (centres on a common lattice of
        the step share most of them).
    pfa : float, optional
        False-alarm probability per PRN search. Default 1e-3.
    refine : bool, optional
        Refine code phase and Doppler and estimate C/N0 for detected PRNs. Default True.
    carrier_hz : float, optional
        RF carrier [Hz] (scales the code Doppler). Default B3I.
    code_source : callable, optional
        ``prn -> +/-1 chips``; default :func:`sdr_di.signal.codes.b3i_code`.
    workers : int, optional
        Threads for ``scipy.fft`` (default: all cores).
    prn_batch : int, optional
        PRNs searched per pass over the Doppler grid (memory: about ``prn_batch x bins x
        fs / 1000 x 4`` bytes).
    keep_grid : bool, optional
        Attach the normalized grid ``S / sigma2`` to each result (code delays in units of
        the zero-stuffed samples when ``upsample > 1``).
    upsample : int, optional
        Zero-stuffing factor of the search (module notes); default
        :func:`acquisition_upsampling` of ``sampling_rate_hz`` (1 at 14.6 MHz and above).
    clean : bool, optional
        Remove the DC offset and blank narrowband lines before the search
        (:func:`~sdr_di.receiver.narrowband.remove_dc_and_lines`). Default True.
    shared_doppler_min : int, optional
        Note the detections when at least this many PRNs are detected in one Doppler bin
        (module notes, "Real inputs"). Default 3.

    Returns
    -------
    list of AcquisitionResult
        One per requested PRN, in the requested order.

    Raises
    ------
    UnknownPrnError
        A PRN outside 1..63.
    AcquisitionError
        (a ``ValueError``) Too few samples, non-integer or non-positive ``coherent_ms``,
        bad parameters.
    """
    prn_list = [check_prn(p) for p in (range(1, 64) if prns is None else prns)]
    m_ms, k_nc = check_search(coherent_ms, noncoherent, doppler_range_hz, pfa)
    passive_kernel_workers()       # before the first parallel kernel (sdr_di.settings)
    fs = float(sampling_rate_hz)
    if not fs > 0:
        raise AcquisitionError(f"sampling rate must be positive, got {sampling_rate_hz}")
    x = np.asarray(samples)
    if x.ndim != 1:
        raise AcquisitionError(f"samples must be 1-D, got shape {x.shape}")
    n_ms0 = round(fs * 1e-3)  # samples per code period
    n_c0 = round(m_ms * fs * 1e-3)  # samples per coherent block
    need = k_nc * n_c0
    if x.size < need:
        raise AcquisitionError(f"acquisition needs {need} samples ({k_nc} x {m_ms} ms at "
                               f"{fs / 1e6:g} MHz), got {x.size}")
    u = acquisition_upsampling(fs) if upsample is None else int(upsample)
    if u < 1:
        raise AcquisitionError(f"upsample must be >= 1, got {upsample}")
    lines = None
    if clean:
        cleaned = remove_dc_and_lines(x[:need], fs, workers=workers)
        x, lines = cleaned.samples, cleaned.line_hz
        if not cleaned.input_power > 0.0:
            return [_silent(p, m_ms, k_nc, pfa, lines) for p in prn_list]
    # the search grid: zero-stuffed samples at u fs (module notes)
    fs_g = fs * u
    n_ms = u * n_ms0  # lags searched
    n_c = u * n_c0
    workers = workers or os.cpu_count() or 1
    t_c = n_c / fs_g
    step = float(doppler_step_hz) if doppler_step_hz else default_doppler_step_hz(m_ms, fs)
    offsets = doppler_offsets(doppler_range_hz, step)
    n_bins = offsets.size
    centres = {p: float(doppler_center_hz) for p in prn_list}
    for p, c in (doppler_centers or {}).items():
        if check_prn(p) in centres:
            centres[check_prn(p)] = float(c)
    if code_source is None:
        code_source = _default_code_source()
    codes = {p: np.asarray(code_source(p)) for p in dict.fromkeys(prn_list)}
    code_len = next(iter(codes.values())).size if codes else CODE_LENGTH_B3I
    threshold = detection_threshold(pfa, n_bins * n_ms, k_nc)
    median_gamma = float(special.gammaincinv(k_nc, 0.5))

    if u > 1:
        xg = np.zeros(need * u, dtype=x.dtype)
        xg[::u] = x[:need]
        blocks = xg.reshape(k_nc, n_c)
    else:
        blocks = x[:need].reshape(k_nc, n_c)
    k_idx = np.arange(n_c, dtype=np.float64)
    b_idx = np.arange(k_nc)
    unique = list(codes)
    found: dict[int, AcquisitionResult] = {}
    batch_size = max(1, int(prn_batch))
    # PRNs of a batch run in parallel threads (pocketfft and the numba kernel release the
    # GIL), each FFT single-threaded: cheaper than threading inside every small FFT.
    with ThreadPoolExecutor(max_workers=workers) as pool:
        for i0 in range(0, len(unique), batch_size):
            batch = unique[i0:i0 + batch_size]
            grid = np.zeros((len(batch), n_bins, n_ms), np.float32)
            # the batch's Doppler bins (PRNs whose centres lie on one lattice share them):
            # bin -> the (PRN index, grid row) pairs it fills
            rows: dict[float, tuple[float, list[tuple[int, int]]]] = {}
            for ip, prn in enumerate(batch):
                for j, o in enumerate(offsets):
                    f = centres[prn] + o
                    rows.setdefault(round(f, 6), (f, []))[1].append((ip, j))
            for fd, cells in rows.values():
                eps = fd / carrier_hz
                ph = (if_hz + fd) / fs_g * k_idx
                ph -= np.floor(ph)
                wipe = np.exp(-2j * np.pi * ph).astype(np.complex64)
                xf = scipy.fft.fft(blocks * wipe, axis=1, workers=workers, overwrite_x=True)
                # block b starts b (n_c - M periods) samples further into the code: code
                # Doppler, and a period of a non-integer number of samples (fs not a multiple
                # of 1 kHz, e.g. 16.3676 MHz) that a rounded n_c leaves behind
                shifts = np.rint(b_idx * (n_c - m_ms * 1e-3 * fs_g / (1.0 + eps))).astype(np.int64)
                resample = abs(eps) * CHIP_RATE_B3I * t_c > 0.1
                rate = CHIP_RATE_B3I * (1.0 + eps) if resample else CHIP_RATE_B3I
                cfs = {ip: _replica_fft(codes[batch[ip]], fs_g, n_c, rate, workers)
                       for ip, _ in cells}

                def one(cell: tuple[int, int], xf: np.ndarray = xf,
                        shifts: np.ndarray = shifts, cfs: dict = cfs,
                        grid: np.ndarray = grid) -> None:
                    ip, j = cell
                    r = scipy.fft.ifft(xf * cfs[ip], axis=1, workers=1, overwrite_x=True)
                    accumulate_power(r, shifts, grid[ip, j])

                list(pool.map(one, cells))
            for ip, prn in enumerate(batch):
                found[prn] = _evaluate(grid[ip], prn, centres[prn] + offsets, x, fs, u, if_hz,
                                       n_ms0, n_c0, k_nc, m_ms, threshold, median_gamma, pfa,
                                       refine, carrier_hz, codes[prn], code_len, keep_grid)
                found[prn].lines_hz = lines
    _note_shared_doppler(found, shared_doppler_min, step)
    return [dataclasses.replace(found[p]) for p in prn_list]


def check_search(coherent_ms, noncoherent, doppler_range_hz: float = 5000.0,
                 pfa: float = 1e-3) -> tuple[int, int]:
    """Checked ``(M, K)`` of a search; raises :class:`AcquisitionError` naming the bad one."""
    if isinstance(coherent_ms, bool) or int(coherent_ms) != coherent_ms or coherent_ms < 1:
        raise AcquisitionError(
            f"coherent_ms must be an integer number of ms >= 1, got {coherent_ms}")
    if isinstance(noncoherent, bool) or int(noncoherent) != noncoherent or noncoherent < 1:
        raise AcquisitionError(f"noncoherent must be an integer >= 1, got {noncoherent}")
    if not 0.0 <= float(doppler_range_hz) <= 50e3:
        raise AcquisitionError(f"doppler range must be in [0, 50000] Hz, got {doppler_range_hz}")
    if not 0.0 < float(pfa) < 1.0:
        raise AcquisitionError(f"pfa must be in (0, 1), got {pfa}")
    return int(coherent_ms), int(noncoherent)


def _silent(prn: int, m_ms: int, k_nc: int, pfa: float, lines) -> AcquisitionResult:
    """Result for an input without power (constant file, all zeros after DC removal)."""
    return AcquisitionResult(
        prn=prn, detected=False, code_phase_chips=math.nan, code_phase_samples=math.nan,
        doppler_hz=math.nan, doppler_coarse_hz=math.nan, cn0_dbhz=math.nan, peak_metric=0.0,
        threshold=math.nan, pfa=pfa, noise_power=0.0, coherent_ms=m_ms, noncoherent=k_nc,
        notes=("no signal power in the input (constant samples)",), lines_hz=lines)


def _note_shared_doppler(found: dict[int, AcquisitionResult], n_min: int,
                         step_hz: float) -> None:
    """Note the detections of ``n_min`` or more PRNs at one Doppler (module notes, "Real
    inputs"): Dopplers within ``_SHARED_DOPPLER_HZ`` of each other when refined, within half
    a bin otherwise. A line leaks into every PRN at the same frequency; satellites rarely
    share a Doppler that closely (7 satellites over +-3.6 kHz: three within 10 Hz has a
    probability of about 1e-3)."""
    det = sorted((r.doppler_hz, prn) for prn, r in found.items() if r.detected)
    groups: list[list[int]] = []
    prev = None
    for fd, prn in det:
        r = found[prn]
        tol = _SHARED_DOPPLER_HZ if r.doppler_refined and prev is not None and \
            found[prev[1]].doppler_refined else 0.5 * step_hz
        if prev is not None and fd - prev[0] <= tol:
            groups[-1].append(prn)
        else:
            groups.append([prn])
        prev = (fd, prn)
    for prns in groups:
        if len(prns) >= max(2, n_min):
            for p in prns:
                note = (f"same Doppler as {len(prns) - 1} other PRNs: a line or artefact "
                        "more likely than satellites")
                found[p].notes = (*found[p].notes, note)


class AcquisitionWarning(UserWarning):
    """Detections that real signals cannot give (:func:`implausible_detections`)."""




def implausible_detections(results: Iterable[AcquisitionResult]
                           ) -> tuple[str | None, list[int]]:
    """What in a set of detections real B3I signals cannot produce.

    Three patterns, checked in this order (GEOs, whose Doppler stays within tens of Hz of
    each other and of zero, are left out of the first two):

    1. ``_ZERO_DOPPLER_MIN`` or more non-GEO PRNs detected at 0 Hz (within
       ``_ZERO_DOPPLER_HZ``): energy at the IF itself, as a wrong sample format, IF or rate
       gives (a 6 s iq_int8 file read as real_int8 gave 12 of them, all at exactly 0 Hz);
    2. more than :data:`MAX_IN_VIEW` detections;
    3. ``_SHARED_DOPPLER_MIN`` or more non-GEO PRNs within ``_SHARED_DOPPLER_HZ`` of one
       Doppler away from zero: a line or a jammer that escaped the blanking.

    Returns
    -------
    problem : str or None
        One phrase naming the pattern and its PRNs; None when the detections are plausible.
    prns : list of int
        The PRNs of pattern 3 (an artefact on otherwise good samples: a receiver may refuse
        just those); empty for patterns 1 and 2 (the whole file is read wrongly) and None.
    """
    det = [r for r in results if r.detected and math.isfinite(r.doppler_hz)]
    moving = sorted((r for r in det if not is_geo(r.prn)), key=lambda r: r.doppler_hz)

    def names(rs) -> str:
        return ", ".join(f"C{r.prn:02d}" for r in sorted(rs, key=lambda r: r.prn))

    zero = [r for r in moving if abs(r.doppler_hz) < _ZERO_DOPPLER_HZ]
    if len(zero) >= _ZERO_DOPPLER_MIN:
        return (f"{len(zero)} PRNs that are not GEOs detected at 0 Hz Doppler "
                f"({names(zero)})"), []
    if len(det) > MAX_IN_VIEW:
        return (f"{len(det)} PRNs detected, more than the {MAX_IN_VIEW} BDS satellites that "
                "can be in view at once"), []
    best: list[AcquisitionResult] = []
    for i, r in enumerate(moving):
        group = [q for q in moving[i:] if q.doppler_hz - r.doppler_hz <= _SHARED_DOPPLER_HZ]
        if len(group) > len(best):
            best = group
    if len(best) >= _SHARED_DOPPLER_MIN:
        return (f"{len(best)} PRNs that are not GEOs detected within {_SHARED_DOPPLER_HZ:g} Hz "
                f"of {best[0].doppler_hz:+.0f} Hz Doppler ({names(best)})"), \
            sorted(r.prn for r in best)
    return None, []


def _evaluate(s: np.ndarray, prn: int, dopplers: np.ndarray, x: np.ndarray, fs: float, u: int,
              if_hz: float, n_ms: int, n_c: int, k_nc: int, m_ms: int, threshold: float,
              median_gamma: float, pfa: float, refine: bool, carrier_hz: float,
              code: np.ndarray, code_len: int, keep_grid: bool) -> AcquisitionResult:
    """Detection and refinement from one PRN's grid ``s`` (n_bins, u n_ms) searched at
    ``u fs``; ``x``, ``fs``, ``n_ms``, ``n_c``: the original samples."""
    n_lags = s.shape[1]
    flat = s.ravel()
    mid = flat.size // 2
    noise = float(np.partition(flat, mid)[mid]) / median_gamma
    if not noise > 0:
        noise = float(np.mean(flat)) / k_nc or 1.0
    j, tau = np.unravel_index(int(np.argmax(s)), s.shape)
    peak = float(s[j, tau]) / noise
    detected = peak > threshold
    n_bins = dopplers.size
    step = float(dopplers[1] - dopplers[0]) if n_bins > 1 else 0.0
    fd = float(dopplers[j])
    tau_f = float(tau)
    if detected:
        if 0 < j < n_bins - 1:
            fd += step * _parabola(float(s[j - 1, tau]), float(s[j, tau]), float(s[j + 1, tau]))
        tau_f += _parabola(float(s[j, (tau - 1) % n_lags]), float(s[j, tau]),
                           float(s[j, (tau + 1) % n_lags]))
    rate = CHIP_RATE_B3I * (1.0 + fd / carrier_hz)
    # The correlation is circular over the block's n_c samples, not over a code period
    # (n_c fs / rate chips differ from a whole number of periods by code Doppler and, where
    # fs is not a multiple of 1 kHz, by the rounded n_c): the samples on the longer side of
    # the lag set the phase. The late side (k < tau) is the longer one beyond half a block.
    n_grid = n_c * u
    tau_s = tau_f - n_grid if tau_f > 0.5 * n_grid else tau_f
    theta = float(np.mod(-tau_s * rate / (fs * u), code_len))
    cn0 = math.nan
    refined = False
    notes: list[str] = []
    if detected and refine:
        xs = _samples(x[:k_nc * n_c])
        noise_1ms = noise * n_ms / n_c
        tab = bit_windows(padded_replicas(code))
        theta, _ = _refine_code(xs, tab, code_len, theta, fd, fs, if_hz, n_ms, carrier_hz)
        fd, refined = _refine_doppler(xs, tab, code_len, theta, fd, fs, if_hz, n_ms,
                                      carrier_hz)
        if not refined:
            notes.append(f"doppler not refined (fewer than {_MIN_REFINE_EPOCHS} whole code "
                         "periods after the code phase): grid value")
        theta, p = _refine_code(xs, tab, code_len, theta, fd, fs, if_hz, n_ms, carrier_hz)
        snr = (float(np.mean(np.abs(p) ** 2)) - noise_1ms) / noise_1ms
        cn0 = 10.0 * math.log10(snr / (n_ms / fs)) if snr > 0 else math.nan
        if m_ms == 1:
            fd = _resolve_doppler(xs, tab, code_len, theta, fd, fs, if_hz, n_ms, carrier_hz)
    rate = CHIP_RATE_B3I * (1.0 + fd / carrier_hz)
    theta = float(np.mod(theta, code_len))
    if theta >= code_len:
        theta = 0.0
    delay = float(np.mod(-theta * fs / rate, code_len * fs / rate))
    return AcquisitionResult(
        prn=prn, detected=bool(detected), code_phase_chips=theta, code_phase_samples=delay,
        doppler_hz=fd, doppler_coarse_hz=float(dopplers[j]), cn0_dbhz=cn0, peak_metric=peak,
        threshold=threshold, pfa=pfa, noise_power=noise,
        grid=(s / noise) if keep_grid else None,
        doppler_bins_hz=dopplers.copy() if keep_grid else None, coherent_ms=m_ms,
        noncoherent=k_nc, doppler_refined=refined, notes=tuple(notes))


def _epoch_starts(x_size: int, theta: float, fd: float, fs: float, n_ms: int, code_len: int,
                  carrier_hz: float) -> np.ndarray:
    """Sample indices of the code-epoch starts after sample 0 with a whole block after them.

    Blocks aligned to code epochs keep NH/data bit transitions (which fall on epoch
    boundaries) out of the block, as a tracking channel does.
    """
    rate = CHIP_RATE_B3I * (1.0 + fd / carrier_hz)
    per = code_len * fs / rate  # samples per code period
    first = ((code_len - np.mod(theta, code_len)) % code_len) * fs / rate
    n = int((x_size - n_ms - first) // per) + 1
    return np.ceil(first + per * np.arange(max(n, 0))).astype(np.int64)


def _samples(x: np.ndarray) -> tuple[np.ndarray, int, int]:
    """``(values, n_comp, n)`` for the bit-window kernel: complex samples as their interleaved
    real view (``n_comp = 2``), real ones as they are; ``n`` samples."""
    x = np.ascontiguousarray(x)
    if np.iscomplexobj(x):
        if x.dtype not in (np.complex64, np.complex128):
            x = x.astype(np.complex64)
        return x.view(np.float32 if x.dtype == np.complex64 else np.float64), 2, x.size
    if x.dtype not in (np.float32, np.float64):
        x = x.astype(np.float32)
    return x, 1, x.size


def _epl(smp, bits, code_len, th, rate, ph, fcs, rot_idx, n, fs, spacing, starts):
    """E/P/L rows with one PRN's replica (bit windows ``bits``) on the samples ``smp``
    (:func:`_samples`): row ``r`` starts at sample ``starts[r]`` with code phase ``th[r]``,
    carrier phase ``ph[r]`` and carrier ``fcs[rot_idx[r]]`` [Hz]; ``n`` samples, code rate
    ``rate`` [chips/s]. Returns complex (3, n_rows)."""
    xv, n_comp, _ = smp
    n_rows = th.size
    theta = reduce_code_phase(th, code_len)
    phi = ph - np.floor(ph)
    dphi_c = np.asarray(fcs, dtype=np.float64) / fs
    rot_re, rot_im = carrier_rotation(dphi_c)
    rot_idx = np.ascontiguousarray(rot_idx, dtype=np.int64)
    out = np.empty((n_rows, 3, 2))
    n_sub = kernel_tasks(n_rows, n)
    correlate_epl_bits(xv, n_comp, bits, np.zeros(n_rows, np.int64), CODE_PAD, code_len,
                       np.ascontiguousarray(starts, dtype=np.int64),
                       np.full(n_rows, n, np.int64), theta, np.full(n_rows, rate / fs), phi,
                       dphi_c[rot_idx], rot_re, rot_im, rot_idx, float(spacing),
                       n_sub, out)
    res = out[..., 0] + 1j * out[..., 1]
    return res.T


def _block_prompts(smp, bits, code_len, thetas, fd, fs, if_hz, starts, n_ms, carrier_hz,
                   spacing):
    """E/P/L of the ``n_ms``-sample blocks at ``starts`` for code-phase hypotheses at sample 0.

    Returns complex (n_hyp * 3, n_blocks): rows hypothesis-major, offsets (+spacing, 0,
    -spacing) within a hypothesis.
    """
    rate = CHIP_RATE_B3I * (1.0 + fd / carrier_hz)
    fc = if_hz + fd
    n_hyp, n_blocks = len(thetas), starts.size
    th = (np.asarray(thetas, dtype=np.float64)[:, None] + rate * starts[None, :] / fs).ravel()
    ph = np.tile(fc * starts / fs, n_hyp)
    st = np.tile(starts, n_hyp)
    r = _epl(smp, bits, code_len, th, rate, ph, [fc], np.zeros(th.size, np.int64), n_ms, fs,
             spacing, st)
    out = np.stack([r[0].reshape(n_hyp, n_blocks), r[1].reshape(n_hyp, n_blocks),
                    r[2].reshape(n_hyp, n_blocks)], axis=1)
    return out.reshape(3 * n_hyp, n_blocks)


def _refine_code(smp, tab, code_len, theta, fd, fs, if_hz, n_ms, carrier_hz):
    """Code phase on a 0.1 chip grid of +-0.4 chip (parabolic vertex); epoch-aligned 1 ms
    prompts at the best phase."""
    d = 0.1
    starts = _epoch_starts(smp[2], theta, fd, fs, n_ms, code_len, carrier_hz)
    hyps = np.array([theta + 0.3, theta, theta - 0.3])
    rows = _block_prompts(smp, tab, code_len, hyps, fd, fs, if_hz, starts, n_ms, carrier_hz, d)
    offsets = (hyps[:, None] + np.array([d, 0.0, -d])[None, :]).ravel()
    power = np.sum(np.abs(rows) ** 2, axis=1)
    order = np.argsort(offsets)
    offsets, power = offsets[order], power[order]
    i = int(np.argmax(power))
    best = float(offsets[i])
    if 0 < i < offsets.size - 1:
        best += d * _parabola(float(power[i - 1]), float(power[i]), float(power[i + 1]))
    starts = _epoch_starts(smp[2], best, fd, fs, n_ms, code_len, carrier_hz)
    p = _block_prompts(smp, tab, code_len, np.array([best]), fd, fs, if_hz, starts, n_ms,
                       carrier_hz, d)[1]
    return best, p


def _refine_doppler(smp, tab, code_len, theta, fd, fs, if_hz, n_ms, carrier_hz):
    """Doppler residual from the frequency of the squared 1 ms prompts (bit signs removed);
    returns ``(fd, refined)`` (not refined with fewer than ``_MIN_REFINE_EPOCHS`` prompts)."""
    starts = _epoch_starts(smp[2], theta, fd, fs, n_ms, code_len, carrier_hz)
    if starts.size < _MIN_REFINE_EPOCHS:
        return fd, False
    p = _block_prompts(smp, tab, code_len, np.array([theta]), fd, fs, if_hz, starts, n_ms,
                       carrier_hz, 0.1)[1]
    z = p * p
    nfft = max(4096, 1 << math.ceil(math.log2(8 * starts.size)))
    spec = np.abs(np.fft.fft(z, nfft))
    i = int(np.argmax(spec))
    off = _parabola(float(spec[i - 1]), float(spec[i]), float(spec[(i + 1) % nfft]))
    f2 = (i + off) / nfft  # cycles per block of the squared prompt
    if f2 >= 0.5:
        f2 -= 1.0
    t_blk = float(starts[-1] - starts[0]) / (starts.size - 1) / fs
    return fd + 0.5 * f2 / t_blk, True


def _resolve_doppler(smp, tab, code_len, theta, fd, fs, if_hz, n_ms, carrier_hz):
    """The best of ``fd`` and ``fd +- 500 Hz`` by the mean epoch-aligned 1 ms prompt power
    (module notes, refinement step 5)."""
    cands = (fd, fd - 500.0, fd + 500.0)
    starts = _epoch_starts(smp[2], theta, fd, fs, n_ms, code_len, carrier_hz)
    if starts.size < _MIN_REFINE_EPOCHS:
        return fd
    rate = CHIP_RATE_B3I * (1.0 + fd / carrier_hz)
    n = min(math.floor(code_len * fs / rate), n_ms)
    n_ep = starts.size
    th = theta + starts * (rate / fs)
    ph = np.concatenate([(if_hz + f) * starts / fs for f in cands])
    res = _epl(smp, tab, code_len, np.tile(th, 3), rate, ph, [if_hz + f for f in cands],
               np.repeat(np.arange(3), n_ep), n, fs, 0.5, np.tile(starts, 3))
    power = np.abs(res[1].reshape(3, n_ep)) ** 2
    return float(cands[int(np.argmax(power.mean(axis=1)))])


def acquire_source(source, start_sample: int = 0, *, fit: bool = True,
                   **kwargs) -> list[AcquisitionResult]:
    """Acquire from an :class:`~sdr_di.receiver.ifreader.IfSource`.

    Reads just the ``coherent_ms x noncoherent`` ms needed from ``start_sample`` and calls
    :func:`acquire` with the source's sample rate, (corrected) IF and carrier; the code phases
    refer to sample ``start_sample`` of the file. Keyword arguments go to :func:`acquire`.

    A file that ends before ``noncoherent`` blocks are read is searched with the whole blocks
    it holds (``fit=True``, the default; the results' ``noncoherent`` says how many), down to
    one coherent block; shorter than that raises :class:`AcquisitionError`.
    """
    fs = source.sampling_rate_hz
    m_ms, k_nc = check_search(kwargs.get("coherent_ms", 1), kwargs.get("noncoherent", 20),
                              kwargs.get("doppler_range_hz", 5000.0), kwargs.get("pfa", 1e-3))
    n_c = round(m_ms * fs * 1e-3)
    avail = source.n_samples - int(start_sample)
    if avail < n_c:
        raise AcquisitionError(
            f"{source.path}: {max(avail, 0)} samples from sample {start_sample}; acquisition "
            f"needs at least one coherent block of {m_ms} ms ({n_c} samples at "
            f"{fs / 1e6:g} MHz)")
    if k_nc * n_c > avail:
        if not fit:
            raise AcquisitionError(
                f"{source.path}: acquisition needs samples [{start_sample}, "
                f"{start_sample + k_nc * n_c}), the file has {source.n_samples}")
        k_nc = avail // n_c
    kwargs["coherent_ms"], kwargs["noncoherent"] = m_ms, k_nc
    kwargs.setdefault("carrier_hz", source.carrier_hz)
    return acquire(source.read(start_sample, k_nc * n_c), fs, source.if_hz, **kwargs)
