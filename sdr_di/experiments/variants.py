"""The per-run bookkeeping of every filter/mode comparison, in one place.

A *variant* is one receiver configuration run on a run's generated files: an integration
filter (with options) in a coupling mode. Every experiment that compares variants
(``count-change``, ``outage``, ``weak-signal``, ``compare``, and so every study) does the
same per variant: run it on the shared files, record whether it completed, fill NaN figures
when it failed, compute the error RMSE/max over a window, write the error time series and
draw the error norms. :func:`run_variants` does that; the experiment adds only its own
figures (a callback) and its own schedule.

Labels
------
A variant's label prefixes its figures (``"<label>.pos_m_rmse"``) and names its files
(``errors_<label>.csv``): the filter entry as given (``ff-aukf``,
``ff-aukf:q_states=nominal``), followed by ``@loose`` or ``@tight`` for those couplings.
Deep, the system's own coupling, has no suffix, so the figures of the deep-only experiments
keep their names; a deep variant with its own measurement architecture has it as the suffix
(``ekf@reset``, ``ekf@discriminator``). ``loose`` here is the receiver's own WLS fixes fed to the filter
(``sdr-di run --mode loose``), never ``sdr-di lc`` (simulated position/velocity, the
``noise-mismatch`` experiment).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ExperimentError
from ..coupling.config import DEEP_MEASUREMENTS
from ..filters.spec import canonical_entry
from . import plotting
from ._deep import DEEP_ONLY, Inputs, record_run, run_deep_variant, segment_metrics
from .entries import MODES, check_filter_entry, filter_list, mode_list, split_entry
from .filter_figures import QUANTITIES, STATS, filter_names_in

__all__ = ["MODES", "Variant", "entry_label", "loop_config", "mode_list", "nan_figures", "plot_error_norms",
           "run_variants", "split_entry",
           "variant_label", "variant_list", "variant_rows", "write_errors_csv"]

def variant_label(filter_spec: str, mode: str = "deep") -> str:
    """Figure prefix of a filter entry in a mode (module notes)."""
    return filter_spec if mode == "deep" else f"{filter_spec}@{mode}"


@dataclasses.dataclass(frozen=True)
class Variant:
    """One receiver configuration of a comparison.

    Attributes
    ----------
    spec : str
        Filter entry as given (``"ff-aukf:q_states=nominal"``).
    filter : str
        Filter registry name.
    options : dict
        Filter options (:func:`~sdr_di.filters.make_filter` keyword arguments).
    mode : str
        ``"loose"``, ``"tight"`` or ``"deep"``, or a deep measurement architecture
        (``"prefilter"``, ``"reset"``, ``"discriminator"``: deep mode with it).
    """

    spec: str
    filter: str
    options: dict
    mode: str = "deep"

    @property
    def label(self) -> str:
        """Figure prefix and file-name stem (module notes)."""
        return variant_label(self.spec, self.mode)

    @property
    def coupling(self) -> str:
        """The coupling mode (``IntegrationConfig.mode``)."""
        return "deep" if self.mode in DEEP_MEASUREMENTS else self.mode

    @property
    def architecture(self) -> str | None:
        """The deep measurement architecture the entry names (None: the cell's)."""
        return self.mode if self.mode in DEEP_MEASUREMENTS else None


def entry_label(entry: str, mode: str = "deep") -> str:
    """Label of a filter entry (``ekf``, ``ekf@tight``) run in a cell whose mode is ``mode``."""
    return variant_label(*split_entry("filters", entry, mode))


def variant_list(exp: str, filters: str, modes: str = "deep") -> list[Variant]:
    """Every mode crossed with every filter entry (mode-major order). An entry with its own
    mode (``ekf@tight``: how a study compares couplings paired on the same files) runs once,
    in that mode, with the first mode's variants."""
    out = []
    entries = [canonical_entry(e) for e in str(filters).split(",") if e.strip()]
    own = [e for e in entries if "@" in e]
    crossed = ",".join(e for e in entries if "@" not in e) if len(own) < len(entries) else ""
    for k, mode in enumerate(mode_list(exp, modes)):
        for spec in filter_list(exp, crossed) if crossed else []:
            name, opts = check_filter_entry(exp, spec)
            out.append(Variant(spec, name, opts, mode))
        for e in own if k == 0 else []:
            spec, m = split_entry(exp, e)
            name, opts = check_filter_entry(exp, spec)
            out.append(Variant(spec, name, opts, m))
    labels = [v.label for v in out]
    if len(set(labels)) != len(labels):
        raise ExperimentError(f"{exp}: filters={filters!r}, modes={modes!r}: the same variant "
                              "twice")
    return out


def loop_config(params: dict, **fixed: Any) -> dict:
    """:class:`~sdr_di.integration.receiver.IntegrationConfig` keywords from an experiment's
    parameters.

    ``filter_rate_hz``, ``output_rate_hz``, ``gnss_rate_hz`` (loose/tight fix or observable
    rate), ``handover_wait_s`` (the hand-over rule's wait after the first fix, before 4
    channels with time and ephemeris suffice), ``deep_cn0_min_dbhz`` (the loop's channel
    gate, as ``cn0_min_dbhz``), ``nco_latency``, ``deep_measurements`` and
    ``fusion_rate_hz`` (deep variants only: :func:`~._deep.run_deep_variant`) are taken
    when present and not ``None``; ``fixed`` wins over them.
    """
    cfg: dict = {}
    for key in ("filter_rate_hz", "output_rate_hz", "gnss_rate_hz", "handover_wait_s"):
        if params.get(key) is not None:
            cfg[key] = float(params[key])
    if params.get("deep_cn0_min_dbhz") is not None:
        cfg["cn0_min_dbhz"] = float(params["deep_cn0_min_dbhz"])
    if params.get("nco_latency") is not None:
        cfg["nco_latency"] = int(params["nco_latency"])
    if params.get("deep_measurements") is not None:
        cfg["deep_measurements"] = str(params["deep_measurements"])
    if params.get("fusion_rate_hz") is not None:
        cfg["fusion_rate_hz"] = float(params["fusion_rate_hz"])
    cfg.update(fixed)
    return cfg


def check_deep_options(exp: str, params: dict) -> None:
    """Reject deep-mode settings the receiver would refuse: an ``nco_latency`` other than
    ``None`` (the receiver's default), 0 or 1; a ``deep_measurements`` that is not an
    architecture (:data:`~sdr_di.coupling.config.DEEP_MEASUREMENTS`); a
    ``fusion_rate_hz`` that does not fit them (:class:`~sdr_di.coupling.config.
    IntegrationConfig`)."""
    from ..coupling.config import DEEP_MEASUREMENTS, IntegrationConfig, is_nco_latency

    v = params.get("nco_latency")
    if v is not None and not is_nco_latency(v):
        raise ExperimentError(f"{exp}: nco_latency={v!r}: expected 0 or 1 (filter intervals "
                              "between an update and the NCO commands it first steers)")
    a = params.get("deep_measurements")
    if a is not None and a not in DEEP_MEASUREMENTS:
        raise ExperimentError(f"{exp}: deep_measurements={a!r}: expected one of "
                              f"{', '.join(DEEP_MEASUREMENTS)}")
    try:
        IntegrationConfig(**{k: params[k] for k in DEEP_ONLY + ("filter_rate_hz",)
                             if params.get(k) is not None})
    except (ValueError, TypeError) as exc:
        raise ExperimentError(f"{exp}: {exc}") from None


def nan_figures(label: str, infix: str = "") -> dict:
    """``{label}.{infix}{q}_{s}`` = NaN for every quantity and statistic (a failed run)."""
    return {f"{label}.{infix}{q}_{s}": math.nan for q, _ in QUANTITIES for s in STATS}


def write_errors_csv(path: Path, res: Any, extra: dict[str, np.ndarray] | None = None) -> Path:
    """One row per output row: ``t_s, n_used, used_Cxx.., cn0_Cxx.., <extra>``, the
    attitude [deg], velocity [m/s] and position [m] errors (ENU)."""
    from ..io.atomic import atomic_open

    extra = extra or {}
    prns = list(res.prns)
    cols = ["t_s", "n_used", *(f"used_C{p:02d}" for p in prns),
            *(f"cn0_C{p:02d}" for p in prns), *extra,
            "att_err_e_deg", "att_err_n_deg", "att_err_u_deg",
            "vel_err_e", "vel_err_n", "vel_err_u", "pos_err_e_m", "pos_err_n_m", "pos_err_u_m"]
    n = np.asarray(res.t).size
    used = np.asarray(res.used, float).reshape(n, len(prns))
    cn0 = np.asarray(res.cn0_dbhz, float).reshape(n, len(prns))
    data = np.column_stack([res.t, res.n_used, used, cn0,
                            *(np.asarray(v, float) for v in extra.values()),
                            res.att_err, res.vel_err, res.pos_err])
    with atomic_open(path, "w") as fh:
        fh.write(",".join(cols) + "\n")
        np.savetxt(fh, data, delimiter=",", fmt="%.10g")
    return path


def plot_error_norms(path: Path, series: dict, title: str,
                     spans: Sequence[tuple[float, float]] = ()) -> Path:
    """Attitude, velocity and position error norms over time, one line per variant."""
    t_by = {n: r.t for n, r in series.items()}
    panels = [(label, {n: np.linalg.norm(getattr(r, f"{q[:3]}_err"), axis=1)
                       for n, r in series.items()}) for q, label in QUANTITIES]
    return plotting.time_series(path, t_by, panels, title=title, spans=spans)


def run_variants(inputs: Inputs, variants: Sequence[Variant], cfg: dict, fig: dict,
                 out_dir: Path, *, window: tuple[float | None, float | None] = (None, None),
                 figures: Callable[[str, Any], dict] | None = None,
                 failed: Callable[[str], dict] | None = None,
                 csv_extra: Callable[[Any], dict] | None = None) -> dict:
    """Run every variant on ``inputs``; record its figures into ``fig``.

    Per variant (label ``f``): ``f.completed``, ``f.error`` or ``f.handover_s`` and
    ``f.acq_after_handover`` (:func:`~._deep.record_run`), ``f.{q}_{rmse,max}`` over
    ``window`` (NaN when it failed), the experiment's own ``figures(f, result)`` (or
    ``failed(f)`` when it failed), and ``errors_<f>.csv`` in ``out_dir`` (with the
    columns of ``csv_extra(result)``).

    Parameters
    ----------
    inputs : Inputs
        The run's generated files (:class:`~._deep.generated_inputs`).
    variants : sequence of Variant
    cfg : dict
        :class:`~sdr_di.integration.receiver.IntegrationConfig` keywords shared by the
        variants (:func:`loop_config`).
    fig : dict
        The run's figures, updated in place.
    out_dir : Path
        The run's output folder.
    window : (t0, t1)
        Time window of the overall RMSE/max [s since file start]; ``None`` = open.

    Returns
    -------
    dict
        ``{label: IntegrationResult}`` of the variants that completed, in order.
    """
    series: dict = {}
    for v in variants:
        arch = {} if v.architecture is None else {"deep_measurements": v.architecture}
        dr = run_deep_variant(inputs, v.filter, mode=v.coupling,
                              filter_options=dict(v.options), **{**cfg, **arch})
        res = record_run(fig, v.label, dr)
        if res is None:
            fig.update(nan_figures(v.label))
            if failed is not None:
                fig.update(failed(v.label))
            continue
        fig.update(segment_metrics(res, window[0], window[1], f"{v.label}."))
        if figures is not None:
            fig.update(figures(v.label, res))
        write_errors_csv(Path(out_dir) / f"errors_{v.label}.csv", res,
                         csv_extra(res) if csv_extra is not None else None)
        series[v.label] = res
    return series


def variant_rows(stats: dict, keys: Sequence[str], *, infix: str = "",
                 std: Callable[[str], bool] = lambda k: True, **fixed: Any) -> list[dict]:
    """One table row per variant found in ``stats``: the mean over runs of
    ``<label>.<infix><key>`` for each key (NaN when absent), ``<key>_std`` beside it when
    there are several runs and ``std(key)``; ``fixed`` columns after the label."""
    rows = []
    for name in filter_names_in(stats):
        row: dict = {"filter": name, **fixed}
        for key in keys:
            st = stats.get(f"{name}.{infix}{key}")
            if isinstance(st, dict) and "mean" in st:
                row[key] = st["mean"]
                if st["n"] > 1 and std(key):
                    row[key + "_std"] = st["std"]
            else:
                row[key] = math.nan
        rows.append(row)
    return rows
