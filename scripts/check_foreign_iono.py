"""Deep mode on a file it did not write, whose assistance file has no ionosphere lines.

Stands in for another generator's recording (no SignalSim build here): a static 40 s file of
our generator starting mid-frame (06:30:14 BDT, so subframe 1 with the Klobuchar set comes
at +16..+22 s), rewritten in SignalSim's layout (``--layout signalsim``, the default:
``INT4X2`` sign-magnitude nibbles and an ``X.bin.tag`` written as IFdataGen writes it, no
JSON sidecar) or read with flags (``--layout flags``: ``--fs/--if/--format``); the start time
by ``--start-week/--start-sow``, the IMU and reference by flags, and a copy of the shipped
RINEX file without its ``IONOSPHERIC CORR`` lines as assistance. Prints the first deep row,
the take-up of the ionosphere and the 3D position RMS after it (the criterion: first row
before 15 s, RMS at most 1 m after the take-up).

    python scripts/check_foreign_iono.py [--fs 2.5e6] [--out /tmp/foreign_iono] [--iono-wait S]
        [--layout signalsim|flags]
"""

from __future__ import annotations

import argparse
import gzip
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from sdr_di.scenario import REPO_ROOT

RINEX = REPO_ROOT / "ephemeris" / "ESBC00DNK_R_20201770000_01D_MN.rnx.gz"
SCENARIO = f"""[scenario]
name = "static"
duration_s = 40.0
seed = 1

[time]
start = "2020-06-25T06:30:14"
scale = "BDT"

[start]
lat_deg = 40.0
lon_deg = 116.0
height_m = 100.0
velocity_enu_mps = [0.0, 0.0, 0.0]
attitude_pitch_roll_yaw_deg = [0.0, 0.0, 0.0]

[[motion]]
type = "hold"
duration_s = 40.0

[imu]
grade = "mems"

[satellites]
ephemeris = "{RINEX}"
"""


def _signalsim_copy(path: Path, meta: dict, out: Path) -> Path:
    """``path`` (``iq_int8``, 4-bit values) rewritten as SignalSim's ``INT4X2`` (per byte I
    in the high nibble, Q in the low, each sign bit 3 and magnitude ``|v|``: the value
    ``+-(2|v| + 1)``) with its ``.tag``, in ``out`` (no JSON sidecar there)."""
    if meta["sample_format"] != "iq_int8" or meta["if_hz"] != 0.0:
        raise SystemExit("--layout signalsim needs an iq_int8 file at IF 0")
    out.mkdir(parents=True, exist_ok=True)
    dst = out / path.name
    raw = np.memmap(path, dtype=np.int8, mode="r")

    def nibble(v):
        return ((v < 0).astype(np.uint8) << 3) | np.minimum(np.abs(v.astype(np.int16)),
                                                            7).astype(np.uint8)

    with open(dst, "wb") as fh:
        step = 1 << 24
        for k in range(0, raw.size, step):
            iq = np.asarray(raw[k:k + step]).reshape(-1, 2)
            fh.write((nibble(iq[:, 0]) << 4 | nibble(iq[:, 1])).astype(np.uint8).tobytes())
    fs_mhz = meta["sampling_rate_hz"] / 1e6
    (out / (path.name + ".tag")).write_text(
        "PROG = IFDataGen\nTIME = 2020/06/25 06:29:46.000\nFMT  = INT4X2\n"
        f"F_S  = {fs_mhz:.6f}\nF_LO = 1268.520000\nIQ   = 1\nBITS = 4\nSCALE = 1.0\n")
    return dst


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fs", type=float, default=2.5e6)
    ap.add_argument("--out", type=Path, default=Path("/tmp/foreign_iono"))
    ap.add_argument("--iono-wait", default=None)
    ap.add_argument("--filter", default="ekf")
    ap.add_argument("--layout", choices=("signalsim", "flags"), default="signalsim")
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    sc = a.out / "static.toml"
    sc.write_text(SCENARIO)
    cli = [sys.executable, "-m", "sdr_di.cli"]
    gen = a.out / "gen"
    if not (gen / "static.bin").exists():
        subprocess.run([*cli, "generate", "--scenario", str(sc), "--fs", str(a.fs), "--out",
                        str(gen), "--no-progress"], check=True)
    meta = json.loads((gen / "static.json").read_text())
    nav = a.out / "no_iono.rnx"
    with gzip.open(RINEX, "rt") as fh:
        nav.write_text("".join(ln for ln in fh if "IONOSPHERIC CORR" not in ln))
    run = a.out / f"run_{a.layout}"
    if a.layout == "signalsim":
        if_file = _signalsim_copy(gen / "static.bin", meta, a.out / "peer")
        layout = []
    else:
        if_file = gen / "static.bin"
        layout = ["--fs", str(meta["sampling_rate_hz"]), "--if", str(meta["if_hz"]),
                  "--format", meta["sample_format"]]
    cmd = [*cli, "run", str(if_file), "--mode", "deep", "--filter", a.filter, *layout,
           "--start-week", str(meta["start"]["week"]),
           "--start-sow", str(meta["start"]["sow"]), "--imu", str(gen / "static_imu.csv"),
           "--truth", str(gen / "static_truth.csv"), "--ephemeris", str(nav),
           "--out", str(run), "--no-progress"]
    if a.iono_wait is not None:
        cmd += ["--iono-wait", a.iono_wait]
    p = subprocess.run(cmd, capture_output=True, text=True)
    print(p.stdout + p.stderr)
    if p.returncode:
        return p.returncode
    head = (run / "static_deep.csv").read_text().splitlines()[1].split(",")
    rows = np.loadtxt(run / "static_deep.csv", delimiter=",", skiprows=2)
    t, iono = rows[:, 0], rows[:, head.index("iono")]
    pe = rows[:, [head.index(c) for c in ("pos_err_e_m", "pos_err_n_m", "pos_err_u_m")]]
    after = iono == 1
    rms = float(np.sqrt(np.mean(np.sum(pe[after] ** 2, axis=1)))) if after.any() else np.nan
    t_up = float(t[np.argmax(after)]) if after.any() else np.nan
    print(f"first deep row {t[0]:.1f} s; ionosphere taken up at {t_up:.1f} s; "
          f"{int((~after).sum())} rows flagged iono = 0; 3D position RMS after the take-up "
          f"{rms:.3f} m over {int(after.sum())} rows; rows {t.size} ({t[-1] - t[0]:.1f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
