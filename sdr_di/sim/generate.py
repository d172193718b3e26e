"""``sdr-di generate``: scenario -> IF file + IMU file + truth file + metadata sidecar.

Outputs in ``out_dir`` (``NAME`` = scenario name unless given):

``NAME.bin``        IF samples (format in the sidecar)
``NAME.json``       metadata sidecar (:mod:`sdr_di.io.sidecar`), written last
``NAME_imu.csv``    200 Hz IMU data (:mod:`sdr_di.io.imu_files`)
``NAME_truth.csv``  200 Hz truth (position, velocity, attitude, specific force, rates)
``NAME.sigmf-data``, ``NAME.sigmf-meta``  with ``sigmf=True`` (``--sigmf``): the SigMF pair
                    (the data a hard link to ``NAME.bin``; :mod:`sdr_di.io.sigmf_files`)

The four files (six with the SigMF pair) are one :class:`~sdr_di.io.atomic.OutputSet`: each
is written under ``<file>.part``; only when all are complete are they renamed, the sidecar
last. On any error or interrupt the ``.part`` files are removed and the files of an earlier
set under the same names are left as they were. The sidecar records the size and digest of
the IF, IMU and truth files (:func:`~sdr_di.io.sidecar.file_fingerprint`), so a set mixed by
a kill between the renames is refused by every reader (:func:`~sdr_di.io.sidecar.check_member`).
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import json
import math
from concurrent.futures import ThreadPoolExecutor, wait
from pathlib import Path

import numpy as np

from .. import __version__
from ..constants import F_B3I
from ..errors import OutputError, ScenarioError
from ..ins.imu import ImuErrorModel
from ..io.atomic import (
    OutputSet,
    check_output_dir,
    ensure_output_dir,
    output_dir_removed_on_failure,
)
from ..io.imu_files import write_imu, write_truth
from ..io.page_cache import ReleaseBehind
from ..paths import check_free_space, check_outputs
from ..io.sample_formats import get_format
from ..io.sidecar import file_fingerprint, write_sidecar
from ..io.sigmf_files import check_b3i_in_band, sigmf_metadata
from ..orbits.rinex_nav import load_nav
from ..scenario.schema import Scenario
from ..signal.navmsg import assistance_klobuchar
from ..timebase import bdt_minus_utc, bdt_to_datetime
from .atmosphere import AtmosphereTruth
from .geometry import ReceiverPath
from .ifgen import SYNTHESIS_VERSION, IfGenerator, build_satellites
from .motion import segment_from_spec
from .oscillator import scenario_clock
from .trajectory import generate_trajectory


def simulate_truth(sc: Scenario):
    """Truth trajectory of a scenario at the IMU rate (true time from the start).

    Raises
    ------
    ScenarioError
        A motion segment is impossible from the state reached at its start.
    """
    where = sc.source or "scenario"
    try:
        segments = [segment_from_spec(s) for s in sc.motion]
        return generate_trajectory(sc.lat, sc.lon, sc.height, np.array(sc.v_n),
                                   np.array(sc.att), segments, rate_hz=sc.imu.rate_hz,
                                   duration=sc.duration_s)
    except ValueError as exc:
        raise ScenarioError(f"{where}: motion: {exc}") from None


def imu_model(sc: Scenario) -> ImuErrorModel:
    """IMU error model of a scenario."""
    return ImuErrorModel.from_spec(sc.imu)


def make_generator(sc: Scenario, truth=None) -> IfGenerator:
    """Build the IF generator of a scenario (loads ephemeris, selects satellites)."""
    nav = load_nav(sc.satellites.ephemeris)
    truth = simulate_truth(sc) if truth is None else truth
    path = ReceiverPath(truth.t, truth.r_e, truth.v_e)
    # the header's coefficients as broadcast (BDS, else GPS lines): what the D1/D2 messages
    # carry, so a receiver decoding them removes exactly the simulated delay model
    iono, source = (assistance_klobuchar(nav) if sc.signal.ionosphere == "klobuchar"
                    else (None, "off"))
    sats = build_satellites(sc, nav, path, iono)
    gen = IfGenerator(sc, sats, path, iono)
    clock = scenario_clock(sc, truth)  # [receiver_clock] line + [oscillator] (truth)
    gen.clock_truth = clock if clock.spec is not None else None
    gen.iono_source = source
    if sc.atmosphere is not None and sc.atmosphere.residuals:
        gen.atmosphere = AtmosphereTruth(sc.atmosphere, [s.prn for s in sats], sc.duration_s,
                                         sc.seed, sc.height)
    return gen


def generate_files(sc: Scenario, out_dir: str | Path, *, name: str | None = None,
                   progress: bool = True, sigmf: bool = False) -> dict[str, Path]:
    """Generate all outputs of a scenario; returns {label: path}.

    ``sigmf``: also write the SigMF pair ``NAME.sigmf-data`` (a hard link to ``NAME.bin``, a
    copy where the file system has none) and ``NAME.sigmf-meta``
    (:func:`~sdr_di.io.sigmf_files.sigmf_metadata`), members of the same output set.

    Raises
    ------
    SdrDiError
        Bad scenario, ephemeris or output problems (see :mod:`sdr_di.errors`).
    """
    out_dir = check_output_dir(out_dir)  # created once the inputs are known good
    name = sc.name if name is None else name
    if not name or "/" in name or name.startswith("."):
        raise OutputError(f"invalid output name {name!r}")
    if sigmf:  # before any work: no SigMF datatype, or a pair the reader would refuse
        sig = sc.signal
        sigmf_metadata(sample_format=sig.sample_format, sampling_rate_hz=sig.sampling_rate_hz,
                       if_hz=sig.if_hz, start_week=sc.week, start_sow=sc.sow)
        check_b3i_in_band(F_B3I - sig.if_hz, sig.sampling_rate_hz,
                          get_format(sig.sample_format).is_complex, where="--sigmf: ",
                          hint="choose --if inside that range or leave out --sigmf")
    paths = {
        "if": out_dir / f"{name}.bin",
        "imu": out_dir / f"{name}_imu.csv",
        "truth": out_dir / f"{name}_truth.csv",
        "metadata": out_dir / f"{name}.json",
    }
    # none of them an input, none too long, room for them: before any work
    check_outputs([*paths.values(), *(sigmf_names(out_dir / name) if sigmf else ())])
    check_free_space(out_dir, estimated_bytes(sc), f"a {sc.duration_s:g} s set at "
                     f"{sc.signal.sampling_rate_hz:g} Hz ({sc.signal.sample_format})")
    truth = simulate_truth(sc)
    gen = make_generator(sc, truth)
    rng = np.random.default_rng(np.random.SeedSequence([sc.seed, 0x1A0]))
    imu = imu_model(sc).apply(truth, rng)

    with output_dir_removed_on_failure(out_dir):  # a failure leaves no empty folder
        out_dir = ensure_output_dir(out_dir)
        duration = gen.n_samples / gen.fs
        bar = None
        if progress:
            from tqdm import tqdm

            # counted in samples (integers), shown in seconds: the bar ends exactly at its total
            bar = tqdm(total=gen.n_samples, unit="s", unit_scale=1.0 / gen.fs,
                       desc=f"generate {name}",
                       bar_format="{l_bar}{bar}| {n:.2f}/{total:.2f} s [{elapsed}<{remaining}]")
        with OutputSet() as files:  # any error or interrupt: the .part files go, old files stay
            try:
                with files.open(paths["if"]) as fh:
                    write_overlapped(fh, gen.chunks(reuse=True), bar)
            finally:
                if bar is not None:
                    bar.close()
            week, sow = sc.week, sc.sow
            bdt = bdt_to_datetime(week, sow)
            write_imu(paths["imu"], imu, week=week, sow=sow, output_set=files)
            clock = gen.clock_truth or scenario_clock(sc, truth)
            draws = truth_draws(imu, gen)
            write_truth(paths["truth"], dataclasses.replace(
                truth, clock_bias_s=clock.bias_s, clock_drift_s_s=clock.drift_s_s),
                week=week, sow=sow, output_set=files,
                records={k: json.dumps(v, separators=(",", ":")) for k, v in draws.items()})
            utc = bdt - _dt.timedelta(seconds=bdt_minus_utc(bdt))
            jams, cn0_eff = gen.jammers.records({s.prn: s.cn0_dbhz for s in gen.sats},
                                                sc.satellites.cn0_dbhz)
            sats = gen.start_summary()
            for row in sats:
                row["effective_cn0_dbhz"] = cn0_eff[row["prn"]]
            meta = {
                "if_file": paths["if"].name,
                "sampling_rate_hz": gen.fs,
                "if_hz": sc.signal.if_hz,
                "carrier_hz": 1268.52e6,
                "sample_format": sc.signal.sample_format,
                "quantization_bits": sc.signal.quantization_bits,
                "spectrum_inverted": False,
                "n_samples": gen.n_samples,
                "duration_s": duration,
                "start": {"week": week, "sow": sow, "bdt": bdt.isoformat(),
                          "utc": utc.isoformat()},
                "receiver_clock": {"bias_s": sc.clock.bias_s, "drift_s_s": sc.clock.drift_s_s},
                "oscillator": None if sc.oscillator is None else sc.oscillator.as_dict(),
                "imu": sc.imu.as_dict(),
                "agc": {"sigma_in": gen.sigma_in, "gain_lsb": gen.gain,
                        **gen.jammers.agc.as_dict()},
                "interference": jams,
                "ionosphere": "klobuchar" if gen.iono is not None else "none",
                "klobuchar_source": gen.iono_source,
                "klobuchar": None if gen.iono is None else {"alpha": list(gen.iono.alpha),
                                                            "beta": list(gen.iono.beta)},
                "troposphere": sc.signal.troposphere,
                "scenario": {"name": sc.name, "hash": sc.hash, "seed": sc.seed,
                             "file": str(sc.source) if sc.source else None},
                "satellites": sats,
                "outages": [{"prn": o.prn, "start_s": o.start_s, "end_s": o.end_s,
                             "attenuation_db": None if math.isinf(o.attenuation_db)
                             else o.attenuation_db} for o in sc.outages],
                "imu_file": paths["imu"].name,
                "truth_file": paths["truth"].name,
                "ephemeris_file": str(sc.satellites.ephemeris),
                "generator": {"name": "sdr-di", "version": __version__,
                              "synthesis_version": SYNTHESIS_VERSION},
            }
            meta.update(draws)  # only with a grade's unit errors or atmosphere residuals
            meta["files"] = {paths[k].name: _fingerprint(paths[k], files)
                             for k in ("if", "imu", "truth")}
            if sigmf:
                paths.update(_write_sigmf_pair(out_dir / name, paths["if"], meta, sc, files))
            write_sidecar(paths["metadata"], meta, output_set=files)  # opened last: renamed last
            files.commit()
    return paths


#: Bytes per row of the IMU and truth CSV files, rounded up (for :func:`estimated_bytes`).
_IMU_ROW_BYTES, _TRUTH_ROW_BYTES = 160, 520


def estimated_bytes(sc: Scenario) -> float:
    """The size of the set :func:`generate_files` writes for ``sc`` [bytes]: the IF samples
    exactly, the IMU and truth files from their row sizes (a SigMF data file is a hard
    link)."""
    n = sc.duration_s * sc.signal.sampling_rate_hz
    rows = sc.duration_s * sc.imu.rate_hz
    return n * get_format(sc.signal.sample_format).bytes_per_sample \
        + rows * (_IMU_ROW_BYTES + _TRUTH_ROW_BYTES)


def sigmf_names(base: Path) -> tuple[Path, Path]:
    """``BASE.sigmf-data`` and ``BASE.sigmf-meta``."""
    return base.with_name(base.name + ".sigmf-data"), base.with_name(base.name + ".sigmf-meta")


def truth_draws(imu, gen: IfGenerator) -> dict:
    """The drawn truth beyond the legacy record, for the sidecar and the truth file's
    header: ``imu_unit`` (:meth:`~sdr_di.ins.imu.ImuUnit.record`, an extended IMU model)
    and ``atmosphere_truth`` (:meth:`~sdr_di.sim.atmosphere.AtmosphereTruth.record`,
    ``[atmosphere] truth = "residuals"``); empty for a legacy scenario (its files keep
    their bytes)."""
    out = {}
    if getattr(imu, "unit", None) is not None:
        out["imu_unit"] = imu.unit.record()
    if gen.atmosphere is not None:
        out["atmosphere_truth"] = gen.atmosphere.record()
    return out


def _write_sigmf_pair(base: Path, if_path: Path, meta: dict, sc: Scenario,
                      files: OutputSet) -> dict[str, Path]:
    """``BASE.sigmf-data`` (the IF file's content, linked) and ``BASE.sigmf-meta``."""
    data, meta_path = sigmf_names(base)
    files.link(if_path, data)
    text = sigmf_metadata(
        sample_format=meta["sample_format"], sampling_rate_hz=meta["sampling_rate_hz"],
        if_hz=meta["if_hz"], start_week=meta["start"]["week"], start_sow=meta["start"]["sow"],
        description=f"BeiDou B3I IF samples of scenario {sc.name!r} (seed {sc.seed})",
        author="sdr-di generate", recorder=f"sdr-di {__version__}",
        extra={"scenario_name": sc.name, "scenario_hash": sc.hash, "seed": sc.seed,
               "quantization_bits": meta["quantization_bits"],
               "sidecar": base.name + ".json"})
    with files.open(meta_path, "w") as fh:
        fh.write(text)
    return {"sigmf-data": data, "sigmf-meta": meta_path}


def write_overlapped(fh, chunks, bar=None) -> None:
    """Write ``chunks`` (from :meth:`IfGenerator.chunks` with ``reuse=True``) to ``fh``, each
    on a writer thread while the next is generated (the kernel releases the GIL).

    At most one write is in flight: it is waited for before the next is started, so the
    buffer it reads is never the one being generated (two buffers cycle). An error of a write
    (disk full) is raised here, in the caller's thread. The written pages leave the page
    cache behind the writer (:class:`~sdr_di.io.page_cache.ReleaseBehind`).
    """
    try:
        release = ReleaseBehind(fh.fileno())
        pos = fh.tell()
    except (AttributeError, OSError, ValueError):   # not a file of the system (a buffer)
        release, pos = None, 0

    def write(buf: memoryview) -> None:
        nonlocal pos
        fh.write(buf)
        pos += buf.nbytes
        if release is not None:
            release.advance(pos)

    with ThreadPoolExecutor(1, thread_name_prefix="sdr-di-writer") as pool:
        pending = None
        try:
            for chunk in chunks:
                if pending is not None:
                    pending.result()
                pending = pool.submit(write, memoryview(np.ascontiguousarray(chunk)).cast("B"))
                if bar is not None:
                    bar.update(int(chunk.shape[0]))
            if pending is not None:
                pending.result()
        finally:
            if pending is not None:
                pending.cancel()
                wait([pending])


def _fingerprint(final: Path, files: OutputSet) -> dict:
    try:
        return file_fingerprint(files.part_name(final))
    except OSError as exc:
        raise OutputError(f"{final}: cannot read back ({exc.strerror or exc})") from None
