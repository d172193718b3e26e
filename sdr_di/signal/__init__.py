"""BeiDou B3I signal layer: ranging codes, NH secondary code, BCH(15,11), D1/D2 navigation
messages (encoder and decoder). Polarity convention everywhere: logic 0 -> +1, logic 1 -> -1.
"""

from .bch import bch_decode, bch_encode
from .codes import NH20, NH20_BITS, b3i_code, b3i_code_bits, nav_type
from .navmsg import (
    EphemerisAssembler,
    NavBits,
    code_period_signs,
    decode_stream,
    decode_subframe,
    find_preamble,
    nav_bits,
)

__all__ = [
    "NH20",
    "NH20_BITS",
    "EphemerisAssembler",
    "NavBits",
    "b3i_code",
    "b3i_code_bits",
    "bch_decode",
    "bch_encode",
    "code_period_signs",
    "decode_stream",
    "decode_subframe",
    "find_preamble",
    "nav_bits",
    "nav_type",
]
