"""The consistency table of an integrated run: NIS per block, NEES per quantity, a verdict each.

A run's summary JSON carries, per statistic, the mean per degree of freedom over the run
(``value``, expected 1), the sample count ``n``, the effective count ``n_eff`` and the 95 %
``band`` (:mod:`~sdr_di.integration.consistency`). The verdict
(:func:`~sdr_di.integration.consistency.verdict`) compares the mean with the band::

    value < low    pessimistic    the filter's covariance is larger than its errors
    value > high   overconfident  the covariance is smaller than its errors
    otherwise      consistent

An entry without a band (a summary written by hand, or by an older version) gets the
chi-square band of the mean of ``n_eff`` (else ``n``) samples of ``dof`` degrees of freedom
each (:func:`~sdr_di.integration.consistency.chi2_band`; ``dof`` from the entry, else 3 for
NEES and 1 for NIS).
"""

from __future__ import annotations

import html
import math

from ..integration.consistency import chi2_band, verdict

__all__ = ["VERDICTS", "consistency_rows", "consistency_table_html", "verdict"]

#: Verdict -> what it means for the filter, in one phrase.
VERDICTS = {"consistent": "covariance matches the errors",
            "pessimistic": "covariance larger than the errors",
            "overconfident": "covariance smaller than the errors",
            "no samples": "nothing to judge"}

_LABELS = {"nis_code": "NIS, code (pseudorange) block", "nis_range": "NIS, pseudorange block",
           "nis_rate": "NIS, pseudorange-rate block", "nis_vel": "NIS, velocity block",
           "nis_pos": "NIS, position block", "nees_pos": "NEES, position",
           "nees_vel": "NEES, velocity", "nees_att": "NEES, attitude"}


def _band(key: str, entry: dict) -> tuple[list[float], int, float]:
    dof = int(entry.get("dof") or (3 if key.startswith("nees") else 1))
    n_eff = entry.get("n_eff")
    n_eff = float(n_eff if n_eff is not None else entry.get("n") or 0)
    band = entry.get("band")
    if not band or any(b is None for b in band):
        band = chi2_band(n_eff, dof)
    return [float(b) for b in band], dof, n_eff


def consistency_rows(consistency: dict) -> list[dict]:
    """One row per statistic of a summary's ``consistency`` entry.

    Returns
    -------
    list of dict
        ``key``, ``label``, ``value`` (mean per degree of freedom), ``low``, ``high`` (the
        95 % band), ``n``, ``n_eff``, ``dof``, ``verdict`` (:func:`verdict`), in the
        summary's order.
    """
    rows = []
    for key, entry in consistency.items():
        if not isinstance(entry, dict):
            continue
        band, dof, n_eff = _band(key, entry)
        value = entry.get("value")
        rows.append({"key": key, "label": _LABELS.get(key, key), "value": value,
                     "low": band[0], "high": band[1], "n": entry.get("n"), "n_eff": n_eff,
                     "dof": dof, "verdict": verdict(value, band)})
    return rows


def _num(v, digits: int = 3) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    return f"{v:.{digits}g}"


def consistency_table_html(consistency: dict, table_id: str) -> str:
    """The table (``id=table_id``) with one sentence on how to read it."""
    rows = consistency_rows(consistency)
    if not rows:
        return "<p><em>the summary has no consistency entry</em></p>"
    out = [f'<table id="{html.escape(table_id)}"><tr><th>statistic</th><th>mean per dof'
           "</th><th>95 % band</th><th>samples (effective)</th><th>dof</th><th>verdict</th>"
           "</tr>"]
    for r in rows:
        cls = {"consistent": "v-holds", "no samples": "v-not-shown"}.get(r["verdict"],
                                                                          "v-reversed")
        out.append(f"<tr><td>{html.escape(r['label'])}</td><td>{_num(r['value'])}</td>"
                   f"<td>{_num(r['low'])} - {_num(r['high'])}</td>"
                   f"<td>{r['n'] if r['n'] is not None else '-'} ({_num(r['n_eff'])})</td>"
                   f"<td>{r['dof']}</td><td class='{cls}'>{html.escape(r['verdict'])}: "
                   f"{html.escape(VERDICTS[r['verdict']])}</td></tr>")
    out.append("</table>")
    rule = consistency.get("band_rule")
    out.append("<p class='note'>Expected value 1 per degree of freedom. Below the band: "
               "pessimistic; above it: overconfident."
               + (f" Band: {html.escape(str(rule))}." if rule else "") + "</p>")
    return "".join(out)
