"""The documentation builds, its API reference renders, and the CLI reference is current.

``mkdocs build --strict`` fails on a broken link between pages, a page missing from the
navigation, or an API entry mkdocstrings cannot collect (it reads the sources statically:
nothing is imported). The CLI page is generated from the parser
(``scripts/cli_reference.py``); every option of every command must appear in it, so a new
flag without a regenerated page fails here.
"""

from __future__ import annotations

import argparse
import re
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


# ---- the API reference documents every parameter (issue 48 item 7) ---------------------------
def _documented_parameters(doc: str) -> set[str]:
    """Names in the numpydoc ``Parameters`` and ``Other Parameters`` sections of ``doc``
    (an entry ``name : type`` or ``a, b : type`` at the section's indentation)."""
    import inspect as _inspect

    lines = _inspect.cleandoc(doc or "").splitlines()
    names: set[str] = set()
    section = None
    for i, line in enumerate(lines):
        nxt = lines[i + 1] if i + 1 < len(lines) else ""
        if nxt and set(nxt.strip()) == {"-"} and line.strip():
            section = line.strip()
            continue
        if section in ("Parameters", "Other Parameters") and line and not line[0].isspace() \
                and set(line.strip()) != {"-"}:
            head = line.split(" : ")[0]
            names.update(n.strip().lstrip("*") for n in head.split(","))
    return names


def _public_functions():
    """Every function the API reference renders (``::: name`` in docs/reference/api.md),
    the methods of the classes it renders with ``members``, and sdr_di's own functions."""
    import importlib
    import inspect as _inspect

    import sdr_di

    text = (REPO / "docs" / "reference" / "api.md").read_text()
    out = {f"sdr_di.{n}": getattr(sdr_di, n) for n in sdr_di.__all__
           if _inspect.isfunction(getattr(sdr_di, n))}
    for m in re.finditer(r"^::: ([\w.]+)(?:\n    options:\n      members: \[([^\]]*)\])?",
                         text, re.M):
        mod, _, attr = m.group(1).rpartition(".")
        try:
            obj = getattr(importlib.import_module(mod), attr)
        except (ImportError, ValueError):
            obj = importlib.import_module(m.group(1))       # a module (sdr_di.errors)
        if _inspect.isfunction(obj):
            out[m.group(1)] = obj
        for member in (m.group(2) or "").split(","):
            fn = getattr(obj, member.strip(), None) if member.strip() else None
            if _inspect.isfunction(fn):
                out[f"{m.group(1)}.{member.strip()}"] = fn
    return out


def test_every_public_function_documents_its_parameters():
    import inspect as _inspect

    missing = {}
    for name, fn in _public_functions().items():
        params = [p.name for p in _inspect.signature(fn).parameters.values()
                  if p.name not in ("self", "cls")]
        undocumented = sorted(set(params) - _documented_parameters(fn.__doc__))
        if undocumented:
            missing[name] = undocumented
    assert not missing, missing
    assert "sdr_di.api.run_with" in _public_functions()      # the walk found the reference
