"""Shared pieces of the deep-receiver experiments (``count-change``, ``outage``, ``weak-signal``).

Each run builds its scenario from a base scenario (default ``signals/default.toml``, the
paper-004 scenario) plus an outage/attenuation schedule (``[[outage]]`` entries of the
scenario schema), generates the IF, IMU and truth files once into a private temporary folder
(never into the run's output folder: the IF file is large and would travel back with the
result), and runs every receiver variant on those same files.

The receivers search only the simulated PRNs (read from the generated sidecar), so start-up
time is spent on tracking, not on searching 63 codes; the deep receiver gets the ephemeris
file as assistance, as ``sdr-di run --mode deep`` does.
"""

from __future__ import annotations

import dataclasses
import json
import math
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ExperimentError
from ..receiver.scalar import ScalarReceiver
from ..scenario import DEFAULT_SCENARIO, Scenario, load_scenario, parse_scenario
from .filter_figures import QUANTITIES

__all__ = [
    "CountingScalarReceiver",
    "DeepRun",
    "Inputs",
    "base_scenario",
    "check_number",
    "generated_inputs",
    "has_mean",
    "parse_list",
    "ranked_prns",
    "record_run",
    "run_deep_variant",
    "segment_metrics",
    "with_outages",
]



def has_mean(st: Any) -> bool:
    """True for a numeric figure's statistics (``aggregate`` gives text figures as
    ``{"value": ...}``)."""
    return isinstance(st, dict) and "mean" in st


def parse_list(name: str, text: Any, kind: type = float) -> list:
    """``"7,6,5"`` -> ``[7, 6, 5]`` (``kind`` int or float); ExperimentError when malformed."""
    try:
        vals = [kind(v) for v in str(text).replace(" ", "").split(",") if v != ""]
    except ValueError:
        raise ExperimentError(f"{name}={text!r}: expected a comma list of "
                              f"{'integers' if kind is int else 'numbers'}") from None
    if not vals or not all(math.isfinite(v) for v in vals):
        raise ExperimentError(f"{name}={text!r}: expected a non-empty comma list of finite "
                              "values")
    return vals


def check_number(exp: str, params: dict, key: str, *, lo: float = 0.0, allow_none: bool = False,
                 lo_open: bool = True) -> None:
    """Reject a non-number (or one not above/at ``lo``) in ``params[key]``."""
    v = params[key]
    if v is None and allow_none:
        return
    bad = isinstance(v, (str, bool)) or v is None or not math.isfinite(v)
    if bad or v < lo or (lo_open and v == lo):
        raise ExperimentError(f"{exp}: {key}={v!r}: expected a number {'>' if lo_open else '>='}"
                              f" {lo:g}")


def base_scenario(params: dict, seed: int, duration_s: float) -> Scenario:
    """The experiment's base scenario with seed, duration, sample rate and C/N0 applied."""
    path = Path(str(params["scenario"])) if params.get("scenario") else DEFAULT_SCENARIO
    sc = load_scenario(path)
    return sc.with_overrides(seed=int(seed), duration_s=float(duration_s),
                             sampling_rate_hz=params.get("sampling_rate_hz"),
                             cn0_dbhz=params.get("cn0_dbhz"))


def with_outages(sc: Scenario, outages: list[dict]) -> Scenario:
    """``sc`` with ``outages`` (``[[outage]]`` tables of ``docs/scenario.md``) appended."""
    raw = json.loads(json.dumps(sc.raw, default=str))
    raw["outage"] = list(raw.get("outage", [])) + [dict(o) for o in outages]
    base = sc.source.parent if sc.source is not None else None
    return parse_scenario(raw, source=sc.source, base_dir=base)


def ranked_prns(sc: Scenario) -> list[int]:
    """The PRNs the generator will simulate, highest elevation at the start first.

    An explicit ``prns`` list keeps its order.
    """
    from ..orbits.rinex_nav import load_nav
    from ..sim.generate import simulate_truth
    from ..sim.geometry import ReceiverPath
    from ..sim.ifgen import select_satellites

    truth = simulate_truth(sc)
    path = ReceiverPath(truth.t, truth.r_e, truth.v_e)
    return [c[0] for c in select_satellites(sc, load_nav(sc.satellites.ephemeris), path, None)]


@dataclasses.dataclass
class Inputs:
    """Generated files of one run, opened."""

    source: Any
    imu: Any
    truth: Any
    nav: Any
    prns: list[int]
    paths: dict


class generated_inputs:
    """Context manager: generate ``sc`` into a temporary folder, yield :class:`Inputs`,
    delete the folder on exit."""

    def __init__(self, sc: Scenario):
        self.sc = sc
        self._tmp: tempfile.TemporaryDirectory | None = None

    def __enter__(self) -> Inputs:
        from ..io.imu_files import read_imu, read_truth
        from ..orbits.rinex_nav import load_nav
        from ..receiver.run_scalar import open_source
        from ..sim.generate import generate_files

        self._tmp = tempfile.TemporaryDirectory(prefix="sdr_di_exp_")
        try:
            paths = generate_files(self.sc, self._tmp.name, progress=False)
            meta = json.loads(Path(paths["metadata"]).read_text(encoding="utf-8"))
            prns = [int(s["prn"]) for s in meta["satellites"]]
            return Inputs(source=open_source(paths["if"]), imu=read_imu(paths["imu"]),
                          truth=read_truth(paths["truth"])[0],
                          nav=load_nav(self.sc.satellites.ephemeris), prns=prns, paths=paths)
        except BaseException:
            self._tmp.cleanup()
            raise

    def __exit__(self, *exc) -> None:
        if self._tmp is not None:
            self._tmp.cleanup()


class CountingScalarReceiver(ScalarReceiver):
    """Scalar receiver that records the first sample of every acquisition search it runs.

    The deep receiver is given one of these as its start-up receiver, so an experiment can
    show from the record (not from reading the code) that no acquisition search ran after
    the hand-over.
    """

    def __init__(self, *args, **kw):
        super().__init__(*args, **kw)
        self.acquisition_samples: list[int] = []

    def _acquire(self, source, sample, prns, **over):
        self.acquisition_samples.append(int(sample))
        return super()._acquire(source, sample, prns, **over)


@dataclasses.dataclass
class DeepRun:
    """One deep run: the result (None when it failed), its error and acquisition record."""

    filter: str
    result: Any
    error: str | None
    acq_after_handover: int


def run_deep_variant(inputs: Inputs, filter_name: str, *, mode: str = "deep",
                     **config: Any) -> DeepRun:
    """Run :class:`~sdr_di.deep.DeepReceiver` with ``filter_name`` in ``mode`` on ``inputs``.

    ``mode`` (``"loose"``, ``"tight"``, ``"deep"``) is the receiver's coupling
    (``DeepConfig.mode``); ``"deep"`` is the configuration's default and is not passed, so
    the call also works with a receiver that predates the modes. ``config`` are further
    :class:`~sdr_di.deep.DeepConfig` fields.

    Exceptions of the package (:class:`~sdr_di.errors.SdrDiError`) and numerical failures
    (``ValueError``, ``FloatingPointError``, ``numpy.linalg.LinAlgError``) are returned as
    ``error`` text, not raised: a filter that fails is a result of the experiment.
    """
    from ..deep import DeepConfig, DeepReceiver
    from ..errors import SdrDiError

    if mode != "deep":
        config["mode"] = mode
    scalar = CountingScalarReceiver(log=False)
    try:
        rx = DeepReceiver(DeepConfig(filter=filter_name, **config), scalar=scalar)
        res = rx.run(inputs.source, inputs.imu, prns=inputs.prns, nav=inputs.nav,
                     truth=inputs.truth)
    except (SdrDiError, ValueError, FloatingPointError, np.linalg.LinAlgError) as exc:
        return DeepRun(filter_name, None, f"{type(exc).__name__}: {exc}", -1)
    k_h = round(res.handover_s * inputs.source.sampling_rate_hz)
    after = sum(1 for s in scalar.acquisition_samples if s >= k_h)
    return DeepRun(filter_name, res, None, after)


def record_run(fig: dict, name: str, dr: DeepRun) -> Any:
    """Figures every deep experiment records for one filter run, into ``fig``.

    ``<name>.completed`` (1 when every error row is finite), and either ``<name>.error``
    (the run failed: returns None) or ``<name>.handover_s`` and
    ``<name>.acq_after_handover`` (returns the :class:`~sdr_di.deep.DeepResult`).
    """
    res = dr.result
    if res is None:
        fig[f"{name}.completed"] = 0
        fig[f"{name}.error"] = dr.error
        return None
    finite = bool(res.t.size) and all(
        np.all(np.isfinite(getattr(res, a))) for a in ("att_err", "vel_err", "pos_err"))
    fig[f"{name}.completed"] = int(finite)
    fig[f"{name}.handover_s"] = float(res.handover_s)
    fig[f"{name}.acq_after_handover"] = dr.acq_after_handover
    return res


def segment_metrics(res: Any, t0: float | None, t1: float | None, prefix: str) -> dict:
    """``{prefix}{q}_{rmse,max}`` of a result's error norms over ``t0 <= t < t1``."""
    from ..integration.metrics import rmse_max

    t = np.asarray(res.t, float)
    sel = np.ones(t.size, bool)
    if t0 is not None:
        sel &= t >= t0
    if t1 is not None:
        sel &= t < t1
    out = {}
    for q, _ in QUANTITIES:
        e = np.asarray(getattr(res, f"{q[:3]}_err"), float)[sel]
        r, m = rmse_max(e)
        out[f"{prefix}{q}_rmse"] = r
        out[f"{prefix}{q}_max"] = m
    return out
