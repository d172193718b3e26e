#!/usr/bin/env python
"""Integration-filter cost: time per predict+update and adaptation time ff-aukf / rae-aukf.

Usage::

    python scripts/bench_filters.py [--epochs 400] [--warmup 50] [--channels 7] [--seed 1]
                                    [--filters ekf ukf ...] [--repeat 3] [--no-sweep]

Synthetic 17-state problem with the state layout of the receiver (DESIGN section 4, paper
004 Table 1) and ``2 N`` measurements (default N = 7 -> 14: pseudorange errors then
pseudorange-rate errors) at 10 Hz:

* process model: a nonlinear INS error model in the spirit of paper 004 eq 2-4 (large-angle
  attitude error through a Rodrigues rotation matrix in the attitude and velocity equations,
  position error in latitude/longitude/height with the radii of curvature, random-constant
  IMU biases, clock bias/drift with a first-order Markov drift), improved-Euler discretized,
  vectorized over sigma points, Jacobian by differentiating the 3 nonlinear attitude terms;
* measurement model: exact range differences to satellites ~2e7 m away for the perturbed
  position (computed without cancellation) plus clock bias, and range-rate errors along the
  perturbed line of sight plus clock drift; analytic Jacobian.

For each filter the table gives the mean wall time of one ``predict()`` + ``update()`` over
``--epochs`` epochs after ``--warmup`` epochs (best of ``--repeat`` runs), the adaptation time
per epoch and in total (hooks of the adaptive rule only, ``time.perf_counter``), then the
ratio of the total adaptation times ff-aukf / rae-aukf over the same epochs (paper 004:
0.1851 s / 0.2935 s = 0.63), measured with the two filters stepped alternately on the same
data so that both see the same machine load. Both rules use the same window (20 epochs).
Three figures per implementation: the plain totals (best run; every run is listed),
``epochs x median epoch`` (robust to a hook being preempted on a shared machine), and the
hooks alone with warm caches (the rule's own work, called repeatedly on a frozen epoch).
The ratio is given for both implementations of the two rules: ``jit`` (the defaults:
ff-aukf's hooks as numba kernels; rae-aukf as a numba kernel compiled with the same options
or with BLAS products, whichever is faster for the size -- ``jit=None``) and ``numpy``
(``jit=False`` for both: plain numpy expressions). At 14 measurements a numpy call costs
about as much as its arithmetic, so the numpy ratio mostly counts calls (about twenty small
ones for ff-aukf, a dozen incl. five matrix products for rae-aukf); the kernels compare the
rules' arithmetic, which is what paper 004 claims is smaller.

A second table repeats the ff-aukf / rae-aukf comparison for more channels and longer
windows (skipped with ``--no-sweep``): the forgetting-factor rule's work is ``O(n m + W n)`` per
epoch against ``O(W m^2 + n m^2 + n^2 m + m^3)`` for the Sage window; with numpy the
advantage only shows as ``m`` and ``W`` grow, with the kernels it shows at every size.

Run as a script, BLAS is limited to one thread (``OPENBLAS_NUM_THREADS`` etc. default to 1):
the filters work on 17 x 17 matrices, where multi-threaded OpenBLAS only adds stalls.

``run(args)`` is the entry point for a ``scripts/bench.py filters`` dispatcher; ``args``
needs the attributes ``epochs``, ``warmup``, ``channels``, ``seed``, ``filters`` and
``repeat`` (optional ``sweep``, default False there). It returns the rows as dicts.
"""

from __future__ import annotations

import os

if __name__ == "__main__":   # before numpy is imported: single-threaded BLAS for small matrices
    for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(_var, "1")

import argparse
import math
import time

import numpy as np

from sdr_di.filters import FILTER_NAMES, MeasurementModel, ProcessModel, make_filter

DT = 0.1                      # filter period [s] (10 Hz)
A_E = 6378137.0
E2 = 0.00669438002290         # CGCS2000 first eccentricity squared
OMEGA_E = 7.2921150e-5
TAU_CLK = 100.0               # clock-drift correlation time [s]


def _rodrigues(phi: np.ndarray) -> np.ndarray:
    """Rotation matrices exp([phi x]) for rows of ``phi`` (p, 3) -> (p, 3, 3)."""
    th = np.sqrt(np.einsum("pi,pi->p", phi, phi))
    small = th < 1e-8
    ths = np.where(small, 1.0, th)
    a = np.where(small, 1.0 - th ** 2 / 6.0, np.sin(ths) / ths)
    b = np.where(small, 0.5 - th ** 2 / 24.0, (1.0 - np.cos(ths)) / ths ** 2)
    K = np.zeros((phi.shape[0], 3, 3))
    K[:, 0, 1], K[:, 0, 2] = -phi[:, 2], phi[:, 1]
    K[:, 1, 0], K[:, 1, 2] = phi[:, 2], -phi[:, 0]
    K[:, 2, 0], K[:, 2, 1] = -phi[:, 1], phi[:, 0]
    return np.eye(3) + a[:, None, None] * K + b[:, None, None] * (K @ K)


class InsErrorModel(ProcessModel):
    """Nonlinear 17-state INS/clock error model (paper 004 eq 2-4 style), ENU, RFU body."""

    dim_x = 17

    def __init__(self, lat: float = math.radians(40.0), h: float = 100.0,
                 v_n=(0.0, 20.0, 0.0), f_n=(0.3, 0.5, 9.8), C_b_n=None) -> None:
        self.lat, self.h = lat, h
        self.v_n = np.asarray(v_n, float)
        self.f_n = np.asarray(f_n, float)
        self.C_b_n = np.eye(3) if C_b_n is None else np.asarray(C_b_n, float)
        s = math.sin(lat)
        self.R_M = A_E * (1 - E2) / (1 - E2 * s * s) ** 1.5
        self.R_N = A_E / math.sqrt(1 - E2 * s * s)
        vE, vN = self.v_n[0], self.v_n[1]
        self.w_ie = np.array([0.0, OMEGA_E * math.cos(lat), OMEGA_E * s])
        self.w_en = np.array([-vN / (self.R_M + h), vE / (self.R_N + h),
                              vE * math.tan(lat) / (self.R_N + h)])
        self.w_in = self.w_ie + self.w_en
        self._A = self._linear_part()

    def _linear_part(self) -> np.ndarray:
        """Continuous-time linear terms (everything except the attitude-rotation terms)."""
        A = np.zeros((17, 17))
        RMh, RNh = self.R_M + self.h, self.R_N + self.h
        L = self.lat
        vE, vN = self.v_n[0], self.v_n[1]
        A[0:3, 9:12] = -self.C_b_n                      # gyro bias into attitude
        A[3:6, 12:15] = self.C_b_n                      # accel bias into velocity
        w = 2 * self.w_ie + self.w_en                   # Coriolis on the velocity error
        A[3:6, 3:6] = -np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
        A[6, 4], A[6, 8] = 1 / RMh, -vN / RMh ** 2      # lat error
        A[7, 3] = 1 / (math.cos(L) * RNh)               # lon error
        A[7, 6] = vE * math.tan(L) / (math.cos(L) * RNh)
        A[7, 8] = -vE / (math.cos(L) * RNh ** 2)
        A[8, 5] = 1.0                                   # height error
        A[15, 16] = 1.0                                 # clock bias <- drift
        A[16, 16] = -1.0 / TAU_CLK
        return A

    def _xdot(self, X: np.ndarray) -> np.ndarray:
        C = _rodrigues(X[:, 0:3])                       # C_n^n' (large-angle error)
        xd = X @ self._A.T
        xd[:, 0:3] += self.w_in - C @ self.w_in         # (I - C_n^n') w_in
        xd[:, 3:6] += self.f_n - np.einsum("pji,j->pi", C, self.f_n)   # (I - C^T) f^n
        return xd

    def f_batch(self, X: np.ndarray, dt: float) -> np.ndarray:
        k1 = self._xdot(X)
        return X + 0.5 * dt * (k1 + self._xdot(X + dt * k1))     # improved Euler

    def f(self, x: np.ndarray, dt: float) -> np.ndarray:
        return self.f_batch(x[None, :], dt)[0]

    def F(self, x: np.ndarray, dt: float) -> np.ndarray:
        # Jacobian of one Euler step of the same dynamics, the 3 attitude columns by
        # central differences of the rotation terms (all other terms are linear)
        Ac = self._A.copy()
        e = 1e-6
        for i in range(3):
            d = np.zeros((2, 17))
            d[0, i], d[1, i] = e, -e
            xd = self._xdot(x[None, :] + d) - (x[None, :] + d) @ self._A.T
            Ac[:, i] += (xd[0] - xd[1]) / (2 * e)
        return np.eye(17) + dt * Ac + 0.5 * dt * dt * (Ac @ Ac)


class PseudorangeModel(MeasurementModel):
    """z = [drho_1..N, drho_dot_1..N]: exact range change for the perturbed position."""

    def __init__(self, sat_enu: np.ndarray, proc: InsErrorModel) -> None:
        self.s = np.asarray(sat_enu, float)             # (N, 3) satellite minus receiver [m]
        self.rho = np.linalg.norm(self.s, axis=1)
        RMh, RNh = proc.R_M + proc.h, proc.R_N + proc.h
        # ENU displacement per (dlat, dlon, dh)
        self.D = np.array([[0.0, RNh * math.cos(proc.lat), 0.0], [RMh, 0.0, 0.0],
                           [0.0, 0.0, 1.0]])

    def h_batch(self, X: np.ndarray) -> np.ndarray:
        dr = X[:, 6:9] @ self.D.T                        # (p, 3) ENU position error
        sd = self.s[None, :, :] - dr[:, None, :]         # (p, N, 3)
        rng = np.sqrt(np.einsum("pni,pni->pn", sd, sd))
        # |s - dr| - |s| without cancellation
        drho = (np.einsum("pi,pi->p", dr, dr)[:, None] - 2.0 * dr @ self.s.T) \
            / (rng + self.rho[None, :])
        u = sd / rng[:, :, None]
        rate = -np.einsum("pni,pi->pn", u, X[:, 3:6])
        return np.hstack([drho + X[:, 15:16], rate + X[:, 16:17]])

    def h(self, x: np.ndarray) -> np.ndarray:
        return self.h_batch(x[None, :])[0]

    def H(self, x: np.ndarray) -> np.ndarray:
        N = self.s.shape[0]
        dr = self.D @ x[6:9]
        sd = self.s - dr
        rng = np.linalg.norm(sd, axis=1)
        u = sd / rng[:, None]
        H = np.zeros((2 * N, 17))
        H[:N, 6:9] = -u @ self.D
        H[:N, 15] = 1.0
        H[N:, 3:6] = -u
        dv = x[3:6]
        # d(-u . dv)/d dr = dv^T (I - u u^T) / rho
        g = (dv[None, :] - (u @ dv)[:, None] * u) / rng[:, None]
        H[N:, 6:9] = g @ self.D
        H[N:, 16] = 1.0
        return H


def make_problem(n_channels: int, seed: int):
    """Process/measurement models, noise and initial conditions of the synthetic problem."""
    rng = np.random.default_rng(seed)
    proc = InsErrorModel()
    az = rng.uniform(0.0, 2 * np.pi, n_channels)
    el = rng.uniform(math.radians(15), math.radians(80), n_channels)
    u = np.column_stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)])
    meas = PseudorangeModel(u * 2.2e7, proc)
    sig_p0 = np.r_[[math.radians(0.5)] * 3, [0.2] * 3, [5 / 6.4e6] * 2, [5.0],
                   [math.radians(8 / 3600)] * 3, [4e-3 * 9.8] * 3, [10.0, 1.0]]
    P0 = np.diag(sig_p0 ** 2)
    q = np.r_[[math.radians(0.04) / 60] * 3, [0.05 / 60] * 3, [0.0] * 3,
              [1e-6] * 3, [1e-5] * 3, [0.1, 0.05]]
    Q = np.diag((q ** 2) * DT)
    R = np.r_[[2.0 ** 2] * n_channels, [0.1 ** 2] * n_channels]
    return proc, meas, P0, Q, R, rng


def _simulate(proc, meas, P0, Q, R, rng, n_epochs):
    x = rng.normal(size=17) * np.sqrt(np.diag(P0))
    zs = []
    for _ in range(n_epochs):
        x = proc.f(x, DT) + rng.normal(size=17) * np.sqrt(np.diag(Q))
        zs.append(meas.h(x) + rng.normal(size=R.size) * np.sqrt(R))
    return zs


def _time_filter(name, proc, meas, P0, Q, R, zs, warmup, **options):
    kf = make_filter(name, proc, meas, np.zeros(17), P0, Q, R0=np.diag(R), dt=DT, **options)
    for z in zs[:warmup]:
        kf.predict()
        kf.update(z)
    if kf.rule is not None:
        kf.rule.reset_timer()
    t0 = time.perf_counter()
    for z in zs[warmup:]:
        kf.predict()
        kf.update(z)
    wall = time.perf_counter() - t0
    adapt = kf.rule.adaptation_time_s if kf.rule is not None else float("nan")
    return wall, adapt


def _paired_adaptation(proc, meas, P0, Q, R, zs, warmup, window=None, jit=True,
                       robust=False) -> tuple[float, float]:
    """Adaptation time [s] of ff-aukf and rae-aukf run side by side on the same data.

    The two filters are stepped alternately, epoch by epoch (alternating which goes first),
    so that both see the same machine load -- on a shared machine separate runs differ by
    more than the effect being measured. ``jit`` selects the implementation of both rules.
    ``robust``: return ``epochs x median`` of the per-epoch adaptation times instead of the
    plain totals (a preempted hook adds milliseconds to one epoch of one filter).
    """
    win = {} if window is None else {"window": window}
    # compiled: ff-aukf's kernels, rae-aukf's faster of kernel and BLAS for the size (its
    # default); numpy: both rules as numpy expressions
    jits = {"ff-aukf": jit, "rae-aukf": None if jit else False}
    kfs = [make_filter(name, proc, meas, np.zeros(17), P0, Q, R0=np.diag(R), dt=DT,
                       jit=jits[name], **win)
           for name in ("ff-aukf", "rae-aukf")]
    for z in zs[:warmup]:
        for kf in kfs:
            kf.predict()
            kf.update(z)
    for kf in kfs:
        kf.rule.reset_timer()
    per_epoch = np.zeros((2, len(zs) - warmup))
    for k, z in enumerate(zs[warmup:]):
        for i in ((0, 1) if k % 2 == 0 else (1, 0)):
            kf = kfs[i]
            t0 = kf.rule.adaptation_time_s
            kf.predict()
            kf.update(z)
            per_epoch[i, k] = kf.rule.adaptation_time_s - t0
    if robust:
        # epochs x median epoch: insensitive to the preemptions of a shared machine
        return tuple(float(x) for x in np.median(per_epoch, axis=1) * per_epoch.shape[1])
    return kfs[0].rule.adaptation_time_s, kfs[1].rule.adaptation_time_s


def _warm_hook_times(proc, meas, P0, Q, R, zs, warmup, jit=True, calls=2000
                     ) -> tuple[float, float]:
    """Per-epoch cost [s] of each rule's hooks with warm caches: after ``warmup`` epochs the
    filter state is frozen and ``before_update`` + ``after_update`` are called ``calls`` times
    on it (best of 5 batches). Measures the rules' own work without the cache misses that the
    filter's sigma-point step causes between two hooks."""
    out = []
    jits = {"ff-aukf": jit, "rae-aukf": None if jit else False}
    for name in ("ff-aukf", "rae-aukf"):
        kf = make_filter(name, proc, meas, np.zeros(17), P0, Q, R0=np.diag(R), dt=DT,
                         jit=jits[name])
        for z in zs[:warmup]:
            kf.predict()
            kf.update(z)
        rule, mp, z, Rp = kf.rule, kf.last_prediction, zs[warmup - 1], np.diag(R)
        state = {k: getattr(rule, k).copy() for k in ("_buf", "s", "s_applied")
                 if hasattr(rule, k)}
        best = math.inf
        for _ in range(5):
            t0 = time.perf_counter()
            for _ in range(calls):
                rule.before_update(kf, mp, z, Rp)
                rule.after_update(kf, z, Rp)
            best = min(best, (time.perf_counter() - t0) / calls)
        for k, v in state.items():                   # leave the rule as it was
            setattr(rule, k, v)
        out.append(best)
    return out[0], out[1]


def run(args: argparse.Namespace) -> list[dict]:
    """Run the benchmark, print the table, return the rows (dicts)."""
    names = list(args.filters) if args.filters else list(FILTER_NAMES)
    proc, meas, P0, Q, R, rng = make_problem(int(args.channels), int(args.seed))
    n_ep = int(args.epochs)
    # the Sage window (20 epochs) must be full before timing, or rae-aukf would not adapt
    warmup = max(int(args.warmup), 30)
    zs = _simulate(proc, meas, P0, Q, R, rng, warmup + n_ep)
    m = R.size
    blas = os.environ.get("OPENBLAS_NUM_THREADS", "default")
    print(f"machine: {os.cpu_count()} cores, BLAS threads {blas}; 17 states, {m} measurements "
          f"({args.channels} channels), 10 Hz, {n_ep} timed epochs after {warmup}, "
          f"best of {args.repeat}")
    print(f"{'filter':<15} {'us/epoch':>10} {'adapt us/epoch':>15} {'adapt total s':>14}")
    rows = []
    for name in names:
        best = None
        for _ in range(max(1, int(args.repeat))):
            wall, adapt = _time_filter(name, proc, meas, P0, Q, R, zs, warmup)
            if best is None or wall < best[0]:
                best = (wall, adapt)
        wall, adapt = best
        row = {"filter": name, "us_per_epoch": wall / n_ep * 1e6,
               "adapt_us_per_epoch": adapt / n_ep * 1e6, "adapt_total_s": adapt}
        rows.append(row)
        a = "-" if math.isnan(adapt) else f"{row['adapt_us_per_epoch']:15.1f}"
        t = "-" if math.isnan(adapt) else f"{adapt:14.4f}"
        print(f"{name:<15} {row['us_per_epoch']:10.1f} {a:>15} {t:>14}")
    if "ff-aukf" in names and "rae-aukf" in names:
        print("adaptation time ff-aukf / rae-aukf over the same epochs, the two filters "
              "stepped alternately (paper 004: 0.1851 s / 0.2935 s = 0.63):")
        for jit in (True, False):
            impl = "jit" if jit else "numpy"
            for robust in (False, True):
                pairs = [_paired_adaptation(proc, meas, P0, Q, R, zs, warmup, jit=jit,
                                            robust=robust)
                         for _ in range(max(1, int(args.repeat)))]
                ratios = sorted(p[0] / p[1] for p in pairs)
                ff = min(p[0] for p in pairs)
                rae = min(p[1] for p in pairs)
                ratio = ff / rae
                kind = "epochs x median epoch" if robust else "total"
                print(f"  [{impl:5s}] {kind:21s}: best {ff:.4f} s / {rae:.4f} s = {ratio:.2f};"
                      f" per run {', '.join(f'{x:.2f}' for x in ratios)}")
                rows.append({"filter": f"ratio ff-aukf/rae-aukf {impl} {kind}", "ff_s": ff,
                             "rae_s": rae, "ratio": ratio, "ratios": ratios})
            ff, rae = _warm_hook_times(proc, meas, P0, Q, R, zs, warmup, jit=jit)
            print(f"  [{impl:5s}] hooks alone, warm     : {ff * 1e6:.1f} us / {rae * 1e6:.1f} us"
                  f" per epoch = {ff / rae:.2f}")
            rows.append({"filter": f"ratio ff-aukf/rae-aukf {impl} warm hooks", "ff_s": ff,
                         "rae_s": rae, "ratio": ff / rae})
    if getattr(args, "sweep", False):
        rows.extend(_sweep(args))
    return rows


def _sweep(args) -> list[dict]:
    """ff-aukf / rae-aukf adaptation time for more channels and longer windows."""
    print("adaptation time per epoch vs channels N (2N measurements) and window W "
          "(same W for both rules):")
    print(f"{'N':>3} {'W':>4} {'impl':>6} {'ff-aukf us':>11} {'rae-aukf us':>12} {'ratio':>6}")
    rows = []
    for N, W in ((7, 20), (7, 64), (12, 64), (20, 100)):
        proc, meas, P0, Q, R, rng = make_problem(N, int(args.seed))
        n_ep = 300
        zs = _simulate(proc, meas, P0, Q, R, rng, W + 10 + n_ep)
        for jit in (True, False):
            pairs = [_paired_adaptation(proc, meas, P0, Q, R, zs, W + 10, window=W, jit=jit)
                     for _ in range(max(1, int(args.repeat)))]
            ff = min(p[0] for p in pairs) / n_ep * 1e6
            rae = min(p[1] for p in pairs) / n_ep * 1e6
            impl = "jit" if jit else "numpy"
            print(f"{N:3d} {W:4d} {impl:>6} {ff:11.1f} {rae:12.1f} {ff / rae:6.2f}")
            rows.append({"filter": "sweep", "impl": impl, "channels": N, "window": W,
                         "ff_us": ff, "rae_us": rae, "ratio": ff / rae})
    return rows


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of this benchmark (shared with ``scripts/bench.py filters``)."""
    parser.add_argument("--epochs", type=int, default=400, help="timed epochs (default 400)")
    parser.add_argument("--warmup", type=int, default=50,
                        help="untimed epochs first (default 50, at least 30)")
    parser.add_argument("--channels", type=int, default=7, help="channels N (2N measurements)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--filters", nargs="+", default=None, choices=FILTER_NAMES,
                        help="filters to time (default all)")
    parser.add_argument("--repeat", type=int, default=3, help="runs per filter, best kept")
    parser.add_argument("--no-sweep", dest="sweep", action="store_false",
                        help="skip the channels/window sweep of ff-aukf vs rae-aukf")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    add_arguments(parser)
    run(parser.parse_args(argv))


if __name__ == "__main__":
    main()
