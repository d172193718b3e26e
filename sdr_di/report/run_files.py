"""What one ``sdr-di run`` (or ``sdr-di lc``) output folder holds, read back as plain arrays.

A folder may hold several runs of the same IF file (the README's tour writes the scalar,
deep, loose and tight runs into one ``STEM_run/``): :func:`find_runs` lists them, one
:class:`RunFiles` each, in the order scalar, deep, loose, tight, lc.

``integrated`` (``sdr-di run --mode deep|loose|tight``): ``STEM_MODE_summary.json``,
``STEM_MODE.csv`` (docs/deep.md), ``STEM_MODE_channels.csv`` and ``STEM_MODE_nis.csv``
(:mod:`~sdr_di.integration.run_integrated`; absent in a folder written before they
existed). ``lc``: ``NAME_lc_FILTER_summary.json`` and ``NAME_lc_FILTER.csv`` (errors only: no
position rows, no channels). ``scalar``: ``STEM_pvt.csv``, ``STEM_channels.csv``,
``STEM_obs.rnx``, ``STEM_nav.rnx`` (docs/solution_format.md) and the run's record
``STEM_scalar_summary.json`` (its input files; absent in older folders); a file still under its
``.part`` name is a run that stopped before it completed, read as far as it goes.

:func:`read_rows` reads an integrated or lc solution CSV into the same keys (time
``t_s`` [s since the IF start], errors and formal 1-sigma in ENU); :func:`read_obs_rinex`
reads the run's own RINEX observation file (C/N0 and lock per satellite and epoch).
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import json
import math
from pathlib import Path

import numpy as np

from ..constants import SECONDS_PER_WEEK
from ..errors import ExperimentError

__all__ = ["INTEGRATED_MODES", "ObsSeries", "RunFiles", "find_runs", "is_run_folder",
           "read_csv_columns", "read_obs_rinex", "read_rows", "scalar_sidecar"]

INTEGRATED_MODES = ("deep", "loose", "tight")

#: ``sdr-di lc`` error CSV column -> the integrated CSV's name of the same quantity.
_LC_NAMES = {"t": "t_s", "att_e_deg": "att_err_e_deg", "att_n_deg": "att_err_n_deg",
             "att_u_deg": "att_err_u_deg", "vel_e": "vel_err_e", "vel_n": "vel_err_n",
             "vel_u": "vel_err_u", "pos_e_m": "pos_err_e_m", "pos_n_m": "pos_err_n_m",
             "pos_u_m": "pos_err_u_m"}

_BDT_EPOCH = _dt.datetime(2006, 1, 1)


@dataclasses.dataclass
class RunFiles:
    """One run found in a folder.

    Attributes
    ----------
    kind : str
        ``"integrated"``, ``"lc"`` or ``"scalar"``.
    mode : str
        ``deep``, ``loose``, ``tight``, ``lc`` or ``scalar``.
    stem : str
        ``STEM_MODE`` (``STEM`` for scalar, ``NAME_lc_FILTER`` for lc): the figures' prefix.
    files : dict
        Paths by role (``summary``, ``solution``, ``channels``, ``nis``, ``pvt``,
        ``rinex_obs``, ``rinex_nav``); a role whose file is absent is left out.
    partial : list of str
        Files found only under their ``.part`` name (the run did not complete).
    summary : dict
        The summary JSON (empty for scalar).
    """

    kind: str
    mode: str
    stem: str
    files: dict
    partial: list = dataclasses.field(default_factory=list)
    summary: dict = dataclasses.field(default_factory=dict)


def _existing(path: Path) -> tuple[Path | None, bool]:
    """``(path, False)`` if it exists, ``(path.part, True)`` if only that does, else None."""
    if path.is_file():
        return path, False
    part = path.with_name(path.name + ".part")
    if part.is_file():
        return part, True
    return None, False


def _read_summary(path: Path) -> dict:
    try:
        s = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ExperimentError(f"report {path}: cannot read ({exc.strerror or exc})") from None
    except (ValueError, RecursionError) as exc:
        raise ExperimentError(f"report {path}: not JSON ({exc})") from None
    if not isinstance(s, dict):
        raise ExperimentError(f"report {path}: not a JSON object")
    return s


def is_run_folder(folder: str | Path) -> bool:
    """True for an ``sdr-di run`` / ``sdr-di lc`` output folder (a scalar ``*_pvt.csv``,
    complete or partial, or a ``*_summary.json``)."""
    folder = Path(folder)
    return folder.is_dir() and any(any(folder.glob(g)) for g in (
        "*_pvt.csv", "*_pvt.csv.part", "*_summary.json"))


def find_runs(folder: str | Path) -> list[RunFiles]:
    """The runs of an output folder (module notes).

    Raises
    ------
    ExperimentError
        A summary that cannot be read or is not a JSON object.
    """
    folder = Path(folder)
    runs: list[RunFiles] = []
    pvts = {p.name.removesuffix(".part") for p in folder.glob("*_pvt.csv*")
            if p.name.endswith(("_pvt.csv", "_pvt.csv.part"))}
    for name in sorted(pvts):
        stem = name.removesuffix("_pvt.csv")
        rec = folder / f"{stem}_scalar_summary.json"
        rf = RunFiles("scalar", "scalar", stem, {"summary": rec} if rec.is_file() else {},
                      summary=_read_summary(rec) if rec.is_file() else {})
        for role, fname in (("pvt", f"{stem}_pvt.csv"), ("channels", f"{stem}_channels.csv"),
                            ("rinex_obs", f"{stem}_obs.rnx"),
                            ("rinex_nav", f"{stem}_nav.rnx")):
            p, part = _existing(folder / fname)
            if p is not None:
                rf.files[role] = p
            if part:
                rf.partial.append(p.name)
        runs.append(rf)
    order = {m: i for i, m in enumerate(INTEGRATED_MODES)}
    found = []
    for path in sorted(folder.glob("*_summary.json")):
        s = _read_summary(path)
        stem = path.name.removesuffix("_summary.json")
        mode = s.get("mode")
        if mode == "scalar":
            continue                      # the record of a scalar run (found by its pvt)
        if mode in INTEGRATED_MODES:
            rf = RunFiles("integrated", mode, stem, {"summary": path}, summary=s)
            for role, fname in (("solution", f"{stem}.csv"),
                                ("channels", f"{stem}_channels.csv"),
                                ("nis", f"{stem}_nis.csv")):
                if (folder / fname).is_file():
                    rf.files[role] = folder / fname
            found.append((order[mode], stem, rf))
        elif "_lc_" in stem:
            rf = RunFiles("lc", "lc", stem, {"summary": path}, summary=s)
            if (folder / f"{stem}.csv").is_file():
                rf.files["solution"] = folder / f"{stem}.csv"
            found.append((len(order), stem, rf))
    runs += [rf for _, _, rf in sorted(found, key=lambda x: (x[0], x[1]))]
    return runs


def read_csv_columns(path: str | Path) -> dict[str, np.ndarray]:
    """A numeric CSV (``#`` comment lines, one line of names) as ``{name: float array}``.

    A truncated last line (a ``.part`` file) is dropped; a value that is not a number
    reads as NaN.

    Raises
    ------
    ExperimentError
        No line of column names.
    """
    path = Path(path)
    try:
        lines = [ln for ln in path.read_text(encoding="utf-8").splitlines()
                 if ln.strip() and not ln.startswith("#")]
    except (OSError, UnicodeDecodeError) as exc:
        raise ExperimentError(f"report {path}: cannot read ({exc})") from None
    if not lines:
        raise ExperimentError(f"report {path}: no column line")
    names = lines[0].split(",")
    rows = []
    for ln in lines[1:]:
        cells = ln.split(",")
        if len(cells) != len(names):
            continue                      # a line cut short by a stopped run
        row = []
        for c in cells:
            try:
                row.append(float(c) if c else math.nan)
            except ValueError:
                row.append(math.nan)
        rows.append(row)
    data = np.asarray(rows, float).reshape(-1, len(names))
    return {n: data[:, i] for i, n in enumerate(names)}


def read_rows(run: RunFiles) -> dict[str, np.ndarray] | None:
    """The solution rows of an integrated or lc run, in one set of keys.

    Returns
    -------
    dict or None
        ``t_s`` (n,) [s since the IF start], ``pos_err`` (n, 3) [m], ``vel_err`` [m/s],
        ``att_err`` [deg] (ENU; NaN without a reference), ``pos_sd``, ``vel_sd``,
        ``att_sd`` (n, 3) formal 1-sigma, same units (NaN when absent); integrated runs also
        ``lat_deg``, ``lon_deg``, ``h_m``, ``n_used``; lc ``nis`` (the NIS per row, all
        blocks together). None when the run has no solution file.
    """
    path = run.files.get("solution")
    if path is None:
        return None
    raw = read_csv_columns(path)
    c = {_LC_NAMES.get(k, k): v for k, v in raw.items()}
    n = c["t_s"].size if "t_s" in c else 0

    def trio(names):
        return np.column_stack([c.get(k, np.full(n, math.nan)) for k in names]).reshape(n, 3)

    out = {"t_s": c.get("t_s", np.zeros(0)),
           "pos_err": trio(("pos_err_e_m", "pos_err_n_m", "pos_err_u_m")),
           "vel_err": trio(("vel_err_e", "vel_err_n", "vel_err_u")),
           "att_err": trio(("att_err_e_deg", "att_err_n_deg", "att_err_u_deg")),
           "pos_sd": trio(("pos_sd_e_m", "pos_sd_n_m", "pos_sd_u_m")),
           "vel_sd": trio(("vel_sd_e", "vel_sd_n", "vel_sd_u")),
           "att_sd": trio(("att_sd_e_deg", "att_sd_n_deg", "att_sd_u_deg"))}
    for k in ("lat_deg", "lon_deg", "h_m", "n_used", "nis"):
        if k in c:
            out[k] = c[k]
    return out


@dataclasses.dataclass
class ObsSeries:
    """C/N0 and lock per satellite from a RINEX observation file the run wrote.

    Attributes
    ----------
    week : int
        BDT week of the first epoch.
    sow : (k,) array
        Receiver-clock time of each epoch [s of ``week``, BDT scale].
    cn0_dbhz : dict
        ``{prn: (k,) array}`` ``S6I`` [dB-Hz], NaN where the satellite is not listed.
    pseudorange : dict
        ``{prn: (k,) bool}`` ``C6I`` present (code lock with a transmit time).
    phase : dict
        ``{prn: (k,) bool}`` ``L6I`` present (carrier lock).
    slip : dict
        ``{prn: (k,) bool}`` loss-of-lock indicator bit 0 of ``L6I`` (a new phase arc).
    """

    week: int
    sow: np.ndarray
    cn0_dbhz: dict
    pseudorange: dict
    phase: dict
    slip: dict


def _field(line: str, k: int) -> tuple[float, str]:
    """Value (NaN if blank) and LLI character of observation ``k`` of a satellite line."""
    s = line[3 + 16 * k: 3 + 16 * k + 16]
    v = s[:14].strip()
    try:
        x = float(v) if v else math.nan
    except ValueError:                    # a damaged line: the value is not there
        x = math.nan
    return x, (s[14:15] if len(s) > 14 else " ")


def read_obs_rinex(path: str | Path) -> ObsSeries | None:
    """:class:`ObsSeries` of ``STEM_obs.rnx`` (docs/solution_format.md, observation types
    ``C6I L6I D6I S6I``); None for a file without epochs or with other observation types."""
    path = Path(path)
    try:
        lines = path.read_text(encoding="ascii", errors="replace").splitlines()
    except OSError:
        return None
    try:
        end = next(i for i, ln in enumerate(lines) if "END OF HEADER" in ln)
    except StopIteration:
        end = -1                           # a body file without its header (a .part)
    types = next((ln[7:60].split() for ln in lines[:end + 1]
                  if "SYS / # / OBS TYPES" in ln and ln.startswith("C")), ["C6I", "L6I",
                                                                           "D6I", "S6I"])
    if types[:4] != ["C6I", "L6I", "D6I", "S6I"]:
        return None
    t: list[float] = []
    week0 = None
    rec: dict[int, dict[int, tuple]] = {}
    for ln in lines[end + 1:]:
        if ln.startswith(">"):
            try:
                y, mo, d, hh, mi = (int(v) for v in ln[2:18].split())
                sec = float(ln[18:29])
            except ValueError:
                break
            dt = (_dt.datetime(y, mo, d, hh, mi) - _BDT_EPOCH).total_seconds() + sec
            week = int(dt // SECONDS_PER_WEEK)
            week0 = week if week0 is None else week0
            t.append(dt - week0 * SECONDS_PER_WEEK)
        elif t and ln[:1] == "C" and ln[1:3].strip().isdigit():
            prn = int(ln[1:3])
            c, _ = _field(ln, 0)
            ph, lli = _field(ln, 1)
            s, _ = _field(ln, 3)
            rec.setdefault(prn, {})[len(t) - 1] = (c, ph, lli, s)
    if not t:
        return None
    k = len(t)
    cn0, pr, phase, slip = {}, {}, {}, {}
    for prn in sorted(rec):
        a = np.full(k, math.nan)
        b, p, sl = np.zeros(k, bool), np.zeros(k, bool), np.zeros(k, bool)
        for i, (c, ph, lli, s) in rec[prn].items():
            a[i], b[i], p[i] = s, math.isfinite(c), math.isfinite(ph)
            sl[i] = lli.strip().isdigit() and int(lli) & 1 == 1
        cn0[prn], pr[prn], phase[prn], slip[prn] = a, b, p, sl
    return ObsSeries(int(week0), np.asarray(t, float), cn0, pr, phase, slip)


def scalar_sidecar(folder: Path, stem: str) -> Path | None:
    """The IF file's sidecar ``STEM.json`` of a scalar run folder: beside the folder (the
    default ``STEM_run/`` next to ``STEM.bin``) or inside it; None when neither exists."""
    for p in (Path(folder).parent / f"{stem}.json", Path(folder) / f"{stem}.json"):
        if p.is_file():
            return p
    return None
