"""Write outputs so that nothing half-written ever carries its final name.

Every output is written to ``<final>.part`` in the same directory and renamed with
:func:`os.replace` only when complete; on any error the ``.part`` file is removed and an
:class:`~sdr_di.errors.OutputError` names the file and the cause.

Files that belong together (an IF file with its IMU, truth and sidecar) are written with an
:class:`OutputSet`: every member goes to its ``.part`` name first, and only when all are
complete are they renamed, in the order they were opened (companions first, the file that
describes them last). A failure or an interrupt before that point removes the new ``.part``
files and leaves whatever an earlier run left under the final names untouched. A kill between
two renames leaves a set whose members do not match their sidecar: the sidecar records each
member's size and digest (:mod:`sdr_di.io.sidecar`) so that readers refuse such a set.
Renames are not followed by ``fsync``: the guarantee holds against a killed or failed
process, not against a power cut.
"""

from __future__ import annotations

import contextlib
import os
import shutil
from pathlib import Path
from typing import IO, Any, Iterator

from ..errors import OutputError
from ..paths import check_not_input


def ensure_output_dir(path: str | Path) -> Path:
    """Create ``path`` if needed and check it is a writable directory.

    Raises
    ------
    OutputError
        It exists as a file, cannot be created, or is not writable.
    """
    path = Path(path)
    check_output_dir(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"output directory {path}: cannot create ({exc.strerror or exc})") from None
    if not path.is_dir():
        raise OutputError(f"output directory {path}: exists and is not a directory")
    if not os.access(path, os.W_OK | os.X_OK):
        raise OutputError(f"output directory {path}: not writable")
    return path


def check_output_dir(path: str | Path) -> Path:
    """Check, without creating anything, that ``path`` is or can become a writable directory.

    For a command to refuse a bad ``--out`` before any work, and to create the folder only
    when it has something to write (:func:`ensure_output_dir`).

    Raises
    ------
    OutputError
        ``path`` or one of its parents exists and is not a directory, or the nearest existing
        folder is not writable.
    """
    path = Path(path)
    probe = path
    while not probe.exists():
        if probe.parent == probe:
            break
        probe = probe.parent
    if probe.exists() and not probe.is_dir():
        what = "exists and is not a directory" if probe == path else f"{probe} is not a directory"
        raise OutputError(f"output directory {path}: {what}")
    if probe.exists() and not os.access(probe, os.W_OK | os.X_OK):
        where = "" if probe == path else f" ({probe})"
        raise OutputError(f"output directory {path}: not writable{where}")
    return path


@contextlib.contextmanager
def output_dir_removed_on_failure(path: str | Path) -> Iterator[Path]:
    """Remove ``path`` again if the block fails and leaves it empty.

    For a command that creates its output folder (:func:`ensure_output_dir`) once its inputs
    are checked, and may still fail or be interrupted before it writes anything there (a run
    with no hand-over, Ctrl-C during the start-up): the folders this call did not find on
    entry, ``path`` and any parents created for it, are removed on any exception (Ctrl-C
    included) as long as they are empty. A folder that holds something is kept.
    """
    path = Path(path)
    new: list[Path] = []           # deepest first
    probe = path
    while not probe.exists() and probe.parent != probe:
        new.append(probe)
        probe = probe.parent
    try:
        yield path
    except BaseException:
        for d in new:
            try:
                d.rmdir()          # only an empty folder
            except OSError:
                break
        raise


@contextlib.contextmanager
def atomic_open(final: str | Path, mode: str = "wb") -> Iterator[IO[Any]]:
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
    check_not_input(final)
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


class OutputSet:
    """Files written under ``.part`` names and renamed together once all are complete.

    Use as a context manager: leaving the block with an exception (``KeyboardInterrupt``
    included) deletes every ``.part`` file of the set; :meth:`commit` renames them to their
    final names in the order they were opened, so the last one opened (the sidecar) appears
    last.

    Examples
    --------
    >>> with OutputSet() as files:                                   # doctest: +SKIP
    ...     with files.open(out / "x.bin") as fh:
    ...         fh.write(data)
    ...     with files.open(out / "x.json", "w") as fh:
    ...         fh.write(text)
    ...     files.commit()
    """

    def __init__(self) -> None:
        self._members: list[tuple[Path, Path]] = []
        self._committed = False

    def __enter__(self) -> OutputSet:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is not None or not self._committed:
            self.discard()

    @staticmethod
    def part_name(final: str | Path) -> Path:
        """The temporary name of ``final`` while it is written."""
        final = Path(final)
        return final.with_name(final.name + ".part")

    @contextlib.contextmanager
    def open(self, final: str | Path, mode: str = "wb") -> Iterator[IO[Any]]:
        """Open the member ``final`` for writing under its ``.part`` name.

        Raises
        ------
        OutputError
            Any OSError while opening or writing (the ``.part`` file is removed).
        """
        final = Path(final)
        if any(f == final for f, _ in self._members):
            raise ValueError(f"{final}: already a member of this output set")
        check_not_input(final)
        part = self.part_name(final)
        try:
            fh = open(part, mode, **({} if "b" in mode else {"encoding": "utf-8", "newline": ""}))
        except OSError as exc:
            raise OutputError(f"{final}: cannot write ({exc.strerror or exc})") from None
        self._members.append((final, part))
        try:
            with fh:
                yield fh
        except OSError as exc:
            raise OutputError(f"{final}: write failed ({exc.strerror or exc})") from None

    def link(self, source: str | Path, final: str | Path) -> None:
        """Add the member ``final`` with the content of the member ``source`` (already
        written): a hard link to ``source``'s ``.part`` file, a copy where the file system
        has no hard links. Renamed by :meth:`commit` in its turn like an opened member.

        Raises
        ------
        OutputError
            Neither link nor copy could be made.
        """
        source, final = Path(source), Path(final)
        src_part = next((p for f, p in self._members if f == source), None)
        if src_part is None:
            raise ValueError(f"{source}: not a member of this output set")
        if any(f == final for f, _ in self._members):
            raise ValueError(f"{final}: already a member of this output set")
        check_not_input(final)
        part = self.part_name(final)
        part.unlink(missing_ok=True)  # a .part left by a killed run
        self._members.append((final, part))
        try:
            os.link(src_part, part)
        except OSError:
            try:
                shutil.copyfile(src_part, part)
            except OSError as exc:
                raise OutputError(f"{final}: cannot write ({exc.strerror or exc})") from None

    def commit(self) -> list[Path]:
        """Rename every member to its final name, in the order opened; returns the names.

        Raises
        ------
        OutputError
            A rename failed; the members not yet renamed are deleted.
        """
        done = []
        for final, part in self._members:
            try:
                os.replace(part, final)
            except OSError as exc:
                self._members = self._members[len(done):]
                self.discard()
                raise OutputError(f"{final}: cannot rename ({exc.strerror or exc})") from None
            done.append(final)
        self._committed = True
        return done

    def discard(self) -> None:
        """Delete the ``.part`` files not yet renamed (final names are never touched)."""
        for _, part in self._members:
            try:
                part.unlink(missing_ok=True)
            except OSError:
                pass


class FinalizingWriter:
    """The life cycle every output writer shares: :meth:`close` publishes the file under its
    final name, :meth:`abort` discards it; used as a context manager it closes on success
    and aborts on an exception. Subclasses implement both and keep ``self._closed``."""

    _closed: bool = False

    def close(self):
        raise NotImplementedError

    def abort(self) -> None:
        raise NotImplementedError

    @property
    def closed(self) -> bool:
        """True after :meth:`close` or :meth:`abort`."""
        return self._closed

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        if exc_type is None:
            self.close()
        else:
            self.abort()
        return False
