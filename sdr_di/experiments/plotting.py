"""PNG plots of experiment results with matplotlib's object API (no pyplot, no display).

matplotlib is a dependency of sdr-di (reports are a feature, not an extra), but a broken or
missing installation must not lose a run's figures: :func:`matplotlib_missing` says why plots
cannot be drawn, and the callers record that note instead of a plot.
"""

from __future__ import annotations

import importlib
import io
import math
import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..io.atomic import atomic_open

__all__ = ["PLOTS_SKIPPED", "bar_chart", "matplotlib_missing", "plain_log_axis", "ratio_axis",
           "rmse_bar_plot", "save_png", "time_series"]

PLOTS_SKIPPED = "plots skipped: matplotlib is not installed (pip install matplotlib)"


def matplotlib_missing() -> str | None:
    """``None`` when matplotlib can draw PNGs, else a one-line note saying why not."""
    try:
        for mod in ("matplotlib.figure", "matplotlib.backends.backend_agg"):
            importlib.import_module(mod)
    except ImportError:
        return PLOTS_SKIPPED
    return None


def save_png(fig, path: Path, dpi: int = 100) -> Path:
    """Draw a :class:`matplotlib.figure.Figure` with the Agg canvas (no display) and write it
    as PNG at ``dpi``, atomically."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    with atomic_open(path, "wb") as fh:
        fh.write(buf.getvalue())
    return path


def plain_log_axis(ax, axis: str = "y") -> None:
    """Ticks of a log axis at 1, 2 and 5 per decade labelled as plain decimals (0.5, 1, 2),
    never in the ``10^x`` forms a reader has to decode ("9.95x10^-1")."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    a = ax.yaxis if axis == "y" else ax.xaxis
    a.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
    a.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    a.set_minor_formatter(NullFormatter())


def ratio_axis(ax, values, axis: str = "y") -> None:
    """Scale of an axis of ratios (1 = equal): logarithmic with :func:`plain_log_axis` when
    ``values`` span a factor of 3 or more, else linear (a log axis over 0.9-1.1 would have
    one labelled tick); plain decimal labels either way."""
    from matplotlib.ticker import FuncFormatter

    v = np.asarray([x for x in np.ravel(values) if np.isfinite(x) and x > 0], float)
    wide = v.size > 0 and v.max() / v.min() >= 3.0
    if wide:
        (ax.set_yscale if axis == "y" else ax.set_xscale)("log")
        plain_log_axis(ax, axis)
    else:
        a = ax.yaxis if axis == "y" else ax.xaxis
        a.set_major_formatter(FuncFormatter(lambda x, _: f"{x:.3g}"))


def time_series(path: Path, t_by_label: dict[str, np.ndarray],
                panels: Sequence[tuple[str, dict[str, np.ndarray]]], title: str = "",
                spans: Sequence[tuple[float, float]] = ()) -> Path:
    """One panel per quantity, one line per label (e.g. error norm per filter) against time.

    Parameters
    ----------
    path : Path
        PNG to write (atomically).
    t_by_label : dict
        Time [s] of each label's series.
    panels : sequence of (ylabel, {label: values})
    title : str
    spans : sequence of (t0, t1)
        Time windows to shade (e.g. noise windows).
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9, 2.6 * len(panels)), layout="constrained")
    axes = fig.subplots(len(panels), 1, sharex=True, squeeze=False)[:, 0]
    for ax, (ylabel, series) in zip(axes, panels):
        for label, y in series.items():
            ax.plot(t_by_label[label], y, lw=1.0, label=label)
        for t0, t1 in spans:
            ax.axvspan(t0, t1, color="0.85", zorder=0)
        ax.set_ylabel(ylabel)
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel("time [s]")
    axes[0].legend(fontsize="x-small", ncol=5, loc="upper right")
    if title:
        fig.suptitle(title)
    return save_png(fig, path)


def bar_chart(path: Path, labels: Sequence[str],
              panels: Sequence[tuple[str, Sequence[float], Sequence[float] | None]],
              title: str = "") -> Path:
    """Grouped panels of bars (one bar per label) with optional error bars (e.g. std)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9, 2.4 * len(panels)), layout="constrained")
    axes = fig.subplots(len(panels), 1, sharex=True, squeeze=False)[:, 0]
    x = np.arange(len(labels))
    for ax, (ylabel, values, err) in zip(axes, panels):
        ax.bar(x, values, yerr=err, capsize=3, color="tab:blue", alpha=0.8)
        ax.set_ylabel(ylabel)
        ax.grid(True, axis="y", alpha=0.3)
    axes[-1].set_xticks(x, labels, rotation=30, ha="right")
    if title:
        fig.suptitle(title)
    return save_png(fig, path)


def rmse_bar_plot(results: list[dict], out_dir: Path, title: str) -> list[Path]:
    """``rmse_by_filter.png``: mean RMSE per filter over the runs, std as error bars."""
    from .filter_figures import QUANTITIES, filter_names_in

    if not results or matplotlib_missing():
        return []
    names = filter_names_in(results[0]["figures"])
    if not names:
        return []
    panels = []
    for q, label in QUANTITIES:
        vals = np.array([[r["figures"].get(f"{n}.{q}_rmse", math.nan) for n in names]
                         for r in results], float)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            panels.append((f"RMSE {label}", np.nanmean(vals, axis=0),
                           np.nanstd(vals, axis=0) if len(results) > 1 else None))
    return [bar_chart(Path(out_dir) / "rmse_by_filter.png", names, panels,
                               title=f"{title} ({len(results)} runs)")]
