"""``weak-signal``: C/N0 swept from 40 down to 15 dB-Hz; the lowest C/N0 each receiver mode
(scalar, loose, tight, deep) holds with all channels and a position error below 10 m.

**Strong start, then the tested level.** Every mode needs a strong signal to start
(acquisition, tracking, bit/frame synchronization, decoding and, for the integration loop,
the hand-over about 12 s into the default scenario). Each level ``L`` is therefore one
generated file in which every satellite has ``cn0_start`` (default 40 dB-Hz) until
``t_step_s`` (default 15 s) and ``L`` from then to the end (``hold_s`` later): a C/N0 step
made with the scenario schema's existing attenuation window (``[[outage]] prn = "all",
attenuation_db = cn0_start - L`` from ``t_step_s`` to the end; the generator scales the
signal amplitude and keeps the noise and the quantizer gain, so the C/N0 of every satellite
drops by exactly that many dB). No new scenario key was needed.

**Modes** (same file, same searched PRNs: the simulated ones):

* ``scalar``: :class:`~sdr_di.receiver.scalar.ScalarReceiver` (acquisition, scalar loops,
  decoding) + :class:`~sdr_di.receiver.pvt.PvtEngine` at 5 Hz, the pipeline of
  ``sdr-di run --mode scalar``, given the same ephemeris assistance and receiver time tag as
  the deep receiver's start-up (decoded records first, then the navigation file: without it
  the scalar PVT waits ~30 s for every ephemeris to be decoded). A channel is *kept* at an
  epoch when it is in ``TRACK`` with code lock and used in the position fix.
* ``loose``, ``tight``, ``deep``: :class:`~sdr_di.integration.receiver.IntegratedReceiver`
  in that coupling (``IntegrationConfig.mode``; ``filter``, default ``ff-aukf``; 10 Hz rows). A channel is *kept*
  when it is in the filter's measurement vector (loose: in the WLS fix fed to the filter).
  ``deep_cn0_min_dbhz`` (default ``none``: the
  :class:`~sdr_di.integration.receiver.IntegrationConfig` default) is the loop's channel C/N0 gate.

**Pass at a level**: over the evaluation window (``settle_s`` after the step to the end) every
channel is kept in at least ``keep_fraction`` (default 0.95) of the epochs, the last epoch has
every channel, every scalar epoch has a valid fix, and the max position error norm is below
``pos_limit_m`` (10 m). A loop run must also have handed over before the step.
**Threshold of a mode** = the lowest level at which it passes and passes at every higher
level of the sweep (NaN when it fails at the highest).

Figures: per level ``L`` and mode ``m``: ``L<L>.<m>.pass``, ``.keep_min`` (lowest per-channel
kept fraction), ``.all_kept_last``, ``.pos_m_max``, ``.pos_m_rmse``, ``.fix_fraction``
(scalar), ``.handover_s`` (loop modes), ``.error`` (when it raised); per mode
``<m>.threshold_dbhz`` (the C/N0 at which the mode loses its solution is one sweep step
below it); ``<m>_gain_db`` = scalar threshold - the mode's threshold.

Files: ``sweep_levels.csv`` (one row per level and mode, with errors) and ``sweep.png``
(kept fraction and max position error against C/N0 per mode).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..errors import ExperimentError
from . import plotting
from ._deep import (
    CountingScalarReceiver,
    base_scenario,
    check_number,
    generated_inputs,
    has_mean,
    parse_list,
    run_deep_variant,
    with_outages,
)
from .entries import check_filter_entry, filter_list
from .variants import MODES as LOOP_MODES
from .variants import check_deep_options, loop_config, mode_list

__all__ = [
    "DESCRIPTION",
    "MODES",
    "NAME",
    "check_params",
    "default_params",
    "levels",
    "plots",
    "run",
    "scalar_run",
    "tables",
    "threshold",
]

NAME = "weak-signal"
DESCRIPTION = ("C/N0 step from 40 dB-Hz to each level of a 40..15 dB-Hz sweep after the "
               "start-up; lowest level each mode (scalar, loose, tight, deep) holds with all "
               "channels and position error < 10 m")

#: ``scalar`` (the scalar receiver's own PVT) and the integration loop's couplings.
MODES = ("scalar", *LOOP_MODES)

default_params: dict = {
    "scenario": None,
    "modes": "scalar,deep",
    "filter": "ff-aukf",
    "cn0_start": 40.0,
    "cn0_stop": 15.0,
    "step_db": 2.5,
    "levels": None,
    "t_step_s": 15.0,
    "hold_s": 15.0,
    "settle_s": 2.0,
    "keep_fraction": 0.95,
    "pos_limit_m": 10.0,
    "sampling_rate_hz": None,
    "deep_cn0_min_dbhz": None,
    "filter_rate_hz": 50.0,
    "nco_latency": None,
    "deep_measurements": None,
    "fusion_rate_hz": None,
    "plots": True,
}


def levels(params: dict) -> list[float]:
    """The C/N0 levels of the sweep, highest first (``levels`` list, else start/stop/step)."""
    if params["levels"] is not None:
        vals = parse_list(f"{NAME}: levels", params["levels"], float)
        return sorted(set(vals), reverse=True)
    a, b, s = float(params["cn0_start"]), float(params["cn0_stop"]), float(params["step_db"])
    n = math.floor((a - b) / s + 1e-9) + 1
    return [round(a - i * s, 6) for i in range(n)]


def _modes(text: str) -> list[str]:
    return mode_list(NAME, text, MODES)


def check_params(params: dict) -> None:
    """Reject bad parameter values with :class:`~sdr_di.errors.ExperimentError`."""
    check_deep_options(NAME, params)
    _modes(params["modes"])
    filter_list(NAME, params["filter"])
    for key in ("cn0_start", "cn0_stop", "step_db", "t_step_s", "hold_s", "pos_limit_m",
                "filter_rate_hz"):
        check_number(NAME, params, key)
    check_number(NAME, params, "settle_s", lo=0.0, lo_open=False)
    check_number(NAME, params, "sampling_rate_hz", allow_none=True)
    check_number(NAME, params, "deep_cn0_min_dbhz", allow_none=True, lo_open=False)
    if not 0.0 < params["keep_fraction"] <= 1.0:
        raise ExperimentError(f"{NAME}: keep_fraction={params['keep_fraction']!r}: expected "
                              "0 < value <= 1")
    if params["cn0_stop"] > params["cn0_start"]:
        raise ExperimentError(f"{NAME}: cn0_stop must not exceed cn0_start")
    if params["settle_s"] >= params["hold_s"]:
        raise ExperimentError(f"{NAME}: settle_s must be shorter than hold_s")
    lv = levels(params)
    if max(lv) > params["cn0_start"]:
        raise ExperimentError(f"{NAME}: levels above cn0_start ({params['cn0_start']:g}) "
                              "cannot be made by attenuation")
    if params["scenario"] is not None and not Path(str(params["scenario"])).is_file():
        raise ExperimentError(f"{NAME}: scenario {params['scenario']}: no such file")


def threshold(passed: dict[float, bool]) -> float:
    """Lowest level that passes with every higher level passing (NaN if the highest fails)."""
    best = math.nan
    for lv in sorted(passed, reverse=True):
        if not passed[lv]:
            break
        best = lv
    return best


def _truth_ecef(truth) -> tuple[np.ndarray, np.ndarray]:
    from ..frames import llh_to_ecef

    r = np.array([llh_to_ecef(*row) for row in truth.llh])
    return np.asarray(truth.t, float), r


def scalar_run(inp, t_eval: float) -> dict:
    """Scalar receiver + PVT over the whole file; per-epoch kept channels and errors.

    The PVT takes its ephemerides and Klobuchar set from
    :class:`~sdr_di.receiver.navdata.NavDataInForce` (decoded data, else the file's) and the
    IF file's time tag, as the deep receiver's start-up does.

    Returns
    -------
    dict
        ``t`` (n,), ``kept`` (n, n_ch) bool, ``valid`` (n,) bool, ``pos_err`` (n,) [m] (NaN
        without a fix), ``prns``, epochs from ``t_eval`` on.
    """
    from ..receiver.navdata import NavDataInForce
    from ..receiver.observables import ReceiverTime
    from ..receiver.pvt import PvtEngine

    src = inp.source
    fs = src.sampling_rate_hz
    rx = CountingScalarReceiver(log=False)
    rt = ReceiverTime.from_sample_zero(fs, src.start_week, src.start_sow)
    ephs = NavDataInForce(inp.nav)
    engine = PvtEngine(fs, ephs, None, rx_time=rt)
    tt, rr = _truth_ecef(inp.truth)
    prns = list(inp.prns)
    rows: dict = {"t": [], "kept": [], "valid": [], "pos_err": []}

    def on_epoch(sample, observations, ephemerides):
        engine.iono = ephs.offer_decoded(ephemerides, rx.klobuchar).klobuchar
        # every channel lost: PvtEngine refuses an empty epoch; it is an epoch without a fix
        sol = engine.process(observations) if observations else None
        t = sample / fs
        if t < t_eval:
            return False
        valid = sol is not None and sol.valid
        used = {int(p) for p in sol.prns} if valid else set()
        by = {o.prn: o for o in observations}
        kept = [p in by and by[p].state == "TRACK" and bool(by[p].code_lock) and p in used
                for p in prns]
        err = math.nan
        if valid:
            truth_r = np.array([np.interp(t, tt, rr[:, j]) for j in range(3)])
            err = float(np.linalg.norm(np.asarray(sol.r_e, float) - truth_r))
        rows["t"].append(t)
        rows["kept"].append(kept)
        rows["valid"].append(valid)
        rows["pos_err"].append(err)
        return False

    rx.run(src, prns=prns, on_epoch=on_epoch, epoch_interval_s=0.2)
    return {"t": np.asarray(rows["t"], float),
            "kept": np.asarray(rows["kept"], bool).reshape(-1, len(prns)),
            "valid": np.asarray(rows["valid"], bool),
            "pos_err": np.asarray(rows["pos_err"], float), "prns": prns}


def _judge(kept: np.ndarray, pos_err: np.ndarray, valid: np.ndarray, params: dict) -> dict:
    if kept.shape[0] == 0:
        return {"pass": 0, "keep_min": math.nan, "all_kept_last": 0, "pos_m_max": math.nan,
                "pos_m_rmse": math.nan, "n_epochs": 0}
    frac = kept.mean(axis=0)
    fin = pos_err[np.isfinite(pos_err)]
    pmax = float(fin.max()) if fin.size else math.nan
    prmse = float(np.sqrt(np.mean(fin ** 2))) if fin.size else math.nan
    ok = (bool(np.all(frac >= params["keep_fraction"])) and bool(kept[-1].all())
          and bool(valid.all()) and math.isfinite(pmax) and pmax < params["pos_limit_m"])
    return {"pass": int(ok), "keep_min": float(frac.min()), "all_kept_last": int(kept[-1].all()),
            "pos_m_max": pmax, "pos_m_rmse": prmse, "n_epochs": int(kept.shape[0])}


def run(params: dict, seed: int, out_dir: Path) -> dict:
    """One sweep: every level generated once, every mode run on it (module docstring).

    Parameters
    ----------
    params : dict
        :data:`default_params` updated by the caller.
    seed : int
        Scenario seed (IF noise, IMU errors); the same for every level.
    out_dir : Path
        Existing directory for ``sweep_levels.csv`` and ``sweep.png``.

    Returns
    -------
    dict
        Flat figures (module docstring).
    """
    check_params(params)
    modes = _modes(params["modes"])
    t_step, hold = float(params["t_step_s"]), float(params["hold_s"])
    duration = t_step + hold
    t_eval = t_step + float(params["settle_s"])
    c0 = float(params["cn0_start"])
    fig: dict = {"duration_s": duration, "t_step_s": t_step, "cn0_start": c0,
                 "filter": params["filter"]}
    rows = []
    passed: dict[str, dict[float, bool]] = {m: {} for m in modes}
    cfg = loop_config(params, output_rate_hz=10.0)
    filt, opts = check_filter_entry(NAME, params["filter"])
    if opts:
        cfg["filter_options"] = opts
    base = base_scenario({**params, "cn0_dbhz": c0}, seed, duration)
    for lv in levels(params):
        sc = base
        if c0 - lv > 0:
            sc = with_outages(base, [{"prn": "all", "start_s": t_step, "end_s": duration + 1.0,
                                      "attenuation_db": c0 - lv}])
        with generated_inputs(sc) as inp:
            fig["sampling_rate_hz"] = float(inp.source.sampling_rate_hz)
            for mode in modes:
                key = f"L{lv:g}.{mode}."
                if mode == "scalar":
                    try:
                        s = scalar_run(inp, t_eval)
                        j = _judge(s["kept"], s["pos_err"], s["valid"], params)
                        j["fix_fraction"] = float(s["valid"].mean()) if s["valid"].size \
                            else math.nan
                    except Exception as exc:  # noqa: BLE001 - a crash at a level is its failure
                        j = {"pass": 0, "error": f"{type(exc).__name__}: {exc}"}
                else:
                    dr = run_deep_variant(inp, filt, mode=mode, **cfg)
                    if dr.result is None:
                        j = {"pass": 0, "error": dr.error}
                    else:
                        r = dr.result
                        sel = r.t >= t_eval
                        j = _judge(r.used[sel], np.linalg.norm(r.pos_err[sel], axis=1),
                                   np.ones(int(sel.sum()), bool), params)
                        j["handover_s"] = float(r.handover_s)
                        if r.handover_s >= t_step:
                            j["pass"] = 0
                            j["error"] = (f"hand-over at {r.handover_s:.2f} s, after the C/N0 "
                                          f"step at {t_step:g} s")
                for k, v in j.items():
                    fig[key + k] = v
                passed[mode][lv] = bool(j["pass"])
                rows.append({"cn0_dbhz": lv, "mode": mode, **j})
    for mode in modes:
        fig[f"{mode}.threshold_dbhz"] = threshold(passed[mode])
    for mode in modes:
        if mode != "scalar" and "scalar" in modes:
            fig[f"{mode}_gain_db"] = (fig["scalar.threshold_dbhz"]
                                      - fig[f"{mode}.threshold_dbhz"])
    _write_csv(Path(out_dir) / "sweep_levels.csv", rows)
    if params["plots"]:
        note = plotting.matplotlib_missing()
        if note is None:
            _plot_sweep(Path(out_dir) / "sweep.png", rows, modes, params, seed)
        else:
            fig["plots_note"] = note
    return fig


def _write_csv(path: Path, rows: list[dict]) -> None:
    from ..io.atomic import atomic_open

    cols = ["cn0_dbhz", "mode", "pass", "keep_min", "all_kept_last", "pos_m_max",
            "pos_m_rmse", "fix_fraction", "handover_s", "n_epochs", "error"]
    with atomic_open(path, "w") as fh:
        fh.write(",".join(cols) + "\n")
        for r in rows:
            fh.write(",".join(str(r.get(c, "")).replace(",", ";") for c in cols) + "\n")


def _plot_sweep(path: Path, rows: list[dict], modes: list[str], params: dict, seed: int) -> None:
    from matplotlib.figure import Figure

    from .plotting import save_png as _save

    fig = Figure(figsize=(8, 5.5), layout="constrained")
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    for m in modes:
        rr = [r for r in rows if r["mode"] == m]
        x = [r["cn0_dbhz"] for r in rr]
        ax1.plot(x, [r.get("keep_min", math.nan) for r in rr], "o-", label=m)
        ax2.semilogy(x, [r.get("pos_m_max", math.nan) for r in rr], "o-", label=m)
    ax1.axhline(params["keep_fraction"], color="0.5", ls="--", lw=0.8)
    ax2.axhline(params["pos_limit_m"], color="0.5", ls="--", lw=0.8)
    ax1.set_ylabel("lowest per-channel\nkept fraction")
    ax2.set_ylabel("max position error [m]")
    ax2.set_xlabel("C/N0 after the step [dB-Hz]")
    ax2.invert_xaxis()
    for ax in (ax1, ax2):
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize="small")
    fig.suptitle(f"weak-signal: C/N0 vs lock (seed {seed})")
    _save(fig, path)


def tables(stats: dict) -> dict[str, list[dict]]:
    """``sweep``: one row per level and mode (mean over runs); ``thresholds``: per mode."""
    rows, thr = [], []
    lv_modes: list[tuple[str, str]] = []
    for key in stats:
        if key.startswith("L") and key.count(".") >= 2:
            lv, mode = _split(key)
            if mode and (lv, mode) not in lv_modes:
                lv_modes.append((lv, mode))
    for lv, mode in lv_modes:
        row: dict = {"cn0_dbhz": float(lv), "mode": mode}
        for k in ("pass", "keep_min", "all_kept_last", "pos_m_max", "pos_m_rmse",
                  "fix_fraction", "handover_s"):
            st = stats.get(f"L{lv}.{mode}.{k}")
            if has_mean(st):
                row[k] = st["mean"]
        rows.append(row)
    for mode in MODES:
        st = stats.get(f"{mode}.threshold_dbhz")
        if has_mean(st):
            thr.append({"mode": mode, "threshold_dbhz": st["mean"], "std": st["std"],
                        "min": st["min"], "max": st["max"], "n": st["n"]})
    return {"sweep": rows, "thresholds": thr}


def _split(key: str) -> tuple[str, str]:
    """``"L27.5.deep.pass"`` -> ``("27.5", "deep")``."""
    body = key[1:]
    for mode in MODES:
        tag = f".{mode}."
        if tag in body:
            return body[: body.index(tag)], mode
    return body, ""


def plots(results: list[dict], out_dir: Path) -> list[Path]:
    """``thresholds.png``: threshold per mode over the runs (mean, std as error bars)."""
    if not results or plotting.matplotlib_missing():
        return []
    panels = []
    names = [m for m in MODES if f"{m}.threshold_dbhz" in results[0]["figures"]]
    if not names:
        return []
    vals = np.array([[r["figures"].get(f"{m}.threshold_dbhz", math.nan) for m in names]
                     for r in results], float)
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        panels.append(("threshold [dB-Hz]", np.nanmean(vals, axis=0),
                       np.nanstd(vals, axis=0) if len(results) > 1 else None))
    return [plotting.bar_chart(Path(out_dir) / "thresholds.png", names, panels,
                               title=f"weak-signal: C/N0 threshold per mode "
                               f"({len(results)} runs)")]
