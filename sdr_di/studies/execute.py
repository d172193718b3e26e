"""One seeded run of an experiment, as executed on a Dask worker (or in-process).

:func:`execute_run` runs the experiment in a private temporary directory and returns its
figures *and the bytes of the files it wrote*, so the client writes every output into its own
folder whether the worker shares its filesystem or not. An exception inside the experiment
becomes a ``"failed"`` record (text only: exception objects of any kind cross the wire
safely); only a worker's death surfaces as an exception of the Dask future.

:func:`write_run_record` writes a record as ``runs/<i>.json`` plus ``runs/<i>/<files>``.
"""

from __future__ import annotations

import json
import socket
import tempfile
import time
import traceback
from pathlib import Path

from ..errors import ExperimentError
from ..io.atomic import atomic_open, ensure_output_dir
from ..io.json_values import finite_or_nan, json_safe  # noqa: F401  (json_safe: its old home)
from ..experiments.registry import Experiment

__all__ = ["MAX_FILE_BYTES", "execute_run", "failed_record", "json_safe", "read_json",
           "restore_floats", "write_files", "write_json", "write_run_record"]

#: Files a run writes larger than this are not shipped back (noted in the record).
MAX_FILE_BYTES = 32 * 1024 * 1024


def _check_figures(figures) -> dict:
    if not isinstance(figures, dict):
        raise ExperimentError(f"run() returned {type(figures).__name__}, expected a dict of "
                              "scalar figures")
    out = {}
    for key, v in figures.items():
        if hasattr(v, "item") and getattr(v, "ndim", 1) == 0:   # numpy scalar
            v = v.item()
        if not isinstance(key, str) or not isinstance(v, (bool, int, float, str)):
            raise ExperimentError(f"figure {key!r} = {v!r} is not a scalar (float, int, str)")
        out[key] = v
    return out


def execute_run(experiment: Experiment, params: dict, seed: int, index: int,
                tmp_root: Path | None = None) -> dict:
    """Run ``experiment`` once with ``seed``; never raises for an error inside the run.

    The run works in a temporary folder under ``tmp_root`` (default: the system's temporary
    folder), removed when the run ends. A study passes a folder of its own output set
    (its file cache), which it removes when it completes, so that a worker killed in the
    middle of a run (cluster shut down, Ctrl-C) leaves nothing in the system's folder.

    Returns
    -------
    dict
        ``index``, ``seed``, ``status`` (``"ok"`` or ``"failed"``), ``figures`` (ok),
        ``error`` and ``traceback`` (failed), ``files`` ({relative path: bytes}),
        ``elapsed_s``, ``host``.
    """
    t0 = time.perf_counter()
    rec: dict = {"index": int(index), "seed": int(seed), "host": socket.gethostname()}
    with tempfile.TemporaryDirectory(prefix="sdr-di-run-", dir=tmp_root) as tmp:
        try:
            rec["figures"] = _check_figures(experiment.run(dict(params), int(seed), Path(tmp)))
            rec["status"] = "ok"
        except Exception as exc:  # noqa: BLE001 - recorded as this run's failure
            rec.update(status="failed", error=f"{type(exc).__name__}: {exc}",
                       traceback=traceback.format_exc(limit=8))
        files, skipped = {}, []
        for p in sorted(Path(tmp).rglob("*")):
            if p.is_file():
                rel = p.relative_to(tmp).as_posix()
                if p.stat().st_size > MAX_FILE_BYTES:
                    skipped.append(rel)
                else:
                    files[rel] = p.read_bytes()
        rec["files"] = files
        if skipped:
            rec["files_skipped"] = skipped
    rec["elapsed_s"] = time.perf_counter() - t0
    return rec


def failed_record(index: int, seed: int, error: str) -> dict:
    """Record of a run that produced no result (e.g. its worker died)."""
    return {"index": int(index), "seed": int(seed), "status": "failed", "error": error,
            "files": {}}


def write_json(path: Path, obj) -> Path:
    """Write ``obj`` as indented strict JSON, atomically (non-finite floats as ``null``:
    :func:`~sdr_di.io.json_values.json_safe`)."""
    with atomic_open(path, "w") as fh:
        json.dump(json_safe(obj), fh, indent=1, sort_keys=False)
        fh.write("\n")
    return path


def write_files(base: Path, files: dict[str, bytes]) -> list[str]:
    """Write ``{relative path: bytes}`` under ``base`` (atomically); the sorted names."""
    base = ensure_output_dir(base)
    for rel, data in files.items():
        dest = base / rel
        ensure_output_dir(dest.parent)
        with atomic_open(dest, "wb") as fh:
            fh.write(data)
    return sorted(files)


def write_run_record(runs_dir: Path, rec: dict, files_dir: Path | None = None,
                     json_path: Path | None = None) -> Path:
    """Write the run's files, then ``runs_dir/<index>.json`` (the record without the bytes).

    Parameters
    ----------
    runs_dir : Path
        Folder of the run records.
    rec : dict
        A record from :func:`execute_run` or :func:`failed_record`.
    files_dir : Path, optional
        Where the run's files go (default ``runs_dir/<index>/``).
    json_path : Path, optional
        Where the record goes (default ``runs_dir/<index>.json``).
    """
    files = rec.get("files") or {}
    meta = {k: v for k, v in rec.items() if k != "files"}
    if files:
        meta["files"] = write_files(files_dir or (Path(runs_dir) / str(rec["index"])), files)
    return write_json(json_path or Path(runs_dir) / f"{rec['index']}.json", meta)


def read_json(path: Path) -> dict:
    """Read a JSON file written by :func:`write_json` (``null`` stays None:
    :func:`restore_floats` for figures)."""
    return json.loads(Path(path).read_text(encoding="utf-8"))


def restore_floats(figures: dict) -> dict:
    """Figures read back from JSON with ``null`` (and the ``"nan"``/``"inf"`` strings of
    records written before issue 48) as floats again (:func:`~sdr_di.io.json_values.
    finite_or_nan`)."""
    return {k: finite_or_nan(v) for k, v in figures.items()}