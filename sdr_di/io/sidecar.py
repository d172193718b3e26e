"""Metadata sidecar (JSON) describing an IF file: everything needed to read it back.

The sidecar of ``run.bin`` is ``run.json``. Keys (schema ``sdr-di-if/1``):

``schema``             ``"sdr-di-if/1"``
``if_file``            IF file name, relative to the sidecar
``sampling_rate_hz``   sample rate [Hz]
``if_hz``              intermediate frequency of the carrier [Hz] (0 for baseband)
``carrier_hz``         RF carrier the IF corresponds to (1268.52e6 for B3I)
``sample_format``      name in :mod:`sdr_di.io.sample_formats`
``quantization_bits``  effective bits of each component
``spectrum_inverted``  false (I + jQ non-inverted)
``n_samples``          samples (complex or real) in the file
``start``              ``{"week": BDT week, "sow": BDT seconds of week, "utc": ISO, "bdt": ISO}``
                       receiver-clock time of sample 0
``duration_s``         n_samples / sampling_rate_hz
``scenario``           ``{"name", "hash", "seed"}``
``satellites``         list of ``{"prn", "nav": "D1"|"D2", "cn0_dbhz", "elevation_deg",
                       "azimuth_deg", "doppler_hz", "code_phase_chips"}`` at t = 0, with
                       ``"toe", "week"`` of the record the signal's orbit comes from and
                       ``"broadcast"``: ``[{"from_s", "toe", "week", "aode"}]``, the records
                       the message carries (a new upload from the first 30 s frame after it
                       went on the air)
                       and ``"effective_cn0_dbhz"``: the theoretical C/N0 with every jammer
                       at its highest J/S (``sdr_di.sim.interference``; = cn0_dbhz without)
``interference``       the scenario's jammers (``[[interference]]`` keys) with their spectral
                       separation ``"kappa_per_hz"`` (of the file as sampled, aliases of the
                       unfiltered chips folded in) and ``"kappa_model"``
``agc``                ``{"sigma_in", "gain_lsb"}`` at the start, ``"time_constant_s"``,
                       ``"target_sigma_lsb"`` (null: Max 1960's optimum step)
``imu_file``, ``truth_file``, ``ephemeris_file``   companion files
``generator``          ``{"name": "sdr-di", "version", "synthesis_version"}``: the
                       sample-synthesis algorithm (``sdr_di.sim.ifgen.SYNTHESIS_VERSION``;
                       a file is byte-identical for a scenario and seed within a version)
``files``              ``{NAME: {"size": bytes, "sha256_first_last_mib": hex}}`` for the IF,
                       IMU and truth files of the set, NAME as written in ``if_file``...
                       (see below; absent in sidecars written by hand or by sdr-di before it
                       recorded them: such members are only checked for existence)

A generated set is written as one :class:`~sdr_di.io.atomic.OutputSet`: the IF, IMU and truth
files under ``.part`` names, then the sidecar, then the renames with the sidecar last. The
sidecar's ``files`` record the size of each member and the SHA-256 of its first and last MiB
(:func:`file_fingerprint`; the whole file when it is shorter than 2 MiB), so that a reader can
tell in one small read whether a member is the file the sidecar was written with:
:func:`check_member` raises :class:`~sdr_di.errors.FileSetError` for a member that is missing,
of another size or of another digest (a re-generation killed between renames, or files copied
from two runs). The digest is not a full-file checksum: it catches a mixed set, not a bit flip
in the middle of a large file.

:func:`read_sidecar` checks the types of every key a reader uses and raises
:class:`~sdr_di.errors.SidecarError` (a :class:`~sdr_di.errors.SampleFormatError`) naming the
sidecar and the key.
"""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path
from typing import Any

from ..errors import FileSetError, SidecarError
from .atomic import OutputSet, atomic_open

SCHEMA = "sdr-di-if/1"

#: Bytes hashed at each end of a member file by :func:`file_fingerprint`.
FINGERPRINT_BYTES = 1 << 20
#: Name of the digest in a ``files`` record.
DIGEST_KEY = "sha256_first_last_mib"
#: Sidecar keys naming members of the set (relative to the sidecar's folder).
MEMBER_KEYS = ("if_file", "imu_file", "truth_file")


def write_sidecar(path: str | Path, meta: dict[str, Any], *,
                  output_set: OutputSet | None = None) -> Path:
    """Write the sidecar; returns its (final) path.

    Parameters
    ----------
    path : path
        Final name of the sidecar.
    meta : dict
        Its contents (``schema`` is added).
    output_set : OutputSet, optional
        Write it as the next member of this set (renamed by the set's ``commit``) instead of
        atomically on its own.
    """
    path = Path(path)
    meta = {"schema": SCHEMA, **meta}
    opener = atomic_open if output_set is None else output_set.open
    with opener(path, "w") as fh:
        json.dump(meta, fh, indent=2, sort_keys=False)
        fh.write("\n")
    return path


def file_fingerprint(path: str | Path) -> dict[str, Any]:
    """Size and SHA-256 of the first and last MiB of a file (module notes).

    Returns
    -------
    dict
        ``{"size": bytes, "sha256_first_last_mib": hex digest}``; the digest also covers the
        size, so two files of different sizes never share it.

    Raises
    ------
    OSError
        The file cannot be read.
    """
    path = Path(path)
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        size = fh.seek(0, 2)
        h.update(str(size).encode("ascii") + b"\n")
        fh.seek(0)
        if size <= 2 * FINGERPRINT_BYTES:
            h.update(fh.read())
        else:
            h.update(fh.read(FINGERPRINT_BYTES))
            fh.seek(size - FINGERPRINT_BYTES)
            h.update(fh.read(FINGERPRINT_BYTES))
    return {"size": size, DIGEST_KEY: h.hexdigest()}


def member_path(sidecar: str | Path, meta: dict[str, Any], key: str) -> Path | None:
    """Path of the member named by ``meta[key]`` (relative to the sidecar), None if absent."""
    name = meta.get(key)
    if not name:
        return None
    p = Path(name)
    return p if p.is_absolute() else Path(sidecar).parent / p


def check_member(sidecar: str | Path, meta: dict[str, Any], key: str) -> Path | None:
    """Resolve the member ``meta[key]`` and check it is the file the sidecar was written with.

    Parameters
    ----------
    sidecar : path
        The sidecar file (members are relative to its folder).
    meta : dict
        Its contents (:func:`read_sidecar`).
    key : str
        ``"if_file"``, ``"imu_file"`` or ``"truth_file"``.

    Returns
    -------
    Path or None
        The member's path; None when the sidecar names no such file.

    Raises
    ------
    FileSetError
        The member is missing, or its size or digest differs from the sidecar's ``files``
        record. A member the sidecar has no record of (a hand-written or older sidecar) is
        only checked for existence.
    """
    path = member_path(sidecar, meta, key)
    if path is None:
        return None
    if not path.is_file():
        raise FileSetError(f"sidecar {sidecar}: {key} {path} not found")
    rec = (meta.get("files") or {}).get(meta[key])
    if rec is None:
        return path
    try:
        got = file_fingerprint(path)
    except OSError as exc:
        raise FileSetError(f"sidecar {sidecar}: {key} {path}: cannot read "
                           f"({exc.strerror or exc})") from None
    if got["size"] != rec["size"] or got[DIGEST_KEY] != rec[DIGEST_KEY]:
        what = (f"{got['size']} bytes, the sidecar records {rec['size']}"
                if got["size"] != rec["size"] else "same size, different content")
        raise FileSetError(
            f"sidecar {sidecar}: {path.name} is not the file this sidecar was written with "
            f"({what}): the set is mixed (an interrupted re-generation?); generate it again")
    return path


def _is_num(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


#: Type checks of the keys readers use: (key, required, test, what the value must be).
_CHECKS: tuple[tuple[str, bool, Any, str], ...] = (
    ("if_file", True, lambda v: isinstance(v, str) and v.strip() != "", "a file name"),
    ("sampling_rate_hz", True, lambda v: _is_num(v) and v > 0, "a number > 0"),
    ("if_hz", True, _is_num, "a finite number"),
    ("sample_format", True, lambda v: isinstance(v, str), "a format name"),
    ("n_samples", True, lambda v: _is_int(v) and v > 0, "an integer > 0"),
    ("start", True, lambda v: isinstance(v, dict), "an object {week, sow, ...}"),
    ("carrier_hz", False, lambda v: _is_num(v) and v > 0, "a number > 0"),
    ("quantization_bits", False, lambda v: _is_int(v) and 1 <= v <= 32, "an integer 1..32"),
    ("spectrum_inverted", False, lambda v: isinstance(v, bool), "true or false"),
    ("imu_file", False, lambda v: isinstance(v, str), "a file name"),
    ("truth_file", False, lambda v: isinstance(v, str), "a file name"),
    ("ephemeris_file", False, lambda v: isinstance(v, str), "a file name"),
    ("files", False, lambda v: isinstance(v, dict) and all(
        isinstance(r, dict) and _is_int(r.get("size")) and isinstance(r.get(DIGEST_KEY), str)
        for r in v.values()), f"an object {{name: {{size, {DIGEST_KEY}}}}}"),
)


#: Optional keys that may be ``null`` (no such companion file / no record).
_NULLABLE = frozenset({"imu_file", "truth_file", "ephemeris_file", "files"})


def companion_files(source, skip: tuple[str, ...] = ()) -> dict:
    """``{"imu", "truth", "ephemeris"}`` paths named by an IF file's sidecar (None if absent).

    ``source``: the :class:`~sdr_di.receiver.ifreader.IfSource` of the IF file. The sidecar is
    the one it was opened from (else ``X.json`` beside ``X.bin``); the IMU and truth files are
    checked against the sizes and digests it records (:func:`check_member`: a mixed set
    raises ``FileSetError``), except those named in ``skip`` (replaced by the caller's own
    files). (Here rather than with the integrated run, which re-exports it: the scalar run
    needs it too, without importing the integration package.)
    """
    out = {"imu": None, "truth": None, "ephemeris": None}
    sidecar = getattr(source, "sidecar_path", None)
    meta = source.meta if sidecar is not None else None
    if meta is None:
        sidecar = source.path.with_suffix(".json")
        if not sidecar.exists():
            return out
        meta = read_sidecar(sidecar)
    for key in ("imu", "truth"):
        if key not in skip:
            out[key] = check_member(sidecar, meta, f"{key}_file")
    out["ephemeris"] = member_path(sidecar, meta, "ephemeris_file")
    return out


class DuplicateKeyError(ValueError):
    """A JSON object with a key twice (JSON readers silently keep the last)."""


def unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """``object_pairs_hook`` of :func:`json.loads` that refuses a key given twice."""
    out: dict[str, Any] = {}
    for k, v in pairs:
        if k in out:
            raise DuplicateKeyError(f"key {k!r} given twice ({out[k]!r:.40} and {v!r:.40}); "
                                    "a reader would silently keep the last")
        out[k] = v
    return out


#: Sampling rates a sidecar may declare [Hz]: from the generator's lowest (below it the B3I
#: code's main lobe is mostly cut) to well above any front end's.
MIN_RATE_HZ, MAX_RATE_HZ = 1.0e6, 1.0e9


def _check_physics(path: Path, meta: dict[str, Any]) -> None:
    """The sidecar's numbers against physics and each other: a rate within
    [:data:`MIN_RATE_HZ`, :data:`MAX_RATE_HZ`], an IF inside the band the rate samples, and
    ``duration_s`` equal to ``n_samples / sampling_rate_hz`` (to a sample)."""
    fs, f_if, n = meta["sampling_rate_hz"], meta["if_hz"], meta["n_samples"]
    if not MIN_RATE_HZ <= fs <= MAX_RATE_HZ:
        raise SidecarError(f"sidecar {path}: sampling_rate_hz {fs:.6g} Hz is outside "
                           f"[{MIN_RATE_HZ:g}, {MAX_RATE_HZ:g}] Hz")
    if abs(f_if) > fs / 2.0:
        raise SidecarError(f"sidecar {path}: if_hz {f_if:.6g} Hz is outside the band "
                           f"+-{fs / 2:g} Hz that sampling_rate_hz {fs:g} Hz holds")
    dur = meta.get("duration_s")
    if dur is not None:
        if not _is_num(dur):
            raise SidecarError(f"sidecar {path}: duration_s must be a finite number, got "
                               f"{dur!r:.60}")
        if abs(dur - n / fs) > max(1.0 / fs, 1e-9 * abs(dur)):
            raise SidecarError(f"sidecar {path}: duration_s {dur:.6g} s, but n_samples / "
                               f"sampling_rate_hz = {n} / {fs:g} Hz = {n / fs:.6g} s")


def read_sidecar(path: str | Path) -> dict[str, Any]:
    """Read and check a sidecar.

    Returns
    -------
    dict
        The sidecar contents; ``start["week"]``/``start["sow"]`` are None when absent.

    Raises
    ------
    SidecarError
        Missing or unreadable file, not a JSON object, wrong schema, missing required key or
        a key of the wrong type or out of range (one line naming the key).
    """
    path = Path(path)
    try:
        meta = json.loads(path.read_text(encoding="utf-8"), object_pairs_hook=unique_keys)
    except DuplicateKeyError as exc:
        raise SidecarError(f"sidecar {path}: {exc}") from None
    except FileNotFoundError:
        raise SidecarError(f"sidecar {path}: not found") from None
    except OSError as exc:
        raise SidecarError(f"sidecar {path}: cannot read ({exc.strerror or exc})") from None
    except (UnicodeDecodeError, ValueError) as exc:  # JSONDecodeError is a ValueError
        raise SidecarError(f"sidecar {path}: not JSON ({exc})") from None
    except RecursionError:
        raise SidecarError(f"sidecar {path}: not JSON (nested too deeply)") from None
    if not isinstance(meta, dict):
        raise SidecarError(f"sidecar {path}: not a JSON object (top level is "
                           f"{type(meta).__name__})")
    if "schema" not in meta:
        raise SidecarError(f"sidecar {path}: not an sdr-di sidecar (no \"schema\": "
                           f"{SCHEMA!r})")
    if meta["schema"] != SCHEMA:
        raise SidecarError(f"sidecar {path}: schema {meta['schema']!r}, expected {SCHEMA!r}")
    for key, required, ok, what in _CHECKS:
        if key not in meta:
            if required:
                raise SidecarError(f"sidecar {path}: missing key {key!r}")
            continue
        if not (meta[key] is None and key in _NULLABLE) and not ok(meta[key]):
            raise SidecarError(f"sidecar {path}: {key} must be {what}, got {meta[key]!r:.60}")
    _check_physics(path, meta)
    start = meta["start"]
    week, sow = start.get("week"), start.get("sow")
    if week is not None and not (_is_int(week) and 0 <= week <= 9999):
        raise SidecarError(f"sidecar {path}: start.week must be a BDT week 0..9999, got "
                           f"{week!r:.60}")
    if sow is not None and not (_is_num(sow) and 0 <= sow < 604800):
        raise SidecarError(f"sidecar {path}: start.sow must be BDT seconds of week in "
                           f"[0, 604800), got {sow!r:.60}")
    return meta


def flag_conflicts(meta: dict[str, Any], *, sampling_rate_hz: float | None = None,
                   if_hz: float | None = None, sample_format: str | None = None,
                   spectrum_inverted: bool = False, start_week: int | None = None,
                   start_sow: float | None = None) -> list[str]:
    """What the command-line description of an IF file says against its sidecar.

    Parameters
    ----------
    meta : dict
        The sidecar (:func:`read_sidecar`).
    sampling_rate_hz, if_hz : float, optional
        ``--fs``, ``--if`` [Hz]; None: not given.
    sample_format : str, optional
        ``--format`` (a name or alias of :mod:`sdr_di.io.sample_formats`).
    spectrum_inverted : bool
        ``--inverted`` (True only when given).
    start_week, start_sow : optional
        ``--start-week``, ``--start-sow`` [BDT week, s].

    Returns
    -------
    list of str
        One phrase per contradiction, naming the flag, its value and the sidecar's (empty
        when the flags agree with the sidecar or are not given).

    Raises
    ------
    SampleFormatError
        ``sample_format`` is not a known format.
    """
    from ..errors import SampleFormatError
    from .sample_formats import get_format

    out = []

    def differ(a: float, b: float) -> bool:
        return abs(float(a) - float(b)) > 1e-6 * max(1.0, abs(float(b)))

    if sampling_rate_hz is not None and differ(sampling_rate_hz, meta["sampling_rate_hz"]):
        out.append(f"--fs {sampling_rate_hz:g} Hz, the sidecar {meta['sampling_rate_hz']:g} Hz")
    if if_hz is not None and differ(if_hz, meta["if_hz"]):
        out.append(f"--if {if_hz:g} Hz, the sidecar {meta['if_hz']:g} Hz")
    if sample_format is not None:
        given = get_format(sample_format).name
        try:
            recorded = get_format(meta["sample_format"]).name
        except SampleFormatError:
            recorded = meta["sample_format"]
        if given != recorded:
            out.append(f"--format {sample_format}, the sidecar {meta['sample_format']}")
    if spectrum_inverted and not meta.get("spectrum_inverted", False):
        out.append("--inverted, the sidecar a non-inverted spectrum")
    start = meta.get("start") or {}
    if start_week is not None and start.get("week") is not None and \
            start_week != start["week"]:
        out.append(f"--start-week {start_week}, the sidecar {start['week']}")
    if start_sow is not None and start.get("sow") is not None and \
            differ(start_sow, start["sow"]):
        out.append(f"--start-sow {start_sow:g} s, the sidecar {start['sow']:g} s")
    return out
