"""The figures of a run's report: matplotlib's object API with the Agg canvas, PNG files.

Each function takes plain arrays (what :mod:`.run_files` reads back from a run folder) and
writes one PNG (:func:`~sdr_di.experiments.plotting.save_png`, atomic); ``run --plots``
and ``sdr-di report`` call the same functions (:mod:`.run_figures`).

Shaded spans (:class:`Spans`), the same in every time figure of a run: before the
hand-over (grey: the scalar start-up, no filter rows), fewer satellites used than the
run's most (orange: an outage or a lost channel), a channel's C/N0 more than
:data:`CN0_DROP_DB` below its own median (red).

Frames: errors and sigmas in the navigation frame ENU (east, north, up); the attitude
error is the rotation vector of the error model in ENU (about east ~ pitch, about north ~
roll for a level vehicle heading north, about up: heading), in degrees.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..constants import orbit_type
from ..experiments.plotting import plain_log_axis, save_png

__all__ = ["CN0_DROP_DB", "DPI", "Spans", "channel_figure", "error_figure",
           "fix_status_figure", "innovation_figure", "nis_figure", "runs_of",
           "sats_used_figure", "sky_figure", "trajectory_figure"]

#: Resolution of the report's PNGs [dots per inch]: 9-inch figures 810 pixels wide, 15-200 kB
#: each (a 60 s run's page is about 0.7 MB).
DPI = 90
#: A channel's C/N0 this far below its own median is shaded as a drop [dB].
CN0_DROP_DB = 6.0
_AXES = ("E", "N", "U")
_MARK = {"GEO": "s", "IGSO": "^", "MEO": "o"}


def runs_of(t: np.ndarray, mask: np.ndarray) -> list[tuple[float, float]]:
    """Spans ``(t0, t1)`` [s] where ``mask`` holds on consecutive samples of ``t``."""
    t = np.asarray(t, float)
    m = np.asarray(mask, bool)
    out = []
    i, n = 0, m.size
    while i < n:
        if m[i]:
            j = i
            while j + 1 < n and m[j + 1]:
                j += 1
            dt = (t[j] - t[j - 1]) if j > 0 else 0.0
            out.append((float(t[i]), float(t[j] + 0.5 * dt)))
            i = j + 1
        else:
            i += 1
    return out


@dataclasses.dataclass
class Spans:
    """Time spans [s since the IF start] shaded in every time figure (module notes)."""

    handover_s: float | None = None
    start_s: float = 0.0
    fewer_sats: list = dataclasses.field(default_factory=list)
    cn0_drop: list = dataclasses.field(default_factory=list)
    #: what the time axis counts from
    xlabel: str = "time since the IF start [s]"

    @classmethod
    def of(cls, t_s, n_used=None, cn0_by_channel: dict | None = None,
           handover_s: float | None = None, start_s: float = 0.0,
           xlabel: str = "time since the IF start [s]") -> Spans:
        """Spans from the satellites used at each row and each channel's C/N0."""
        t = np.asarray(t_s, float)
        fewer = []
        if n_used is not None and np.size(n_used):
            n = np.asarray(n_used, float)
            fewer = runs_of(t, n < np.nanmax(n))
        drop: list = []
        for tc, c in (cn0_by_channel or {}).values():
            c = np.asarray(c, float)
            if np.isfinite(c).sum() > 3:
                drop += runs_of(np.asarray(tc, float), c < np.nanmedian(c) - CN0_DROP_DB)
        return cls(handover_s, start_s, fewer, drop, xlabel)

    def shade(self, ax) -> None:
        """Shade the spans on a time axis (labels for the legend on the first use)."""
        if self.handover_s is not None and math.isfinite(self.handover_s):
            ax.axvspan(self.start_s, self.handover_s, color="0.88", zorder=0,
                       label="scalar start-up")
            ax.axvline(self.handover_s, color="0.3", lw=0.8, ls=":", label="hand-over")
        for i, (a, b) in enumerate(self.fewer_sats):
            ax.axvspan(a, b, color="tab:orange", alpha=0.15, zorder=0,
                       label="fewer satellites" if i == 0 else None)
        for i, (a, b) in enumerate(self.cn0_drop):
            ax.axvspan(a, b, color="tab:red", alpha=0.12, zorder=0,
                       label=f"C/N0 drop > {CN0_DROP_DB:g} dB" if i == 0 else None)

    def xlim(self, t: np.ndarray) -> tuple[float, float]:
        """x range: from the IF start (shows the start-up) to the last row."""
        t = np.asarray(t, float)
        hi = float(np.nanmax(t)) if t.size else 1.0
        lo = self.start_s if self.handover_s is not None else (float(np.nanmin(t))
                                                                if t.size else 0.0)
        return lo, max(hi, lo + 1e-3)


def _figure(n_rows: int, height: float = 2.1, width: float = 9.0, sharex: bool = True):
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height * n_rows + 0.6), layout="constrained")
    axes = fig.subplots(n_rows, 1, sharex=sharex, squeeze=False)[:, 0]
    return fig, axes


def error_figure(path: Path, t_s, err, sd, *, quantity: str, unit: str, spans: Spans,
                 title: str, axis_names: Sequence[str] = _AXES,
                 envelope: str = "filter") -> Path:
    """Error per axis against time with the filter's +-3 sigma envelope.

    Parameters
    ----------
    path : Path
        PNG to write.
    t_s : (n,) array
        Row times [s since the IF start].
    err, sd : (n, 3) arrays
        Error against the reference and the filter's formal 1-sigma, per ENU axis, in
        ``unit`` (``sd`` all NaN: no envelope, said in the legend).
    quantity, unit : str
        Axis label text, e.g. ``"position error"``, ``"m"``.
    envelope : str
        Whose sigma ``sd`` is (``"filter"``, ``"PVT"``), for the legend and title.
    """
    t = np.asarray(t_s, float)
    err = np.asarray(err, float).reshape(-1, 3)
    sd = np.asarray(sd, float).reshape(-1, 3)
    fig, axes = _figure(3)
    for j, ax in enumerate(axes):
        spans.shade(ax)
        if np.isfinite(sd[:, j]).any():
            ax.fill_between(t, -3 * sd[:, j], 3 * sd[:, j], color="tab:blue", alpha=0.18,
                            lw=0, label=f"{envelope} +-3 sigma")
        ax.plot(t, err[:, j], color="k", lw=0.9, label="error")
        ax.axhline(0.0, color="0.5", lw=0.5)
        out = np.abs(err[:, j]) > 3 * sd[:, j]
        if out.any():
            ax.plot(t[out], err[out, j], "r.", ms=3, label="outside 3 sigma")
        ax.set_ylabel(f"{axis_names[j]} [{unit}]")
        ax.grid(True, alpha=0.3)
    axes[0].set_xlim(*spans.xlim(t))
    axes[-1].set_xlabel(spans.xlabel)
    axes[0].legend(fontsize="x-small", ncol=6, loc="upper left")
    whose = f" and the {envelope}'s +-3 sigma" if np.isfinite(sd).any() else ""
    fig.suptitle(f"{title}: {quantity} per axis [{unit}]{whose}", fontsize="medium")
    return save_png(fig, path, DPI)


def nis_figure(path: Path, t_s, nis_blocks: np.ndarray, block_names: Sequence[str], dof,
               summary_entries: Sequence[dict | None], *, spans: Spans, title: str,
               window_s: float = 1.0) -> Path:
    """NIS per degree of freedom of each measurement block against time, with its band.

    Per update: the points; their mean over ``window_s`` (line) with the 95 % chi-square
    band of such a mean (``k`` updates of ``dof`` each: chi2(k dof) / (k dof), shaded);
    the run's mean and its band from the summary (dashed).

    Parameters
    ----------
    t_s : (k,) array
        Update times [s since the IF start].
    nis_blocks : (k, b) array
        NIS per degree of freedom of each block.
    dof : (k,) array
        Degrees of freedom of a block at each update.
    summary_entries : sequence of dict or None
        The summary's ``consistency`` entry of each block (``value``, ``band``).
    """
    from ..integration.consistency import chi2_band

    t = np.asarray(t_s, float)
    nb = np.asarray(nis_blocks, float).reshape(t.size, -1)
    d = np.asarray(dof, float).reshape(-1)
    fig, axes = _figure(nb.shape[1])
    dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    k = max(1, int(round(window_s / dt))) if dt > 0 else 1
    d_med = int(round(float(np.nanmedian(d)))) if d.size else 1
    for j, ax in enumerate(axes):
        spans.shade(ax)
        y = nb[:, j]
        ax.plot(t, y, ".", ms=2, color="0.55", label="per update")
        if y.size >= k:
            kern = np.ones(k) / k
            mean = np.convolve(np.nan_to_num(y), kern, mode="valid")
            tm = np.convolve(t, kern, mode="valid")
            lo, hi = chi2_band(k, max(d_med, 1))
            ax.axhspan(lo, hi, color="tab:green", alpha=0.15,
                       label=f"95 % band of a {k * dt:.2g} s mean")
            ax.plot(tm, mean, color="tab:blue", lw=1.1, label=f"{k * dt:.2g} s mean")
        e = summary_entries[j] if j < len(summary_entries) else None
        if e and e.get("value") is not None:
            ax.axhline(e["value"], color="k", ls="--", lw=0.9, label="run mean")
            b = e.get("band") or []
            for v in b:
                if v is not None:
                    ax.axhline(v, color="k", ls=":", lw=0.7)
        ax.axhline(1.0, color="tab:green", lw=0.8)
        ax.set_yscale("log")
        plain_log_axis(ax)
        ax.set_ylabel(f"NIS {block_names[j]}\nper dof ({d_med})")
        ax.grid(True, alpha=0.3, which="both")
    axes[0].set_xlim(*spans.xlim(t))
    axes[-1].set_xlabel(spans.xlabel)
    axes[0].legend(fontsize="x-small", ncol=6, loc="upper left")
    fig.suptitle(f"{title}: NIS per measurement block against its chi-square band "
                 "(dotted: the run mean's band)", fontsize="medium")
    return save_png(fig, path, DPI)


def trajectory_figure(path: Path, east_north: np.ndarray, truth_en: np.ndarray | None, *,
                      title: str, origin: str) -> Path:
    """East-north track [m from ``origin``] of the solution, with the truth's when given."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.5, 6.0), layout="constrained")
    ax = fig.subplots()
    en = np.asarray(east_north, float).reshape(-1, 2)
    if truth_en is not None:
        tr = np.asarray(truth_en, float).reshape(-1, 2)
        ax.plot(tr[:, 0], tr[:, 1], color="tab:green", lw=3, alpha=0.5, label="truth")
    ax.plot(en[:, 0], en[:, 1], color="k", lw=0.9, label="solution")
    if en.size:
        ax.plot(en[0, 0], en[0, 1], "o", color="tab:blue", label="first row")
        ax.plot(en[-1, 0], en[-1, 1], "s", color="tab:red", label="last row")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize="small")
    ax.set_title(f"{title}: trajectory (from {origin})", fontsize="medium")
    return save_png(fig, path, DPI)


def channel_figure(path: Path, cn0: dict, lock: dict, *, spans: Spans, title: str,
                   lock_label: str, slips: dict | None = None, weak: dict | None = None,
                   weak_label: str = "") -> Path:
    """C/N0 of each channel (top) and its lock over time (bottom, one bar per channel).

    Parameters
    ----------
    cn0 : dict
        ``{prn: (t [s], C/N0 [dB-Hz])}``.
    lock : dict
        ``{prn: (t [s], bool)}``: the state drawn as a dark bar (``lock_label``).
    weak : dict, optional
        ``{prn: (t [s], bool)}``: a weaker state drawn as a light bar (``weak_label``).
    slips : dict, optional
        ``{prn: (t [s], bool)}``: marked as red ticks (new phase arcs).
    """
    from matplotlib.figure import Figure

    prns = sorted(set(cn0) | set(lock))
    fig = Figure(figsize=(9.0, 2.6 + 0.28 * len(prns) + 0.6), layout="constrained")
    ax0, ax1 = fig.subplots(2, 1, sharex=True,
                            gridspec_kw={"height_ratios": [2.6, 0.28 * max(len(prns), 1)]})
    t_all = []
    for p in prns:
        if p in cn0:
            t, c = (np.asarray(a, float) for a in cn0[p])
            ax0.plot(t, c, lw=0.9, marker=_MARK[orbit_type(p)], ms=2, markevery=0.1,
                     label=f"C{p:02d}")
            t_all.append(t)
    spans.shade(ax0)
    ax0.set_ylabel("C/N0 [dB-Hz]")
    ax0.grid(True, alpha=0.3)
    ax0.legend(fontsize="x-small", ncol=8, loc="lower left")
    for i, p in enumerate(prns):
        if weak and p in weak:
            t, m = weak[p]
            for a, b in runs_of(t, m):
                ax1.broken_barh([(a, b - a)], (i - 0.35, 0.7), color="tab:blue", alpha=0.3)
        if p in lock:
            t, m = lock[p]
            for a, b in runs_of(t, m):
                ax1.broken_barh([(a, b - a)], (i - 0.35, 0.7), color="tab:blue")
            t_all.append(np.asarray(t, float))
        if slips and p in slips:
            t, m = (np.asarray(a) for a in slips[p])
            ax1.plot(t[m.astype(bool)], np.full(int(m.sum()), i), "|", color="tab:red",
                     ms=9)
    ax1.set_yticks(range(len(prns)), [f"C{p:02d} {orbit_type(p)}" for p in prns],
                   fontsize="x-small")
    ax1.set_ylim(-0.6, len(prns) - 0.4)
    ax1.set_xlabel(spans.xlabel)
    ax1.grid(True, axis="x", alpha=0.3)
    t_cat = np.concatenate(t_all) if t_all else np.zeros(1)
    ax0.set_xlim(*spans.xlim(t_cat))
    key = f"dark: {lock_label}" + (f"; light: {weak_label}" if weak else "") + (
        "; red ticks: new phase arc (LLI)" if slips else "")
    ax1.set_title(key, fontsize="x-small", loc="left")
    fig.suptitle(f"{title}: C/N0 and lock per channel", fontsize="medium")
    return save_png(fig, path, DPI)


def innovation_figure(path: Path, innov: dict, *, spans: Spans, title: str) -> Path:
    """Normalized innovation ``y / sqrt(S)`` of each channel, one panel per measurement
    block (deep: code, rate), with the +-3 lines a consistent filter stays within.

    Parameters
    ----------
    innov : dict
        ``{block: {prn: (t [s], y / sqrt(S) [-])}}``.
    """
    blocks = list(innov)
    fig, axes = _figure(len(blocks))
    t_all = []
    for ax, b in zip(axes, blocks):
        spans.shade(ax)
        for prn, (t, v) in sorted(innov[b].items()):
            t = np.asarray(t, float)
            ax.plot(t, np.asarray(v, float), lw=0.8, marker=_MARK[orbit_type(prn)], ms=2,
                    markevery=0.1, label=f"C{prn:02d}")
            t_all.append(t)
        for s in (-3.0, 3.0):
            ax.axhline(s, color="tab:red", lw=0.8, ls="--")
        ax.axhline(0.0, color="0.5", lw=0.5)
        ax.set_ylabel(f"{b} innovation\n/ sqrt(S) [-]")
        ax.grid(True, alpha=0.3)
    axes[0].set_xlim(*spans.xlim(np.concatenate(t_all) if t_all else np.zeros(1)))
    axes[-1].set_xlabel(spans.xlabel)
    axes[0].legend(fontsize="x-small", ncol=9, loc="upper left")
    fig.suptitle(f"{title}: normalized innovation per channel (dashed: +-3)",
                 fontsize="medium")
    return save_png(fig, path, DPI)


def sats_used_figure(path: Path, t_s, n_used, *, spans: Spans, title: str,
                     label: str = "satellites used") -> Path:
    """Number of satellites used against time."""
    fig, axes = _figure(1, height=2.0)
    ax = axes[0]
    spans.shade(ax)
    ax.step(np.asarray(t_s, float), np.asarray(n_used, float), where="post", color="k")
    ax.set_ylabel(label)
    ax.set_xlim(*spans.xlim(np.asarray(t_s, float)))
    ax.set_xlabel(spans.xlabel)
    ax.grid(True, alpha=0.3)
    from matplotlib.ticker import MaxNLocator

    n = np.asarray(n_used, float)
    ax.set_ylim(0, (np.nanmax(n) if np.isfinite(n).any() else 1) + 1)
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax.legend(fontsize="x-small", loc="lower right")
    fig.suptitle(f"{title}: {label}", fontsize="medium")
    return save_png(fig, path, DPI)


def fix_status_figure(path: Path, t_s, status: Sequence[str], n_sats, pdop, *, spans: Spans,
                      title: str) -> Path:
    """Fix status (one row per status seen), satellites in the fix and PDOP against time."""
    t = np.asarray(t_s, float)
    st = np.asarray(status, str)
    kinds = ["fix"] + sorted(set(st) - {"fix"})
    fig, axes = _figure(3, height=1.7)
    y = np.array([kinds.index(s) for s in st])
    for ax in axes:
        spans.shade(ax)
    axes[0].plot(t, y, "|", ms=8, color="k")
    axes[0].set_yticks(range(len(kinds)), kinds, fontsize="x-small")
    axes[0].set_ylim(-0.5, len(kinds) - 0.5)
    axes[1].step(t, np.asarray(n_sats, float), where="post", color="k")
    axes[1].set_ylabel("satellites\nin the fix")
    axes[1].set_ylim(0, float(np.nanmax(np.r_[np.asarray(n_sats, float), 1.0])) + 1)
    axes[2].plot(t, np.asarray(pdop, float), color="k")
    axes[2].set_ylabel("PDOP")
    for ax in axes:
        ax.grid(True, alpha=0.3)
    axes[0].set_xlim(*spans.xlim(t))
    axes[-1].set_xlabel(spans.xlabel)
    fig.suptitle(f"{title}: fix status, satellites and PDOP", fontsize="medium")
    return save_png(fig, path, DPI)


def sky_figure(path: Path, tracks: dict, *, title: str, used: Sequence[int] = ()) -> Path:
    """Sky plot: azimuth (north up, clockwise) and elevation of each satellite over the run.

    Parameters
    ----------
    tracks : dict
        ``{prn: (az_deg (k,), el_deg (k,))}``.
    used : sequence of int
        PRNs tracked by the run (drawn solid; the others hollow).
    """
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    fig = Figure(figsize=(6.5, 6.5), layout="constrained")
    ax = fig.add_subplot(projection="polar")
    ax.set_theta_zero_location("N")
    ax.set_theta_direction(-1)
    ax.set_rlim(0, 90)
    ax.set_rticks([0, 30, 60, 80], ["90", "60", "30", "10"], fontsize="x-small")
    ax.set_rlabel_position(135)
    colors = {"GEO": "tab:red", "IGSO": "tab:purple", "MEO": "tab:blue"}
    for prn, (az, el) in sorted(tracks.items()):
        az, el = np.radians(np.asarray(az, float)), np.asarray(el, float)
        ok = np.isfinite(az) & np.isfinite(el) & (el > 0)
        if not ok.any():
            continue
        kind = orbit_type(prn)
        ax.plot(az[ok], 90 - el[ok], color=colors[kind], lw=1.5)
        solid = prn in used
        ax.plot(az[ok][-1], 90 - el[ok][-1], _MARK[kind], ms=9, color=colors[kind],
                mfc=colors[kind] if solid else "white")
        ax.annotate(f"C{prn:02d}", (az[ok][-1], 90 - el[ok][-1]), fontsize="x-small",
                    xytext=(6, 4), textcoords="offset points")
    handles = [Line2D([], [], marker=_MARK[k], color=c, ls="", label=k)
               for k, c in colors.items()]
    handles.append(Line2D([], [], marker="o", color="0.3", mfc="white", ls="",
                          label="not tracked"))
    ax.legend(handles=handles, fontsize="x-small", loc="lower left",
              bbox_to_anchor=(-0.12, -0.08))
    ax.set_title(f"{title}: sky (azimuth from north, elevation [deg]); marker at the end",
                 fontsize="medium")
    return save_png(fig, path, DPI)
