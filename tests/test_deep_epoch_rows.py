"""The vector loop's correlator-row kernel against its plain numpy form, bit for bit."""

import numpy as np

from sdr_di.constants import CODE_LENGTH_B3I
from sdr_di.deep._numba_epoch_rows import epoch_rows
from sdr_di.deep.vector_tracking import VectorChannel, _epoch_rows
from sdr_di.signal.codes import NH20


def test_epoch_rows_kernel_equals_plain_form():
    rng = np.random.default_rng(3)
    L = CODE_LENGTH_B3I
    fs = 25e6
    total = 0
    for trial in range(40):
        n_ch = int(rng.integers(1, 9))
        k0 = int(rng.integers(10**6, 10**9))
        k1 = k0 + int(rng.choice([500_000, 50_000, 25_000, 12_345]))
        dc = 10.23e6 * (1 + rng.uniform(-5e-6, 5e-6, n_ch)) / fs
        chans, c0 = [], np.empty(n_ch)
        for i in range(n_ch):
            # next epoch starts within about one epoch of k0 (or past k1: no rows)
            s = k0 + int(rng.integers(-25_000, 25_000)) if i != 2 else k1 + 5
            e = int(rng.integers(0, 10**7))
            # chip count at k0 consistent with epoch e starting at s
            c0[i] = e * L - (s - k0) * dc[i] + rng.uniform(-0.4, 0.4)
            chans.append(VectorChannel(prn=i + 1, idx=i, is_d1=bool(rng.integers(0, 2)), eph=None,
                               next_start=s, epoch=e, phase=float(rng.uniform(0, 1))))
        dp0 = rng.uniform(-0.3, 0.3, n_ch)
        dp1 = dp0 + rng.uniform(-1e-6, 1e-6, n_ch)
        nxt = np.array([c.next_start for c in chans], np.int64)
        ep = np.array([c.epoch for c in chans], np.int64)
        ph = np.array([c.phase for c in chans])
        is_d1 = np.array([c.is_d1 for c in chans])
        reps, *cols = epoch_rows(nxt, ep, ph, c0, dc, dp0, dp1, is_d1,
                                 NH20.astype(np.float64), L, k0, k1)
        parts = [_epoch_rows(c, float(c0[i]), float(dc[i]), float(dp0[i]), float(dp1[i]),
                             k0, k1) for i, c in enumerate(chans)]
        assert reps.tolist() == [len(p[0]) for p in parts]
        total += int(sum(reps))
        for j in range(7):
            want = np.concatenate([p[j] for p in parts])
            np.testing.assert_array_equal(cols[j], want)
            assert cols[j].dtype.kind == want.dtype.kind or want.size == 0
        for i, c in enumerate(chans):     # the plain form advanced the channels
            assert (nxt[i], ep[i], ph[i]) == (c.next_start, c.epoch, c.phase)
    assert total > 500
