"""What the page shows of one run (:class:`RunSection`) and the pieces the figure modules
share: the figure record, drawing only when the PNG is missing or stale, the local
east-north conversion and number formatting."""

from __future__ import annotations

import dataclasses
import html
import math
from pathlib import Path

import numpy as np

from ..frames import radii_of_curvature
from .run_files import RunFiles

__all__ = ["Drawer", "FigureRef", "RunSection", "east_north", "fmt", "newest_mtime"]


@dataclasses.dataclass
class FigureRef:
    """A figure of a run: its id on the page (``PLOTSTEM-NAME``), caption and PNG."""

    fig_id: str
    caption: str
    path: Path


@dataclasses.dataclass
class RunSection:
    """What the page shows of one run (module notes)."""

    run: RunFiles
    title: str
    facts: list = dataclasses.field(default_factory=list)      # HTML
    failures: list = dataclasses.field(default_factory=list)   # plain text
    notes: list = dataclasses.field(default_factory=list)      # plain text: left out, why
    figures: list = dataclasses.field(default_factory=list)    # FigureRef
    tables: list = dataclasses.field(default_factory=list)     # (id, title, HTML)


class Drawer:
    """Draws a figure only when its PNG is missing or older than the data it shows."""

    def __init__(self, folder: Path, plot_stem: str, newest_input: float, redraw: bool,
                 section: RunSection):
        self.folder, self.plot_stem = folder, plot_stem
        self.newest, self.redraw, self.section = newest_input, redraw, section

    def __call__(self, name: str, caption: str, draw) -> None:
        path = self.folder / f"{self.plot_stem}_{name}.png"
        if self.redraw or not path.is_file() or path.stat().st_mtime < self.newest:
            draw(path)
        self.section.figures.append(FigureRef(f"{self.plot_stem}-{name}", caption, path))


def newest_mtime(paths) -> float:
    """Latest modification time of the files that exist among ``paths`` (0 if none)."""
    return max((Path(p).stat().st_mtime for p in paths if p is not None and Path(p).exists()),
               default=0.0)


def east_north(lat_deg, lon_deg, h_m, lat0: float, lon0: float) -> np.ndarray:
    """East and north [m] of geodetic points from (lat0, lon0) [rad] (local tangent plane,
    radii of curvature at lat0: a run's few km)."""
    R_M, R_N = (float(r) for r in radii_of_curvature(lat0))
    h = np.nan_to_num(np.asarray(h_m, float))
    return np.column_stack([(np.radians(lon_deg) - lon0) * (R_N + h) * math.cos(lat0),
                            (np.radians(lat_deg) - lat0) * (R_M + h)])


def fmt(v, digits: int = 3) -> str:
    """``v`` at ``digits`` significant digits for the page (``-`` for None, ``nan``)."""
    if v is None:
        return "-"
    try:
        v = float(v)
    except (TypeError, ValueError):
        return html.escape(str(v))
    return "nan" if not math.isfinite(v) else f"{v:.{digits}g}"
