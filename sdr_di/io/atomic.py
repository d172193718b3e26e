"""Write outputs so that nothing half-written ever carries its final name.

Every output is written to ``<final>.part`` in the same directory and renamed with
:func:`os.replace` only when complete; on any error the ``.part`` file is removed and an
:class:`~sdr_di.errors.OutputError` names the file and the cause.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import BinaryIO, Iterator

from ..errors import OutputError


def ensure_output_dir(path: str | Path) -> Path:
    """Create ``path`` if needed and check it is a writable directory.

    Raises
    ------
    OutputError
        It exists as a file, cannot be created, or is not writable.
    """
    path = Path(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"output directory {path}: cannot create ({exc.strerror or exc})") from None
    if not path.is_dir():
        raise OutputError(f"output directory {path}: exists and is not a directory")
    if not os.access(path, os.W_OK | os.X_OK):
        raise OutputError(f"output directory {path}: not writable")
    return path


@contextlib.contextmanager
def atomic_open(final: str | Path, mode: str = "wb") -> Iterator[BinaryIO]:
    """Open ``final.part`` for writing; rename to ``final`` on success, delete on failure.

    Parameters
    ----------
    final : path
        The name the complete file will have.
    mode : str
        ``"wb"`` or ``"w"`` (text, UTF-8).

    Raises
    ------
    OutputError
        Any OSError while writing (disk full, permission...), with the partial file removed.
    """
    final = Path(final)
    part = final.with_name(final.name + ".part")
    try:
        fh = open(part, mode, **({} if "b" in mode else {"encoding": "utf-8", "newline": ""}))
    except OSError as exc:
        raise OutputError(f"{final}: cannot write ({exc.strerror or exc})") from None
    ok = False
    try:
        with fh:
            yield fh
        ok = True
    except OSError as exc:
        raise OutputError(f"{final}: write failed ({exc.strerror or exc})") from None
    finally:
        if ok:
            try:
                os.replace(part, final)
            except OSError as exc:
                part.unlink(missing_ok=True)
                raise OutputError(f"{final}: cannot rename ({exc.strerror or exc})") from None
        else:
            part.unlink(missing_ok=True)
