"""The tuning section of a study's ``report.html`` (from ``tuning.csv``, :mod:`.tuning`)."""

from __future__ import annotations

import html
from pathlib import Path

from .campaign_report import sig
from .tables import read_csv_table

__all__ = ["tuning_html"]


def tuning_html(path: Path) -> str:
    """``<h2>Tuning</h2>``: per filter the chosen options (flagged when the point lies on an
    edge of its grid: ``edge`` in tuning.csv), then the criterion over the grid (mean over
    the tuning cells and training seeds; the chosen point in bold)."""
    head, table = read_csv_table(path)
    rows = [dict(zip(head, r)) for r in table]
    means = [r for r in rows if r["seed"] == "mean"]
    seeds = list(dict.fromkeys(r["seed"] for r in rows if r["seed"] != "mean"))
    parts = ["<h2>Tuning</h2>",
             f"<p>Each filter's options chosen before the evaluation, on the training seeds "
             f"{html.escape(', '.join(seeds))} (disjoint from the evaluation seeds) of "
             f"{html.escape(' / '.join(dict.fromkeys(r['cell'] for r in means)))} "
             "(cells joined by + are pooled; one choice per group): the lowest criterion "
             "(mean over those runs; a failed run scores inf)"
             + (", among the points whose NIS stayed in the band" if "nis_ok" in head else "")
             + ". Chosen:</p><ul>"]
    groups = len(set(r["cell"] for r in means))
    for r in means:
        if r["chosen"] == "1":
            where = f" in {r['cell']}" if groups > 1 else ""
            flag = ""
            if r.get("edge") == "1":
                flag = (" <span class='v-reversed'>&#9888; on the grid's edge: "
                        f"{html.escape(r.get('edge_options', ''))}; the best value may lie "
                        "beyond the grid</span>")
            parts.append(f"<li><b>{html.escape(r['filter'])}</b>{html.escape(where)}: "
                         f"<code>{html.escape(r['options'])}</code> (score "
                         f"{sig(float(r['score']))}){flag}</li>")
    parts.append("</ul><table><tr><th>cells</th><th>filter</th><th>options</th><th>score</th>"
                 + ("<th>NIS in band</th>" if "nis_ok" in head else "") + "</tr>")
    for r in means:
        b, e = ("<b>", "</b>") if r["chosen"] == "1" else ("", "")
        parts.append(f"<tr><td>{html.escape(r['cell'])}</td><td>{html.escape(r['filter'])}</td>"
                     f"<td>{b}"
                     f"{html.escape(r['options'])}{e}</td><td>{b}{sig(float(r['score']))}{e}"
                     "</td>" + (f"<td>{html.escape(r.get('nis_ok', ''))}</td>"
                                if "nis_ok" in head else "") + "</tr>")
    parts.append("</table>")
    return "".join(parts)
