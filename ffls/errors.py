"""Errors that reach the user as one line naming the file and what is wrong, and the one output policy.

Every file ffls writes goes through :func:`atomic_output` (one file) or :func:`atomic_folder`
(a folder of files). Both write beside the target and rename onto it only when the writer
succeeded, so that an error, Ctrl-C or SIGTERM leaves the old output (or nothing), never a
half-written one. Every write failure (no such folder, permission, read-only file system, disk
full, the path is a folder) becomes one :class:`OutputError` naming the path. While
:func:`guard_inputs` is active (the CLI activates it), an output that would replace a file
registered as an input (:func:`register_input`) is refused.
"""
from __future__ import annotations

import contextlib
import contextvars
import errno
import os
import shutil
import stat
import tempfile
from pathlib import Path

__all__ = ["FflsError", "InputError", "OutputError", "GLUnavailable", "atomic_output", "atomic_folder",
           "check_output_path", "os_error_message", "register_input", "guard_inputs", "kept_on_interrupt",
           "outputs_on_interrupt",
           "interrupt_note", "name_output", "disk_full", "available_memory", "physical_memory", "atomic_outputs",
           "not_a_regular_file", "broken_link"]


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


class OutputError(FflsError, OSError):
    """An output cannot be written: no folder, no permission, read-only, disk full, would replace an input."""


class GLUnavailable(FflsError):
    """No OpenGL 4.3+ context could be created (neither EGL nor OSMesa)."""


_WHY = {
    errno.ENOSPC: "no space left on the device (disk full)",
    errno.EDQUOT: "disk quota exceeded",
    errno.EACCES: "permission denied",
    errno.EPERM: "operation not permitted",
    errno.EROFS: "read-only file system",
    errno.EISDIR: "is a folder, not a file",
    errno.ENOTDIR: "a part of the path is a file, not a folder",
    errno.ENOENT: "no such file or folder",
    errno.ENAMETOOLONG: "file name too long",
    errno.EFBIG: "file too large for the file system",
    errno.EXDEV: "cannot rename across file systems",
}


def os_error_message(e: OSError) -> str:
    """A short reason for an OSError, without the path (the caller names it)."""
    if e.errno in _WHY:
        return _WHY[e.errno]
    return e.strerror or (str(e.args[0]) if len(e.args) == 1 else "") or type(e).__name__


# ----------------------------------------------------------------------------- inputs
_INPUTS: contextvars.ContextVar = contextvars.ContextVar("ffls_inputs", default=None)


def _identity(path: Path):
    try:
        st = os.stat(path)
    except OSError:
        return None
    return (st.st_dev, st.st_ino)


def register_input(path: str | os.PathLike) -> None:
    """Record ``path`` as an input of the running command (no-op outside :func:`guard_inputs`)."""
    reg = _INPUTS.get()
    if reg is not None:
        ident = _identity(Path(path))
        if ident is not None:
            reg[ident] = Path(path)


@contextlib.contextmanager
def kept_on_interrupt(note: str):
    """While active, an interruption (Ctrl-C, SIGTERM: a :class:`KeyboardInterrupt`) carries
    ``note``, what the work keeps on purpose (a resumable store's staged photos), which the command
    line says instead of "nothing partial was left" (:func:`interrupt_note`)."""
    try:
        yield
    except KeyboardInterrupt as e:
        if interrupt_note(e) is None:
            e.ffls_kept = str(note)
        raise


def interrupt_note(e: BaseException) -> str | None:
    """What an interrupted command kept on purpose (:func:`kept_on_interrupt`) and the outputs it
    had completed before the interruption (:func:`outputs_on_interrupt`), or None."""
    kept = getattr(e, "ffls_kept", None)
    done = [p for p in getattr(e, "ffls_written", None) or () if os.path.lexists(p)]  # (not in a staging folder)
    if not done:
        return kept
    names = ", ".join(str(p) for p in done)
    return f"{names} {'was' if len(done) == 1 else 'were'} written whole before it; {kept or 'nothing partial was left'}"


_WRITTEN: contextvars.ContextVar = contextvars.ContextVar("ffls_written", default=None)


@contextlib.contextmanager
def outputs_on_interrupt():
    """While active, the outputs :func:`atomic_output`, :func:`atomic_outputs` and
    :func:`atomic_folder` complete (renamed onto their paths) are recorded, and an interruption
    (a :class:`KeyboardInterrupt`) carries them for :func:`interrupt_note`: a Ctrl-C just after
    ``ffls relight`` renamed its image said "nothing partial was left" of a whole output."""
    done: list = []
    token = _WRITTEN.set(done)
    try:
        yield
    except KeyboardInterrupt as e:
        if done and getattr(e, "ffls_written", None) is None:
            e.ffls_written = list(done)
        raise
    finally:
        _WRITTEN.reset(token)


def _completed(path: Path, renamed=None) -> None:
    """Record ``path`` as a completed output (:func:`outputs_on_interrupt`).

    Called after its rename, and, with ``renamed`` (the :func:`_identity` of the temporary file
    or folder taken before the rename), from the handler of an exception that may have come
    between the rename and that call: a Ctrl-C goes to any thread of the process (the signal
    mask holds it from this one only), and Python raises it at the main thread's next bytecode.
    Recorded then only where ``path`` is that file."""
    done = _WRITTEN.get()
    if done is not None and path not in done and (renamed is None or _identity(path) == renamed):
        done.append(path)


@contextlib.contextmanager
def guard_inputs():
    """While active, :func:`atomic_output` and :func:`atomic_folder` refuse to replace a registered input."""
    token = _INPUTS.set({})
    try:
        yield
    finally:
        _INPUTS.reset(token)


def _check_not_input(path: Path) -> None:
    reg = _INPUTS.get()
    if not reg:
        return
    ident = _identity(path)
    if ident is not None and ident in reg:
        raise OutputError("refusing to overwrite an input of this command", path)
    if path.is_dir():  # a folder output must not hold an input either
        root = str(path.resolve()) + os.sep
        for p in reg.values():
            if str(Path(p).resolve()).startswith(root):
                raise OutputError(f"refusing to replace a folder that holds an input ({p})", path)


# ----------------------------------------------------------------------------- output policy
def _through_link(path: Path) -> Path:
    """The file a symbolic link ``path`` points to (an output is written through the link, as cp,
    ffmpeg and oiiotool do); ``path`` itself when it is no link. A dangling link is refused, as
    GNU cp refuses to write through one: its target's folder may not be what the user meant."""
    if not path.is_symlink():
        return path
    target = Path(os.path.realpath(path))
    if not target.exists():
        raise OutputError(f"{broken_link(path)}; ffls writes through a link only to an existing file or folder "
                          "(as cp does)", path)
    return target


#: What an existing path that is neither a file nor a folder is, by its ``stat`` type
_SPECIAL_KINDS = ((stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
                  (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


def broken_link(path: str | os.PathLike) -> str | None:
    """What is wrong with a symbolic link ``path`` that leads nowhere: a loop of links (which
    was called "not found"), or a link to a missing file; None for anything else."""
    try:
        if not os.path.islink(path):
            return None
        os.stat(path)
    except OSError as e:
        if e.errno == errno.ELOOP:
            return "is a symbolic link loop (its links lead back to themselves, to no file)"
        return f"is a symbolic link to {os.path.realpath(path)}, which does not exist"
    except ValueError:
        return None
    return None


def not_a_regular_file(path: str | os.PathLike) -> str | None:
    """``'is a FIFO (named pipe), not a regular file'`` (a device, a socket) for an existing ``path``
    that is neither a regular file nor a folder (after links), else None.

    Such a path is refused as an input, where reading a FIFO waited for a writer forever and
    ``/dev/zero`` was read until the memory ran out, and as an output, where the atomic rename
    replaced it (``-o /dev/null``, run as root, replaced the device with a regular file).
    """
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError) as e:
        return broken_link(path) if isinstance(e, OSError) else None
    if stat.S_ISREG(mode) or stat.S_ISDIR(mode):
        return None
    kind = next((name for test, name in _SPECIAL_KINDS if test(mode)), "a special file")
    return f"is {kind}, not a regular file"


def check_output_path(path: str | os.PathLike, folder: bool = False) -> Path:
    """Check, before any work, that ``path`` can be written as a file (or, ``folder=True``, a folder).

    The parent folder must exist and be a writable folder; an existing ``path`` must be a file
    (a folder for ``folder=True``) and not an input (:func:`guard_inputs`). A symbolic link is
    written through: the path returned is the link's target, which must exist.

    Raises
    ------
    OutputError
        One line naming the path and the problem.
    """
    try:
        return _check_output_path(Path(path), folder)
    except OSError as e:  # (a name over the file system's limit: ENAMETOOLONG from a stat, a traceback)
        if isinstance(e, OutputError):
            raise
        raise OutputError(f"cannot use this path ({os_error_message(e)})", path) from None


def _check_output_path(path: Path, folder: bool) -> Path:
    path = _through_link(path)
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.exists():
        raise OutputError("output folder does not exist", parent)
    if not parent.is_dir():
        raise OutputError("is a file, not a folder", parent)
    special = not_a_regular_file(path)
    if special:  # (an output is a temporary file renamed over the path: that would replace the device)
        raise OutputError(f"{special}: ffls writes an output beside its path and renames it there, which would "
                          f"replace it; name a {'folder' if folder else 'file'}", path)
    if path.exists() or path.is_symlink():
        if folder and not path.is_dir():
            raise OutputError("exists and is a file, not a folder", path)
        if not folder and path.is_dir():
            raise OutputError("is a folder, not a file", path)
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputError("folder is not writable (permission denied or read-only)", parent)
    _check_not_input(path)
    return path


def name_output(e: BaseException, staged: Path, path: Path) -> BaseException:
    """Say the user's output ``path`` where the error ``e`` names the temporary ``staged`` path.

    A writer inside :func:`atomic_output` or :func:`atomic_folder` sees only the temporary file
    or staging folder, and a library's message (OpenEXR's "Failed to write pixel data to image
    file .a.x1y2.tmp.exr") names it; the user gave ``path``. ``e`` (an :class:`FflsError`) is
    changed in place and returned; other exceptions are returned as they are.
    """
    if not isinstance(e, FflsError):
        return e
    old, new = str(staged), str(path)
    if e.path is not None and str(e.path).startswith(old):
        e.path = Path(new + str(e.path)[len(old):])
    e.message = e.message.replace(old, new)
    e.args = (f"{e.path}: {e.message}" if e.path is not None else e.message,)
    return e


def disk_full(folder: str | os.PathLike, need: int = 1 << 20) -> bool:
    """Whether the file system of ``folder`` has less than ``need`` bytes free (1 MiB): what a
    writer that reports no reason (OpenCV's ``VideoWriter`` that does not open) most likely met."""
    try:
        return shutil.disk_usage(folder).free < need
    except OSError:
        return False


def available_memory() -> int:
    """Bytes of memory available to a new allocation (``MemAvailable``; total physical memory as fallback)."""
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return physical_memory() or 1 << 62


def physical_memory() -> int | None:
    """Bytes of physical memory of this machine, or ``None`` where the system does not say."""
    try:
        return int(os.sysconf("SC_PHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE")) or None
    except (ValueError, OSError, AttributeError):
        return None


def _raise_os(e: OSError, path: Path):
    raise OutputError(f"cannot write ({os_error_message(e)})", path) from None


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike, suffix: str | None = None, part: bool = False):
    """Yield a temporary path beside ``path``; rename it onto ``path`` only if the block succeeds.

    Once renamed, ``path`` is named by the line of a later interruption (:func:`outputs_on_interrupt`)
    unless it is a ``part`` of a larger output (a store's bookkeeping files).

    A failing writer (an exception, Ctrl-C, SIGTERM turned into an exception by the CLI) leaves
    nothing behind, neither the temporary file nor a half-written output, and an existing
    ``path`` stays as it was. The temporary name keeps the extension (some writers choose the
    format from it). After the block the temporary file must exist and be non-empty (writers
    such as ``cv2.imwrite`` do not report every failure). A full disk shows as an error of the
    writer's ``write`` (ext4 and tmpfs reserve blocks at write time) or as this size check; the
    file is not fsync'ed (that would guard against a power cut, not promised here, and costs
    about 5 ms a file: 40% of a 100-image ``ffls synth`` at 64 px).

    Raises
    ------
    OutputError
        The output cannot be written (:func:`check_output_path`; permission, read-only file
        system, disk full, ...), or the writer left an empty or missing file; one line naming
        ``path``.
    """
    path = check_output_path(path)
    parent = path.parent if str(path.parent) else Path(".")
    suffix = path.suffix if suffix is None else suffix
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=f".tmp{suffix}", dir=parent)
        os.close(fd)
    except OSError as e:
        _raise_os(e, path)
    tmp = Path(tmp)
    renamed = None  # (the file's identity once it is being renamed onto path)
    try:
        try:
            yield tmp
        except OSError as e:  # the writer's own error: one line naming the output
            if isinstance(e, FflsError):
                raise
            _raise_os(e, path)
        try:
            size = os.stat(tmp).st_size
        except FileNotFoundError:
            size = -1
        if size <= 0:
            if disk_full(parent):
                raise OutputError(f"cannot write ({_WHY[errno.ENOSPC]})", path)
            raise OutputError("the writer left " + ("no file" if size < 0 else "an empty file")
                              + " (disk full or a library error)", path)
        try:
            os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; outputs get the usual mode
            group = _GROUP.get()
            if group is not None:  # renamed with the group's other outputs (atomic_outputs)
                group.append((tmp, path))
            else:
                renamed = None if part else _identity(tmp)
                os.replace(tmp, path)
                if not part:
                    _completed(path)
        except OSError as e:
            _raise_os(e, path)
    except BaseException as e:
        if renamed is not None:
            _completed(path, renamed)
        with contextlib.suppress(OSError):
            tmp.unlink()
        name_output(e, tmp, path)
        raise


_GROUP: contextvars.ContextVar = contextvars.ContextVar("ffls_output_group", default=None)


@contextlib.contextmanager
def atomic_outputs():
    """While active, the files :func:`atomic_output` completes are renamed onto their paths together,
    when the block succeeds: a command that writes several files (``ffls lights``: lights.json, the
    ``--lp`` export and the ``--plot``) leaves all of them new or none, never new ones beside old ones.

    The renames run with Ctrl-C and SIGTERM held. On an error or interruption every completed
    temporary file is removed and each path is left as it was. Nothing inside the block may read
    back an output it wrote (it is not there yet).
    """
    pending: list = []
    renamed = path = None
    token = _GROUP.set(pending)
    try:
        try:
            yield
        finally:
            _GROUP.reset(token)
        with _signals_deferred():
            while pending:
                tmp, path = pending[0]
                renamed = _identity(tmp)
                try:
                    os.replace(tmp, path)
                except OSError as e:
                    _raise_os(e, path)
                pending.pop(0)
                _completed(path)
    except BaseException:
        if renamed is not None:
            _completed(path, renamed)
        for tmp, _ in pending:
            with contextlib.suppress(OSError):
                tmp.unlink()
        raise


@contextlib.contextmanager
def atomic_folder(path: str | os.PathLike):
    """Yield an empty staging folder beside ``path``; swap it in for ``path`` only if the block succeeds.

    An existing ``path`` (a folder) is replaced as a whole, only after success: it is renamed
    aside, the staging folder renamed onto ``path``, and the old one deleted. On failure or
    interruption the staging folder is deleted and ``path`` is left as it was.

    Raises
    ------
    OutputError
        ``path`` is a file, its parent does not exist or is not writable, it holds an input, or a
        rename fails; one line naming ``path``.
    """
    path = check_output_path(path, folder=True)
    parent = path.parent if str(path.parent) else Path(".")
    try:
        stage = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".tmp", dir=parent))
    except OSError as e:
        _raise_os(e, path)
    os.chmod(stage, 0o777 & ~_umask())
    old = renamed = None
    try:
        try:
            yield stage
        except OSError as e:
            if isinstance(e, FflsError):
                raise
            _raise_os(e, path)
        with _signals_deferred():  # Ctrl-C / SIGTERM between the two renames would lose both folders
            try:
                if path.exists():
                    old = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".old", dir=parent))
                    os.replace(path, old / path.name)
                renamed = _identity(stage)
                os.replace(stage, path)
                _completed(path)
            except OSError as e:
                if old is not None and (old / path.name).exists() and not path.exists():
                    os.replace(old / path.name, path)  # put the old output back
                _raise_os(e, path)
    except BaseException as e:
        if renamed is not None:
            _completed(path, renamed)
        shutil.rmtree(stage, ignore_errors=True)
        name_output(e, stage, path)
        raise
    finally:
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)


@contextlib.contextmanager
def _signals_deferred():
    """Hold SIGINT and SIGTERM (delivered when the block ends) where the platform and thread allow.

    The mask (:func:`signal.pthread_sigmask`) is this thread's only: the kernel gives a Ctrl-C to any
    thread that does not block it (OpenCV's, Dask's, a pool's), whose C handler marks it pending, and
    Python runs the handler in the main thread at its next bytecode, inside the block. So in the main
    thread the handlers are also replaced, while held, by one that records the signal; the recorded
    signals are raised again (:func:`signal.raise_signal`) when the block ends, to the handlers it
    found. (Elsewhere than the main thread no Python handler runs: the mask alone.)
    """
    import signal
    import threading

    sigs = (signal.SIGINT, signal.SIGTERM)
    caught: list = []
    handlers = {}
    if threading.current_thread() is threading.main_thread():
        for s in sigs:
            if signal.getsignal(s) is not None:  # (None: a handler not set from Python; left alone)
                handlers[s] = signal.signal(s, lambda signum, frame: caught.append(signum))
    try:
        try:
            old = signal.pthread_sigmask(signal.SIG_BLOCK, sigs)
        except (AttributeError, ValueError, OSError):
            yield
            return
        try:
            yield
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, old)  # (a signal held meanwhile is recorded here)
    finally:
        for s, h in handlers.items():
            signal.signal(s, h)
        for s in dict.fromkeys(caught):
            signal.raise_signal(s)


def run_uninterrupted(step) -> None:
    """Run ``step()`` to its end even when Ctrl-C or SIGTERM arrives meanwhile, then raise the interrupt.

    Signals are held while ``step`` runs; one that was already pending raises in the middle of it
    all the same (Python runs its handler at the next bytecode), so ``step`` must be resumable:
    called again, it carries on where it stopped and does nothing once done. Used where an
    interrupted clean-up would leave things worse than either end (file descriptors redirected,
    a folder half swapped).
    """
    interrupt = None
    while True:
        try:
            with _signals_deferred():
                step()
            break
        except KeyboardInterrupt as e:  # cli.Terminated (SIGTERM) is a KeyboardInterrupt too
            interrupt = interrupt or e
    if interrupt is not None:
        raise interrupt


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask
