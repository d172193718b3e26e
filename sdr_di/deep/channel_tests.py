"""The vector loop's channel tests: bit-sum C/N0, fast test and loss test of every channel,
one kernel call per pass over the channels (:class:`ChannelTests`).

Per channel and interval (:mod:`sdr_di.deep.vector_tracking` notes), on the epochs the
interval correlated:

1. the noise correlator's values go to the channel's noise ring, which gives the noise
   power the C/N0 uses (:class:`~sdr_di.receiver.lock.PostCorrelationNoise`, continued from
   the scalar channel at the hand-over);
2. the prompts go to the channel's bit sums (:class:`~sdr_di.deep.bit_power.BitPower`);
3. when a bit sum completed: the *fast test* on the last ``FAST_MS`` of bit sums (C/N0 at
   least ``cn0_min_dbhz - fast_margin_db``; failed: the interval is left out of the
   measurement vector), and where it fails the *loss test* on the last ``LOSS_MS``
   (``cn0_min_dbhz - loss_margin_db``; failed: the channel is lost, its bit sums emptied, and
   it rejoins only on a whole window of fresh sums); the channel's C/N0 is taken up from the
   whole window when the fast test passed and the window holds enough sums.

:class:`BitPower` and :class:`PostCorrelationNoise` are the plain forms of steps 1-2, one
channel at a time; :class:`ChannelTests` keeps the same state as arrays over the channels
and runs the three steps for all the channels of a pass in one call of
:func:`~sdr_di.deep._numba_channel_tests.channel_tests` (the same values bit for bit,
``tests/test_deep_channel_tests.py``), which replaces a few dozen numpy calls per channel and
interval (``docs/notes/speed.md``, session 27).
"""

from __future__ import annotations

import numpy as np

from ..receiver.lock import PostCorrelationNoise
from ._numba_channel_tests import channel_tests

__all__ = ["ChannelTests", "FAST_MS", "LOSS_MS", "CN0_MIN_MS"]

FAST_MS = 60      # bit sums of the fast test (interval left out) [ms]
LOSS_MS = 120     # bit sums of the loss test [ms]
CN0_MIN_MS = 40   # bit sums before the loop's own C/N0 replaces the scalar loop's [ms]


class ChannelTests:
    """Bit-sum rings and noise rings of the vector loop's channels, and their tests
    (module notes).

    Parameters
    ----------
    bit_ms : sequence of int
        Data bit of each channel [ms] (D1 20, D2 2).
    window_ms : int
        C/N0 window [ms] (``cn0_window_ms``): ``max(window_ms // bit_ms, 2)`` bit sums per
        channel.
    fs : float
        Sample rate [Hz].
    fast_threshold_dbhz, loss_threshold_dbhz : float
        C/N0 the fast and the loss test need [dB-Hz].
    noise : PostCorrelationNoise, optional
        Template of the noise rings (length, z, values needed; default
        :class:`PostCorrelationNoise`'s).

    Attributes
    ----------
    new : ndarray of int (n,)
        Bit sums each channel completed in the last :meth:`run` that included it.
    count_tested : ndarray of int (n,)
        Bit sums each channel held when its tests last ran.
    """

    def __init__(self, bit_ms, window_ms: int, fs: float, fast_threshold_dbhz: float,
                 loss_threshold_dbhz: float, noise: PostCorrelationNoise | None = None) -> None:
        bit_ms = np.asarray(bit_ms, np.int64)
        n = bit_ms.size
        self.fs = float(fs)
        self.size = np.maximum(int(window_ms) // bit_ms, 2).astype(np.int64)
        nmax = int(self.size.max()) if n else 1
        self.p = np.zeros((n, nmax), np.complex128)
        self.n = np.zeros((n, nmax))
        self.count = np.zeros(n, np.int64)
        self.acc_p = np.zeros(n, np.complex128)
        self.acc_n = np.zeros(n)
        self.fast_k = (FAST_MS // bit_ms).astype(np.int64)
        self.loss_k = (LOSS_MS // bit_ms).astype(np.int64)
        self.cn0_min_k = (CN0_MIN_MS // bit_ms).astype(np.int64)
        self.fast_threshold = float(fast_threshold_dbhz)
        self.loss_threshold = float(loss_threshold_dbhz)
        tpl = PostCorrelationNoise() if noise is None else noise
        self.nz_v = np.zeros((n, tpl.n_values))
        self.nz_i = np.zeros(n, np.int64)
        self.nz_count = np.zeros(n, np.int64)
        self.nz_z = np.full(n, tpl.z)
        self.nz_min = np.full(n, tpl.min_values, np.int64)
        self.new = np.zeros(n, np.int64)
        self.count_tested = np.zeros(n, np.int64)

    def take_noise(self, i: int, noise: PostCorrelationNoise) -> None:
        """Channel ``i``'s noise ring continues ``noise`` (the scalar channel's values, in
        their slots)."""
        values, next_slot = noise.ring()
        if values.size != self.nz_v.shape[1]:
            raise ValueError(f"noise ring of {values.size} values, the bank's hold "
                             f"{self.nz_v.shape[1]}")
        self.nz_v[i] = values
        self.nz_i[i], self.nz_count[i] = next_slot, noise.count
        self.nz_z[i], self.nz_min[i] = noise.z, noise.min_values

    def run(self, ch0: int, counts: np.ndarray, prompts: np.ndarray, nsamp: np.ndarray,
            bit_start: np.ndarray, noise: np.ndarray, noise_ok: np.ndarray,
            input_power: float, cn0: np.ndarray, rejoining: np.ndarray,
            fast_fail: np.ndarray) -> None:
        """The tests of channels ``ch0 .. ch0 + len(counts) - 1`` on their epochs of one pass
        (consecutive in the arrays; :func:`~sdr_di.deep._numba_channel_tests.channel_tests`
        gives the arguments). ``cn0`` [dB-Hz], ``rejoining`` and ``fast_fail`` (every
        channel's) are updated in place."""
        channel_tests(int(ch0), np.asarray(counts, np.int64), prompts, nsamp, bit_start,
                      noise, noise_ok, float(input_power), self.fs, self.p, self.n,
                      self.size, self.count, self.acc_p, self.acc_n, self.nz_v, self.nz_i,
                      self.nz_count, self.nz_z, self.nz_min, self.fast_k, self.loss_k,
                      self.cn0_min_k, self.fast_threshold, self.loss_threshold, cn0,
                      rejoining, fast_fail, self.new, self.count_tested)
