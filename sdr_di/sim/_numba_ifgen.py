"""Numba kernel of the IF generator (sample-rate loop on plain arrays).

The caller (:mod:`sdr_di.sim.ifgen`) describes each satellite's signal on a grid of *nodes*
every ``N`` samples (about 1 ms): code phase, code-epoch index, carrier phase and amplitude at
the node, and the per-sample code and carrier increments over the following interval (linear
interpolation between exactly computed node values: nothing accumulates across intervals).

Inside an interval the code and carrier phases are 32.32 and 0.32 fixed-point accumulators
(resolution 2^-32 chip / cycle per sample: after 25 000 samples the drift is below 1e-5 chip and
1e-5 cycle before the next node resets it). The carrier uses a 4096-entry cosine/sine table
(phase step 2 pi / 4096: amplitude loss below 1e-6 dB, spurs near -72 dBc, far below the
thermal noise of any B3I sample stream).

Noise is drawn inside the kernel from NumPy ``Generator`` objects (SFC64 bit generators, NumPy's
ziggurat normal as compiled by numba), one per *stream*: the intervals of a chunk are split
into ``len(gens)`` contiguous blocks, each consumed in order by its own generator, so the output
depends only on the seeds, never on thread scheduling.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

LUT_BITS = 12
LUT_SIZE = 1 << LUT_BITS
_LUT_PHASE = np.arange(LUT_SIZE) * (2.0 * np.pi / LUT_SIZE)
LUT_COS = np.cos(_LUT_PHASE).astype(np.float32)
LUT_SIN = np.sin(_LUT_PHASE).astype(np.float32)

_TWO32 = 4294967296.0


@njit(cache=True, parallel=True)
def synthesize_chunk(
    out,  # int8/int16 (n, 2) complex or (n, 1) real: quantized samples (written)
    gens,  # tuple of numpy Generators: noise streams
    n_per_node,  # samples per node interval
    codes,  # float32 (n_sat, 10230) +/-1 chips
    chip0,  # float64 (n_sat, n_nodes): chip phase in [0, 10230) at each node
    ms0,  # int64 (n_sat, n_nodes): code-epoch index at each node
    dchip,  # float64 (n_sat, n_nodes): chips per sample over the interval (> 0)
    ph0,  # float64 (n_sat, n_nodes): carrier phase [cycles] in [0, 1) at each node
    dph,  # float64 (n_sat, n_nodes): carrier cycles per sample over the interval
    amp,  # float32 (n_sat, n_nodes): amplitude over the interval (noise sigma = 1)
    sym,  # float32 (n_sat, n_sym): data x NH symbol (+/-1) of each code epoch
    sym_base,  # int64 (n_sat,): code-epoch index of sym[:, 0]
    lut_cos,
    lut_sin,
    gain,  # float32: quantizer input scale (LSB per unit noise sigma)
    level,  # int: largest quantizer magnitude L (1: sign only)
):
    """Fill ``out`` with quantized signal + unit-variance noise for ``n_nodes`` intervals.

    Complex output (``out.shape[1] == 2``) is ``sum a * d * c * exp(+j 2 pi phi) + n``; real
    output is its real part plus real noise.
    """
    n_sat = codes.shape[0]
    n_nodes = chip0.shape[1]
    ncomp = out.shape[1]
    n_streams = len(gens)
    per = (n_nodes + n_streams - 1) // n_streams
    shift = 32 - LUT_BITS
    chips_fx = np.int64(10230) << 32
    for h in prange(n_streams):
        g = gens[h]
        bre = np.zeros(n_per_node, dtype=np.float32)  # in-phase sum of the satellites
        bim = np.zeros(n_per_node, dtype=np.float32)  # quadrature (unused for real output)
        for j in range(h * per, min(n_nodes, (h + 1) * per)):
            bre[:] = 0.0
            bim[:] = 0.0
            for s in range(n_sat):
                a = amp[s, j]
                if a == 0.0:
                    continue
                chip = np.int64(chip0[s, j] * _TWO32)
                dc = np.int64(np.round(dchip[s, j] * _TWO32))
                ph = np.int64(ph0[s, j] * _TWO32)
                dp = np.int64(np.round(dph[s, j] * _TWO32))
                ms = ms0[s, j]
                cur = a * sym[s, ms - sym_base[s]]
                for i in range(n_per_node):
                    c = codes[s, chip >> 32] * cur
                    li = ph >> shift
                    bre[i] += c * lut_cos[li]
                    bim[i] += c * lut_sin[li]  # branch-free: cheaper than testing ncomp
                    chip += dc
                    if chip >= chips_fx:
                        chip -= chips_fx
                        ms += 1
                        cur = a * sym[s, ms - sym_base[s]]
                    ph = (ph + dp) & 0xFFFFFFFF
            k0 = j * n_per_node
            for i in range(n_per_node):
                for c in range(ncomp):
                    x = ((bre[i] if c == 0 else bim[i]) + np.float32(g.standard_normal())) * gain
                    if level == 1:
                        q = 1 if x >= 0.0 else -1
                    else:
                        q = int(np.floor(x + 0.5))
                        if q > level:
                            q = level
                        elif q < -level:
                            q = -level
                    out[k0 + i, c] = q

