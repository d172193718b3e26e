"""IMU and truth files: CSV with a commented, self-describing header.

Both files are UTF-8 text: header lines starting with ``#`` (``# key: value``), then one line
of comma-separated column names, then one line per sample, values written with 17
significant digits (exact float64 round trip). Time ``t`` is seconds since the scenario start;
the header gives the BDT week and seconds of week of ``t = 0`` and the nominal rate.
Files are written to ``<name>.part`` and renamed when complete
(:func:`sdr_di.io.atomic.atomic_open`), so a file with its final name is always complete.

IMU file (``write_imu`` / ``read_imu``)::

    # sdr-di imu v1
    # bdt_week_t0: 2111
    # bdt_sow_t0: 388800
    # rate_hz: 200
    # sample: average over (t[k-1], t[k]] (integrated increments / dt)
    # frame: body Right-Front-Up; gyro = angular rate w.r.t. inertial space
    # true_accel_bias_mps2: bx by bz        (simulation record only; optional)
    # true_gyro_bias_rads: ...  true_accel_scale: ...  true_gyro_scale: ...
    # columns: t [s], gyro_x/y/z [rad/s], accel_x/y/z [m/s^2]
    t,gyro_x,gyro_y,gyro_z,accel_x,accel_y,accel_z

Truth file (``write_truth`` / ``read_truth``) columns:
``t`` [s]; ``lat, lon`` [deg]; ``h`` [m]; ``v_e, v_n, v_u`` [m/s] (ENU); ``pitch, roll,
yaw`` [deg]; ``f_x, f_y, f_z`` [m/s^2] and ``w_x, w_y, w_z`` [rad/s] (body, interval
averages as in the IMU file); ``x_e, y_e, z_e`` [m], ``vx_e, vy_e, vz_e`` [m/s],
``ax_e, ay_e, az_e`` [m/s^2] (ECEF, instantaneous, for Hermite interpolation); then, in
files written since the truth oscillator (issue 14), ``clock_bias_s`` [s] and
``clock_drift_s_s`` [s/s]: the true receiver clock (receiver time - true time, and its rate
averaged over ``(t[k-1], t[k]]``). Readers accept both column sets (without the clock
columns ``Truth.clock_bias_s`` is None).

Time scale: ``t`` in both files is *true* time (BDT) since the scenario start, BDT =
``(bdt_week_t0, bdt_sow_t0) + t``; the IF file's sample 0 is at *receiver* time
``(week, sow)`` of the start, so IF time ``s`` and ``t`` differ by the clock bias:
``s = t + clock_bias_s(t)``.

Readers check the header, the column names and count on every line, NaN/inf, strictly
increasing time, and the sample spacing (each ``dt`` within half a nominal interval of
``1 / rate_hz``), and raise :class:`sdr_di.errors.ImuDataError` naming the file, the line and
the problem.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..errors import ImuDataError
from ..frames import euler_to_C_b_n
from ..ins.imu import ImuData
from ..ins.truth import Truth
from .atomic import OutputSet, atomic_open
from ..paths import note_input

IMU_COLUMNS = ("t", "gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z")
TRUTH_COLUMNS = (
    "t", "lat", "lon", "h", "v_e", "v_n", "v_u", "pitch", "roll", "yaw",
    "f_x", "f_y", "f_z", "w_x", "w_y", "w_z",
    "x_e", "y_e", "z_e", "vx_e", "vy_e", "vz_e", "ax_e", "ay_e", "az_e",
)
#: Truth columns with the receiver clock (written when ``Truth.clock_bias_s`` is set).
TRUTH_CLOCK_COLUMNS = TRUTH_COLUMNS + ("clock_bias_s", "clock_drift_s_s")
_FMT = "%.17g"
_TRUE_KEYS = (("true_accel_bias_mps2", "accel_bias"), ("true_gyro_bias_rads", "gyro_bias"),
              ("true_accel_scale", "accel_scale"), ("true_gyro_scale", "gyro_scale"))


def _epoch_lines(week: int | None, sow: float | None) -> list[str]:
    out = []
    if week is not None:
        out.append(f"bdt_week_t0: {int(week)}")
    if sow is not None:
        out.append(f"bdt_sow_t0: {float(sow)!r}")
    return out


def _check_shapes(kind: str, t, **arrays) -> int:
    n = np.shape(t)
    if len(n) != 1 or n[0] < 1:
        raise ValueError(f"{kind}: t must be a non-empty 1-D array, got shape {n}")
    for name, a in arrays.items():
        if np.shape(a) != (n[0], 3):
            raise ValueError(f"{kind}: {name} must have shape ({n[0]}, 3), got {np.shape(a)}")
    return n[0]


def _write(path: Path, kind: str, header: list[str], columns: tuple[str, ...],
           data: np.ndarray, output_set: OutputSet | None) -> None:
    if data.ndim != 2 or data.shape[1] != len(columns):  # pragma: no cover - checked before
        raise ValueError(f"{kind}: {data.shape[1]} columns to write, expected {len(columns)}")
    opener = atomic_open if output_set is None else output_set.open
    with opener(path, "w") as fh:
        fh.write(f"# sdr-di {kind} v1\n")
        for line in header:
            fh.write(f"# {line}\n")
        fh.write(",".join(columns) + "\n")
        np.savetxt(fh, data, fmt=_FMT, delimiter=",")


def write_imu(path: str | Path, imu: ImuData, week: int | None = None,
              sow: float | None = None, *, output_set: OutputSet | None = None) -> Path:
    """Write an IMU record (atomically).

    Parameters
    ----------
    path : path
        Output file name.
    imu : ImuData
        The record; its ``week``/``sow`` are used unless given here.
    week, sow : int, float, optional
        BDT week and seconds of week of ``t = 0``.
    output_set : OutputSet, optional
        Write the file as a member of this set (renamed by its ``commit``).

    Returns
    -------
    Path
        The written file.

    Raises
    ------
    ValueError
        Arrays of inconsistent shapes (nothing is written).
    OutputError
        The file cannot be written.
    """
    path = Path(path)
    _check_shapes("IMU record", imu.t, f_b=imu.f_b, w_ib_b=imu.w_ib_b)
    week = imu.week if week is None else week
    sow = imu.sow if sow is None else sow
    header = _epoch_lines(week, sow) + [
        f"rate_hz: {float(imu.rate_hz)!r}",
        "sample: average over (t[k-1], t[k]] (integrated increments / dt)",
        "frame: body Right-Front-Up (x right, y front, z up); gyro = angular rate of body "
        "w.r.t. inertial space",
    ]
    for key, attr in _TRUE_KEYS:
        val = getattr(imu, attr)
        if val is not None:
            header.append(f"{key}: " + " ".join(_FMT % v for v in np.asarray(val, float)))
    header.append("columns: t [s since scenario start], gyro_x gyro_y gyro_z [rad/s], "
                  "accel_x accel_y accel_z [m/s^2]")
    data = np.column_stack([imu.t, imu.w_ib_b, imu.f_b])
    _write(path, "imu", header, IMU_COLUMNS, data, output_set)
    return path


def write_truth(path: str | Path, truth: Truth, week: int | None = None,
                sow: float | None = None, *, output_set: OutputSet | None = None,
                records: dict[str, str] | None = None) -> Path:
    """Write a trajectory truth record (atomically, or as a member of ``output_set``);
    columns in the module docstring.

    ``records``: extra header lines ``# key: value`` after the epoch and rate (the generator's
    drawn truth: ``imu_unit``, ``atmosphere_truth``, one-line JSON); readers skip keys they do
    not know.

    Raises
    ------
    ValueError
        Arrays of inconsistent shapes (nothing is written).
    OutputError
        The file cannot be written.
    """
    path = Path(path)
    _check_shapes("truth", truth.t, llh=truth.llh, v_n=truth.v_n, att=truth.att, f_b=truth.f_b,
                  w_ib_b=truth.w_ib_b, r_e=truth.r_e, v_e=truth.v_e, a_e=truth.a_e)
    header = _epoch_lines(week, sow) + [f"rate_hz: {float(truth.rate_hz)!r}"] + [
        f"{k}: {v}" for k, v in (records or {}).items()] + [
        "frames: ENU navigation, body Right-Front-Up, ECEF CGCS2000; yaw clockwise from North",
        "sample: PVA and ECEF instantaneous at t; f_b, w_ib_b average over (t[k-1], t[k]]",
        "columns: t [s since scenario start], lat lon [deg], h [m], v_e v_n v_u [m/s], "
        "pitch roll yaw [deg], f_x f_y f_z [m/s^2], w_x w_y w_z [rad/s], "
        "x_e y_e z_e [m], vx_e vy_e vz_e [m/s], ax_e ay_e az_e [m/s^2]"
        + ("" if truth.clock_bias_s is None else
           ", clock_bias_s [s] (receiver time - true time), clock_drift_s_s [s/s]"),
    ]
    cols = [truth.t, np.degrees(truth.llh[:, :2]), truth.llh[:, 2], truth.v_n,
            np.degrees(truth.att), truth.f_b, truth.w_ib_b, truth.r_e, truth.v_e, truth.a_e]
    columns = TRUTH_COLUMNS
    if truth.clock_bias_s is not None:
        for name in ("clock_bias_s", "clock_drift_s_s"):
            if np.shape(getattr(truth, name)) != np.shape(truth.t):
                raise ValueError(f"truth: {name} must have shape {np.shape(truth.t)}")
        cols += [truth.clock_bias_s, truth.clock_drift_s_s]
        columns = TRUTH_CLOCK_COLUMNS
    _write(path, "truth", header, columns, np.column_stack(cols), output_set)
    return path


def _read(path: Path, kind: str, columns: tuple[str, ...],
          rate_hz: float | None, alt_columns: tuple[str, ...] | None = None
          ) -> tuple[dict[str, str], np.ndarray, float]:
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ImuDataError(f"{kind} file {path}: cannot read ({exc.strerror or exc})") from None
    except UnicodeDecodeError:
        raise ImuDataError(f"{kind} file {path}: not a UTF-8 text file") from None
    lines = text.splitlines()
    meta: dict[str, str] = {}
    i = 0
    while i < len(lines) and lines[i].startswith("#"):
        body = lines[i][1:].strip()
        if ":" in body:
            key, _, value = body.partition(":")
            meta.setdefault(key.strip(), value.strip())
        i += 1
    if i >= len(lines):
        raise ImuDataError(f"{kind} file {path}: no column line (empty or header only)")
    names = tuple(c.strip() for c in lines[i].split(","))
    if alt_columns is not None and names == alt_columns:
        columns = alt_columns
    if names != columns:
        raise ImuDataError(f"{kind} file {path} line {i + 1}: expected columns "
                           f"{','.join(columns)}, got {lines[i]!r}")
    first = i + 1
    rows = [ln for ln in lines[first:]]
    while rows and not rows[-1].strip():
        rows.pop()
    if len(rows) < 2:
        raise ImuDataError(f"{kind} file {path}: fewer than 2 samples")
    ncol = len(columns)
    for j, ln in enumerate(rows):
        if ln.count(",") != ncol - 1:
            raise ImuDataError(f"{kind} file {path} line {first + j + 1}: expected {ncol} "
                               f"columns, found {ln.count(',') + 1}")
    try:
        data = np.loadtxt(rows, delimiter=",", dtype=float, ndmin=2)
    except ValueError as exc:
        raise ImuDataError(f"{kind} file {path}: unreadable number ({exc})") from None
    bad = ~np.isfinite(data)
    if bad.any():
        j, c = np.argwhere(bad)[0]
        raise ImuDataError(f"{kind} file {path} line {first + j + 1}: column {columns[c]!r} is "
                           f"not a finite number ({data[j, c]})")
    t = data[:, 0]
    dt = np.diff(t)
    nonmono = np.flatnonzero(dt <= 0)
    if nonmono.size:
        j = int(nonmono[0]) + 1
        raise ImuDataError(f"{kind} file {path} line {first + j + 1}: time not increasing "
                           f"(t = {float(t[j])!r} s after {float(t[j - 1])!r} s)")
    if rate_hz is None:
        if "rate_hz" in meta:
            try:
                rate_hz = float(meta["rate_hz"])
            except ValueError:
                raise ImuDataError(f"{kind} file {path}: bad rate_hz {meta['rate_hz']!r}") from None
            if not (math.isfinite(rate_hz) and rate_hz > 0):
                raise ImuDataError(f"{kind} file {path}: bad rate_hz {meta['rate_hz']!r}")
        else:
            rate_hz = 1.0 / float(np.median(dt))
    nominal = 1.0 / rate_hz
    gaps = np.flatnonzero(np.abs(dt - nominal) > 0.5 * nominal)
    if gaps.size:
        j = int(gaps[0]) + 1
        raise ImuDataError(
            f"{kind} file {path} line {first + j + 1}: sample spacing {dt[j - 1]:.6g} s at "
            f"t = {float(t[j])!r} s deviates from the nominal {nominal:.6g} s by more than half a "
            f"sample (gap or duplicate)")
    return meta, data, rate_hz


def _epoch(meta: dict[str, str], path: Path, kind: str) -> tuple[int | None, float | None]:
    try:
        week = int(meta["bdt_week_t0"]) if "bdt_week_t0" in meta else None
        sow = float(meta["bdt_sow_t0"]) if "bdt_sow_t0" in meta else None
    except ValueError:
        raise ImuDataError(f"{kind} file {path}: bad BDT epoch in header") from None
    return week, sow


def read_imu(path: str | Path, rate_hz: float | None = None) -> ImuData:
    """Read and validate an IMU file.

    Parameters
    ----------
    path : path
        File written by :func:`write_imu` (or in its format).
    rate_hz : float, optional
        Nominal rate [Hz]; default the header's ``rate_hz`` (else the median spacing).

    Returns
    -------
    ImuData
        With ``week``/``sow`` of ``t = 0`` and the true error constants when the header has
        them.

    Raises
    ------
    ImuDataError
        Unreadable file, wrong columns or column count, NaN/inf, non-increasing time, gaps.
    """
    path = Path(path)
    meta, data, rate = _read(path, "IMU", IMU_COLUMNS, rate_hz)
    note_input(path, what="IMU file")
    week, sow = _epoch(meta, path, "IMU")
    extra = {}
    for key, attr in _TRUE_KEYS:
        if key in meta:
            try:
                v = np.array([float(x) for x in meta[key].split()])
            except ValueError:
                v = np.zeros(0)
            if v.shape != (3,):
                raise ImuDataError(f"IMU file {path}: header {key} needs 3 numbers")
            extra[attr] = v
    return ImuData(t=data[:, 0].copy(), w_ib_b=data[:, 1:4].copy(), f_b=data[:, 4:7].copy(),
                   rate_hz=rate, week=week, sow=sow, **extra)


def read_truth(path: str | Path) -> tuple[Truth, int | None, float | None]:
    """Read and validate a truth file.

    Returns
    -------
    truth : Truth
        ``C_b_n`` recomputed from the Euler angles.
    week, sow : int or None, float or None
        BDT epoch of ``t = 0`` from the header.

    Raises
    ------
    ImuDataError
        As :func:`read_imu`.
    """
    path = Path(path)
    meta, d, rate = _read(path, "truth", TRUTH_COLUMNS, None, TRUTH_CLOCK_COLUMNS)
    note_input(path, what="truth file")
    week, sow = _epoch(meta, path, "truth")
    llh = np.column_stack([np.radians(d[:, 1:3]), d[:, 3]])
    att = np.radians(d[:, 7:10])
    truth = Truth(
        t=d[:, 0].copy(), llh=llh, v_n=d[:, 4:7].copy(), att=att,
        C_b_n=euler_to_C_b_n(att[:, 0], att[:, 1], att[:, 2]),
        f_b=d[:, 10:13].copy(), w_ib_b=d[:, 13:16].copy(), r_e=d[:, 16:19].copy(),
        v_e=d[:, 19:22].copy(), a_e=d[:, 22:25].copy(), rate_hz=rate,
        clock_bias_s=d[:, 25].copy() if d.shape[1] > 25 else None,
        clock_drift_s_s=d[:, 26].copy() if d.shape[1] > 26 else None,
    )
    return truth, week, sow
