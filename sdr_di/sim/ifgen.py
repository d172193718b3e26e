"""B3I IF generator: scenario + ephemeris + truth -> quantized IF sample chunks.

Data flow per chunk of ``chunk_ms`` milliseconds (bounded memory whatever the file length):

1. node grid every ``N = round(fs / 1000)`` samples; receiver-clock time of node ``j`` is
   ``s_j = j N / fs`` after the start; true time ``t_j = (s_j - b0) / (1 + drift)``;
2. :func:`~sdr_di.sim.geometry.satellite_delays` gives each satellite's code and carrier delay
   at the nodes (light time, Sagnac, satellite clock with relativity, Klobuchar ionosphere,
   Saastamoinen troposphere; with ``[atmosphere] truth = "residuals"`` the truth's drawn
   departures from those two models, :mod:`~sdr_di.sim.atmosphere`);
3. code phase ``(t_sv - t0_nav) * 10.23e6 mod 10230`` and code-epoch index, carrier phase
   ``f_IF s - f_B3I D_carr`` and per-sample increments are handed to the numba kernel
   (:mod:`~sdr_di.sim._numba_ifgen`) with the data x NH symbols of the epochs in the chunk;
4. the kernel sums the satellites, adds white Gaussian noise (unit variance per component)
   and quantizes (:mod:`~sdr_di.sim._numba_ifgen`: vectorized synthesis, counter-based noise,
   so the file does not depend on the chunking or the thread count).

Amplitude from C/N0 with noise variance sigma^2 = 1 per component: complex baseband
``A = sqrt(2 C/N0 / fs)`` (C = A^2, N0 = 2 sigma^2 / fs); real IF ``A = sqrt(4 C/N0 / fs)``
(C = A^2 / 2, N0 = 2 sigma^2 / fs).

Automatic gain: the quantizer step follows the expected input power (noise, all nominal
signals and the jammers on; :mod:`~sdr_di.sim.interference`, ``[agc]``), at the step that
maximizes the SNR of a uniform quantizer for a Gaussian input (Max 1960: 0.9957 sigma for 4
levels, 0.5860 for 8, 0.3352 for 16, 0.1881 for 32, 0.1041 for 64, 0.0568 for 128, 0.0308
for 256; beyond 8 bits a 4-sigma full scale) unless ``[agc].target_sigma_lsb`` says
otherwise. Without jammers it is constant: it does not follow the C/N0 changes of outages
(each satellite is 34 dB under the noise). Multipath replicas are extra rows of the kernel's
satellite arrays (:mod:`~sdr_di.sim.multipath`).

Sample 0 is at receiver-clock time ``(week, sow)`` of the scenario start.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from concurrent.futures import ThreadPoolExecutor
from typing import Iterator

import numba
import numpy as np

from ..constants import CHIP_RATE_B3I, F_B3I, SECONDS_PER_WEEK, is_geo
from ..errors import NoEphemerisError, ScenarioError
from ..frames import ecef_to_llh
from ..io.sample_formats import get_format, quantizer_levels
from ..orbits.ephemeris import Ephemeris, Klobuchar
from ..scenario.schema import Scenario
from ..settings import passive_kernel_workers
from ..signal.codes import NH20_BITS, b3i_code
from ..signal.navmsg import NavBits, nav_bits
from ._numba_ifgen import code_words, pack_iq_int4_kernel, synthesize_chunk
from .geometry import ReceiverPath, satellite_delays
from .interference import JammerPlan
from .multipath import SignalRow, replica_rows


#: Version of the sample-synthesis algorithm (recorded in the sidecar's ``generator``): files
#: of one scenario and seed are byte-identical within a version. 2: counter-based
#: near-Gaussian noise and polynomial carrier (1: NumPy SFC64 ziggurat noise, carrier table).
SYNTHESIS_VERSION = 2
#: Node intervals per geometry computation (:meth:`IfGenerator.node_state`) at least.
GEOMETRY_BLOCK_NODES = 1000
#: Node intervals handed to a kernel thread at a time (dynamic schedule: a thread slowed by
#: other load takes fewer).
KERNEL_CHUNK_NODES = 8
#: Optimal uniform-quantizer step / sigma for 2**bits levels (Max 1960), bits 1..8.
_MAX_STEP = {1: None, 2: 0.9957, 3: 0.5860, 4: 0.3352, 5: 0.1881, 6: 0.1041, 7: 0.0568,
             8: 0.0308}


def quantizer_gain(bits: int, sigma: float) -> float:
    """Gain [LSB per unit input] of the automatic gain control for ``bits`` bits.

    Parameters
    ----------
    bits : int
        Quantization bits (mid-tread grid ``-L..L``).
    sigma : float
        Expected RMS of each input component (noise plus signals).
    """
    if bits == 1:
        return 1.0 / sigma
    if bits in _MAX_STEP:
        return 1.0 / (_MAX_STEP[bits] * sigma)
    return quantizer_levels(bits) / (4.0 * sigma)


def cn0_to_amplitude(cn0_dbhz: float, fs: float, complex_baseband: bool) -> float:
    """Signal amplitude for a C/N0 [dB-Hz] with unit noise variance per component."""
    cn0 = 10.0 ** (cn0_dbhz / 10.0)
    return math.sqrt((2.0 if complex_baseband else 4.0) * cn0 / fs)


@dataclasses.dataclass
class SatelliteSignal:
    """One simulated satellite: its record, message stream and strength."""

    prn: int
    eph: Ephemeris
    nav: NavBits
    cn0_dbhz: float
    amplitude: float
    elevation_deg: float = float("nan")
    azimuth_deg: float = float("nan")
    #: ``(BDT sow from which it is broadcast, record)`` of every record the message carries,
    #: the first from the stream's start (:func:`broadcast_nav_bits`).
    broadcast: list = dataclasses.field(default_factory=list)

    @property
    def is_d1(self) -> bool:
        return not is_geo(self.prn)


def _week_seconds_between(week_a: int, sow_a: float, week_b: int, sow_b: float) -> float:
    return (week_a - week_b) * SECONDS_PER_WEEK + (sow_a - sow_b)


def select_satellites(sc: Scenario, nav, path: ReceiverPath,
                      iono: Klobuchar | None) -> list[tuple[int, Ephemeris, float, float]]:
    """Choose the simulated satellites: (prn, record, elevation [rad], azimuth [rad]).

    ``prns = "auto"``: the ``count`` highest satellites above the elevation mask at the start
    that have a healthy record valid then. An explicit list: each PRN must have a record
    (:class:`~sdr_di.errors.NoEphemerisError`) and be above the horizon.
    """
    mask = math.radians(sc.satellites.elevation_mask_deg)
    zero = np.zeros(1)
    cands = []
    prns = sc.satellites.prns if sc.satellites.prns is not None else tuple(nav.prns)
    for prn in prns:
        try:
            eph = nav.select(prn, sc.week, sc.sow, broadcast=True)
        except NoEphemerisError:
            if sc.satellites.prns is not None:
                raise
            continue
        d = satellite_delays(eph, path, zero, sc.sow, zero, None, False)
        cands.append((prn, eph, float(d.el[0]), float(d.az[0])))
    if sc.satellites.prns is not None:
        low = [f"C{p:02d} ({math.degrees(e):.1f} deg)" for p, _, e, _ in cands if e < 0]
        if low:
            raise ScenarioError(f"satellites below the horizon at the start: {', '.join(low)}")
        return cands
    up = sorted((c for c in cands if c[2] >= mask), key=lambda c: -c[2])
    if len(up) < sc.satellites.count:
        raise ScenarioError(
            f"only {len(up)} BDS satellites with ephemeris are above "
            f"{sc.satellites.elevation_mask_deg:g} deg at the start; the scenario asks for "
            f"{sc.satellites.count}")
    return up[: sc.satellites.count]


class IfGenerator:
    """Streams quantized IF chunks for a scenario.

    Parameters
    ----------
    sc : Scenario
        Validated scenario.
    sats : list of SatelliteSignal
        Simulated satellites.
    path : ReceiverPath
        Receiver truth trajectory.
    iono : Klobuchar or None
        Ionosphere coefficients used (None: no ionosphere).
    """

    def __init__(self, sc: Scenario, sats: list[SatelliteSignal], path: ReceiverPath,
                 iono: Klobuchar | None):
        passive_kernel_workers()       # before the first parallel kernel (sdr_di.settings)
        self.sc = sc
        self.sats = sats
        self.path = path
        self.iono = iono if sc.signal.ionosphere == "klobuchar" else None
        #: Where the Klobuchar coefficients come from (set by the builder; for the sidecar).
        self.iono_source = "given"
        sig = sc.signal
        self.fs = sig.sampling_rate_hz
        self.n_per_node = int(round(self.fs / 1000.0))
        self.node_dt = self.n_per_node / self.fs
        self.fmt = get_format(sig.sample_format)
        self.ncomp = 2 if sig.complex_baseband else 1
        self.level = quantizer_levels(sig.quantization_bits)
        sig_pow = sum(s.amplitude**2 / 2.0 for s in sats)
        self.sigma_in = math.sqrt(1.0 + sig_pow)
        self.gain = quantizer_gain(sig.quantization_bits, self.sigma_in)
        self.n_nodes_total = int(math.ceil(sc.duration_s / self.node_dt - 1e-9))
        self.n_samples = self.n_nodes_total * self.n_per_node
        self.codes = np.stack([b3i_code(s.prn) for s in sats]).astype(np.float32)
        #: Kernel rows: the direct signals (row k = satellite k), then the multipath replicas.
        self.rows = [SignalRow(k) for k in range(len(sats))] + replica_rows(
            [s.prn for s in sats], sc.multipath)
        self.code_words = code_words(self.codes[[r.k for r in self.rows]])
        self.jammers = JammerPlan(
            sc.interference, sc.agc, self.fs, sig.if_hz, sig.complex_baseband,
            sc.satellites.cn0_dbhz, self.sigma_in,
            lambda sigma: quantizer_gain(sig.quantization_bits, sigma), sc.seed)
        self.noise_key = np.uint64(np.random.SeedSequence([sc.seed, 0x1F5D2])
                                   .generate_state(1, np.uint64)[0])
        self.nh = 1.0 - 2.0 * NH20_BITS.astype(np.float32)
        self.chunk_nodes = sig.chunk_ms
        #: Truth oscillator path (:class:`~sdr_di.sim.oscillator.ClockTruth`, set by the
        #: builder when the scenario has ``[oscillator]``); None: the ``[receiver_clock]`` line.
        self.clock_truth = None
        #: Truth atmosphere residuals (:class:`~sdr_di.sim.atmosphere.AtmosphereTruth`, set
        #: by the builder for ``[atmosphere] truth = "residuals"``); None: truth = model.
        self.atmosphere = None

    # -- geometry on the node grid ------------------------------------------------------
    def node_times(self, j: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Receiver time s [s], true time t [s] and clock bias b [s] of nodes ``j``."""
        s = j * self.node_dt
        ck = self.sc.clock
        t = (s - ck.bias_s) / (1.0 + ck.drift_s_s)
        if self.clock_truth is None:
            return s, t, ck.bias_s + ck.drift_s_s * t
        # truth oscillator (sim/oscillator.py): s = t + line(t) + x(t), one fixed-point step
        # (x changes by < 1e-7 s/s, so the step leaves < 1e-13 s)
        t = t - self.clock_truth.noise_at(t) / (1.0 + ck.drift_s_s)
        return s, t, ck.bias_s + ck.drift_s_s * t + self.clock_truth.noise_at(t)

    def node_state(self, j0: int, n: int) -> dict[str, np.ndarray]:
        """Kernel inputs for node intervals ``j0 .. j0 + n - 1``."""
        j = np.arange(j0, j0 + n + 1, dtype=np.float64)
        s, t, b = self.node_times(j)
        sig = self.sc.signal
        n_rows = len(self.rows)
        chip0 = np.empty((n_rows, n))
        ms0 = np.empty((n_rows, n), np.int64)
        dchip = np.empty((n_rows, n))
        ph0 = np.empty((n_rows, n))
        dph = np.empty((n_rows, n))
        amp = np.empty((n_rows, n), np.float32)
        sym_lists, bases = [], np.empty(n_rows, np.int64)
        r_rx = self.path(t)[0]
        rx = (r_rx, ecef_to_llh(r_rx))  # once per chunk, shared by every satellite
        delays = {}
        for i, row in enumerate(self.rows):  # direct signals first, then replicas
            sat = self.sats[row.k]
            if row.k not in delays:
                delays[row.k] = satellite_delays(sat.eph, self.path, t, self.sc.sow, b,
                                                 self.iono, sig.troposphere == "saastamoinen",
                                                 rx=rx, atmosphere=self.atmosphere)
            d = delays[row.k]
            x = _week_seconds_between(self.sc.week, self.sc.sow, sat.nav.week, sat.nav.t0)
            d_code, d_carr = d.d_code, d.d_carr
            if row.height_m:  # ground reflection: the excess path of the image antenna
                tau = row.ground_delay_s(d.el)
                d_code, d_carr = d_code + tau, d_carr + tau
            u_ms = (x + s - d_code) * 1000.0  # code epochs since the first nav bit
            if row.delay_chips:
                u_ms = u_ms - row.delay_chips / 10230.0
            ms = np.floor(u_ms).astype(np.int64)
            chip0[i] = ((u_ms - ms) * 10230.0)[:-1]
            ms0[i] = ms[:-1]
            du = np.diff(s) - np.diff(d_code)
            dchip[i] = du * CHIP_RATE_B3I / self.n_per_node
            phi = sig.if_hz * s - F_B3I * d_carr
            dphi = sig.if_hz * np.diff(s) - F_B3I * np.diff(d_carr)
            if row.phase_cycles or row.doppler_hz:
                phi = phi + row.phase_cycles + row.doppler_hz * s
                dphi = dphi + row.doppler_hz * np.diff(s)
            ph0[i] = np.mod(phi[:-1], 1.0)
            dph[i] = dphi / self.n_per_node
            amp[i] = row.alpha * sat.amplitude * self.outage_factor(sat.prn, t[:-1])
            m = np.arange(ms.min(), ms.max() + 2)
            if sat.is_d1:
                bits = sat.nav.bits[m // 20]
                sym = (1.0 - 2.0 * bits) * self.nh[m % 20]
            else:
                sym = 1.0 - 2.0 * sat.nav.bits[m // 2].astype(np.float32)
            sym_lists.append(sym.astype(np.float32))
            bases[i] = m[0]
        width = max(len(x) for x in sym_lists)
        sym = np.ones((n_rows, width), np.float32)
        for k, x in enumerate(sym_lists):
            sym[k, : len(x)] = x
        return dict(chip0=chip0, ms0=ms0, dchip=dchip, ph0=ph0, dph=dph, amp=amp, sym=sym,
                    sym_base=bases, s=s, t=t, jam_amp=self.jammers.amplitudes(t[:-1]))

    def outage_factor(self, prn: int, t: np.ndarray) -> np.ndarray:
        """Amplitude factor (0 = blocked) of the outage schedule at true times ``t``."""
        f = np.ones_like(t)
        for o in self.sc.outages:
            if o.prn is None or o.prn == prn:
                inside = (t >= o.start_s) & (t < o.end_s)
                f[inside] *= 0.0 if math.isinf(o.attenuation_db) else 10 ** (-o.attenuation_db / 20)
        return f

    # -- sample streaming --------------------------------------------------------------
    def synthesize(self, j0: int, n: int, out: np.ndarray | None = None,
                   state: dict[str, np.ndarray] | None = None) -> np.ndarray:
        """Quantized samples of node intervals ``j0 .. j0 + n - 1``, ``(n N, ncomp)`` int8 or
        int16 (``out`` reused when given and of that shape; ``state``: the intervals'
        :meth:`node_state`, computed when not given)."""
        dtype = np.int16 if self.fmt.dtype.itemsize == 2 else np.int8
        shape = (n * self.n_per_node, self.ncomp)
        if out is None or out.shape != shape or out.dtype != dtype:
            out = np.empty(shape, dtype)
        st = self.node_state(j0, n) if state is None else state
        jp = self.jammers
        with numba.parallel_chunksize(KERNEL_CHUNK_NODES):
            synthesize_chunk(out, self.noise_key, j0 * self.n_per_node, self.n_per_node,
                             self.code_words, st["chip0"], st["ms0"], st["dchip"], st["ph0"],
                             st["dph"], st["amp"], st["sym"], st["sym_base"],
                             self.agc_gains(j0, st["jam_amp"]), self.level, jp.kind,
                             st["jam_amp"], jp.freq, jp.phase, jp.key, jp.rate, jp.taps)
        return out

    def agc_gains(self, j0: int, jam_amp: np.ndarray) -> np.ndarray:
        """Quantizer gains of nodes ``j0 ..`` (:class:`~sdr_di.sim.interference.JammerPlan`:
        constant without jammers); nodes skipped since the last call are replayed, so the
        gains do not depend on the order the ranges are asked in."""
        jp = self.jammers
        if len(jp.jammers) and j0 not in (0, jp.agc_node):
            start = jp.agc_node if jp.agc_node < j0 else 0
            for b0 in range(start, j0, GEOMETRY_BLOCK_NODES):
                nb = min(GEOMETRY_BLOCK_NODES, j0 - b0)
                t = self.node_times(np.arange(b0, b0 + nb, dtype=np.float64))[1]
                jp.gains(b0, jp.amplitudes(t), self.node_dt)
        return jp.gains(j0, jam_amp, self.node_dt)

    def chunks(self, n_nodes: int | None = None, *,
               reuse: bool = False) -> Iterator[np.ndarray]:
        """Yield quantized chunks in the container layout of the sample format.

        Each chunk is ``(n, 2)`` / ``(n, 1)`` int8 or int16, or ``(n,)`` uint8 for ``iq_int4``.
        The geometry (:meth:`node_state`) is computed for blocks of at least
        :data:`GEOMETRY_BLOCK_NODES` intervals (its cost is mostly per call), one block ahead
        on a helper thread, the samples ``chunk_ms`` at a time; none of it changes the
        samples.

        Parameters
        ----------
        n_nodes : int, optional
            Generate only the first ``n_nodes`` node intervals (~ms); default the whole file.
        reuse : bool
            Cycle two buffers: a yielded array is overwritten by the chunk after the next one
            (so a writer thread can write one while the next is generated, with no allocation
            per chunk). Default False: every chunk is a new array.
        """
        total = self.n_nodes_total if n_nodes is None else min(n_nodes, self.n_nodes_total)
        block = max(self.chunk_nodes, GEOMETRY_BLOCK_NODES)
        bufs: list = [None, None]
        packed: list = [None, None]
        ci = 0
        with ThreadPoolExecutor(1, thread_name_prefix="sdr-di-geometry") as pool:
            # the next block's geometry is computed while this block's samples are made
            # (the kernel releases the GIL)
            ahead = pool.submit(self.node_state, 0, min(block, total))
            for b0 in range(0, total, block):
                b1 = min(b0 + block, total)
                geo = ahead.result()
                if b1 < total:
                    ahead = pool.submit(self.node_state, b1, min(block, total - b1))
                for j0 in range(b0, b1, self.chunk_nodes):
                    n = min(self.chunk_nodes, b1 - j0)
                    a, b = j0 - b0, j0 - b0 + n
                    st = {k: (np.ascontiguousarray(v[:, a:b]) if v.ndim == 2 and k != "sym"
                              else v) for k, v in geo.items()}
                    out = self.synthesize(j0, n, bufs[ci % 2], st)
                    if reuse:
                        bufs[ci % 2] = out
                    if self.fmt.name == "iq_int4":
                        p = packed[ci % 2]
                        if p is None or p.shape[0] != out.shape[0]:
                            p = np.empty(out.shape[0], np.uint8)
                            if reuse:
                                packed[ci % 2] = p
                        pack_iq_int4_kernel(p, out)
                        yield p
                    else:
                        yield out
                    ci += 1

    def start_summary(self) -> list[dict]:
        """Per-satellite state at sample 0 for the sidecar."""
        st = self.node_state(0, 1)
        rows = []
        for k, sat in enumerate(self.sats):
            doppler = st["dph"][k, 0] * self.fs - self.sc.signal.if_hz
            rows.append(dict(prn=sat.prn, nav="D1" if sat.is_d1 else "D2",
                             cn0_dbhz=sat.cn0_dbhz, elevation_deg=round(sat.elevation_deg, 3),
                             azimuth_deg=round(sat.azimuth_deg, 3),
                             doppler_hz=round(float(doppler), 3),
                             code_phase_chips=round(float(st["chip0"][k, 0]), 4),
                             toe=sat.eph.toe, week=sat.eph.week,
                             broadcast=[{"from_s": round(max(t - self.sc.sow, 0.0), 3),
                                         "toe": e.toe, "week": e.week, "aode": e.AODE}
                                        for t, e in sat.broadcast]))
        return rows


#: The broadcast record changes only at these boundaries of BDT [s]: a D1 frame (subframes
#: 1-3 carry the ephemeris) and ten D2 frames (subframe 1's pages 1-10 carry it).
RECORD_SWITCH_S = 30.0


def broadcast_nav_bits(nav, eph: Ephemeris, week: int, sow_start: float, duration_s: float,
                       iono: Klobuchar | None) -> tuple[NavBits, list[tuple[float, Ephemeris]]]:
    """Navigation bits of ``eph.prn`` as the satellite sends them over an interval: the record
    on the air (``nav.select(..., broadcast=True)``, its latest upload) from each
    :data:`RECORD_SWITCH_S` boundary on, so a file that spans an upload carries the new record
    from the first frame after it went on the air, as a real satellite does.

    The satellite's orbit and clock in the signal (the geometry) stay those of ``eph``, the
    record at the start: a receiver that takes up the new record then sees the difference of
    two consecutive uploads as an ephemeris error (decimetres), which is what it sees in the
    field.

    Returns
    -------
    (NavBits, list of (float, Ephemeris))
        The bits, and ``(BDT sow from which it is broadcast, record)`` per record.
    """
    t_end = sow_start + duration_s
    records = [(float(sow_start), eph)]
    t = (math.floor(sow_start / RECORD_SWITCH_S) + 1) * RECORD_SWITCH_S
    while t < t_end:
        try:
            rec = nav.select(eph.prn, week, t, broadcast=True)
        except NoEphemerisError:
            rec = records[-1][1]
        cur = records[-1][1]
        if (rec.week, rec.toe, rec.AODE) != (cur.week, cur.toe, cur.AODE):
            records.append((t, rec))
        t += RECORD_SWITCH_S
    parts = []
    for i, (a, rec) in enumerate(records):
        b = records[i + 1][0] if i + 1 < len(records) else t_end
        parts.append(nav_bits(rec, week, a, b - a, iono=iono))
    for p0, p1 in itertools.pairwise(parts):
        if abs(p0.t_end - p1.t0) > 1e-9:  # the switch falls on a subframe edge of both
            raise RuntimeError(f"C{eph.prn:02d}: message parts do not join at {p1.t0}")
    bits = parts[0] if len(parts) == 1 else dataclasses.replace(
        parts[0], bits=np.concatenate([p.bits for p in parts]))
    return bits, records


def build_satellites(sc: Scenario, nav, path: ReceiverPath,
                     iono: Klobuchar | None) -> list[SatelliteSignal]:
    """Select satellites and build their navigation-message streams (the record on the air
    at each frame: :func:`broadcast_nav_bits`)."""
    chosen = select_satellites(sc, nav, path, iono)
    sats = []
    for prn, eph, el, az in chosen:
        cn0 = sc.satellites.cn0_per_prn.get(prn, sc.satellites.cn0_dbhz)
        bits, records = broadcast_nav_bits(nav, eph, sc.week, sc.sow - 1.0,
                                           sc.duration_s + 2.0, iono)
        amp = cn0_to_amplitude(cn0, sc.signal.sampling_rate_hz, sc.signal.complex_baseband)
        sats.append(SatelliteSignal(prn, eph, bits, cn0, amp, math.degrees(el),
                                    math.degrees(az), broadcast=records))
    return sats
