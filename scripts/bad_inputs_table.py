"""Regenerate the table of ``docs/bad_inputs.md`` from ``tests/test_bad_inputs.py``.

Each case of ``CASES`` is run on the working tree in-process (as the test runs it) for the
"after" column. The "before" column is the case's outcome on the code before issue 12
(commit 42d342a): kept from the current table for a case already in it, and for a new case
either run there (``--before-tree DIR``: an extracted copy of that commit, e.g. ``git
archive 42d342a | tar -x -C DIR``; the case runs as ``python -m sdr_di.cli`` in DIR on the
same work folder) or written ``not run``. The text above the table is kept, with its
counts updated.

Usage::

    python scripts/bad_inputs_table.py [--before-tree /tmp/old] [--check]
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import io
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
DOC = REPO / "docs" / "bad_inputs.md"
#: Characters of an error message kept in a table cell.
MSG_CHARS = 113


def _cases_module():
    spec = importlib.util.spec_from_file_location("bad_inputs_cases",
                                                  REPO / "tests" / "test_bad_inputs.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _cut(msg: str, d: Path) -> str:
    """``msg`` as a table cell: the work folder as ``{d}``, the repository as ``.``, cut."""
    msg = msg.replace(str(d), "{d}").replace(f"{REPO}/", "./").replace("|", "\\|")
    msg = msg.replace("][", "]\\[")  # "[[x]][0]" is not a Markdown reference link
    return msg if len(msg) <= MSG_CHARS else msg[:MSG_CHARS] + "..."


def _snapshot(d: Path) -> set[Path]:
    return set(d.rglob("*"))


def _clean(d: Path, before: set[Path]) -> list[str]:
    """Remove what a case left in ``d`` (only the new files and folders: a run that wrote
    beside an input must not take the input's folder with it); their names."""
    new = _snapshot(d) - before
    tops = sorted(p for p in new if p.parent not in new)
    for p in tops:
        if p.is_dir():
            shutil.rmtree(p, ignore_errors=True)
        else:
            p.unlink(missing_ok=True)
    return [p.relative_to(d).as_posix() for p in tops]


def _after(main, argv: list[str], d: Path, status: int = 2) -> str:
    """The case's outcome now; ``status`` is the exit status it must give (2: bad input; 1:
    a run that ends without a fix, ``docs/errors.md``)."""
    import warnings

    before = _snapshot(d)
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()), \
            warnings.catch_warnings():
        warnings.simplefilter("always")
        try:
            rc = main(argv)
        except SystemExit as exc:
            rc = exc.code if isinstance(exc.code, int) else 1
    left = _clean(d, before)
    lines = [ln for ln in err.getvalue().splitlines() if ln.strip()]
    if rc == status and len(lines) == 1 and lines[0].startswith("sdr-di: error: ") \
            and not left:
        return f"one line, exit {status}: " + _cut(lines[0][len("sdr-di: error: "):], d)
    return f"NOT ONE LINE: exit {rc}, {len(lines)} lines, left {left}"


def _before(tree: Path, argv: list[str], d: Path) -> str:
    return _before_run(tree, argv, d).replace(f"{tree}/", "./")


def _before_run(tree: Path, argv: list[str], d: Path) -> str:
    before = _snapshot(d)
    env = {**os.environ, "PYTHONPATH": str(tree)}
    res = subprocess.run([sys.executable, "-m", "sdr_di.cli", *argv], cwd=tree, env=env,
                         capture_output=True, text=True, timeout=300, check=False)
    left = _clean(d, before)
    err = res.stderr
    lines = [ln for ln in err.splitlines() if ln.strip()]
    if "Traceback" in err:
        exc = next((ln.split(":")[0] for ln in reversed(lines) if re.match(r"^[\w.]+(:|$)", ln)),
                   "?")
        return f"traceback ({exc})" + (", left files" if left else "")
    if res.returncode == 0:
        return "exit 0: ran" + (", wrote files" if left else "")
    if res.returncode == 1:
        return "exit 1: " + _cut(lines[-1] if lines else "", d)
    if left:
        return f"exit 2 after work (left {', '.join(left)})"
    if any(ln.startswith("usage:") for ln in lines):
        return f"exit 2, {len(lines)} lines (usage + error)"
    if len(lines) == 1:
        return "one line, exit 2: " + _cut(lines[0].removeprefix("sdr-di: error: "), d)
    return f"exit {res.returncode}, {len(lines)} lines"


def _old_rows(text: str) -> dict[str, str]:
    rows = {}
    for ln in text.splitlines():
        m = re.match(r"^\| ([\w\-]+) \| `.*` \| (.*) \| (.*) \|$", ln)
        if m and m.group(1) != "case":
            rows[m.group(1)] = m.group(2)
    return rows


def _summary(before: list[str]) -> str:
    n = len(before)
    one = sum(b.startswith("one line, exit 2") for b in before)
    tb = sum(b.startswith("traceback") for b in before)
    usage = sum("(usage + error)" in b for b in before)
    ok = sum(b.startswith("exit 0") for b in before)
    failed = sum(b.startswith("exit 1") for b in before)
    late = sum(b.startswith("exit 2 after work") for b in before)
    na = sum(b.startswith("n/a") for b in before)
    nr = sum(b.startswith("not run") for b in before)
    text = (f"Before: {one} of {n} one line with exit 2; {tb} tracebacks;\n"
            f"{usage} multi-line argparse errors; {ok} accepted (exit 0) and\n"
            f"{failed} reported as failed runs (exit 1); {late} exit 2 only after\n"
            f"work had started; {na} cases of `acquire`, a command added since.")
    if nr:
        text += f" {nr} not run on the old code."
    return text


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before-tree", type=Path, default=None,
                    help="extracted tree of commit 42d342a, for the new cases' before column")
    ap.add_argument("--check", action="store_true",
                    help="print the table instead of writing docs/bad_inputs.md")
    args = ap.parse_args()
    mod = _cases_module()
    from sdr_di.cli import main as cli_main
    from sdr_di.scenario import load_scenario
    from sdr_di.sim.generate import generate_files

    doc = DOC.read_text(encoding="utf-8")
    old = _old_rows(doc)
    with tempfile.TemporaryDirectory(prefix="bad_inputs_") as tmp:
        gen, d = Path(tmp) / "generated", Path(tmp) / "d"
        d.mkdir()
        sc = load_scenario(mod.DEFAULT_SCENARIO).with_overrides(duration_s=0.02,
                                                                 sampling_rate_hz=2.5e6)
        generate_files(sc, gen, name="s", progress=False)
        mod.make_workdir(d, gen)
        os.chdir(REPO)
        rows, befores = [], []
        for c in mod.CASES:
            case, argv, status = c[0], c[1], mod.case_status(c)
            a = [x.format(d=d) for x in argv]
            if case in old:
                b = old[case]
            elif args.before_tree is not None:
                b = _before(args.before_tree, a, d)
            else:
                b = "not run"
            after = _after(cli_main, a, d, status)
            shown = " ".join(["sdr-di", *argv]).replace("|", "\\|")
            rows.append(f"| {case} | `{shown}` | {b} | {after} |")
            befores.append(b)
    table = "| case | command | before | after |\n|---|---|---|---|\n" + "\n".join(rows) + "\n"
    n_ok = sum(r.split(" | ")[-1].startswith("one line, exit ") for r in rows)
    head = doc.split("\n| case | command |", 1)[0]
    head = re.sub(r"Before: .*?added since\.( \d+ not run on the old code\.)?",
                  _summary(befores), head, flags=re.DOTALL)
    head = re.sub(r"After: \d+ of \d+ one line", f"After: {n_ok} of {len(rows)} one line", head)
    if args.check:
        print(head + "\n" + table)
    else:
        DOC.write_text(head.rstrip("\n") + "\n\n" + table, encoding="utf-8")
    return 0 if n_ok == len(rows) else 1


if __name__ == "__main__":
    sys.exit(main())
