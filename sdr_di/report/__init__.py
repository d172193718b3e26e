"""The report of one run: ``sdr-di report RUN_DIR`` and ``sdr-di run --plots``.

Modules, in the order the data flows:

``run_files``          what a run folder holds, read back as arrays (no rerun)
``figures``            one function per figure (matplotlib, Agg, PNG)
``sky``                azimuth and elevation of the satellites from broadcast ephemerides
``consistency_table``  NIS per block and NEES per quantity against their bands, a verdict each
``run_figures``        the figures and tables of one run from its files
``run_page``           the self-contained HTML page (figures embedded as base64 PNG)

This package sits above the receiver, integration and studies packages (it reads their
files and borrows the report style of :mod:`sdr_di.studies.campaign_report`); only the CLI
and the ``report`` command call it.
"""

from .consistency_table import consistency_rows, verdict
from .run_files import find_runs, is_run_folder
from .run_page import render_run_report, write_run_plots

__all__ = ["consistency_rows", "find_runs", "is_run_folder", "render_run_report", "verdict",
           "write_run_plots"]
