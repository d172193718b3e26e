"""A run that cannot be right says so; messages name what the user typed; no leftovers
(issue 28 items 1-3).

Small files only: one 1 s, 2.5 MHz generated set shared by the module (``short_set``).
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest

from sdr_di.cli import main


@pytest.fixture(scope="module")
def short_set(tmp_path_factory) -> Path:
    """A 1 s generated set at 2.5 MHz (iq_int8): ``s.bin`` with its sidecar and companions."""
    d = tmp_path_factory.mktemp("short_set")
    assert main(["generate", "--no-progress", "--fs", "2.5e6", "--duration", "1", "--out",
                 str(d), "--name", "s"]) == 0
    return d


def _run(capsys, argv: list[str]) -> tuple[int, list[str]]:
    rc = main(argv)
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    return rc, err


# -- item 3: no leftovers --------------------------------------------------------------------

def test_failed_deep_run_leaves_no_folder_and_says_what_length_it_needs(short_set, tmp_path,
                                                                       capsys):
    out = tmp_path / "a" / "run"          # two levels that do not exist yet
    rc, err = _run(capsys, ["run", str(short_set / "s.bin"), "--mode", "deep",
                            "--no-progress", "--out", str(out)])
    assert rc == 1 and len(err) == 1 and err[0].startswith("sdr-di: error: "), err
    assert "no hand-over" in err[0] and "too short for the hand-over" in err[0], err[0]
    m = re.search(r"needs about (\d+) s", err[0])
    assert m and int(m.group(1)) == 12, err[0]      # two D1 subframes of 6 s
    assert not (tmp_path / "a").exists()
