"""SigMF recordings (``X.sigmf-meta`` beside ``X.sigmf-data``): read and write their metadata.

SigMF (the Signal Metadata Format) is the metadata format most SDR capture tools write. The
metadata file is JSON; its structure is checked with the ``sigmf`` library (schema and
namespace checks: :meth:`sigmf.SigMFFile.validate`), not by hand. What sdr-di reads:

=====================  ====================================================================
``core:datatype``      sample layout: ``ci8`` -> ``iq_int8``, ``ri8`` -> ``real_int8`` (also
                       with an ``_le``/``_be`` suffix, meaningless for bytes),
                       ``ci16_le`` -> ``iq_int16``, ``ri16_le`` -> ``real_int16``,
                       ``cf32_le`` -> ``gr_complex`` (:data:`DATATYPES`); any other datatype
                       (unsigned ``cu8``, big-endian, 32-bit integers, float64, real float)
                       is refused in one line naming it
``core:sample_rate``   sample rate [Hz] (required here unless ``--fs`` is given)
``core:num_channels``  must be 1
``core:frequency``     of the first capture: the RF frequency at 0 Hz of the samples [Hz].
                       The B3I IF follows: ``IF = 1268.52 MHz - core:frequency`` (the IF
                       convention of ``docs/formats.md``: the carrier appears at ``+IF`` in
                       I + jQ). For real datatypes SigMF does not say what the centre is;
                       sdr-di takes it as the LO (as a PocketSDR tag's ``F_LO``), and a
                       negative real IF is read at ``|IF|`` with the spectrum inverted
``core:datetime``      of the first capture: UTC time of the capture's first sample; sample
                       0's BDT week and seconds of week follow (leap seconds included,
                       :func:`sdr_di.timebase.utc_to_bdt`), a hint as ``--start-week/sow``
``core:sample_start``, ``core:offset``: place the capture's time on sample 0 of the file
=====================  ====================================================================

Several captures: the first gives the frequency and the time and a :class:`SigmfWarning`
says so; captures at different frequencies are refused (the receiver reads one IF).
Annotations are ignored. Refused in one line (:class:`~sdr_di.errors.SampleFormatError`):
metadata that is not JSON or fails the library's validation, no capture, no
``core:frequency``, ``core:header_bytes``/``core:trailing_bytes`` (non-sample bytes in the
data file), several channels, a required (``optional: false``) extension other than
``sdr_di``, a ``core:datetime`` before 2006, and a centre frequency that leaves B3I outside
the recorded band (:func:`check_b3i_in_band`).

Writing: :func:`sigmf_metadata` builds the metadata of an sdr-di IF file (datatype, rate,
version, author/recorder, one capture with frequency and datetime, the scenario name, hash and
seed under the ``sdr_di`` extension namespace), validated by the library before it is written.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import json
import math
import warnings
from pathlib import Path
from typing import Any

from ..constants import F_B3I
from ..errors import SampleFormatError
from ..timebase import bdt_minus_utc, bdt_to_datetime, utc_to_bdt
from .sample_formats import get_format

__all__ = ["DATATYPES", "B3I_MAIN_LOBE_HALF_WIDTH_HZ", "SigmfSource", "SigmfWarning",
           "check_b3i_in_band", "sigmf_meta_path", "sigmf_metadata", "sigmf_source"]

META_EXT, DATA_EXT = ".sigmf-meta", ".sigmf-data"
#: SigMF datatype -> sample format of the registry (:mod:`sdr_di.io.sample_formats`).
DATATYPES = {"ci8": "iq_int8", "ri8": "real_int8", "ci16_le": "iq_int16",
             "ri16_le": "real_int16", "cf32_le": "gr_complex"}
#: Half-width of the B3I main lobe [Hz] (chip rate 10.23 Mchip/s).
B3I_MAIN_LOBE_HALF_WIDTH_HZ = 10.23e6
#: Extension namespace of sdr-di's fields (scenario name, hash, seed).
NAMESPACE = "sdr_di"
_MAX_META_BYTES = 16 << 20


class SigmfWarning(UserWarning):
    """A SigMF recording read with a simplification (several captures: the first is used)."""


@dataclasses.dataclass(frozen=True)
class SigmfSource:
    """Reader options derived from a SigMF recording (and the explicit overrides).

    Attributes
    ----------
    meta_path, data_path : Path
        The metadata and the data file.
    sample_format : str
        Registry name.
    sampling_rate_hz, if_hz : float
        Sample rate and IF [Hz] as :class:`~sdr_di.receiver.ifreader.IfSource` takes them.
    spectrum_inverted : bool
        Read with the spectrum inverted (real samples with the LO above the carrier, or
        ``--inverted``).
    start_week, start_sow : int, float or None
        BDT week and seconds of week of sample 0 from ``core:datetime`` (or the overrides).
    center_hz : float
        ``core:frequency`` of the first capture [Hz].
    n_captures : int
        Captures in the metadata.
    """

    meta_path: Path
    data_path: Path
    sample_format: str
    sampling_rate_hz: float
    if_hz: float
    spectrum_inverted: bool
    start_week: int | None
    start_sow: float | None
    center_hz: float
    n_captures: int


def sigmf_meta_path(path: str | Path) -> Path | None:
    """The SigMF metadata a path names, or None when it names no SigMF recording.

    ``X.sigmf-meta`` is itself; ``X.sigmf-data`` and the base name ``X`` (no such file, or a
    file without suffix) give ``X.sigmf-meta`` when it exists. Any other path (``X.bin``,
    ``X.json``) gives None: those are described by a JSON sidecar, a tag or the options.

    Raises
    ------
    SampleFormatError
        A SigMF archive (``X.sigmf``, compressed or not) or collection: not read.
    """
    p = Path(path)
    if p.name.endswith(META_EXT):
        return p
    if p.name.endswith((".sigmf", ".sigmf.gz", ".sigmf.xz", ".sigmf.zip", ".sigmf-collection")):
        raise SampleFormatError(f"SigMF {p}: archives and collections are not read; extract "
                                "the recording and name its .sigmf-meta or .sigmf-data")
    if p.name.endswith(DATA_EXT):
        meta = p.with_name(p.name[:-len(DATA_EXT)] + META_EXT)
        return meta if meta.exists() else None
    if not p.exists() or (p.is_file() and p.suffix == ""):
        meta = p.with_name(p.name + META_EXT)
        return meta if meta.is_file() else None
    return None


def _load(meta_path: Path):
    """The library's :class:`sigmf.SigMFFile` of a metadata file, validated (no data file)."""
    import jsonschema
    from sigmf import SigMFFile
    from sigmf.error import SigMFError

    try:
        with open(meta_path, "rb") as fh:
            raw = fh.read(_MAX_META_BYTES + 1)
    except FileNotFoundError:
        raise SampleFormatError(f"SigMF {meta_path}: not found") from None
    except OSError as exc:
        raise SampleFormatError(f"SigMF {meta_path}: cannot read ({exc.strerror or exc})"
                                ) from None
    if len(raw) > _MAX_META_BYTES:
        raise SampleFormatError(f"SigMF {meta_path}: larger than {_MAX_META_BYTES >> 20} MiB, "
                                "not a metadata file")
    from .sidecar import DuplicateKeyError, unique_keys

    try:
        doc = json.loads(raw.decode("utf-8"), object_pairs_hook=unique_keys)
    except DuplicateKeyError as exc:
        raise SampleFormatError(f"SigMF {meta_path}: {exc}") from None
    except (UnicodeDecodeError, ValueError) as exc:
        raise SampleFormatError(f"SigMF {meta_path}: not JSON ({exc})") from None
    except RecursionError:
        raise SampleFormatError(f"SigMF {meta_path}: not JSON (nested too deeply)") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("global"), dict):
        raise SampleFormatError(f"SigMF {meta_path}: no \"global\" object")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # undeclared namespaces: the library's notice
            rec = SigMFFile(metadata=doc, skip_checksum=True)
            rec.validate()
    except jsonschema.exceptions.ValidationError as exc:
        where = "/".join(str(k) for k in exc.absolute_path) or "top level"
        raise SampleFormatError(f"SigMF {meta_path}: not valid SigMF metadata ({where}: "
                                f"{exc.message:.120})") from None
    except (SigMFError, KeyError, TypeError, ValueError, AttributeError) as exc:
        raise SampleFormatError(f"SigMF {meta_path}: not valid SigMF metadata ({exc})"
                                ) from None
    return rec


def check_b3i_in_band(center_hz: float, sampling_rate_hz: float, is_complex: bool, *,
                      where: str = "", carrier_hz: float = F_B3I,
                      hint: str = "give --if to read it anyway") -> float:
    """The IF of B3I in a recording centred at ``center_hz``, checked to lie in its band.

    The recorded band is ``+-fs/2`` about the centre (complex samples) or ``0..fs/2`` above
    the LO (real samples: half-width ``fs/4`` about ``fs/4``); B3I's main lobe is
    ``+-10.23 MHz`` about the carrier. The band must hold as much of the main lobe as it can:
    a band wider than the lobe holds all of it (``|IF - mid| <= half - 10.23 MHz``), a
    narrower band lies inside it (``|IF - mid| <= 10.23 MHz - half``) and has the carrier in
    its inner half (``|IF - mid| <= half / 2``, room for the Doppler search and the filter
    edges). The limit is continuous in ``fs`` (0 at ``half = 10.23 MHz``); at 2.5 MHz
    complex it is 0.625 MHz, at 25 MHz 2.27 MHz.

    Parameters
    ----------
    center_hz : float
        RF frequency at 0 Hz of the samples [Hz] (``core:frequency``).
    sampling_rate_hz : float
        Sample rate ``fs`` [Hz].
    is_complex : bool
        I/Q samples.
    where, hint : str, optional
        Prefix (the file) and end (what to do) of the error message.
    carrier_hz : float, optional
        Carrier [Hz] (B3I).

    Returns
    -------
    float
        ``carrier_hz - center_hz`` [Hz].

    Raises
    ------
    SampleFormatError
        B3I outside the recorded band (one line with the figures and what would fit).
    """
    fs = float(sampling_rate_hz)
    if_hz = carrier_hz - float(center_hz)
    if is_complex:
        mid, half = 0.0, fs / 2.0
    else:
        mid, half = fs / 4.0, fs / 4.0
    lobe = B3I_MAIN_LOBE_HALF_WIDTH_HZ
    limit = half - lobe if half >= lobe else min(lobe - half, half / 2.0)
    off = abs(abs(if_hz) - mid)
    if not (math.isfinite(if_hz) and off <= limit + 1e-6):
        kind = "complex" if is_complex else "real"
        raise SampleFormatError(
            f"{where}core:frequency {center_hz / 1e6:.9g} MHz puts B3I ({carrier_hz / 1e6:g} "
            f"MHz) at IF {if_hz / 1e6:+.6g} MHz, outside the {kind} band of fs "
            f"{fs / 1e6:g} MHz (the IF must lie within {limit / 1e6:g} MHz of "
            f"{mid / 1e6:g} MHz: docs/formats.md, SigMF); {hint}")
    return if_hz


def _num(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def sigmf_source(meta_path: str | Path, *, sample_format: str | None = None,
                 sampling_rate_hz: float | None = None, if_hz: float | None = None,
                 spectrum_inverted: bool = False, start_week: int | None = None,
                 start_sow: float | None = None, carrier_hz: float = F_B3I) -> SigmfSource:
    """Reader options of a SigMF recording, explicit options overriding its values one by one.

    Parameters
    ----------
    meta_path : path
        The ``.sigmf-meta`` file (:func:`sigmf_meta_path`).
    sample_format, sampling_rate_hz, if_hz : optional
        Replace the datatype's format, ``core:sample_rate`` and the IF from
        ``core:frequency`` (and with it the band check).
    spectrum_inverted : bool, optional
        ``--inverted``.
    start_week, start_sow : optional
        Replace the time from ``core:datetime`` (both or neither).
    carrier_hz : float, optional
        RF carrier [Hz] (B3I).

    Raises
    ------
    SampleFormatError
        Module notes (one line naming the file and the field).
    """
    meta_path = Path(meta_path)
    where = f"SigMF {meta_path}: "
    rec = _load(meta_path)
    glob, captures = rec.get_global_info(), rec.get_captures()
    data_path = meta_path.with_name(meta_path.name[:-len(META_EXT)] + DATA_EXT) \
        if meta_path.name.endswith(META_EXT) else meta_path.with_suffix(DATA_EXT)
    if glob.get("core:dataset"):
        data_path = meta_path.parent / str(glob["core:dataset"])
    if glob.get("core:metadata_only"):
        raise SampleFormatError(f"{where}core:metadata_only: the recording has no samples")
    if not data_path.is_file():
        raise SampleFormatError(f"{where}data file {data_path} not found")
    for ext in glob.get("core:extensions") or []:
        if not ext.get("optional", True) and ext.get("name") != NAMESPACE:
            raise SampleFormatError(f"{where}requires the SigMF extension {ext.get('name')!r} "
                                    "(optional: false), which sdr-di does not read")
    datatype = str(glob.get("core:datatype"))
    if datatype[1:] in ("i8_le", "i8_be"):  # byte order means nothing for 8-bit samples
        datatype = datatype[:3]
    if sample_format is None:
        if datatype not in DATATYPES:
            raise SampleFormatError(
                f"{where}core:datatype {datatype} cannot be read (readable: "
                f"{', '.join(DATATYPES)}); convert the samples or give --format")
        sample_format = DATATYPES[datatype]
    fmt = get_format(sample_format)
    if int(glob.get("core:num_channels", 1)) != 1:
        raise SampleFormatError(f"{where}core:num_channels {glob['core:num_channels']}: only "
                                "single-channel recordings are read")
    if glob.get("core:trailing_bytes") or any(c.get("core:header_bytes") for c in captures):
        raise SampleFormatError(f"{where}core:header_bytes/core:trailing_bytes: a data file "
                                "with non-sample bytes is not read")
    if sampling_rate_hz is None:
        fs = glob.get("core:sample_rate")
        if not (_num(fs) and fs > 0):
            raise SampleFormatError(f"{where}core:sample_rate {fs!r} is not a rate > 0 Hz; "
                                    "give --fs")
        sampling_rate_hz = float(fs)
    if not captures:
        raise SampleFormatError(f"{where}no capture (core:frequency, core:datetime)")
    first = captures[0]
    freqs = {c.get("core:frequency") for c in captures}
    if len(freqs) > 1:
        shown = ", ".join(f"{f / 1e6:.6g}" if _num(f) else repr(f) for f in
                          [c.get("core:frequency") for c in captures][:4])
        raise SampleFormatError(f"{where}{len(captures)} captures at different frequencies "
                                f"({shown} MHz): the receiver reads one IF; split the "
                                "recording")
    center = first.get("core:frequency")
    inverted = bool(spectrum_inverted)
    if if_hz is None:
        if not _num(center):
            what = "no core:frequency" if center is None else f"core:frequency {center!r}"
            raise SampleFormatError(f"{where}the first capture has {what}; give --if")
        if_hz = check_b3i_in_band(center, sampling_rate_hz, fmt.is_complex, where=where,
                                  carrier_hz=carrier_hz)
        if not fmt.is_complex and if_hz < 0.0:
            if_hz, inverted = -if_hz, True
    if len(captures) > 1:
        warnings.warn(f"{where}{len(captures)} captures: using the first's frequency and time "
                      "and reading the samples as one continuous stream", SigmfWarning,
                      stacklevel=2)
    if start_week is None and start_sow is None and first.get("core:datetime"):
        i0 = int(first.get("core:sample_start", 0)) - int(glob.get("core:offset", 0))
        start_week, start_sow = _start_time(where, first["core:datetime"],
                                            i0 / sampling_rate_hz)
    return SigmfSource(meta_path, data_path, fmt.name, float(sampling_rate_hz), float(if_hz),
                       inverted, start_week, start_sow,
                       float(center) if _num(center) else math.nan, len(captures))


def _start_time(where: str, text: str, t0_s: float) -> tuple[int, float]:
    """BDT week and sow of sample 0 from a capture's UTC ``core:datetime`` at ``t0_s``."""
    from sigmf.utils import parse_iso8601_datetime

    try:
        utc = parse_iso8601_datetime(str(text)).replace(tzinfo=None)
    except ValueError:
        raise SampleFormatError(f"{where}core:datetime {text!r:.60} is not an ISO 8601 UTC "
                                "time (YYYY-MM-DDTHH:MM:SS[.fff]Z)") from None
    utc -= _dt.timedelta(seconds=t0_s)
    try:
        return utc_to_bdt(utc)
    except ValueError:
        raise SampleFormatError(f"{where}core:datetime {text} is before the BDT epoch "
                                "2006-01-01; give --start-week/--start-sow") from None


def sigmf_metadata(*, sample_format: str, sampling_rate_hz: float, if_hz: float,
                   start_week: int, start_sow: float, carrier_hz: float = F_B3I,
                   description: str = "", author: str = "", recorder: str = "",
                   extra: dict[str, Any] | None = None) -> str:
    """SigMF metadata text of an sdr-di IF file, validated by the ``sigmf`` library.

    Parameters
    ----------
    sample_format : str
        Registry name; must have a SigMF datatype (:data:`DATATYPES`; ``iq_int4`` has none).
    sampling_rate_hz, if_hz : float
        Sample rate and IF [Hz]; ``core:frequency = carrier_hz - if_hz``.
    start_week, start_sow : int, float
        BDT time of sample 0 (written as UTC ``core:datetime``, leap seconds removed).
    description, author, recorder : str, optional
        ``core:description``, ``core:author``, ``core:recorder`` (omitted when empty).
    extra : dict, optional
        Fields of the ``sdr_di`` namespace (keys without the prefix), declared as an optional
        extension.

    Returns
    -------
    str
        The ``.sigmf-meta`` JSON.

    Raises
    ------
    SampleFormatError
        A format without a SigMF datatype.
    """
    from sigmf import SigMFFile

    name = get_format(sample_format).name
    datatype = next((k for k, v in DATATYPES.items() if v == name), None)
    if datatype is None:
        raise SampleFormatError(f"--sigmf: sample format {name} has no SigMF datatype "
                                f"(SigMF formats: {', '.join(sorted(DATATYPES.values()))})")
    bdt = bdt_to_datetime(start_week, start_sow)
    utc = bdt - _dt.timedelta(seconds=bdt_minus_utc(bdt))
    glob: dict[str, Any] = {"core:datatype": datatype, "core:sample_rate": float(sampling_rate_hz)}
    for key, val in (("core:description", description), ("core:author", author),
                     ("core:recorder", recorder)):
        if val:
            glob[key] = val
    if extra:
        glob["core:extensions"] = [{"name": NAMESPACE, "version": "1.0.0", "optional": True}]
        glob.update({f"{NAMESPACE}:{k}": v for k, v in extra.items()})
    rec = SigMFFile(metadata={"global": glob, "captures": [], "annotations": []})
    rec.add_capture(0, metadata={"core:frequency": float(carrier_hz - if_hz),
                                 "core:datetime": utc.strftime("%Y-%m-%dT%H:%M:%S.%fZ")})
    rec.validate()
    return rec.dumps()
