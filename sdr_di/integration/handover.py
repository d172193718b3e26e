"""The hand-over from the scalar start-up to the integration loop.

The rule (when: a valid WLS fix with velocity, every tracked channel timed and with an
ephemeris, ionosphere coefficients or ``iono_wait_s`` spent) runs on the start-up's epochs in
:meth:`~sdr_di.integration.receiver.IntegratedReceiver.run`; its reasons are the receiver's
module notes (*Hand-over*). This module makes what the loop takes over:

``handover_channels``          deep mode's channel states from the scalar channels
``handover_decoder``           a channel's navigation decoder, with its subframe in progress
``offer_subframe_klobuchar``   ionosphere coefficients of a decoded subframe 1 before the
                               channel's ephemeris is complete
:class:`HandoverError`         the start-up never reached a state the loop can take over
"""

from __future__ import annotations

import dataclasses
from typing import Any

from ..coupling.config import IntegrationConfig
from ..deep.navdecode import ChannelNavDecoder
from ..deep.vector_tracking import SampleClock, VectorChannel
from ..errors import HandoverError  # noqa: F401  (defined in sdr_di.errors, imported from here)
from ..receiver.navdata import NavDataInForce
from ..receiver.scalar import ScalarReceiver
from ..signal.navmsg import klobuchar_of_subframe

__all__ = ["D1_BIT_RATE_HZ", "Handover", "HandoverError", "handover_channels",
           "handover_decoder", "handover_span_s", "offer_subframe_klobuchar"]


#: D1 navigation message bit rate [bit/s] (MEO/IGSO satellites; GEOs' D2 is 10 times faster).
D1_BIT_RATE_HZ = 50.0




def handover_span_s(config: IntegrationConfig) -> tuple[float, float]:
    """Seconds of file the scalar start-up needs before a hand-over: (usual, longest).

    Usual: two D1 subframes: the first preamble can come a whole subframe into the file and
    the frame (hence the time of week the fix needs) is confirmed at the next one. Longest:
    plus ``handover_wait_s`` when a tracked channel lacks navigation data at the first fix.
    """
    from ..signal.words import SUBFRAME_BITS

    usual = 2.0 * SUBFRAME_BITS / D1_BIT_RATE_HZ
    return usual, usual + config.handover_wait_s


@dataclasses.dataclass
class Handover:
    """The scalar start-up's state at the hand-over to the integration loop (every mode).

    Attributes
    ----------
    first_fix : int or None
        Sample of the first valid fix (the hand-over's waits count from it).
    sample : int or None
        Sample of the hand-over epoch; None while it is not reached.
    sol : PvtSolution or None
        The WLS fix of that epoch (position, velocity, clock for the alignment and ``P0``).
    prns : list of int
        The channels handed over: tracked, with time, code lock and ephemeris in force.
    next_start : int or None
        Loose and tight: the first sample of the loop's grid (the handed-over channels'
        next code epochs, where deep's would start).
    channels : list of int
        Loose and tight: every channel of the receiver at the hand-over.
    """

    first_fix: int | None = None
    sample: int | None = None
    sol: Any = None           # PvtSolution once reached
    prns: list[int] = dataclasses.field(default_factory=list)
    next_start: int | None = None
    channels: list[int] = dataclasses.field(default_factory=list)

    @property
    def reached(self) -> bool:
        """Whether the hand-over happened."""
        return self.sample is not None


def handover_channels(cfg: IntegrationConfig, rx: ScalarReceiver, navdata: NavDataInForce,
                      hand: Handover, clock: SampleClock) -> list[VectorChannel]:
    """Vector-loop state of every handed-over channel, from its scalar channel: next
    code epoch (sample and number on the satellite clock), carrier phase, C/N0, the
    ephemeris in force at the fix and the navigation decoder with its subframe in
    progress."""
    sol = hand.sol
    S0 = clock.S0
    chans: list[VectorChannel] = []
    for i, prn in enumerate(hand.prns):
        c = rx.channels[prn]
        s = int(c.next_start)
        o = c.observation_at(s)
        eph = navdata.select(prn, sol.week, sol.sow)
        e = round((o.t_tx_sow - S0) * 1000.0)
        bit_ms = 20 if c.is_d1 else 2
        chans.append(VectorChannel(prn=prn, idx=i, is_d1=c.is_d1, eph=eph, next_start=s,
                                   epoch=e, phase=float(c.phi),
                                   bit_ms=bit_ms, cn0_dbhz=float(c.cn0_dbhz),
                                   nav=handover_decoder(c, e, round(S0 * 1000.0))))
    return chans


def offer_subframe_klobuchar(rx: ScalarReceiver, navdata: NavDataInForce, t_s: float) -> None:
    """Offer the Klobuchar set of the latest D1 subframe 1 any scalar channel decoded (the
    channels give the coefficients only with a complete ephemeris, up to 18 s later)."""
    for c in rx.channels.values():
        for d in reversed(c.subframes[-5:]):
            k = klobuchar_of_subframe(d)
            if k is not None:
                navdata.offer_klobuchar(k, t_s)
                return


def handover_decoder(sc, epoch: int, ms0: int) -> ChannelNavDecoder:
    """Navigation decoder of a handed-over channel.

    It takes the scalar channel ``sc``'s assembler, the bits of its subframe in progress and
    the subframes it still held for the lock confirmation, which wait for the loop's own
    test (:mod:`~sdr_di.deep.navdecode` notes). ``sc``'s epoch counter moves to the loop's
    numbering, in which ``sc``'s next epoch is ``epoch``; ``ms0`` is the satellite-clock
    millisecond of the week of loop epoch 0 (a held subframe's end, an epoch edge after its
    last bit, becomes the bit number ``ceil((ms0 + loop epoch) / bit_ms)``).
    """
    dec = ChannelNavDecoder(sc.prn, sc.is_d1, ms0, sc.assembler)
    shift = epoch - int(sc.epoch)            # loop epoch = scalar epoch + shift
    for end, sf in sc.take_unconfirmed():
        dec.hold(sf, -(-(ms0 + end + shift) // dec.bit_ms))
    runs = sc.demodulated_bits()
    if runs:
        e0, bits = runs[-1]
        dec.seed(e0 + shift, bits)
    return dec
