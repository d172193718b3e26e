"""Scalar mode as the integrated modes: the sidecar's navigation file as assistance, accuracy
against the truth file, ``--duration``, empty times before the first fix, progress to 100 %,
``--plots`` and ``sdr-di report RUN_DIR``.

One file, the session's 16 s at 2.5 MHz (test_front_door's), read for 8.5 s:
without assistance the first fix needs a decoded ephemeris (subframes 1-3, 18 s or more of
D1 message), so a fix inside 8.5 s shows the assistance.
"""

from pathlib import Path

import pytest

from sdr_di.cli import main
from sdr_di.io.solution_files import read_solution_csv
from sdr_di.receiver.run_scalar import open_source, run_scalar


@pytest.fixture(scope="module")
def short_file(if_files) -> Path:
    return if_files(16.0).if_file


def test_scalar_run_uses_the_sidecar_ephemeris_and_reports_accuracy(short_file, tmp_path,
                                                                    capsys):
    out = tmp_path / "run"
    rc = main(["run", str(short_file), "--duration", "8.5", "--out", str(out),
               "--no-progress", "--plots"])
    text = capsys.readouterr().out
    assert rc == 0, text
    assert "assistance: the sidecar's navigation file" in text
    assert "errors vs reference" in text and "processed 8.5 s" in text
    pvt = out / "default_pvt.csv"
    sol = read_solution_csv(pvt)
    fix = sol["status"] == "fix"
    assert fix.any()
    # rows before the first fix: empty week and seconds-of-week fields, not a week 0
    lines = [ln for ln in pvt.read_text().splitlines() if not ln.startswith("#")]
    first = lines[1].split(",")
    assert first[:2] == ["", ""] and first[3:5] == ["", ""], lines[1]
    assert lines[-1].split(",")[0] not in ("", "0")

    # --plots: the report's figures (the truth file is there); `report RUN_DIR` embeds them
    names = ("fix-pos-error", "fix-vel-error", "channels", "sky", "fix-status", "trajectory")
    pngs = sorted(p.name for p in out.glob("*.png"))
    assert pngs == sorted(f"default_scalar_{n}.png" for n in names)
    assert main(["report", str(out)]) == 0
    page = (out / "report.html").read_text()
    assert "<h1>Run: run</h1>" in page and page.count("<img") == len(names)
    for n in names:
        assert f'id="default_scalar-{n}"' in page, n
    assert 'id="default_scalar-navdata"' in page and "C08" in page and "IGSO" in page
    assert "no reference trajectory" not in page and "no fix" not in page

    # the same file without assistance: no ephemeris decoded in 8.5 s, so no fix
    res = run_scalar(open_source(short_file), tmp_path / "cold", duration_s=8.5,
                     progress=False)
    assert res.n_fixes == 0 and sum(fix) > 0
    # its report: the failure stated, what it wrote shown, each part left out said
    assert main(["report", str(tmp_path / "cold")]) == 0
    page = (tmp_path / "cold" / "report.html").read_text()
    assert "no fix in" in page and "the run failed" in page
    assert "no fix: no fix errors" in page and "fix-pos-error" not in page
    assert 'id="default_scalar-channels"' in page and 'id="default_scalar-navdata"' in page
    # stopped part-way: the solution file still under its .part name, no run record
    cold = tmp_path / "cold"
    (cold / "default_pvt.csv").rename(cold / "default_pvt.csv.part")
    (cold / "default_scalar_summary.json").unlink()
    assert main(["report", str(cold)]) == 0
    page = (cold / "report.html").read_text()
    assert "default_pvt.csv.part: still under its temporary name" in page


def test_scalar_progress_bar_says_what_it_does_and_ends_at_100(short_file, tmp_path, capsys):
    run_scalar(open_source(short_file), tmp_path / "p", duration_s=2.0, progress=True)
    err = capsys.readouterr().err.replace("\r", "\n").splitlines()
    bars = [ln for ln in err if ln.startswith("run scalar")]
    assert bars and "acquisition" in bars[0], bars[:2]
    assert "100%" in bars[-1] and "2.0/2.0 s" in bars[-1], bars[-1]
