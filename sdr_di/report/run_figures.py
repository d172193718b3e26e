"""The figures and tables of one run, from what its folder holds (``run --plots`` and
``sdr-di report`` both come here).

:func:`draw_run` reads a :class:`~sdr_di.report.run_files.RunFiles` and returns a
:class:`RunSection`: its figures (PNG beside the run's files, ``PLOTSTEM_NAME.png``, drawn
when missing or older than the data they show), its tables (HTML), the facts of the run,
what failed, and one line for each part left out with the reason.

One module per kind of run: :mod:`.integrated_figures`, :mod:`.scalar_figures`; the
section and its helpers: :mod:`.section`.

Figures (``NAME``; ``PLOTSTEM`` = ``STEM_MODE``, ``STEM_scalar`` for a scalar run):

============== ======================================================================
integrated     ``pos-error``, ``vel-error``, ``att-error`` (per ENU axis with the filter's
(deep, loose,  +-3 sigma; with a reference), ``nis`` (per block against its band),
tight, lc)     ``trajectory`` (east-north, with the truth), ``channels`` (C/N0 and use
               per channel), ``innovations`` (deep, tight: per channel, normalized),
               ``sats-used``; table ``consistency``. ``lc`` has no position
               rows and no channels (its NIS is per row, all blocks together).
scalar         ``fix-pos-error``, ``fix-vel-error`` (per ENU axis against the reference
               file the run recorded), ``channels`` (C/N0 and lock from the
               run's RINEX observation file), ``sky``, ``fix-status``, ``trajectory``;
               table ``navdata`` (per satellite: orbit, state, ephemeris decoded, toe,
               subframes, records in the navigation file written)
============== ======================================================================
"""

from __future__ import annotations

from pathlib import Path

from .integrated_figures import integrated_section
from .run_files import RunFiles
from .scalar_figures import scalar_section
from .section import FigureRef, RunSection

__all__ = ["FigureRef", "RunSection", "draw_run"]


def draw_run(folder: str | Path, run: RunFiles, redraw: bool = False) -> RunSection:
    """Figures, tables, facts and notes of one run of ``folder`` (module notes).

    ``redraw``: draw every figure even when its PNG is up to date (``run --plots``).
    """
    folder = Path(folder)
    if run.kind == "scalar":
        return scalar_section(folder, run, redraw)
    return integrated_section(folder, run, redraw)
