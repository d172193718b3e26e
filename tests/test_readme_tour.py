"""The README's 5-minute tour, every command of it, at 2.5 MHz (so the guide cannot rot).

The commands are read from the README's ``bash`` block that follows the ``<!-- tour:``
marker, in order, and run in-process through :func:`sdr_di.cli.main` with four changes that
keep them small and out of the repository: ``signals/out`` becomes a temporary folder,
``generate`` gets ``--fs 2.5e6`` (10x smaller: the README's figures are for this file, 20 s
at 2.5 MHz; the deep, loose and tight runs hand over at about 12.2 s and report errors
after it, which are checked against the README's figures), runs and generation get
``--no-progress``, and the study gets ``--runs 1 --workers 0`` (one seed, in process).
Each command is one test, in the README's order; a command whose predecessor failed is
skipped rather than failed again.
"""

from __future__ import annotations

import json
import re
import shlex
from pathlib import Path

import pytest

from sdr_di.cli import main

REPO = Path(__file__).resolve().parents[1]
MARK = "<!-- tour:"


def tour_commands(readme: Path = REPO / "README.md") -> list[str]:
    """The ``sdr-di`` commands of the tour block, comments stripped, in order."""
    lines = readme.read_text().splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith(MARK))
    i = next(j for j in range(start, len(lines)) if lines[j].startswith("```"))
    cmds = []
    for ln in lines[i + 1:]:
        if ln.startswith("```"):
            break
        cmd = ln.split("#", 1)[0].strip()
        if cmd:
            cmds.append(cmd)
    return cmds


TOUR = tour_commands()

_FIGURES = re.compile(r"position is\s+about ([\d.]+) m RMSE in all three, velocity about "
                      r"([\d.]+) m/s in deep and ([\d.]+) m/s in loose and\s+tight "
                      r"\(`tests/test_readme_tour.py` holds each figure within (\d+) %")


def readme_figures(mode: str, readme: Path = REPO / "README.md") -> tuple[float, float, float]:
    """The README's position and velocity RMSE for ``mode`` [m, m/s] and the tolerance it
    states (a fraction)."""
    m = _FIGURES.search(" ".join(readme.read_text().split()))
    assert m, "the README's sentence of tour figures is missing"
    pos, vel_deep, vel_other, pct = (float(v) for v in m.groups())
    return pos, vel_deep if mode == "deep" else vel_other, pct / 100.0


def test_the_readme_states_its_tour_figures_and_tolerance():
    assert readme_figures("deep") == (0.25, 0.01, 0.3)
    assert readme_figures("tight")[1] == 0.02
_state: dict[str, object] = {"failed": None}


def _small(cmd: str, place: Path) -> list[str]:
    argv = shlex.split(cmd.replace("signals/out", str(place / "signals" / "out")))
    assert argv[0] == "sdr-di", cmd
    argv = argv[1:]
    sub = argv[0]
    if sub == "generate":
        argv += ["--fs", "2.5e6", "--no-progress"]
        if "--out" not in argv:
            argv += ["--out", str(place / "signals" / "out")]
    elif sub == "run":
        argv += ["--no-progress"]
    elif sub == "study":
        argv = [str(REPO / a) if a.startswith("studies/") else a for a in argv]
        argv += ["--runs", "1", "--workers", "0"]
    return argv


def test_the_tour_is_the_four_modes_a_study_and_its_report():
    subs = [shlex.split(c)[1] for c in TOUR]
    assert subs[0] == "generate" and subs[-2:] == ["study", "report"]
    assert "report signals/out/tour_run" in " ".join(TOUR)      # the runs' own page
    modes = {"scalar"}
    for c in TOUR:
        a = shlex.split(c)
        if "--mode" in a:
            modes.add(a[a.index("--mode") + 1])
    assert modes == {"scalar", "deep", "loose", "tight"}


@pytest.fixture(scope="module")
def place(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("tour")


@pytest.mark.slow
@pytest.mark.parametrize("i", range(len(TOUR)), ids=[f"{i}-{shlex.split(c)[1]}"
                                                     for i, c in enumerate(TOUR)])
def test_tour_command(i, place, capsys):
    if _state["failed"] is not None:
        pytest.skip(f"an earlier tour command failed: {_state['failed']}")
    argv = _small(TOUR[i], place)
    try:
        rc = main(argv)
        out = capsys.readouterr().out
        assert rc == 0, f"{TOUR[i]}: exit {rc}"
        _check(argv, out, place)
    except BaseException:
        _state["failed"] = TOUR[i]
        raise


def _check(argv: list[str], out: str, place: Path) -> None:
    """What the README says each command prints or writes."""
    sub = argv[0]
    if sub == "generate":
        name = argv[argv.index("--name") + 1]
        for suffix in (".bin", ".json", "_imu.csv", "_truth.csv"):
            assert (place / "signals" / "out" / f"{name}{suffix}").is_file()
    elif sub == "run":
        mode = argv[argv.index("--mode") + 1] if "--mode" in argv else "scalar"
        ifp = Path(argv[1])
        run_dir = ifp.parent / f"{ifp.stem}_run"
        if mode == "scalar":
            assert (run_dir / f"{ifp.stem}_pvt.csv").is_file()
            assert (run_dir / f"{ifp.stem}.nmea").is_file()
        else:
            assert "errors vs reference" in out, out
            summary = json.loads((run_dir / f"{ifp.stem}_{mode}_summary.json").read_text())
            assert summary["mode"] == mode
            pos, vel, tol = readme_figures(mode)
            m = summary["metrics"]
            assert abs(m["pos_m_rmse"] - pos) <= tol * pos, (mode, m["pos_m_rmse"], pos)
            assert abs(m["vel_mps_rmse"] - vel) <= tol * vel, (mode, m["vel_mps_rmse"], vel)
            assert (run_dir / f"{ifp.stem}_{mode}.csv").is_file()
    elif sub == "study":
        d = Path(argv[argv.index("--out") + 1])
        for f in ("runs.csv", "cells.csv", "report.html"):
            assert (d / f).is_file(), f
    elif sub == "report":
        page = (Path(argv[1]) / "report.html").read_text()
        if Path(argv[1]).name == "tour_run":    # the runs' report: each run's figures
            for mode in ("deep", "loose", "tight"):
                for name in ("pos-error", "vel-error", "att-error", "nis", "trajectory",
                             "channels", "sats-used", "consistency"):
                    assert f'id="tour_{mode}-{name}"' in page, (mode, name)
            for mode in ("deep", "tight"):                  # per channel: not loose (a fix)
                assert f'id="tour_{mode}-innovations"' in page, mode
            assert 'id="tour_loose-innovations"' not in page
            for name in ("fix-pos-error", "fix-vel-error", "channels", "sky", "fix-status",
                         "trajectory", "navdata"):
                assert f'id="tour_scalar-{name}"' in page, name
