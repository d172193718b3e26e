"""The scalar channel's numba kernels (receiver._numba_channel) against their plain Python
forms, bit for bit: the block plan on random NCO states, the per-epoch bookkeeping on random
correlator sums, and a short receiver run."""

import copy
import math

import numpy as np

from sdr_di.receiver._numba_channel import plan_block
from sdr_di.receiver.channel import _HIST, Channel
from sdr_di.receiver.lock import _NOISE_LAG_STEP, NOISE_MIN_LAG_CHIPS, noise_samples
from sdr_di.receiver.run_scalar import open_source, sidecar_assistance
from sdr_di.receiver.scalar import ScalarReceiver
from sdr_di.receiver.tracking import ChannelState

L = 10230


def test_plan_block_equals_reference():
    rng = np.random.default_rng(7)
    ch = Channel(27, 2.5e6, 0.0, log=False)
    for trial in range(300):
        fs = float(rng.choice([2.5e6, 4.092e6, 25e6, 30.69e6]))
        m = int(rng.integers(1, 21))
        start = int(rng.integers(0, 2**40))
        th = float(rng.choice([0.0, rng.uniform(0.0, 20.0), rng.uniform(0, L)]))
        rate = 10.23e6 * (1.0 + rng.uniform(-4e-6, 4e-6))
        dchip = rate / fs
        fd = float(rng.uniform(-5000.0, 5000.0))
        if_hz = float(rng.choice([0.0, 1.25e6, -3e6]))
        dphi, ddop = (if_hz + fd) / fs, fd / fs
        args = (m, start, th, float(rng.uniform(0, 1)), float(rng.uniform(-1e6, 1e6)),
                int(rng.integers(-5, 2**33)), rate, dchip, dphi, ddop, fd,
                fd + float(rng.normal()), float(rng.normal()), start + 0.5 * m * L * fs / rate)
        ref = [np.full_like(a, -1.0) for a in (ch._hist, ch._rows, ch._ends)]
        ch._hist, ch._rows, ch._ends = ref
        ch.n_noise = noise_samples(fs)
        ch._plan_reference(*args)
        jit = [np.full_like(a, -1.0) for a in ref]
        plan_block(*args, L, ch.n_noise, NOISE_MIN_LAG_CHIPS, _NOISE_LAG_STEP, *jit)
        for a, b in zip(ref, jit):
            np.testing.assert_array_equal(a, b)
        assert np.count_nonzero(ref[0][:, 5] >= 0) == min(m, _HIST)


def _synced_channel(prn: int, coh_ms_state: int) -> Channel:
    """A tracking channel with bit synchronization (set directly), no log."""
    ch = Channel(prn, 2.5e6, 0.0, log=False)
    ch.noise_power_per_sample = 2.0
    ch.start(1234, 3000.0, 120.0, 40.0)
    ch.state = ChannelState.TRACK
    ch._enter_track()
    ch._pll_ctr.reset(locked=True)
    ch.carrier_lock = True
    ch._bit_off = coh_ms_state
    ch._plan()
    return ch


def _state(ch: Channel) -> tuple:
    return (ch.epoch, ch.next_start, ch.theta, ch.phi, ch.dphase, ch.fd, ch.code_rate,
            ch.carrier.freq_hz, ch.carrier.vel_hz, ch.carrier.acc_hz_s, ch.code.rate_corr_cps,
            ch._bit_acc, ch._bit_n, ch._eval_count, ch._n_tracked, tuple(ch._coh),
            repr(ch.cn0_dbhz), ch.lock_metric, ch.state, ch._bit_off, ch._frozen,
            ch._ring.tobytes(), ch._hist.tobytes(), list(ch._bits), ch.block)


def test_plain_epochs_equal_python_epochs():
    """process_block with the kernels and with the Python epochs: the same state after every
    block (random sums, D1 and D2, signal present and weak)."""
    rng = np.random.default_rng(11)
    n_blocks_kernel = 0
    for prn, amp in ((27, 300.0), (3, 300.0), (30, 25.0)):
        a = _synced_channel(prn, int(rng.integers(0, 2)))
        b = copy.deepcopy(a)
        b.jit = False
        phase = rng.uniform(0, 2 * math.pi)
        for _ in range(400):
            m = a.n_block_epochs
            assert b.n_block_epochs == m and a.block == b.block
            n_rows = 2 * m
            sign = rng.choice([-1.0, 1.0])
            outs = (rng.normal(0, 30, (n_rows, 3)) + 1j * rng.normal(0, 30, (n_rows, 3)))
            outs[0::2, 1] += sign * amp * np.exp(1j * phase)
            outs[0::2, 0] += sign * 0.5 * amp * np.exp(1j * phase)
            outs[0::2, 2] += sign * 0.5 * amp * np.exp(1j * phase)
            if a.tracking and a.bit_synced and m > 1:
                n_blocks_kernel += 1
            a.process_block(outs.copy())
            b.process_block(outs.copy())
            assert _state(a) == _state(b)
            if not a.tracking:
                break
    assert n_blocks_kernel > 300


def test_short_run_same_observations_with_and_without_kernels(if_files, monkeypatch):
    path = if_files(3.0).if_file

    def run(jit: bool) -> list[str]:
        monkeypatch.setattr(Channel, "jit", jit)
        src = open_source(path)
        seen: list[str] = []

        def on_epoch(sample, obs, eph):
            seen.extend(repr(o) for o in obs)

        rx = ScalarReceiver(log=False)
        rx.run(src, on_epoch=on_epoch, assist=sidecar_assistance(src))
        synced = sum(c.bit_synced for c in rx.channels.values())
        return seen, synced

    with_kernels, synced = run(True)
    assert synced >= 5 and len(with_kernels) > 100
    assert run(False)[0] == with_kernels
