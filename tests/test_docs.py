"""The documentation builds, its API reference renders, and the CLI reference is current.

``mkdocs build --strict`` fails on a broken link between pages, a page missing from the
navigation, or an API entry mkdocstrings cannot collect (it reads the sources statically:
nothing is imported). The CLI page is generated from the parser
(``scripts/cli_reference.py``); every option of every command must appear in it, so a new
flag without a regenerated page fails here.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import pytest

from sdr_di.cli import build_parser

REPO = Path(__file__).resolve().parents[1]


def test_docs_build_strict_with_the_api_reference(tmp_path):
    pytest.importorskip("mkdocstrings")
    site = tmp_path / "site"
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-q",
                           "-f", str(REPO / "mkdocs.yml"), "-d", str(site)],
                          cwd=REPO, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    api = (site / "reference" / "api" / "index.html").read_text()
    for name in ("generate", "run", "study", "register_filter", "parse_filter_spec",
                 "KalmanFilterBase"):
        assert 'id="sdr_di.' in api and name in api, name
    assert (site / "guides" / "write_a_filter" / "index.html").is_file()


def _commands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def test_cli_reference_lists_every_command_and_option():
    page = (REPO / "docs" / "reference" / "cli.md").read_text()
    for name, sub in _commands(build_parser()).items():
        assert f"## `sdr-di {name}`" in page, name
        section = page.split(f"## `sdr-di {name}`", 1)[1].split("\n## ", 1)[0]
        for action in sub._actions:
            for opt in action.option_strings:
                assert opt in section, f"sdr-di {name} {opt}: run scripts/cli_reference.py"
