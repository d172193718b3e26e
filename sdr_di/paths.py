"""Paths a command reads and writes: an output never lands on an input, and a path the
system refuses is one line.

Two rules every command keeps (issue 49 items 1 and 3):

- **No output is an input.** While a command runs (:func:`command_scope`, entered by the CLI
  and by each function of :mod:`sdr_di.api`), every reader notes the real path of the file
  it read (:func:`note_input`: the IF file, its sidecar, SigMF metadata, ephemeris, IMU,
  truth, scenario, assumptions, study spec). Every writer of :mod:`sdr_di.io.atomic` asks
  :func:`check_not_input` before it opens its ``.part`` file, and the commands check the
  names they will write before any work (:func:`check_outputs`): an output whose real path
  is one of the inputs (same file by name, link or hard link) is refused with
  :class:`OutputIsInputError`. Outside a scope (internal use) nothing is noted and nothing
  refused.
- **An OSError on a path is a bad input.** :func:`path_error` turns an ``OSError`` (a name
  too long, a path through a file, a permission) into a one-line
  :class:`PathError` naming the path (shortened: a 4 KB path is not
  repeated in full) and the system's reason; :func:`check_path_length` refuses a name or a
  path longer than the file system takes before anything is created.
"""

from __future__ import annotations

import contextlib
import contextvars
import os
from collections.abc import Iterable, Iterator
from pathlib import Path

from .errors import OutputError, SdrDiError

#: Real paths (and (device, inode) pairs) of the files read by the running command; None
#: outside :func:`command_scope`.
_INPUTS: contextvars.ContextVar[dict | None] = contextvars.ContextVar("sdr_di_inputs",
                                                                       default=None)

#: Characters of a path kept in a message (head and tail, the middle elided).
SHOWN_PATH_CHARS = 120


class OutputIsInputError(OutputError, ValueError):
    """An output of a command would replace one of its inputs (its real path, a link or a
    hard link to it)."""


class PathError(SdrDiError):
    """A path the system refused (too long, through a file, no permission...): one line."""


class PathTooLongError(PathError, ValueError):
    """A path, or one of its names, is longer than the file system takes."""


class OutOfSpaceError(OutputError):
    """The outputs a command is about to write do not fit the free space (estimated before
    any work)."""


def shown(path: str | os.PathLike) -> str:
    """``path`` for a one-line message: at most :data:`SHOWN_PATH_CHARS` characters, the
    middle elided."""
    s = os.fspath(path)
    if len(s) <= SHOWN_PATH_CHARS:
        return s
    k = SHOWN_PATH_CHARS // 2 - 2
    return f"{s[:k]}...{s[-k:]} ({len(s)} characters)"


@contextlib.contextmanager
def command_scope() -> Iterator[None]:
    """Collect the inputs of one command (nested scopes share the outer one)."""
    if _INPUTS.get() is not None:
        yield
        return
    token = _INPUTS.set({"paths": {}, "ids": {}})
    try:
        yield
    finally:
        _INPUTS.reset(token)


def note_input(*paths: str | os.PathLike | None, what: str = "input") -> None:
    """Record ``paths`` as inputs of the running command (None and missing files skipped)."""
    reg = _INPUTS.get()
    if reg is None:
        return
    for p in paths:
        if p is None:
            continue
        try:
            real = os.path.realpath(p)
            st = os.stat(real)
        except (OSError, ValueError):
            continue
        reg["paths"][real] = (what, os.fspath(p))
        reg["ids"][(st.st_dev, st.st_ino)] = (what, os.fspath(p))


def check_not_input(path: str | os.PathLike) -> None:
    """Refuse to write ``path`` when it is an input of the running command.

    Raises
    ------
    OutputIsInputError
        ``path`` (its real path, or the file it names by a hard link) was read as an input.
    """
    reg = _INPUTS.get()
    if reg is None:
        return
    try:
        real = os.path.realpath(path)
    except (OSError, ValueError):
        return
    hit = reg["paths"].get(real)
    if hit is None:
        try:
            st = os.stat(real)
            hit = reg["ids"].get((st.st_dev, st.st_ino))
        except OSError:
            hit = None
    if hit is not None:
        what, given = hit
        raise OutputIsInputError(
            f"output {shown(path)} is the {what} {shown(given)}: writing it would destroy "
            "the input; choose another --out (or --name), or move the input")


def check_outputs(paths: Iterable[str | os.PathLike]) -> None:
    """:func:`check_not_input` and :func:`check_path_length` for every output a command
    will write, before any work."""
    for p in paths:
        check_path_length(p)
        check_not_input(p)


def check_path_length(path: str | os.PathLike) -> None:
    """Refuse a path or a name longer than the file system takes (``PC_NAME_MAX``,
    ``PC_PATH_MAX`` of the nearest existing folder).

    Raises
    ------
    PathTooLongError
    """
    p = Path(path)
    probe = p.parent
    while True:
        try:
            if probe.exists():
                break
        except OSError:
            pass
        if probe.parent == probe:
            break
        probe = probe.parent
    try:
        name_max = os.pathconf(probe, "PC_NAME_MAX")
        path_max = os.pathconf(probe, "PC_PATH_MAX")
    except (OSError, ValueError, AttributeError):
        name_max, path_max = 255, 4096
    long_name = next((n for n in p.parts if len(os.fsencode(n)) > name_max), None)
    if long_name is not None:
        raise PathTooLongError(f"{shown(path)}: the name {shown(long_name)} is longer than "
                               f"the {name_max} bytes the file system takes")
    if len(os.fsencode(os.path.abspath(p))) >= path_max:
        raise PathTooLongError(f"{shown(path)}: longer than the {path_max} bytes the file "
                               "system takes")


def path_error(exc: OSError) -> PathError:
    """An ``OSError`` on a path as a one-line error naming the path and the reason."""
    where = exc.filename if exc.filename is not None else ""
    why = exc.strerror or str(exc)
    return PathError(f"{shown(where)}: {why}" if where else why)


def read_toml(path: str | os.PathLike, what: str, error: type[Exception]) -> dict:
    """Read the TOML file ``path`` (a ``what``: "scenario", "study"...) as a dict, noted as
    an input of the running command.

    Every failure is one ``error(...)`` naming the file: unreadable (any ``OSError``), not
    UTF-8, not TOML, or nested deeper than the parser's recursion allows (a table 3000 deep
    raised a 3002-line ``RecursionError``, issue 49 item 4).
    """
    import tomllib

    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise error(f"{what} {shown(path)}: cannot read ({exc.strerror or exc})") from None
    try:
        raw = tomllib.loads(data.decode("utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise error(f"{what} {shown(path)}: not valid TOML ({exc})") from None
    except RecursionError:
        raise error(f"{what} {shown(path)}: not valid TOML (nested too deeply for the "
                    "parser)") from None
    note_input(path, what=what)
    return raw


def file_safe(name: str) -> str:
    """``name`` (a filter entry, an import path ``pkg.mod:Name``) as part of a file name:
    every character other than letters, digits, ``_``, ``.`` and ``-`` becomes ``_``."""
    import re

    return re.sub(r"[^A-Za-z0-9_.-]", "_", name)


def check_free_space(out_dir: str | os.PathLike, n_bytes: float, what: str) -> None:
    """Refuse to start writing about ``n_bytes`` (``what``: the estimate, in words) into
    ``out_dir`` when its file system (that of the nearest existing folder) has less free.

    Raises
    ------
    OutOfSpaceError
    """
    import shutil

    probe = Path(out_dir)
    while not probe.exists() and probe.parent != probe:
        probe = probe.parent
    try:
        free = shutil.disk_usage(probe).free
    except OSError:
        return
    if n_bytes > free:
        raise OutOfSpaceError(f"{shown(out_dir)}: {what} needs about {_size(n_bytes)}, the "
                              f"file system has {_size(free)} free")


def _size(n: float) -> str:
    for unit in ("bytes", "kB", "MB", "GB", "TB", "PB", "EB"):
        if abs(n) < 1000 or unit == "EB":
            return f"{n:.0f} {unit}" if unit == "bytes" else f"{n:.3g} {unit}"
        n /= 1000
    return f"{n:g}"


@contextlib.contextmanager
def outside_scope() -> Iterator[None]:
    """Suspend :func:`command_scope` for code that reads and rewrites its own intermediate
    files (a study's or an experiment's runs, in this process: their generated sets are
    cached, read, removed and made again); the command's own inputs stay protected around
    it."""
    token = _INPUTS.set(None)
    try:
        yield
    finally:
        _INPUTS.reset(token)
