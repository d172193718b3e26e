"""Tables as CSV (for programs) and Markdown (for people), written atomically."""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from pathlib import Path

from ..io.atomic import atomic_open

__all__ = ["columns_of", "format_cell", "read_csv_table", "stats_rows", "write_table"]


def columns_of(rows: Sequence[dict]) -> list[str]:
    """Union of the rows' keys in first-seen order."""
    cols: list[str] = []
    for row in rows:
        for k in row:
            if k not in cols:
                cols.append(k)
    return cols


def format_cell(v, digits: int = 6) -> str:
    """Text of a cell: floats with ``digits`` significant digits, NaN as ``nan``, None as
    empty."""
    if v is None:
        return ""
    if isinstance(v, float):
        return "nan" if math.isnan(v) else f"{v:.{digits}g}"
    return str(v)


def stats_rows(stats: dict[str, dict]) -> list[dict]:
    """Rows ``figure, n, mean, std, min, max`` (or ``value``) of :func:`.aggregate.aggregate`."""
    rows = []
    for key, st in stats.items():
        if "value" in st:
            rows.append({"figure": key, "value": st["value"]})
        else:
            rows.append({"figure": key, "n": st["n"], "mean": st["mean"], "std": st["std"],
                         "min": st["min"], "max": st["max"]})
    return rows


def write_table(out_dir: Path, name: str, rows: Sequence[dict],
                columns: Sequence[str] | None = None,
                md_columns: Sequence[str] | None = None) -> tuple[Path, Path]:
    """Write ``<name>.csv`` (full precision) and ``<name>.md`` (6 significant digits).

    ``columns`` (default: all keys) selects the columns of both files, ``md_columns`` those
    of the Markdown file only (for wide tables).

    Returns
    -------
    (Path, Path)
        The CSV and Markdown files.
    """
    cols = list(columns) if columns is not None else columns_of(rows)
    out_dir = Path(out_dir)
    csv_path, md_path = out_dir / f"{name}.csv", out_dir / f"{name}.md"
    with atomic_open(csv_path, "w") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(cols)
        for row in rows:
            w.writerow(["" if row.get(c) is None else (repr(row[c]) if isinstance(row[c], float)
                                                       else row[c]) for c in cols])
    cols = list(md_columns) if md_columns is not None else cols
    with atomic_open(md_path, "w") as fh:
        fh.write("| " + " | ".join(cols) + " |\n")
        fh.write("|" + "|".join("---" for _ in cols) + "|\n")
        for row in rows:
            cells = (format_cell(row.get(c)).replace("|", "\\|") for c in cols)
            fh.write("| " + " | ".join(cells) + " |\n")
    return csv_path, md_path


def read_csv_table(path: Path) -> tuple[list[str], list[list[str]]]:
    """Header and rows of a CSV table written by :func:`write_table`."""
    text = Path(path).read_text(encoding="utf-8")
    rows = list(csv.reader(io.StringIO(text)))
    return (rows[0], rows[1:]) if rows else ([], [])
