"""Errors that reach the user as one line naming the file and what is wrong, and atomic output."""
from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path


class FflsError(Exception):
    """A user-facing error. ``str(e)`` is one line: ``PATH: what is wrong``.

    The CLI prints it as ``ffls: error: PATH: what is wrong`` and exits with status 2; no
    traceback is shown.
    """

    def __init__(self, message: str, path: str | os.PathLike | None = None):
        self.path = None if path is None else Path(path)
        self.message = " ".join(str(message).split())  # one line, always
        super().__init__(f"{self.path}: {self.message}" if self.path is not None else self.message)


class InputError(FflsError):
    """Bad input data: a missing, corrupt or inconsistent file."""


class GLUnavailable(FflsError):
    """No OpenGL 4.3+ context could be created (neither EGL nor OSMesa)."""


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike, suffix: str | None = None):
    """Yield a temporary path beside ``path``; rename it onto ``path`` only if the block succeeds.

    A failing writer leaves nothing behind, neither the temporary file nor a half-written output.
    The temporary name keeps the extension (some writers choose the format from it).
    """
    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise FflsError("output folder does not exist", parent)
    suffix = path.suffix if suffix is None else suffix
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=f".tmp{suffix}", dir=parent)
    os.close(fd)
    tmp = Path(tmp)
    try:
        yield tmp
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; outputs get the usual mode
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask
