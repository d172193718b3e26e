"""Numba kernel of the per-channel pre-filter (one channel, the epochs of one interval).

Plain arrays only; the model and notation are documented in :mod:`sdr_di.deep.prefilter`.
"""

from __future__ import annotations

import math

import numba
import numpy as np


@numba.njit(cache=True)
def wrap_half_pi(a: float) -> float:
    """Reduce an angle [rad] to [-pi/2, pi/2) (the data-bit-insensitive phase ambiguity)."""
    return a - math.pi * math.floor(a / math.pi + 0.5)


@numba.njit(cache=True)
def prefilter_epochs(x, P, early, prompt, late, t_epoch, spacing, beta, r_tau, r_phi,
                     q_tau, q_phi, s_f, C, q_tau_m, q_phi_m, s_f_m):
    """Run the 3-state pre-filter over consecutive epochs of one channel, in place.

    Parameters
    ----------
    x : float64 (3,)
        ``[dtau (chips), dphi (rad), df (Hz)]`` at the start of the first epoch; on return at
        the start of the epoch after the last one.
    P : float64 (3, 3)
        Its covariance (updated in place).
    early, prompt, late : complex128 (m,)
        Correlator sums of the epochs.
    t_epoch : float64 (m,)
        Epoch durations [s].
    spacing : float
        Early/late offset d [chips].
    beta : float
        Code chips per carrier cycle, ``f_code / f_carr``.
    r_tau, r_phi : float64 (m,)
        Discriminator noise variances [chips^2], [rad^2] of each epoch.
    q_tau, q_phi : float
        Process noise per epoch [chips^2], [rad^2].
    s_f : float
        Frequency random-walk PSD [Hz^2/s].
    C : float64 (3, 3)
        Error covariance of ``x`` under the noise model (updated in place): the Joseph form
        with the filter's gain ``K``, ``C <- (I - K H) C (I - K H)^T + K R K^T``, then
        ``C <- F C F^T + diag(q_tau_m, q_phi_m T, s_f_m T)``.
    q_tau_m, q_phi_m, s_f_m : float
        The noise model's process noise: code per epoch [chips^2], phase random-walk PSD
        [rad^2/s] and frequency random-walk PSD [Hz^2/s].

    Returns
    -------
    nis : float
        Sum of the normalized innovations squared (2 per epoch).
    """
    m = prompt.shape[0]
    nis = 0.0
    A = np.empty((3, 3))
    Kt = np.empty((3, 2))
    AC = np.empty((3, 3))
    CN = np.empty((3, 3))
    for j in range(m):
        T = t_epoch[j]
        ea = abs(early[j])
        la = abs(late[j])
        s = ea + la
        z_tau = (1.0 - spacing) * (ea - la) / s if s > 0.0 else 0.0
        pr = prompt[j]
        if pr.real != 0.0:
            z_phi = math.atan(pr.imag / pr.real)
        else:
            z_phi = 0.5 * math.pi
        # measurement rows (epoch averages of the state at its start)
        h02 = 0.5 * beta * T
        h12 = math.pi * T
        y0 = z_tau - (x[0] + h02 * x[2])
        y1 = wrap_half_pi(z_phi - (x[1] + h12 * x[2]))
        # PH^T (3x2)
        a0 = P[0, 0] + h02 * P[0, 2]
        a1 = P[1, 0] + h02 * P[1, 2]
        a2 = P[2, 0] + h02 * P[2, 2]
        b0 = P[0, 1] + h12 * P[0, 2]
        b1 = P[1, 1] + h12 * P[1, 2]
        b2 = P[2, 1] + h12 * P[2, 2]
        S00 = a0 + h02 * a2 + r_tau[j]
        S01 = b0 + h02 * b2
        S10 = a1 + h12 * a2
        S11 = b1 + h12 * b2 + r_phi[j]
        det = S00 * S11 - S01 * S10
        i00 = S11 / det
        i01 = -S01 / det
        i10 = -S10 / det
        i11 = S00 / det
        nis += y0 * (i00 * y0 + i01 * y1) + y1 * (i10 * y0 + i11 * y1)
        K00 = a0 * i00 + b0 * i10
        K01 = a0 * i01 + b0 * i11
        K10 = a1 * i00 + b1 * i10
        K11 = a1 * i01 + b1 * i11
        K20 = a2 * i00 + b2 * i10
        K21 = a2 * i01 + b2 * i11
        x[0] += K00 * y0 + K01 * y1
        x[1] += K10 * y0 + K11 * y1
        x[2] += K20 * y0 + K21 * y1
        # P <- P - K (H P) with H P = [a^T; b^T]
        for r in range(3):
            kr0 = K00 if r == 0 else (K10 if r == 1 else K20)
            kr1 = K01 if r == 0 else (K11 if r == 1 else K21)
            P[r, 0] -= kr0 * a0 + kr1 * b0
            P[r, 1] -= kr0 * a1 + kr1 * b1
            P[r, 2] -= kr0 * a2 + kr1 * b2
        for r in range(3):
            for c in range(r + 1, 3):
                v = 0.5 * (P[r, c] + P[c, r])
                P[r, c] = v
                P[c, r] = v
        # error covariance under the noise model, Joseph form with this gain:
        # A = I - K H (H rows [1, 0, h02], [0, 1, h12]), C <- A C A^T + K R K^T
        for r in range(3):
            kr0 = K00 if r == 0 else (K10 if r == 1 else K20)
            kr1 = K01 if r == 0 else (K11 if r == 1 else K21)
            A[r, 0] = (1.0 if r == 0 else 0.0) - kr0
            A[r, 1] = (1.0 if r == 1 else 0.0) - kr1
            A[r, 2] = (1.0 if r == 2 else 0.0) - kr0 * h02 - kr1 * h12
            Kt[r, 0] = kr0
            Kt[r, 1] = kr1
        for r in range(3):
            for c in range(3):
                acc = 0.0
                for k in range(3):
                    acc += A[r, k] * C[k, c]
                AC[r, c] = acc
        for r in range(3):
            for c in range(r, 3):
                acc = Kt[r, 0] * r_tau[j] * Kt[c, 0] + Kt[r, 1] * r_phi[j] * Kt[c, 1]
                for k in range(3):
                    acc += AC[r, k] * A[c, k]
                CN[r, c] = acc
                CN[c, r] = acc
        x[1] = wrap_half_pi(x[1])
        # propagate to the next epoch start: F = [[1, 0, beta T], [0, 1, 2 pi T], [0, 0, 1]]
        f02 = beta * T
        f12 = 2.0 * math.pi * T
        x[0] += f02 * x[2]
        x[1] += f12 * x[2]
        # P <- F P F^T + Q
        p00, p01, p02 = P[0, 0], P[0, 1], P[0, 2]
        p11, p12, p22 = P[1, 1], P[1, 2], P[2, 2]
        n00 = p00 + 2.0 * f02 * p02 + f02 * f02 * p22
        n01 = p01 + f12 * p02 + f02 * p12 + f02 * f12 * p22
        n02 = p02 + f02 * p22
        n11 = p11 + 2.0 * f12 * p12 + f12 * f12 * p22
        n12 = p12 + f12 * p22
        P[0, 0] = n00 + q_tau
        P[0, 1] = n01
        P[1, 0] = n01
        P[0, 2] = n02
        P[2, 0] = n02
        P[1, 1] = n11 + q_phi
        P[1, 2] = n12
        P[2, 1] = n12
        P[2, 2] = p22 + s_f * T
        c00, c01, c02 = CN[0, 0], CN[0, 1], CN[0, 2]
        c11, c12, c22 = CN[1, 1], CN[1, 2], CN[2, 2]
        m01 = c01 + f12 * c02 + f02 * c12 + f02 * f12 * c22
        m02 = c02 + f02 * c22
        m12 = c12 + f12 * c22
        C[0, 0] = c00 + 2.0 * f02 * c02 + f02 * f02 * c22 + q_tau_m
        C[0, 1] = m01
        C[1, 0] = m01
        C[0, 2] = m02
        C[2, 0] = m02
        C[1, 1] = c11 + 2.0 * f12 * c12 + f12 * f12 * c22 + q_phi_m * T
        C[1, 2] = m12
        C[2, 1] = m12
        C[2, 2] = c22 + s_f_m * T
    return nis


@numba.njit(cache=True)
def prefilter_channels(ch0, counts, bounds, early, prompt, late, t_block, cn0_lin, spacing,
                       beta, x, P, C, q_tau, q_phi, s_f, q_phi_m, s_f_m, nis):
    """:func:`prefilter_epochs` of channels ``ch0, ch0 + 1, ...`` over their coherent blocks
    of one pass, with each block's discriminator variances from the channel's C/N0
    (:func:`~sdr_di.deep.prefilter.discriminator_variances`, the same operations).

    Parameters
    ----------
    ch0 : int
        First channel of the pass.
    counts : int64 (m,)
        Epochs of each of the pass's channels (a channel without one is left alone).
    bounds : int64 (m + 1,)
        Channel ``k``'s blocks are ``[bounds[k], bounds[k + 1])`` of the block arrays.
    early, prompt, late : complex128 (b,)
        Correlator sums of the blocks.
    t_block : float64 (b,)
        Block durations [s].
    cn0_lin : float64 (m,)
        C/N0 of each channel [Hz] (not NaN; at least 1 Hz is used).
    spacing, beta, q_tau, q_phi, s_f, q_phi_m, s_f_m : float
        As :func:`prefilter_epochs` (``q_tau_m = 0``).
    x, P, C : float64 (n, 3), (n, 3, 3), (n, 3, 3)
        Every channel's state, design covariance and error covariance (updated in place).
    nis : float64 (m,)
        Sum of the normalized innovations squared of each channel (out; left alone for a
        channel without epochs).
    """
    for k in range(counts.shape[0]):
        if counts[k] == 0:
            continue
        i = ch0 + k
        b0 = bounds[k]
        b1 = bounds[k + 1]
        c = max(cn0_lin[k], 1.0)
        r_tau = np.empty(b1 - b0)
        r_phi = np.empty(b1 - b0)
        for j in range(b1 - b0):
            snr = c * t_block[b0 + j]
            r_tau[j] = spacing / (2.0 * snr) * (1.0 + 1.0 / snr)
            r_phi[j] = 1.0 / (2.0 * snr) * (1.0 + 1.0 / (2.0 * snr))
        nis[k] = prefilter_epochs(x[i], P[i], early[b0:b1], prompt[b0:b1], late[b0:b1],
                                  t_block[b0:b1], spacing, beta, r_tau, r_phi, q_tau, q_phi,
                                  s_f, C[i], 0.0, q_phi_m, s_f_m)


def _warm() -> None:  # pragma: no cover - compile on import of the bank when cached
    x = np.zeros(3)
    P = np.eye(3)
    z = np.ones(1, np.complex128)
    t = np.full(1, 1e-3)
    r = np.ones(1)
    prefilter_epochs(x, P, z, z, z, t, 0.5, 0.008, r, r, 0.0, 0.0, 1.0, np.eye(3), 0.0, 0.0,
                     1.0)
