"""Numba kernel of the deep/tight measurement matrix (paper 004 eq 10-12), set every filter
interval (twice in the deep loop): the numpy form, the tested reference, is
:meth:`sdr_di.coupling.measurements.RangeRateMeasurementModel.set_geometry` with
``jit = False``. Products summed left to right (numpy's ``matmul`` may fuse them, so the
two agree to an ulp, not bit for bit)."""

from __future__ import annotations

from numba import njit


@njit(cache=True, boundscheck=False)
def range_rate_H(U, C1, C2, pos0, vel0, clock_bias, clock_drift, H):
    """Fill ``H`` (2 N, n), zeros in, with ``-U C1`` in the position columns
    ``pos0:pos0 + 3`` of the first ``N`` rows, ``-U C2`` in the velocity columns
    ``vel0:vel0 + 3`` of the last ``N``, and ones in the clock bias and drift columns.
    ``U`` (N, 3) unit lines of sight (ECEF); ``C1 = d r_e / d(lat, lon, h)`` and
    ``C2 = C_n^e`` (3, 3)."""
    N = U.shape[0]
    for i in range(N):
        u0, u1, u2 = U[i, 0], U[i, 1], U[i, 2]
        for j in range(3):
            H[i, pos0 + j] = -(u0 * C1[0, j] + u1 * C1[1, j] + u2 * C1[2, j])
            H[N + i, vel0 + j] = -(u0 * C2[0, j] + u1 * C2[1, j] + u2 * C2[2, j])
        H[i, clock_bias] = 1.0
        H[N + i, clock_drift] = 1.0
