"""Single-epoch B3I position, velocity and time (PVT) by weighted least squares.

Frames and units: ECEF CGCS2000 [m, m/s]; ENU navigation frame for velocity ``v_n`` and the
DOPs; geodetic ``llh`` = (lat [rad], lon [rad], h [m]). Clock bias ``b`` [m] is receiver
clock minus BDT times c (so the fix time in BDT is ``t_rx - b / c``); clock drift [m/s] its
rate.

Position model (per satellite, pseudorange ``P`` from :mod:`~sdr_di.receiver.observables`)::

    P = | R_z(omega_e tau) r_sat(t_tx) - r | + b - c dt_sv(t_tx) + T + I + noise

* ``t_tx`` (BDT) = ``t_sv - dt_sv``: the observed satellite-clock transmit time corrected
  with the broadcast clock polynomial *including the relativistic term* (two passes); no TGD
  (B3I is the clock reference signal). The satellite position is evaluated at ``t_tx`` from
  the decoded ephemeris, so it does not depend on the receiver clock.
* Sagnac: the satellite position is rotated into the ECEF frame of the reception instant by
  ``omega_e tau``, with the *geometric* travel time ``tau = |...| / c`` (iterated), never the
  pseudorange (which contains the possibly milliseconds-large receiver clock error).
* Ionosphere ``I``: BDS Klobuchar from the broadcast coefficients, scaled to B3I
  (:func:`~sdr_di.orbits.atmosphere.iono_delay_b3i_m`), at the BDT receive time
  ``t_rx - b/c``; troposphere ``T``: Saastamoinen (standard atmosphere). Both use the
  elevation clipped below at 0.1 deg exactly as the IF generator does.

Iterations: Gauss-Newton from ``x0`` (default the Earth's centre, zero clock bias). Phase 1
uses all satellites without atmosphere or elevation mask until the update is below 1 km;
phase 2 applies the mask and the corrections (recomputed each iteration) until the update is
below ``tol_m``.

Weights (``weighting="elevation_cn0"``, the default)::

    sigma_i^2 = sigma_0^2 / sin^2(el_i) * 10^((CN0_ref - CN0_i) / 10)

with ``sigma_0`` = ``sigma_pr_m`` (1 m) for pseudoranges and ``sigma_rate_mps`` (0.05 m/s)
for rates, ``CN0_ref`` = 45 dB-Hz (code/frequency discriminator noise variance is inversely
proportional to C/N0; residual atmosphere and multipath grow like 1/sin el). An unknown
C/N0 counts as the reference. ``weighting="equal"`` uses ``sigma_0`` for every satellite.
The reported ``cov`` is the formal covariance (H^T W H)^-1 with these sigmas, and ``cov_v``
the velocity solution's (J^T W J)^-1 (J the Jacobian of the rate model below at the
solution, sigma_0 = ``sigma_rate_mps``). Both are formal: they hold what the weight model
assumes (white, independent errors of the given sigmas), not the tracking loops' actual
noise; the loose coupling takes them as its ``R`` (docs/coupling.md).

Velocity model (pseudorange rate ``D = -lambda * doppler`` per receiver-clock second)::

    D = (rho_dot + d - c ddt_sv + d(T - I)/dt) / (1 + d / c)
    rho_dot = (e . R v_sat - e . v) / (1 + (e . R v_sat - e . omega_e R' r_sat) / c)

with ``d`` the clock drift [m/s], ``e`` the unit line of sight, ``R = R_z(omega_e tau)`` and
``R'`` its derivative with respect to the angle: the Earth-rotation (Sagnac) terms, the
shortening of the transmit interval by the range rate (``dt_tx/dt_rx = 1 - tau_dot``), the
carrier-phase sign of the ionosphere and the time derivative of the atmospheric models
(central difference over +-0.5 s) are all modelled, so generator-consistent Doppler gives
the truth velocity to well below 1 mm/s.

The same models run forwards (a receiver state in, pseudoranges and rates out) are
:func:`modelled_observables`: the tight coupling's predicted observables.

DOPs come from the unweighted geometry matrix in ENU with rows ``[-e_ENU, 1]``:
``Q = (H^T H)^-1``, GDOP = sqrt(tr Q), PDOP = sqrt(Q_EE + Q_NN + Q_UU), HDOP = sqrt(Q_EE +
Q_NN), VDOP = sqrt(Q_UU), TDOP = sqrt(Q_bb).

Sanity checks set :attr:`PvtSolution.status` (never an exception for a bad epoch): fewer than
4 usable satellites (with ephemeris, above the mask) -> ``too_few_satellites``; singular
geometry or GDOP above ``max_gdop`` -> ``bad_geometry``; no convergence -> ``no_convergence``;
with redundancy (n > 4), a pseudorange residual RMS above ``max_residual_rms_m`` ->
``large_residuals`` (the solution is filled in but not valid).
"""

from __future__ import annotations

import dataclasses
import enum
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from ..constants import C_LIGHT, OMEGA_E, SECONDS_PER_WEEK
from ..errors import NoEphemerisError, UnknownPrnError
from ..frames import C_e_n, ecef_to_llh, elevation_azimuth
from ..orbits.atmosphere import (B1I_TO_B3I, KLOBUCHAR_H_M, KLOBUCHAR_R_M, STANDARD_HUMIDITY,
                                 iono_delay_b3i_m, saastamoinen_delay)
from ..orbits.broadcast import sat_pos_vel_clock_stacked, stack_ephemerides
from ..orbits.ephemeris import Ephemeris, Klobuchar
from . import _numba_range_model as _k
from .navdata import NavDataInForce
from .observables import (
    ChannelObservationLike,
    ObservableBuilder,
    Observables,
    ReceiverTime,
)

__all__ = [
    "Dops",
    "PvtConfig",
    "PvtEngine",
    "PvtSolution",
    "PvtStatus",
    "SatelliteStates",
    "atmosphere_delays",
    "compute_dops",
    "measurement_variances",
    "modelled_observables",
    "sagnac_rotation",
    "satellite_states",
    "solve",
    "solve_position",
    "solve_velocity",
]

_EL_FLOOR = math.radians(0.1)
#: Klobuchar's ``R / (R + h)`` and ``c (f_B1I / f_B3I)^2`` [m/s]: the atmosphere kernel's
#: constants
_RATIO_K = KLOBUCHAR_R_M / (KLOBUCHAR_R_M + KLOBUCHAR_H_M)
_IONO_M_PER_S = C_LIGHT * B1I_TO_B3I
_ZERO4 = np.zeros(4)
#: Whether :func:`atmosphere_delays` runs the range model's atmosphere kernel
#: (:func:`._numba_range_model.atmosphere`, one call; the numpy form's values to a few
#: ulp); False: the numpy form :func:`atmosphere_delays_numpy` (the tested reference).
jit = True
_PHASE1_TOL_M = 1.0e3
_ATM_RATE_DT_S = 0.5


class PvtStatus(str, enum.Enum):
    """Outcome of a PVT epoch (``str`` values are what the solution files carry)."""

    FIX = "fix"
    TOO_FEW_SATELLITES = "too_few_satellites"
    BAD_GEOMETRY = "bad_geometry"
    NO_CONVERGENCE = "no_convergence"
    LARGE_RESIDUALS = "large_residuals"
    NOT_COMPUTED = "not_computed"

    def __str__(self) -> str:  # "fix", not "PvtStatus.FIX"
        return self.value


@dataclasses.dataclass(frozen=True)
class Dops:
    """Dilution of precision (dimensionless; time in metres of c*t)."""

    gdop: float
    pdop: float
    hdop: float
    vdop: float
    tdop: float

    @classmethod
    def nan(cls) -> Dops:
        """All NaN (no geometry)."""
        return cls(*(5 * (math.nan,)))


@dataclasses.dataclass(frozen=True)
class PvtConfig:
    """Solver settings (see the module docstring for the models).

    Attributes
    ----------
    elevation_mask_deg : float
        Satellites below are not used [deg].
    ionosphere, troposphere : bool
        Apply the Klobuchar (if coefficients are given) and Saastamoinen corrections.
    weighting : {"elevation_cn0", "equal"}
        Weight model.
    sigma_pr_m, sigma_rate_mps : float
        Zenith, reference-C/N0 sigma of pseudorange [m] and pseudorange rate [m/s].
    cn0_ref_dbhz : float
        Reference C/N0 of the weight model [dB-Hz].
    max_iter : int
        Maximum iterations of the final (masked, corrected) phase.
    tol_m : float
        Convergence threshold on the norm of the state update [m].
    max_residual_rms_m : float
        Residual RMS above which a redundant fix is flagged ``large_residuals`` [m].
    max_rate_residual_rms_mps : float
        Same for the velocity solution [m/s].
    max_gdop : float
        GDOP above which the geometry is rejected.
    """

    elevation_mask_deg: float = 10.0
    ionosphere: bool = True
    troposphere: bool = True
    weighting: str = "elevation_cn0"
    sigma_pr_m: float = 1.0
    sigma_rate_mps: float = 0.05
    cn0_ref_dbhz: float = 45.0
    max_iter: int = 10
    tol_m: float = 1.0e-4
    max_residual_rms_m: float = 30.0
    max_rate_residual_rms_mps: float = 2.0
    max_gdop: float = 30.0

    def __post_init__(self):
        if self.weighting not in ("elevation_cn0", "equal"):
            raise ValueError(f"PvtConfig.weighting must be 'elevation_cn0' or 'equal', "
                             f"got {self.weighting!r}")


def _nan3() -> np.ndarray:
    return np.full(3, np.nan)


@dataclasses.dataclass(frozen=True)
class PvtSolution:
    """One epoch's navigation solution.

    Attributes
    ----------
    status : PvtStatus
        Position status (``FIX`` = valid).
    velocity_status : PvtStatus
        Velocity status (``NOT_COMPUTED`` until :func:`solve_velocity`).
    sample_index : int
        IF sample of the epoch.
    week : int
        BDT week of the fix time.
    sow : float
        BDT seconds of week of the fix: receiver time minus clock bias / c [s] (the receiver
        time itself when there is no fix).
    rx_week : int
        Receiver-clock week.
    rx_sow : float
        Receiver-clock seconds of week of the epoch [s].
    r_e : ndarray (3,)
        Position, ECEF [m] (NaN without a solution).
    llh : ndarray (3,)
        Geodetic latitude [rad], longitude [rad], ellipsoidal height [m].
    v_e : ndarray (3,)
        Velocity, ECEF [m/s] (NaN until solved).
    v_n : ndarray (3,)
        Velocity, ENU [m/s].
    clock_bias_m : float
        Receiver clock bias times c [m].
    clock_drift_mps : float
        Receiver clock drift times c [m/s].
    dops : Dops
        Geometry of the satellites used.
    n_sats : int
        Satellites used in the position solution.
    prns : ndarray of int
        Their PRNs.
    elevation, azimuth : ndarray
        Their elevation and azimuth [rad].
    residuals : ndarray
        Pseudorange residuals (observed - modelled) of the used satellites [m].
    rate_residuals : ndarray
        Pseudorange-rate residuals [m/s] (NaN where not used; empty until solved).
    cov : ndarray (4, 4)
        Formal covariance of (x, y, z, b), ECEF [m^2].
    cov_v : ndarray (4, 4)
        Formal covariance of the velocity solution (v_x, v_y, v_z, d), ECEF [m^2/s^2] (NaN
        until solved).
    iterations : int
        Gauss-Newton iterations (both phases).
    message : str
        Human-readable detail for a non-fix status ("" for a fix).
    """

    status: PvtStatus
    sample_index: int
    week: int
    sow: float
    rx_week: int
    rx_sow: float
    r_e: np.ndarray = dataclasses.field(default_factory=_nan3)
    llh: np.ndarray = dataclasses.field(default_factory=_nan3)
    v_e: np.ndarray = dataclasses.field(default_factory=_nan3)
    v_n: np.ndarray = dataclasses.field(default_factory=_nan3)
    clock_bias_m: float = math.nan
    clock_drift_mps: float = math.nan
    dops: Dops = dataclasses.field(default_factory=Dops.nan)
    n_sats: int = 0
    prns: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0, np.int64))
    elevation: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))
    azimuth: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))
    residuals: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))
    rate_residuals: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))
    cov: np.ndarray = dataclasses.field(default_factory=lambda: np.full((4, 4), np.nan))
    cov_v: np.ndarray = dataclasses.field(default_factory=lambda: np.full((4, 4), np.nan))
    velocity_status: PvtStatus = PvtStatus.NOT_COMPUTED
    iterations: int = 0
    message: str = ""

    @property
    def valid(self) -> bool:
        """True for a valid position fix."""
        return self.status is PvtStatus.FIX

    @property
    def velocity_valid(self) -> bool:
        """True for a valid velocity solution."""
        return self.velocity_status is PvtStatus.FIX

    @property
    def t_bdt(self) -> float:
        """Fix time as BDT seconds since the BDT epoch [s]."""
        return self.week * SECONDS_PER_WEEK + self.sow


# --- satellite states -----------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class SatelliteStates:
    """Satellite states at transmit time for the satellites of an :class:`Observables`.

    Attributes
    ----------
    ok : ndarray of bool (n,)
        A healthy ephemeris was available.
    r_e, v_e : ndarray (n, 3)
        Position [m] and velocity [m/s], ECEF of the *transmit* instant (no Sagnac yet).
    dt_sv, ddt_sv : ndarray (n,)
        Satellite clock offset [s] (with relativity) and drift [s/s] at transmit time.
    missing : tuple of int
        PRNs without a usable ephemeris.
    """

    ok: np.ndarray
    r_e: np.ndarray
    v_e: np.ndarray
    dt_sv: np.ndarray
    ddt_sv: np.ndarray
    missing: tuple[int, ...]


def lookup_ephemeris(ephemerides: Any, prn: int, week: int, sow: float) -> Ephemeris | None:
    """The healthy, finite record of ``prn`` in force at BDT (``week``, ``sow``) [s] from a
    ``{prn: Ephemeris}`` mapping or an object with ``select`` (e.g.
    :class:`~sdr_di.receiver.navdata.NavDataInForce`); None when there is none."""
    if hasattr(ephemerides, "select"):
        try:
            return ephemerides.select(prn, week, sow)
        except (NoEphemerisError, UnknownPrnError):
            return None
    eph = ephemerides.get(prn)
    if eph is None or not eph.healthy or not eph.finite():
        return None
    return eph


def satellite_states(obs: Observables, ephemerides: Mapping[int, Ephemeris] | Any
                     ) -> SatelliteStates:
    """Satellite positions, velocities and clocks at the true transmit time.

    The observed satellite-clock time ``t_sv`` is converted to BDT with
    ``t = t_sv - dt_sv(t)`` (two passes; the second changes ``t`` by ~1e-13 s).

    Parameters
    ----------
    obs : Observables
        The epoch's observables.
    ephemerides : mapping PRN -> Ephemeris, or an object with ``select(prn, week, sow)``
        (e.g. :class:`~sdr_di.orbits.rinex_nav.NavData`). Missing or unhealthy records make
        the satellite unusable (listed in ``missing``).
    """
    n = obs.n
    r = np.full((n, 3), np.nan)
    v = np.full((n, 3), np.nan)
    dt = np.full(n, np.nan)
    ddt = np.full(n, np.nan)
    ok = np.zeros(n, bool)
    missing = []
    by_week: dict[int, list[tuple[int, Ephemeris]]] = {}
    for i in range(n):
        prn, wk, t_sv = int(obs.prn[i]), int(obs.t_tx_week[i]), float(obs.t_tx_sow[i])
        eph = lookup_ephemeris(ephemerides, prn, wk, t_sv)
        if eph is None:
            missing.append(prn)
            continue
        by_week.setdefault(wk, []).append((i, eph))
    # every satellite of a week in one stacked evaluation per pass: each row is the value
    # the record gives alone (sat_pos_vel_clock_stacked), bit for bit
    for wk, sats in by_week.items():
        idx = [i for i, _ in sats]
        stack = stack_ephemerides([eph for _, eph in sats])
        t_sv = obs.t_tx_sow[idx].astype(float)[:, None]
        _, _, d0, _ = sat_pos_vel_clock_stacked(stack, t_sv, week=wk)
        _, _, d1, _ = sat_pos_vel_clock_stacked(stack, t_sv - d0, week=wk)
        ri, vi, di, ddi = sat_pos_vel_clock_stacked(stack, t_sv - d1, week=wk)
        r[idx], v[idx], dt[idx], ddt[idx] = ri[:, 0], vi[:, 0], di[:, 0], ddi[:, 0]
        ok[idx] = True
    return SatelliteStates(ok, r, v, dt, ddt, tuple(missing))


def _rot_z(vec: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Rows of ``vec`` (n, 3) times R_z(theta) = [[c, s, 0], [-s, c, 0], [0, 0, 1]]."""
    c, s = np.cos(theta), np.sin(theta)
    out = np.empty(vec.shape)       # filled in place: np.stack costs as much as the rotation
    x, y = vec[:, 0], vec[:, 1]
    out[:, 0], out[:, 1], out[:, 2] = c * x + s * y, -s * x + c * y, vec[:, 2]
    return out


def _drot_z(vec: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Rows of ``vec`` times dR_z/dtheta = [[-s, c, 0], [-c, -s, 0], [0, 0, 0]]."""
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([-s * vec[:, 0] + c * vec[:, 1], -c * vec[:, 0] - s * vec[:, 1],
                     np.zeros_like(c)], axis=-1)


def _norms(d: np.ndarray) -> np.ndarray:
    """``np.linalg.norm(d, axis=-1)`` of real rows, bit for bit (its own reduction),
    without its argument handling (the deep loop predicts ranges every interval)."""
    return np.sqrt(np.add.reduce(d * d, axis=-1))


def sagnac_rotation(r_sat: np.ndarray, r_rx: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rotated satellite positions, geometric ranges and rotation angles (travel time iterated).

    ``r_sat`` (n, 3) ECEF of the transmit instant, ``r_rx`` (3,) or (n, 3) [m]; returns the
    positions in the ECEF frame of the reception instant (n, 3), the ranges (n,) [m] and the
    Earth-rotation angles (n,) [rad]. Also used forwards by the vector loop's NCO model.
    """
    rho = _norms(r_sat - r_rx)
    for _ in range(3):
        theta = OMEGA_E * rho / C_LIGHT
        r_rot = _rot_z(r_sat, theta)
        rho = _norms(r_rot - r_rx)
    theta = OMEGA_E * rho / C_LIGHT
    r_rot = _rot_z(r_sat, theta)
    return r_rot, _norms(r_rot - r_rx), theta


def atmosphere_delays(r_rx: np.ndarray, r_sat_rot: np.ndarray, t_sow: float,
                iono: Klobuchar | None, cfg: PvtConfig) -> tuple[np.ndarray, np.ndarray,
                                                                 np.ndarray, np.ndarray]:
    """Elevation, azimuth [rad], tropospheric and B3I ionospheric delays [m].

    One receiver position ``r_rx`` (3,) [m], satellites ``r_sat_rot`` (n, 3), BDT ``t_sow``.
    By the kernel unless ``jit`` is off (:func:`atmosphere_delays_numpy`).
    """
    if not jit:
        return atmosphere_delays_numpy(r_rx, r_sat_rot, t_sow, iono, cfg)
    r_sat_rot = np.asarray(r_sat_rot, float).reshape(-1, 3)
    n = r_sat_rot.shape[0]
    el, az, trop, ion = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    _k.atmosphere(r_sat_rot, np.asarray(r_rx, float).reshape(3), float(t_sow),
                  *atmosphere_kernel_args(iono, cfg), el, az, trop, ion)
    return el, az, trop, ion


def atmosphere_kernel_args(iono: Klobuchar | None, cfg: PvtConfig) -> tuple:
    """The atmosphere kernel's arguments after the receive time
    (:func:`._numba_range_model.atmosphere`, also :func:`~._numba_range_model.
    predict_instant`'s): the ionosphere switch and Klobuchar ``alpha``, ``beta``, the
    troposphere switch and humidity, the elevation floor and the Klobuchar constants."""
    ion_on = bool(cfg.ionosphere and iono is not None)
    alpha, beta = (np.asarray(iono.alpha, float), np.asarray(iono.beta, float)) if ion_on \
        else (_ZERO4, _ZERO4)
    return (ion_on, alpha, beta, bool(cfg.troposphere), STANDARD_HUMIDITY, _EL_FLOOR,
            _RATIO_K, _IONO_M_PER_S)


def atmosphere_delays_numpy(r_rx: np.ndarray, r_sat_rot: np.ndarray, t_sow: float,
                            iono: Klobuchar | None, cfg: PvtConfig
                            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`atmosphere_delays` in numpy (the reference of the kernel)."""
    llh = ecef_to_llh(r_rx)
    el, az = elevation_azimuth(r_rx, r_sat_rot, llh=llh)
    el_pos = np.maximum(el, _EL_FLOOR)
    if cfg.troposphere:
        tropo = saastamoinen_delay(llh[0], llh[2], el_pos)
    else:
        tropo = np.zeros_like(el)
    if cfg.ionosphere and iono is not None:
        ion = iono_delay_b3i_m(iono, llh[0], llh[1], el_pos, az, t_sow)
    else:
        ion = np.zeros_like(el)
    # (both have el's shape already for one receiver: the broadcast view only when not)
    return el, az, *(a if a.shape == el.shape else np.broadcast_to(a, el.shape)
                     for a in (tropo, ion))


def _atmosphere_rate(r_rx: np.ndarray, v_rx: np.ndarray, r_sat_rot: np.ndarray,
                     v_sat_rot: np.ndarray, t_sow: float, iono: Klobuchar | None,
                     cfg: PvtConfig) -> np.ndarray:
    """``d(T - I)/dt`` [m/s] of each satellite: central difference (+-0.5 s) of the models
    along the satellite and receiver motion (the carrier sign of the ionosphere)."""
    h = _ATM_RATE_DT_S
    _, _, tp, ip = atmosphere_delays(r_rx + v_rx * h, r_sat_rot + v_sat_rot * h, t_sow + h,
                                     iono, cfg)
    _, _, tm, im = atmosphere_delays(r_rx - v_rx * h, r_sat_rot - v_sat_rot * h, t_sow - h,
                                     iono, cfg)
    return ((tp - ip) - (tm - im)) / (2.0 * h)


def _sigma2(sigma0: float, el: np.ndarray | None, cn0: np.ndarray, cfg: PvtConfig) -> np.ndarray:
    """Measurement variances of the weight model (see the module docstring)."""
    s2 = np.full(cn0.shape, sigma0 * sigma0)
    if cfg.weighting == "equal":
        return s2
    if el is not None:
        s2 = s2 / np.maximum(np.sin(el), np.sin(_EL_FLOOR)) ** 2
    c = np.where(np.isfinite(cn0), cn0, cfg.cn0_ref_dbhz)
    return s2 * 10.0 ** ((cfg.cn0_ref_dbhz - c) / 10.0)


def measurement_variances(el: np.ndarray, cn0_dbhz: np.ndarray,
                          config: PvtConfig | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Pseudorange [m^2] and pseudorange-rate [(m/s)^2] variances of the weight model
    (module notes) at elevations ``el`` [rad] and C/N0 ``cn0_dbhz`` (NaN: the reference)."""
    cfg = config or PvtConfig()
    el = np.asarray(el, float)
    cn0 = np.asarray(cn0_dbhz, float)
    return (_sigma2(cfg.sigma_pr_m, el, cn0, cfg), _sigma2(cfg.sigma_rate_mps, el, cn0, cfg))


def compute_dops(r_rx: np.ndarray, r_sat_rot: np.ndarray) -> tuple[Dops, np.ndarray | None]:
    """DOPs of a geometry (see the module docstring).

    Parameters
    ----------
    r_rx : ndarray (3,)
        Receiver ECEF position [m].
    r_sat_rot : ndarray (n, 3)
        Satellite ECEF positions in the receive-time frame [m].

    Returns
    -------
    Dops, and the ENU cofactor matrix Q (4, 4) (``Dops.nan()`` and None when singular).
    """
    los = r_sat_rot - r_rx
    e = los / np.linalg.norm(los, axis=-1)[:, None]
    llh = ecef_to_llh(r_rx)
    e_enu = e @ C_e_n(llh[0], llh[1]).T
    H = np.hstack([-e_enu, np.ones((e.shape[0], 1))])
    if H.shape[0] < 4:
        return Dops.nan(), None
    N = H.T @ H
    if np.linalg.cond(N) > 1e12:
        return Dops.nan(), None
    Q = np.linalg.inv(N)
    d = np.diag(Q)
    return Dops(gdop=float(math.sqrt(d.sum())), pdop=float(math.sqrt(d[:3].sum())),
                hdop=float(math.sqrt(d[:2].sum())), vdop=float(math.sqrt(d[2])),
                tdop=float(math.sqrt(d[3]))), Q


def _parse_x0(x0: Any) -> tuple[np.ndarray, float]:
    if x0 is None:
        return np.zeros(3), 0.0
    if isinstance(x0, PvtSolution):
        if np.all(np.isfinite(x0.r_e)):
            cb = x0.clock_bias_m if math.isfinite(x0.clock_bias_m) else 0.0
            return np.array(x0.r_e, float), float(cb)
        return np.zeros(3), 0.0
    a = np.asarray(x0, float).ravel()
    if a.size not in (3, 4) or not np.all(np.isfinite(a)):
        raise ValueError(f"x0 must be a finite ECEF position (3,) or (x, y, z, b) (4,), "
                         f"got {x0!r}")
    return a[:3].copy(), float(a[3]) if a.size == 4 else 0.0


def _time_fix(week: int, sow: float, clock_bias_m: float) -> tuple[int, float]:
    t = float(sow) - float(clock_bias_m) / C_LIGHT if math.isfinite(clock_bias_m) else float(sow)
    if not math.isfinite(t):
        return int(week), t
    n = math.floor(t / SECONDS_PER_WEEK)
    return int(week) + n, t - n * SECONDS_PER_WEEK


def _no_fix(obs: Observables, status: PvtStatus, message: str, **kw) -> PvtSolution:
    return PvtSolution(status=status, sample_index=obs.sample_index, week=obs.week, sow=obs.sow,
                       rx_week=obs.week, rx_sow=obs.sow, message=message, **kw)


# --- position -------------------------------------------------------------------------------
def solve_position(obs: Observables, ephemerides: Mapping[int, Ephemeris] | Any,
                   iono: Klobuchar | None, x0: Any = None, config: PvtConfig | None = None,
                   *, sat: SatelliteStates | None = None) -> PvtSolution:
    """Weighted least-squares position and clock bias of one epoch.

    Parameters
    ----------
    obs : Observables
        Pseudoranges at a common receive time.
    ephemerides : mapping PRN -> Ephemeris, or object with ``select(prn, week, sow)``
        Decoded broadcast records.
    iono : Klobuchar or None
        Broadcast Klobuchar coefficients (the B1I model, scaled here to B3I); None: no
        ionospheric correction.
    x0 : None, PvtSolution, or array_like (3,) / (4,)
        Initial ECEF position [m] (and clock bias [m]); default the Earth's centre.
    config : PvtConfig, optional
        Solver settings.
    sat : SatelliteStates, optional
        Precomputed :func:`satellite_states` of ``obs``.

    Returns
    -------
    PvtSolution
        Velocity fields NaN (``velocity_status = NOT_COMPUTED``). A bad epoch returns a
        solution with a non-``FIX`` status and a message, never raises.
    """
    cfg = config or PvtConfig()
    if obs.n == 0:
        why = "no satellite with a pseudorange"
        if obs.unknown_week:
            why += ("; transmit week unknown for "
                    + ", ".join(f"C{p:02d}" for p in obs.unknown_week))
        return _no_fix(obs, PvtStatus.TOO_FEW_SATELLITES, why)
    sat = satellite_states(obs, ephemerides) if sat is None else sat
    avail = sat.ok & np.isfinite(obs.pseudorange_m)
    if avail.sum() < 4:
        why = f"{int(avail.sum())} satellites with pseudorange and ephemeris (need 4)"
        if sat.missing:
            why += f"; no ephemeris for {', '.join(f'C{p:02d}' for p in sat.missing)}"
        return _no_fix(obs, PvtStatus.TOO_FEW_SATELLITES, why)

    idx_all = np.flatnonzero(avail)
    P = obs.pseudorange_m
    cdt = C_LIGHT * sat.dt_sv
    r, cb = _parse_x0(x0)
    mask_rad = math.radians(cfg.elevation_mask_deg)
    iters = 0
    phase = 1
    k2 = 0
    converged = False
    used = idx_all
    el = az = None
    while True:
        if phase == 1:
            used = idx_all
            r_rot, rho, _ = sagnac_rotation(sat.r_e[used], r)
            corr = np.zeros(used.size)
            el_u = None
        else:
            r_rot_all, _, _ = sagnac_rotation(sat.r_e[idx_all], r)
            el, az, tr, io = atmosphere_delays(r, r_rot_all, obs.sow - cb / C_LIGHT, iono, cfg)
            keep = el >= mask_rad
            if keep.sum() < 4:
                low = [f"C{int(obs.prn[i]):02d}" for i in idx_all[~keep]]
                return _no_fix(obs, PvtStatus.TOO_FEW_SATELLITES,
                               f"{int(keep.sum())} satellites above the "
                               f"{cfg.elevation_mask_deg:g} deg mask (need 4; below: "
                               f"{', '.join(low)})", iterations=iters)
            used = idx_all[keep]
            r_rot = r_rot_all[keep]
            rho = np.linalg.norm(r_rot - r, axis=-1)
            corr = tr[keep] + io[keep]
            el_u = el[keep]
        e = (r_rot - r) / rho[:, None]
        pred = rho + cb - cdt[used] + corr
        y = P[used] - pred
        H = np.hstack([-e, np.ones((used.size, 1))])
        w = 1.0 / _sigma2(cfg.sigma_pr_m, el_u, obs.cn0_dbhz[used], cfg)
        N = H.T @ (H * w[:, None])
        if not np.all(np.isfinite(N)) or np.linalg.cond(N) > 1e14:
            return _no_fix(obs, PvtStatus.BAD_GEOMETRY, "singular geometry", iterations=iters)
        dx = np.linalg.solve(N, H.T @ (w * y))
        r = r + dx[:3]
        cb = cb + dx[3]
        iters += 1
        step = float(np.linalg.norm(dx))
        if not math.isfinite(step):
            return _no_fix(obs, PvtStatus.NO_CONVERGENCE, "non-finite update", iterations=iters)
        if phase == 1:
            if step < _PHASE1_TOL_M:
                phase = 2
            elif iters >= 20:
                return _no_fix(obs, PvtStatus.NO_CONVERGENCE,
                               f"no convergence from the initial position (last step "
                               f"{step:.3g} m)", iterations=iters)
            continue
        k2 += 1
        if step < cfg.tol_m:
            converged = True
            break
        if k2 >= cfg.max_iter:
            break

    # final residuals and geometry at the solution
    r_rot_all, _, _ = sagnac_rotation(sat.r_e[idx_all], r)
    el, az, tr, io = atmosphere_delays(r, r_rot_all, obs.sow - cb / C_LIGHT, iono, cfg)
    keep = np.isin(idx_all, used)
    r_rot = r_rot_all[keep]
    rho = np.linalg.norm(r_rot - r, axis=-1)
    res = P[used] - (rho + cb - cdt[used] + tr[keep] + io[keep])
    e = (r_rot - r) / rho[:, None]
    H = np.hstack([-e, np.ones((used.size, 1))])
    w = 1.0 / _sigma2(cfg.sigma_pr_m, el[keep], obs.cn0_dbhz[used], cfg)
    cov = np.linalg.inv(H.T @ (H * w[:, None]))
    dops, _ = compute_dops(r, r_rot)
    week, sow = _time_fix(obs.week, obs.sow, cb)
    llh = ecef_to_llh(r)
    status, msg = PvtStatus.FIX, ""
    rms = float(np.sqrt(np.mean(res * res)))
    if not converged:
        status, msg = PvtStatus.NO_CONVERGENCE, f"no convergence in {cfg.max_iter} iterations"
    elif not math.isfinite(dops.gdop) or dops.gdop > cfg.max_gdop:
        status, msg = PvtStatus.BAD_GEOMETRY, f"GDOP {dops.gdop:.3g} > {cfg.max_gdop:g}"
    elif used.size > 4 and rms > cfg.max_residual_rms_m:
        status, msg = (PvtStatus.LARGE_RESIDUALS,
                       f"pseudorange residual RMS {rms:.3g} m > {cfg.max_residual_rms_m:g} m")
    return PvtSolution(
        status=status, sample_index=obs.sample_index, week=week, sow=sow, rx_week=obs.week,
        rx_sow=obs.sow, r_e=r, llh=llh, clock_bias_m=float(cb), dops=dops,
        n_sats=int(used.size), prns=obs.prn[used].copy(), elevation=el[keep], azimuth=az[keep],
        residuals=res, cov=cov, iterations=iters, message=msg)


# --- velocity -------------------------------------------------------------------------------
def solve_velocity(obs: Observables, ephemerides: Mapping[int, Ephemeris] | Any,
                   solution: PvtSolution, iono: Klobuchar | None = None,
                   config: PvtConfig | None = None, *, sat: SatelliteStates | None = None
                   ) -> PvtSolution:
    """Weighted least-squares velocity and clock drift from pseudorange rates.

    Uses the satellites of the position ``solution`` that have a finite pseudorange rate.

    Parameters
    ----------
    obs : Observables
        The same epoch's observables (pseudorange rates [m/s]).
    ephemerides : mapping PRN -> Ephemeris, or object with ``select``
        As :func:`solve_position`.
    solution : PvtSolution
        Position solution of the epoch (must have a finite position).
    iono : Klobuchar or None
        For the rate of the ionospheric delay (carrier sign: -dI/dt).
    config : PvtConfig, optional
        Solver settings (weights, troposphere/ionosphere switches, residual threshold).
    sat : SatelliteStates, optional
        Precomputed :func:`satellite_states` of ``obs``.

    Returns
    -------
    PvtSolution
        ``solution`` with ``v_e``, ``v_n``, ``clock_drift_mps``, ``rate_residuals`` and
        ``velocity_status`` filled in.
    """
    cfg = config or PvtConfig()
    if not np.all(np.isfinite(solution.r_e)):
        return dataclasses.replace(solution, velocity_status=PvtStatus.TOO_FEW_SATELLITES)
    sat = satellite_states(obs, ephemerides) if sat is None else sat
    pos = {int(p): i for i, p in enumerate(obs.prn)}
    # satellites of the position fix, in its order (-1: not in these observables)
    idx_used = np.array([pos.get(int(p), -1) for p in solution.prns], np.int64)
    rate_res = np.full(idx_used.size, np.nan)
    safe = np.maximum(idx_used, 0)
    good = ((idx_used >= 0) & sat.ok[safe] & np.isfinite(obs.pseudorange_rate_mps[safe])
            if obs.n else np.zeros(idx_used.size, bool))
    idx = idx_used[good]
    if idx.size < 4:
        return dataclasses.replace(solution, velocity_status=PvtStatus.TOO_FEW_SATELLITES,
                                   rate_residuals=rate_res)
    r = solution.r_e
    cb = solution.clock_bias_m
    t_rx = obs.sow - cb / C_LIGHT
    D = obs.pseudorange_rate_mps[idx]
    r_rot, rho, theta = sagnac_rotation(sat.r_e[idx], r)
    v_rot = _rot_z(sat.v_e[idx], theta)
    g_rot = OMEGA_E * _drot_z(sat.r_e[idx], theta)
    e = (r_rot - r) / rho[:, None]
    A = np.einsum("ij,ij->i", e, v_rot)
    G = np.einsum("ij,ij->i", e, g_rot)
    kfac = 1.0 + (A - G) / C_LIGHT
    c_ddt = C_LIGHT * sat.ddt_sv[idx]
    el, _ = elevation_azimuth(r, r_rot)
    w = 1.0 / _sigma2(cfg.sigma_rate_mps, el, obs.cn0_dbhz[idx], cfg)
    v = np.zeros(3)
    cd = 0.0
    for _ in range(4):
        atm_rate = _atmosphere_rate(r, v, r_rot, v_rot, t_rx, iono, cfg)
        num = (A - e @ v) / kfac + cd - c_ddt + atm_rate
        scale = 1.0 + cd / C_LIGHT
        f = num / scale
        J = np.hstack([-e / (kfac * scale)[:, None],
                       (1.0 / scale - num / (C_LIGHT * scale * scale))[:, None]])
        y = D - f
        N = J.T @ (J * w[:, None])
        dx = np.linalg.solve(N, J.T @ (w * y))
        v = v + dx[:3]
        cd = cd + dx[3]
        if np.linalg.norm(dx) < 1e-7:
            break
    num = (A - e @ v) / kfac + cd - c_ddt + atm_rate
    scale = 1.0 + cd / C_LIGHT
    res = D - num / scale
    rate_res[good] = res
    J = np.hstack([-e / (kfac * scale)[:, None],
                   (1.0 / scale - num / (C_LIGHT * scale * scale))[:, None]])
    cov_v = np.linalg.inv(J.T @ (J * w[:, None]))
    llh = solution.llh
    v_n = C_e_n(llh[0], llh[1]) @ v
    vstat = PvtStatus.FIX
    if idx.size > 4 and float(np.sqrt(np.mean(res * res))) > cfg.max_rate_residual_rms_mps:
        vstat = PvtStatus.LARGE_RESIDUALS
    return dataclasses.replace(solution, v_e=v, v_n=v_n, clock_drift_mps=float(cd),
                               rate_residuals=rate_res, cov_v=cov_v, velocity_status=vstat)


def modelled_observables(sat: SatelliteStates, idx: np.ndarray, r_rx: np.ndarray,
                         v_rx: np.ndarray, clock_bias_m: float, clock_drift_mps: float,
                         t_sow: float, iono: Klobuchar | None,
                         config: PvtConfig | None = None):
    """Pseudoranges and rates the PVT's models give for a receiver state (module notes).

    The position and velocity models of :func:`solve_position` / :func:`solve_velocity` run
    forwards: satellite states at the observed transmit times, Sagnac rotation with the
    geometric travel time, satellite clock and its drift, Saastamoinen and B3I Klobuchar
    delays and their rates. At a WLS solution's state they reproduce the measured
    observables up to the solution's residuals.

    Parameters
    ----------
    sat : SatelliteStates
        :func:`satellite_states` of the epoch's observables.
    idx : (n,) int array
        The satellites (indices into ``sat``) to model.
    r_rx, v_rx : (3,) arrays
        Receiver ECEF position [m] and velocity [m/s] at the reception instant.
    clock_bias_m, clock_drift_mps : float
        Receiver clock bias [m] and drift [m/s] (receiver clock minus BDT, times c).
    t_sow : float
        BDT of the reception instant (receiver time minus clock bias / c) [s of week].
    iono : Klobuchar or None
        Ionosphere coefficients in force.
    config : PvtConfig, optional
        Model switches (ionosphere, troposphere).

    Returns
    -------
    P : (n,) pseudoranges [m];  D : (n,) pseudorange rates [m/s per receiver-clock second];
    U : (n, 3) unit line-of-sight vectors receiver -> satellite, ECEF;  el : (n,) elevations
    [rad].
    """
    cfg = config or PvtConfig()
    idx = np.asarray(idx, np.int64)
    r = np.asarray(r_rx, float)
    v = np.asarray(v_rx, float)
    cb, cd = float(clock_bias_m), float(clock_drift_mps)
    r_rot, rho, theta = sagnac_rotation(sat.r_e[idx], r)
    el, _, tr, io = atmosphere_delays(r, r_rot, t_sow, iono, cfg)
    P = rho + cb - C_LIGHT * sat.dt_sv[idx] + tr + io
    v_rot = _rot_z(sat.v_e[idx], theta)
    g_rot = OMEGA_E * _drot_z(sat.r_e[idx], theta)
    U = (r_rot - r) / rho[:, None]
    A = np.einsum("ij,ij->i", U, v_rot)
    G = np.einsum("ij,ij->i", U, g_rot)
    kfac = 1.0 + (A - G) / C_LIGHT
    num = ((A - U @ v) / kfac + cd - C_LIGHT * sat.ddt_sv[idx]
           + _atmosphere_rate(r, v, r_rot, v_rot, t_sow, iono, cfg))
    return P, num / (1.0 + cd / C_LIGHT), U, el


def solve(obs: Observables, ephemerides: Mapping[int, Ephemeris] | Any,
          iono: Klobuchar | None, x0: Any = None, config: PvtConfig | None = None,
          *, sat: SatelliteStates | None = None) -> PvtSolution:
    """Position, then velocity (when the position has a finite solution) of one epoch.

    Parameters as :func:`solve_position` (``sat``: the satellite states of ``obs`` with
    ``ephemerides``, computed here when None); returns the complete :class:`PvtSolution`.
    """
    if obs.n == 0:
        return solve_position(obs, ephemerides, iono, x0, config)
    if sat is None:
        sat = satellite_states(obs, ephemerides)
    sol = solve_position(obs, ephemerides, iono, x0, config, sat=sat)
    if np.all(np.isfinite(sol.r_e)):
        sol = solve_velocity(obs, ephemerides, sol, iono, config, sat=sat)
    return sol


class PvtEngine:
    """Epoch-by-epoch PVT from channel observations (keeps receiver time and last fix).

    Parameters
    ----------
    fs : float
        IF sampling rate [Hz].
    ephemerides : mapping PRN -> Ephemeris, or object with ``select``
        Decoded records (may be replaced as new ones are decoded: :attr:`ephemerides`).
    iono : Klobuchar or None
        Broadcast ionosphere coefficients.
    config : PvtConfig, optional
        Solver settings.
    rx_time : ReceiverTime, optional
        Preset receiver clock (default: first-fix initialization, with the (week, toe) of a
        record of a mapping ``ephemerides`` as time hint for unknown transmit weeks).

    Attributes
    ----------
    navdata : NavDataInForce
        The navigation data in force (:mod:`~sdr_di.receiver.navdata`): a receiver offers
        it what it decodes and sets ``ephemerides = navdata``, ``iono =
        navdata.klobuchar``, so every mode applies the same rules.
    """

    def __init__(self, fs: float, ephemerides: Mapping[int, Ephemeris] | Any,
                 iono: Klobuchar | None, config: PvtConfig | None = None,
                 rx_time: ReceiverTime | None = None):
        hint = None
        if rx_time is None and isinstance(ephemerides, Mapping) and ephemerides:
            e = next(iter(ephemerides.values()))
            hint = (e.week, e.toe)
        self.builder = ObservableBuilder(fs, rx_time, time_hint=hint)
        self.ephemerides = ephemerides
        self.iono = iono
        self.navdata = NavDataInForce(None)
        self.config = config or PvtConfig()
        self.last_fix: PvtSolution | None = None
        #: Observables of the last :meth:`process` call (None before the first).
        self.last_observables: Observables | None = None
        #: Their satellite states (None before the first call, or without observables).
        self.last_satellites: SatelliteStates | None = None

    def process(self, channels: list[ChannelObservationLike],
                sample_index: int | None = None) -> PvtSolution:
        """Observables and PVT of one epoch; the last valid fix seeds the next one.

        ``sample_index`` (the epoch's sample) lets an epoch without any channel (total
        blockage) still give a row: status ``too_few_satellites`` at the receiver time.
        """
        obs = self.builder(channels, sample_index)
        self.last_observables = obs
        self.last_satellites = satellite_states(obs, self.ephemerides) if obs.n else None
        sol = solve(obs, self.ephemerides, self.iono, self.last_fix, self.config,
                    sat=self.last_satellites)
        if sol.valid:
            self.last_fix = sol
        return sol
