"""Navigation-message decoding of a vector-loop channel after the hand-over.

The scalar channel's bit and frame synchronization are not needed any more: in the vector
loop a channel's code epochs are numbered by the satellite-clock millisecond (``S0 + e`` ms,
:mod:`~sdr_di.deep.nco`), so its data-bit edges (D1: whole 20 ms, NH code wiped off; D2:
whole 2 ms) and subframe edges (D1: whole 6 s; D2: whole 0.6 s) are known. The decoder

1. sums the NH-wiped 1 ms prompts of each bit (a bit cut by the hand-over is summed over
   the epochs the loop has);
2. decides the bit coherently against a phase reference taken from the recent bit sums
   (decision-directed: ``ref <- lambda ref + d_k B_k``, ``lambda = exp(-T_bit / tau_ref)``,
   ``tau_ref`` = 20 ms). The loop's carrier NCO follows the INS and leaves a residual phase
   that drifts by the residual Doppler (a few hundredths of a hertz once the filter has
   converged, up to a few hertz right after the hand-over: 0.4 rad per 20 ms bit at 3 Hz),
   which the reference follows; the reference starts on the real axis, the phase of the
   scalar loop's prompt at the hand-over (the deep NCO continues its phase), so the bits
   keep the scalar channel's polarity and the subframe in progress at the hand-over can be
   completed from the scalar channel's demodulated bits (:meth:`ChannelNavDecoder.seed`);
3. cuts the bit stream at the subframe edges and decodes each complete subframe with the
   receiver's decoders (:func:`~sdr_di.signal.navmsg.decode_subframe` after the preamble
   gave the polarity; the Costas-type ambiguity is resolved per subframe), accepts it only
   when its start time equals the subframe edge's (a BCH miscorrection or a lost channel
   fails this), and holds it (:class:`~sdr_di.signal.navmsg.HeldSubframes`, the scalar
   channel's rule) until the loop's fast C/N0 test passes on a window of bit sums that
   starts after its last bit (:meth:`ChannelNavDecoder.confirm`); a failed test drops it
   (:meth:`ChannelNavDecoder.interrupt`). Without this, the subframe that completed in the
   interval whose test then failed had already been taken: its last bits came from noise,
   which BCH(15,11) "corrects" to some codeword (TCXO 25 MHz seed 3: C30's subframe 1 with
   AODE 30). The subframes the scalar channel decoded but had not yet confirmed at the
   hand-over (one that ended less than its 0.10-0.12 s confirmation delay before it) are
   held here too (:meth:`ChannelNavDecoder.hold`, their ends moved to the loop's bit
   numbers) and wait for the same test: passing them on unconfirmed would take one whose
   last bits came after a blockage began. A confirmed subframe feeds the scalar channel's
   :class:`~sdr_di.signal.navmsg.EphemerisAssembler` (subframes decoded before the hand-over
   complete sets with those decoded after), and what it completes goes to the loop's
   navigation data (:meth:`ChannelNavDecoder.confirm`). The Klobuchar coefficients are
   taken from a D1 subframe 1 as soon as it is confirmed (all eight are in it), without
   waiting for the subframes 2-3 that complete the ephemeris. A subframe reaches the
   assembler one test window (60 ms) to one window plus an interval after its end.
"""

from __future__ import annotations

import math

import numpy as np

from ..constants import SECONDS_PER_WEEK
from ..errors import NavMessageError
from ..signal.navmsg import (
    EphemerisAssembler,
    HeldSubframes,
    decode_subframe,
    klobuchar_of_subframe,
)
from ..signal.words import PREAMBLE, SUBFRAME_BITS

__all__ = ["ChannelNavDecoder"]

_TAU_REF_MS = 20.0
_NPRE = PREAMBLE.size


class ChannelNavDecoder:
    """Bits and subframes of one vector-loop channel (module notes).

    Parameters
    ----------
    prn : int
    is_d1 : bool
        D1 (20 ms bits, 6 s subframes) or D2 (2 ms bits, 0.6 s subframes).
    ms0 : int
        Satellite-clock millisecond of the week of the loop's epoch 0 (``S0`` in ms).
    assembler : EphemerisAssembler, optional
        The scalar channel's assembler (default a new one).

    Attributes
    ----------
    n_subframes, n_failed : int
        Subframes this decoder decoded (held or confirmed; not those handed to
        :meth:`hold` by the scalar channel) and complete subframes that failed (preamble,
        BCH, time check).
    """

    def __init__(self, prn: int, is_d1: bool, ms0: int,
                 assembler: EphemerisAssembler | None = None) -> None:
        self.prn = int(prn)
        self.bit_ms = 20 if is_d1 else 2
        self.sub_ms = 6000 if is_d1 else 600
        self.ms0 = int(ms0)
        self.assembler = assembler or EphemerisAssembler(self.prn)
        self._lam = math.exp(-self.bit_ms / _TAU_REF_MS)
        self._ref = 1.0 + 0.0j
        self._acc = 0j
        self._acc_bit: int | None = None   # bit number (ms of week // bit_ms) being summed
        self._bits: list[int] = []
        self._first_bit: int | None = None  # bit number of self._bits[0] (a subframe edge)
        self._held = HeldSubframes()        # decoded, awaiting the signal test (notes)
        self.n_subframes = 0
        self.n_failed = 0

    def seed(self, first_epoch: int, bits) -> None:
        """Bits demodulated by the scalar channel before the hand-over.

        ``first_epoch``: loop epoch number of the leading edge of ``bits[0]``; bits 0/1 with
        the scalar channel's polarity (:meth:`~sdr_di.receiver.channel.Channel.
        demodulated_bits`, its epochs moved to the loop's numbering). The bits of the
        subframe in progress are kept.
        """
        b = np.asarray(bits, np.uint8)
        ms = self.ms0 + int(first_epoch)
        if b.size == 0 or ms % self.bit_ms:
            return
        k0 = ms // self.bit_ms
        per = self.sub_ms // self.bit_ms
        edge = (k0 + b.size - 1) // per * per      # last subframe edge within the run
        if edge < k0:
            return
        self._first_bit = edge
        self._bits = [int(v) for v in b[edge - k0:]]
        self._acc_bit = k0 + b.size                # next bit expected

    def add(self, prompts: np.ndarray, epochs: np.ndarray) -> None:
        """Add consecutive NH-wiped 1 ms prompts with their loop epoch numbers.

        Decoded subframes are held until :meth:`confirm`.
        """
        if len(prompts) == 0:
            return
        bitno = (self.ms0 + np.asarray(epochs, np.int64)) // self.bit_ms
        first = np.empty(bitno.size, bool)        # the first epoch of each bit
        first[0] = True
        np.not_equal(bitno[1:], bitno[:-1], out=first[1:])
        edges = first.nonzero()[0]
        sums = np.add.reduceat(np.asarray(prompts, np.complex128), edges)
        self.add_sums(bitno[edges].tolist(), sums.tolist())

    def add_sums(self, bits: list, sums: list) -> None:
        """:meth:`add` of the prompts' sums over the bits they fall in: bit numbers
        (satellite-clock ms of the week // ``bit_ms``, increasing) and the sum of each
        bit's prompts in this call (``np.add.reduceat`` over the bits' first epochs; the
        vector loop makes them for a pass's channels at once)."""
        for k, s in zip(bits, sums):
            if self._acc_bit is not None and k == self._acc_bit:
                self._acc += s
                continue
            if self._acc_bit is not None and k == self._acc_bit + 1:
                self._on_bit(self._acc_bit, self._acc)
            elif self._acc_bit is not None:
                self._bits, self._first_bit = [], None      # gap in the epochs: restart
            self._acc_bit, self._acc = k, s

    def hold(self, sf: dict, end_bit: int) -> None:
        """Hold decoded subframe ``sf`` until :meth:`confirm` (or drop it at
        :meth:`interrupt`).

        ``end_bit``: bit number (satellite-clock ms of the week // ``bit_ms``) after the
        subframe's last bit. The decoder holds its own subframes; the vector loop hands it
        those the scalar channel still held at the hand-over
        (:meth:`~sdr_di.receiver.channel.Channel.take_unconfirmed`), which end before any bit
        the loop adds, in the order of their ends.
        """
        self._held.hold(sf, end_bit)

    def confirm(self, n_bits: int) -> list:
        """The channel's signal test passed on its last ``n_bits`` complete bit sums (the
        bits before the one in progress): pass the held subframes that ended before them to
        the assembler (module notes).

        Returns
        -------
        list of (Ephemeris or None, Klobuchar or None)
            Per subframe passed on: the data set it completed (if any) and the ionosphere
            coefficients it carried or completed (if any).
        """
        if not self._held or self._acc_bit is None:
            return []
        out = []
        for d in self._held.confirmed(self._acc_bit - int(n_bits)):
            out += self._use(d)
        return out

    def interrupt(self) -> None:
        """The signal was not there for some of the recent bits (the channel failed its C/N0
        test): drop the subframe in progress and the held ones. Without this a subframe whose first words came
        before a blockage and the rest from noise was accepted: BCH(15,11) is a perfect code,
        so every noise word "corrects" to a codeword, and the time check only sees word 1
        (a blocked C30 record got an argument of perigee 0.37 rad off, a range step of
        2000 km)."""
        self._bits, self._first_bit = [], None
        self._held.drop()

    # -- internals ------------------------------------------------------------------------
    def _on_bit(self, k: int, s: complex) -> None:
        d = 1.0 if (s * self._ref.conjugate()).real >= 0.0 else -1.0
        self._ref = self._lam * self._ref + d * s
        per = self.sub_ms // self.bit_ms
        if k % per == 0:
            self._bits, self._first_bit = [], k
        if self._first_bit is None:
            return
        self._bits.append(0 if d > 0 else 1)
        if len(self._bits) < SUBFRAME_BITS:
            return
        seg = np.asarray(self._bits, np.uint8)
        self._bits, first = [], self._first_bit
        self._first_bit = None
        self._decode(seg, first)

    def _decode(self, seg: np.ndarray, first_bit: int) -> None:
        head = seg[:_NPRE]
        if np.array_equal(head, PREAMBLE):
            bits = seg
        elif np.array_equal(head, 1 - PREAMBLE):
            bits = 1 - seg
        else:
            self.n_failed += 1
            return
        try:
            d = decode_subframe(bits, prn=self.prn)
        except NavMessageError:
            self.n_failed += 1
            return
        t_edge = (first_bit * self.bit_ms / 1000.0) % SECONDS_PER_WEEK
        dt = (d["t_start"] - t_edge + SECONDS_PER_WEEK / 2) % SECONDS_PER_WEEK \
            - SECONDS_PER_WEEK / 2
        if abs(dt) > 1e-6:
            self.n_failed += 1
            return
        self.n_subframes += 1
        self.hold(d, first_bit + SUBFRAME_BITS)

    def _use(self, d: dict) -> list:
        try:
            res = self.assembler.add(d)
        except NavMessageError:
            res = None
        eph, klob = res if res is not None else (None, None)
        klob = klobuchar_of_subframe(d) or klob
        return [] if eph is None and klob is None else [(eph, klob)]
