"""``jamming``: the J/S at which each receiver mode (scalar, loose, tight, deep) loses the
satellites under a noise jammer whose J/S ramps up over one file (issue 15's closing figure).

**Schedule** (one generated file per run): every satellite at the scenario's C/N0 (default
40 dB-Hz), no jammer until ``t_on_s`` (default 15 s, after the deep hand-over at about
12 s); from ``t_on_s`` a band-limited noise jammer (``[[interference]] type = "noise"``,
``jammer_bandwidth_hz`` wide, ``jammer_offset_hz`` from the carrier) whose J/S goes linearly
in dB from ``js_start_db`` to ``js_stop_db`` over ``ramp_s`` (the generator's ramp,
``js_end_db``; ``docs/impairments.md``); the file ends with the ramp. J/S is relative to a
satellite at the nominal C/N0 (``docs/impairments.md``). ``bits`` is the quantizer's output
width (4: the default front end, ``iq_int8``; 16: ``iq_int16``, where quantization adds no
loss of its own); the front end's AGC follows the jammer.

**Effective C/N0.** The J/S of the ramp maps to the nominal satellite's effective C/N0
through the sidecar's spectral separation coefficient ``kappa`` of the file as sampled:
``1 / (C/N0)_eff = 1 / (C/N0) + (J/S) kappa`` (:func:`~sdr_di.sim.interference
.effective_cn0_dbhz`; the J/S is relative to that satellite).

**Modes** are those of ``weak-signal`` on the same file (:mod:`.weak_signal`): ``scalar``
(scalar loops + PVT at 5 Hz; a channel is *kept* at an epoch when in ``TRACK`` with code
lock and used in the fix) and the loop couplings ``loose``, ``tight``, ``deep`` (10 Hz rows;
*kept* = in the filter's measurement vector).

**Loss (defined before any run).** At an output epoch a mode *holds its solution* when at
least ``min_channels`` (4) channels are kept, the scalar PVT has a valid fix (scalar), and
the position error norm is below ``pos_limit_m`` (10 m); it *holds every channel* when all
simulated channels are kept. A mode **loses its solution** at the first epoch ``t >=
t_on_s`` from which it fails to hold its solution at every epoch of the next
``loss_window_s`` (2 s); the **J/S at loss** is the ramp's J/S at that epoch. The first
channel drop is defined the same way with "holds every channel". A mode that never loses
has ``lost = 0`` and NaN thresholds (the ramp's top is a lower bound). A loop run must have
handed over before ``t_on_s``, else the run records the error and NaN.

**Reference without a jammer** (``reference = true``, the default): a second file, the
same seed and schedule without the jammer, in which every satellite's C/N0 follows the
effective C/N0 path of the ramp as a staircase of ``ref_step_s`` (0.5 s) attenuation
windows (``[[outage]] attenuation_db``). The C/N0 at which a mode loses its solution there is
an independent measurement of the same threshold: when the receiver's loss under the jammer
is what the effective C/N0 says, ``<mode>.jam_minus_ref_db`` is near 0 (within the step and
the ramp's slope times the loss window).

Figures per mode ``m``: ``m.lost`` (0/1), ``m.js_loss_db``, ``m.cn0_eff_loss_dbhz``
(effective C/N0 at that J/S), ``m.t_loss_s``, ``m.js_drop_db`` (first channel drop),
``m.handover_s`` (loop modes), ``m.error``; with the reference ``m.ref_cn0_loss_dbhz``,
``m.jam_minus_ref_db``; and ``deep_gain_js_db`` etc. = the mode's J/S at loss minus the
scalar's. Run figures: ``kappa_per_hz``, ``sampling_rate_hz``, ``bits``.
Files: ``loss_<m>.csv`` per mode (epoch, J/S, effective C/N0, kept channels, position error;
jammed file) and ``jamming.png`` (kept channels against J/S per mode).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ..errors import ExperimentError, ScenarioError
from ..scenario import Scenario, parse_scenario
from . import plotting
from ._deep import (
    base_scenario,
    check_number,
    generated_inputs,
    has_mean,
    run_deep_variant,
)
from .entries import check_filter_entry, filter_list
from .variants import check_deep_options, loop_config, mode_list
from .weak_signal import MODES, scalar_run

__all__ = ["DESCRIPTION", "MODES", "NAME", "check_params", "default_params", "js_at",
           "loss_time", "plots", "run", "tables"]

NAME = "jamming"
DESCRIPTION = ("noise jammer ramped in J/S after the start-up; J/S (and effective C/N0) at "
               "which each mode (scalar, loose, tight, deep) loses its solution")

default_params: dict = {
    "scenario": None,
    "modes": "scalar,deep",
    "filter": "ff-aukf",
    "bits": 4,
    "jammer_bandwidth_hz": 2.0e6,
    "jammer_offset_hz": 0.0,
    "js_start_db": 30.0,
    "js_stop_db": 55.0,
    "t_on_s": 15.0,
    "ramp_s": 25.0,
    "min_channels": 4,
    "pos_limit_m": 10.0,
    "loss_window_s": 2.0,
    "reference": True,
    "ref_step_s": 0.5,
    "sampling_rate_hz": None,
    "deep_cn0_min_dbhz": None,
    "filter_rate_hz": 50.0,
    "nco_latency": None,
    "deep_measurements": None,
    "fusion_rate_hz": None,
    "plots": True,
}

#: Output widths of the quantizer: bits -> sample format (complex, real).
_FORMATS = {4: ("iq_int8", "real_int8"), 8: ("iq_int8", "real_int8"),
            16: ("iq_int16", "real_int16")}


def _modes(text: str) -> list[str]:
    return mode_list(NAME, text, MODES)


def check_params(params: dict) -> None:
    """Reject bad parameter values with :class:`~sdr_di.errors.ExperimentError` (one line
    naming the parameter)."""
    check_deep_options(NAME, params)
    _modes(params["modes"])
    filter_list(NAME, params["filter"])
    if isinstance(params["bits"], bool) or params["bits"] not in _FORMATS:
        raise ExperimentError(f"{NAME}: bits={params['bits']!r}: expected one of "
                              f"{', '.join(map(str, _FORMATS))}")
    for key in ("jammer_bandwidth_hz", "t_on_s", "ramp_s", "pos_limit_m", "loss_window_s",
                "ref_step_s", "filter_rate_hz"):
        check_number(NAME, params, key)
    for key in ("jammer_offset_hz", "js_start_db", "js_stop_db"):
        check_number(NAME, params, key, lo=-math.inf)
    check_number(NAME, params, "sampling_rate_hz", allow_none=True)
    check_number(NAME, params, "deep_cn0_min_dbhz", allow_none=True, lo_open=False)
    if isinstance(params["min_channels"], bool) or params["min_channels"] not in range(1, 64):
        raise ExperimentError(f"{NAME}: min_channels={params['min_channels']!r}: expected an "
                              "integer 1..63")
    if params["js_stop_db"] <= params["js_start_db"]:
        raise ExperimentError(f"{NAME}: js_stop_db={params['js_stop_db']!r}: must exceed "
                              f"js_start_db ({params['js_start_db']!r}): the ramp goes up")
    if params["loss_window_s"] >= params["ramp_s"]:
        raise ExperimentError(f"{NAME}: loss_window_s={params['loss_window_s']!r}: must be "
                              f"shorter than ramp_s ({params['ramp_s']!r})")
    if params["scenario"] is not None and not Path(str(params["scenario"])).is_file():
        raise ExperimentError(f"{NAME}: scenario {params['scenario']}: no such file")
    # the jammer's own checks (J/S range, band inside the sampled band) before any work
    base = base_scenario({**params, "cn0_dbhz": None}, 0, _duration(params))
    try:
        _jammed(base, params)
    except ScenarioError as exc:
        where, _, what = str(exc).partition("]: ")
        raise ExperimentError(f"{NAME}: jammer (js_start_db, js_stop_db, jammer_bandwidth_hz, "
                              f"jammer_offset_hz, bits): {what or where}") from None


def _duration(params: dict) -> float:
    return float(params["t_on_s"]) + float(params["ramp_s"])


def js_at(params: dict, t) -> np.ndarray:
    """J/S [dB] of the ramp at times ``t`` [s] (NaN before ``t_on_s``)."""
    t = np.asarray(t, float)
    t0, r = float(params["t_on_s"]), float(params["ramp_s"])
    a, b = float(params["js_start_db"]), float(params["js_stop_db"])
    return np.where(t >= t0, a + (b - a) * (t - t0) / r, np.nan)


def _with_signal(sc: Scenario, raw: dict) -> Scenario:
    base = sc.source.parent if sc.source is not None else None
    return parse_scenario(raw, source=sc.source, base_dir=base)


def _raw(sc: Scenario, params: dict) -> dict:
    raw = json.loads(json.dumps(sc.raw, default=str))
    sig = raw.setdefault("signal", {})
    bits = int(params["bits"])
    sig["sample_format"] = _FORMATS[bits][0 if sc.signal.complex_baseband else 1]
    sig["quantization_bits"] = bits
    return raw


def _jammed(sc: Scenario, params: dict) -> Scenario:
    """``sc`` at ``bits`` with the ramped noise jammer."""
    raw = _raw(sc, params)
    raw["interference"] = list(raw.get("interference", [])) + [{
        "type": "noise", "offset_hz": float(params["jammer_offset_hz"]),
        "bandwidth_hz": float(params["jammer_bandwidth_hz"]),
        "js_db": float(params["js_start_db"]), "js_end_db": float(params["js_stop_db"]),
        "start_s": float(params["t_on_s"]), "end_s": _duration(params)}]
    return _with_signal(sc, raw)


def _reference(sc: Scenario, params: dict, cn0_path) -> Scenario:
    """``sc`` at ``bits`` without the jammer, every satellite attenuated along ``cn0_path``
    (callable: time [s] -> C/N0 [dB-Hz]) in ``ref_step_s`` steps from ``t_on_s``."""
    raw = _raw(sc, params)
    c0 = sc.satellites.cn0_dbhz
    step, t0, t1 = float(params["ref_step_s"]), float(params["t_on_s"]), _duration(params)
    n = math.ceil((t1 - t0) / step - 1e-9)
    outs = []
    for k in range(n):
        a, b = t0 + k * step, min(t0 + (k + 1) * step, t1)
        att = c0 - cn0_path(0.5 * (a + b))
        if att > 0:
            outs.append({"prn": "all", "start_s": a, "end_s": b if k < n - 1 else t1 + 1.0,
                         "attenuation_db": round(att, 4)})
    raw["outage"] = list(raw.get("outage", [])) + outs
    return _with_signal(sc, raw)


def loss_time(t: np.ndarray, holds: np.ndarray, t_from: float, window_s: float) -> float:
    """First epoch ``t_k >= t_from`` from which ``holds`` is False at every epoch of
    ``[t_k, t_k + window_s]`` (the window must lie inside the record); NaN when none.

    Parameters
    ----------
    t : (n,) epoch times [s], increasing
    holds : (n,) bool
    t_from, window_s : float [s]
    """
    t = np.asarray(t, float)
    bad = ~np.asarray(holds, bool)
    if t.size == 0:
        return math.nan
    # index of the next epoch that holds, for every epoch (n when none)
    nxt = np.full(t.size + 1, t.size)
    for k in range(t.size - 1, -1, -1):
        nxt[k] = k if not bad[k] else nxt[k + 1]
    for k in np.flatnonzero((t >= t_from) & bad):
        if t[k] + window_s > t[-1]:
            break
        j = nxt[k]
        if j == t.size or t[j] > t[k] + window_s:
            return float(t[k])
    return math.nan


def _mode_series(inp, mode: str, params: dict, filt: str, cfg: dict) -> dict:
    """Per epoch of one mode on ``inp``: ``t``, ``kept`` (n, n_ch), ``valid``, ``pos_err``
    [m]; ``handover_s`` for the loop modes; ``error`` when the run failed."""
    if mode == "scalar":
        try:
            s = scalar_run(inp, 0.0)
        except Exception as exc:  # noqa: BLE001 - a crash is the run's failure
            return {"error": f"{type(exc).__name__}: {exc}"}
        return s
    dr = run_deep_variant(inp, filt, mode=mode, **cfg)
    if dr.result is None:
        return {"error": dr.error}
    r = dr.result
    out = {"t": np.asarray(r.t, float), "kept": np.asarray(r.used, bool),
           "valid": np.ones(np.asarray(r.t).size, bool),
           "pos_err": np.linalg.norm(r.pos_err, axis=1), "handover_s": float(r.handover_s)}
    if r.handover_s >= float(params["t_on_s"]):
        out["error"] = (f"hand-over at {r.handover_s:.2f} s, after the jammer's start at "
                        f"{params['t_on_s']:g} s")
    return out


def _losses(s: dict, params: dict) -> tuple[float, float]:
    """(t of solution loss, t of first channel drop) of a mode's series (NaN: none)."""
    kept, pos = s["kept"], s["pos_err"]
    n_kept = kept.sum(axis=1)
    ok_pos = np.isfinite(pos) & (pos < float(params["pos_limit_m"]))
    holds = (n_kept >= int(params["min_channels"])) & s["valid"] & ok_pos
    t0, w = float(params["t_on_s"]), float(params["loss_window_s"])
    return loss_time(s["t"], holds, t0, w), loss_time(s["t"], kept.all(axis=1), t0, w)


def run(params: dict, seed: int, out_dir: Path) -> dict:
    """One ramp (and its reference): every mode on the same file (module docstring).

    Parameters
    ----------
    params : dict
        :data:`default_params` updated by the caller.
    seed : int
        Scenario seed (IF noise, jammer samples, IMU errors).
    out_dir : Path
        Existing directory for ``loss_<mode>.csv`` and ``jamming.png``.

    Returns
    -------
    dict
        Flat figures (module docstring).
    """
    from ..sim.interference import effective_cn0_dbhz

    check_params(params)
    modes = _modes(params["modes"])
    duration = _duration(params)
    base = base_scenario({**params, "cn0_dbhz": None}, seed, duration)
    c0 = float(base.satellites.cn0_dbhz)
    cfg = loop_config(params, output_rate_hz=10.0)
    filt, opts = check_filter_entry(NAME, params["filter"])
    if opts:
        cfg["filter_options"] = opts
    fig: dict = {"duration_s": duration, "t_on_s": float(params["t_on_s"]), "cn0_dbhz": c0,
                 "bits": int(params["bits"]), "filter": params["filter"],
                 "jammer_bandwidth_hz": float(params["jammer_bandwidth_hz"]),
                 "jammer_offset_hz": float(params["jammer_offset_hz"])}
    series: dict = {}
    with generated_inputs(_jammed(base, params)) as inp:
        meta = json.loads(Path(inp.paths["metadata"]).read_text(encoding="utf-8"))
        kappa = float(meta["interference"][-1]["kappa_per_hz"])
        fig["sampling_rate_hz"] = float(inp.source.sampling_rate_hz)
        fig["kappa_per_hz"] = kappa

        def eff(js):
            return effective_cn0_dbhz(c0, c0, [(float(js), kappa)])

        fig["cn0_eff_start_dbhz"] = eff(params["js_start_db"])
        fig["cn0_eff_stop_dbhz"] = eff(params["js_stop_db"])
        for mode in modes:
            s = _mode_series(inp, mode, params, filt, cfg)
            series[mode] = s
            _record(fig, mode, s, params, eff)
            if "t" in s:
                _write_csv(Path(out_dir) / f"loss_{mode}.csv", s, params, eff)
    if params["reference"]:
        def path(t):
            return eff(js_at(params, t))

        with generated_inputs(_reference(base, params, path)) as inp:
            for mode in modes:
                s = _mode_series(inp, mode, params, filt, cfg)
                t_loss = _losses(s, params)[0] if "t" in s else math.nan
                # the staircase's C/N0 at the loss epoch (the step holding it)
                fig[f"{mode}.ref_cn0_loss_dbhz"] = _stair_cn0(params, path, t_loss)
                fig[f"{mode}.jam_minus_ref_db"] = (fig[f"{mode}.cn0_eff_loss_dbhz"]
                                                   - fig[f"{mode}.ref_cn0_loss_dbhz"])
                if "error" in s:
                    fig[f"{mode}.ref_error"] = s["error"]
    if "scalar" in modes:
        for mode in modes:
            if mode != "scalar":
                fig[f"{mode}_gain_js_db"] = fig[f"{mode}.js_loss_db"] - fig["scalar.js_loss_db"]
    if params["plots"]:
        note = plotting.matplotlib_missing()
        if note is None:
            _plot(Path(out_dir) / "jamming.png", series, params, seed)
        else:
            fig["plots_note"] = note
    return fig


def _stair_cn0(params: dict, path, t: float) -> float:
    if not math.isfinite(t):
        return math.nan
    step, t0 = float(params["ref_step_s"]), float(params["t_on_s"])
    k = math.floor((t - t0) / step + 1e-9)
    a, b = t0 + k * step, min(t0 + (k + 1) * step, _duration(params))
    return float(path(0.5 * (a + b)))


def _record(fig: dict, mode: str, s: dict, params: dict, eff) -> None:
    key = f"{mode}."
    if "handover_s" in s:
        fig[key + "handover_s"] = s["handover_s"]
    if "error" in s:
        fig[key + "error"] = s["error"]
        for k in ("js_loss_db", "cn0_eff_loss_dbhz", "t_loss_s", "js_drop_db"):
            fig[key + k] = math.nan
        fig[key + "lost"] = 0
        return
    t_loss, t_drop = _losses(s, params)
    js = float(js_at(params, t_loss)) if math.isfinite(t_loss) else math.nan
    fig[key + "lost"] = int(math.isfinite(t_loss))
    fig[key + "t_loss_s"] = t_loss
    fig[key + "js_loss_db"] = js
    fig[key + "cn0_eff_loss_dbhz"] = eff(js) if math.isfinite(js) else math.nan
    fig[key + "js_drop_db"] = (float(js_at(params, t_drop)) if math.isfinite(t_drop)
                               else math.nan)


def _write_csv(path: Path, s: dict, params: dict, eff) -> None:
    from ..io.atomic import atomic_open

    js = js_at(params, s["t"])
    with atomic_open(path, "w") as fh:
        fh.write("t_s,js_db,cn0_eff_dbhz,n_kept,fix_valid,pos_err_m\n")
        for k in range(s["t"].size):
            e = eff(js[k]) if math.isfinite(js[k]) else math.nan
            fh.write(f"{s['t'][k]:.3f},{js[k]:.4g},{e:.4g},{int(s['kept'][k].sum())},"
                     f"{int(s['valid'][k])},{s['pos_err'][k]:.4g}\n")


def _plot(path: Path, series: dict, params: dict, seed: int) -> None:
    from matplotlib.figure import Figure

    from .plotting import save_png as _save

    fig = Figure(figsize=(8, 4.5), layout="constrained")
    ax = fig.subplots()
    for mode, s in series.items():
        if "t" not in s:
            continue
        sel = s["t"] >= float(params["t_on_s"])
        ax.plot(js_at(params, s["t"][sel]), s["kept"][sel].sum(axis=1), label=mode)
    ax.axhline(int(params["min_channels"]) - 0.5, color="0.5", ls="--", lw=0.8)
    ax.set_xlabel("J/S [dB]")
    ax.set_ylabel("channels kept")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize="small")
    fig.suptitle(f"jamming: {params['bits']}-bit, noise jammer "
                 f"{params['jammer_bandwidth_hz'] / 1e6:g} MHz (seed {seed})")
    _save(fig, path)


def tables(stats: dict) -> dict[str, list[dict]]:
    """``thresholds``: per mode, the J/S and effective C/N0 at loss (mean over runs)."""
    rows = []
    for mode in MODES:
        st = stats.get(f"{mode}.js_loss_db")
        if not has_mean(st) and f"{mode}.lost" not in stats:
            continue
        row: dict = {"mode": mode}
        for k in ("lost", "js_loss_db", "cn0_eff_loss_dbhz", "js_drop_db",
                  "ref_cn0_loss_dbhz", "jam_minus_ref_db"):
            v = stats.get(f"{mode}.{k}")
            if has_mean(v):
                row[k] = v["mean"]
                if k in ("js_loss_db", "cn0_eff_loss_dbhz", "jam_minus_ref_db"):
                    row[k + "_std"] = v["std"]
                    row[k + "_min"], row[k + "_max"] = v["min"], v["max"]
        row["n"] = stats[f"{mode}.lost"]["n"] if has_mean(stats.get(f"{mode}.lost")) else 0
        rows.append(row)
    return {"thresholds": rows}


def plots(results: list[dict], out_dir: Path) -> list[Path]:
    """``thresholds.png``: J/S at loss per mode over the runs (mean, std as error bars)."""
    if not results or plotting.matplotlib_missing():
        return []
    names = [m for m in MODES if f"{m}.js_loss_db" in results[0]["figures"]]
    if not names:
        return []
    vals = np.array([[r["figures"].get(f"{m}.js_loss_db", math.nan) for m in names]
                     for r in results], float)
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        panels = [("J/S at loss [dB]", np.nanmean(vals, axis=0),
                   np.nanstd(vals, axis=0) if len(results) > 1 else None)]
    return [plotting.bar_chart(Path(out_dir) / "thresholds.png", names, panels,
                               title=f"jamming: J/S at loss per mode ({len(results)} runs)")]
