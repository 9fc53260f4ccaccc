"""Every file the CLI writes for an operator (exports, reports, charts, anchors) goes through here.

The data goes to a temporary file this process creates itself beside the target (``mkstemp``:
``O_CREAT|O_EXCL|O_NOFOLLOW``, a random name), is fsynced, then takes the target's name in one
step; so no planted symlink is ever followed, a reader never sees half a file, and a failure
leaves nothing behind. An existing target (a symlink too) is never replaced without
``force``; with it, the name is replaced, never whatever a symlink there points to.
"""

from __future__ import annotations

import contextlib
import errno
import io
import os
import stat
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO, TextIO

from faultledger.errors import FaultLedgerError

OUTPUT_MODE = 0o640
"""Owner writes, group reads, others nothing: reports hold fault descriptions and sources."""


class OutputFileError(FaultLedgerError):
    """The file cannot or may not be written; the message names it and says why."""


class OutputExistsError(OutputFileError):
    """The target exists and ``force`` was not given; it was left untouched."""


def check_target(target: Path, force: bool = False) -> None:
    """Raise ``OutputFileError`` now (before any work) if ``target`` cannot be written:
    it exists and ``force`` is false, or it is a directory."""
    try:
        info = target.lstat()
    except FileNotFoundError:
        return
    except OSError as error:
        raise OutputFileError(f"cannot write {target}: {error.strerror or error}") from None
    if stat.S_ISDIR(info.st_mode):
        raise OutputFileError(f"cannot write {target}: it is a directory")
    if not force:
        kind = "a symlink" if stat.S_ISLNK(info.st_mode) else "a file"
        raise OutputExistsError(f"{target} exists ({kind}); add --force to replace it")


@contextlib.contextmanager
def open_output(target: Path, force: bool = False, mode: int = OUTPUT_MODE
                ) -> Iterator[BinaryIO]:
    """A binary file whose content becomes ``target`` when the block ends without error.

    Without ``force`` an existing ``target`` is an ``OutputExistsError``, also when it
    appears while the block runs (the final step is a hard link, which never replaces).
    """
    check_target(target, force)
    directory = target.parent
    try:
        fd, temporary = tempfile.mkstemp(prefix=f".{target.name[:64]}.", suffix=".tmp",
                                         dir=directory)  # [:64]: stays within NAME_MAX
    except OSError as error:
        raise OutputFileError(f"cannot write {target}: {error.strerror or error}") from None
    try:
        with os.fdopen(fd, "wb") as out:
            os.fchmod(out.fileno(), mode)  # exactly, whatever the umask
            yield out
            out.flush()
            os.fsync(out.fileno())
        _publish(temporary, target, force)
    except OSError as error:
        _remove(temporary)
        raise OutputFileError(f"cannot write {target}: {error.strerror or error}") from None
    except BaseException:
        _remove(temporary)
        raise
    _sync_directory(directory)


@contextlib.contextmanager
def open_text_output(target: Path, force: bool = False, mode: int = OUTPUT_MODE
                     ) -> Iterator[TextIO]:
    """``open_output`` as UTF-8 text with newlines written as given (CSV, JSON Lines)."""
    with open_output(target, force, mode) as raw:
        text = io.TextIOWrapper(raw, encoding="utf-8", newline="")
        try:
            yield text
            text.flush()
        except BaseException:
            with contextlib.suppress(Exception):
                text.detach()
            raise
        text.detach()  # the binary file stays open for open_output's fsync


def write_output(target: Path, data: bytes | str, force: bool = False,
                 mode: int = OUTPUT_MODE) -> None:
    """Write all of ``data`` (str as UTF-8) to ``target``, by the rules of ``open_output``."""
    with open_output(target, force, mode) as out:
        out.write(data.encode("utf-8") if isinstance(data, str) else data)


def _publish(temporary: str, target: Path, force: bool) -> None:
    if force:
        os.replace(temporary, target)  # replaces the name itself, never a symlink's target
        return
    try:
        os.link(temporary, target)  # never replaces: fails if the name exists
    except FileExistsError:
        raise OutputExistsError(
            f"{target} appeared while it was written; add --force to replace it") from None
    except OSError as error:
        if error.errno not in (errno.EPERM, errno.EOPNOTSUPP, errno.EXDEV, errno.EMLINK):
            raise
        # No hard links here (some network and FUSE file systems): checked, then renamed.
        check_target(target, force)
        os.replace(temporary, target)
        return
    _remove(temporary)


def _remove(temporary: str) -> None:
    with contextlib.suppress(FileNotFoundError):
        os.unlink(temporary)


def _sync_directory(directory: Path) -> None:
    """Make the new name durable; not every platform or file system can, which is fine."""
    with contextlib.suppress(OSError):
        fd = os.open(directory, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
