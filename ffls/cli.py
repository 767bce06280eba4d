"""The ``ffls`` command: a thin layer over the library, and the one-line error policy.

Each subcommand is a module (:mod:`ffls.commands`: built in, or registered by another package
under the entry-point group ``ffls.commands``, as the viewer registers ``view``) that defines
``NAME``, ``HELP``, ``add_arguments(parser)`` and ``run(args) -> int``; ``run`` is one library
call that a test can make without a subprocess.

The error policy (``docs/reliability.md``), applied here once for every command:

* a bad argument (:mod:`ffls.commands.common` types) or bad input (:class:`ffls.errors.FflsError`)
  is one line on stderr, ``ffls COMMAND: error: ...``, and exit status 2; never a traceback;
* an OS error that escapes a command (a file that cannot be read or written) is one line naming
  the file, status 2; running out of memory is one line, status 2;
* Ctrl-C (SIGINT) and SIGTERM unwind the command (every output is atomic, so nothing partial is
  left) and print one line, status 130 or 143, naming the outputs completed before the signal
  (:func:`ffls.errors.outputs_on_interrupt`);
* a Python warning (a light map's clamped negatives, ...) is one line, ``ffls COMMAND: warning: ...``,
  held with the informational lines until the inputs are loaded, so a command that fails prints
  only its error line;
* while a command runs, its inputs are protected: an output that would replace one is refused
  (:func:`ffls.errors.guard_inputs`).
"""
from __future__ import annotations

import argparse
import contextlib
import re
import signal
import sys
import warnings

from ffls import INTERRUPTED_LINE
from ffls.commands import command_modules
from ffls.commands.common import deferred_notes, print_notes
from ffls.errors import FflsError, guard_inputs, interrupt_note, os_error_message, outputs_on_interrupt

__all__ = ["build_parser", "subcommands", "main", "OneLineParser", "Terminated", "STDOUT_CLOSED"]


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised in the main thread like Ctrl-C so that every ``finally`` and atomic write unwinds."""


class OneLineParser(argparse.ArgumentParser):
    """An ArgumentParser whose usage errors are one line (``PROG: error: ...``) and exit status 2.

    Flags are never abbreviated (``allow_abbrev=False``, inherited by every subparser): argparse
    read ``relight --light 10,45`` (a flag of ``render``) as an ambiguous prefix of ``--lights``
    and ``--lights-map``, and a unique prefix (``--exp 2``) silently as the flag it starts.
    """

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)
        self.register("action", None, _StoreOnce)
        self.register("action", "store", _StoreOnce)

    def parse_known_args(self, args=None, namespace=None):
        self._given = list(sys.argv[1:] if args is None else args)  # (for the hint in error)
        self._stored = {}  # (what each flag was given, for _StoreOnce)
        return super().parse_known_args(args, namespace)

    def _dash_value_hint(self, message: str) -> str:
        """``--rotate -90,0,0``: argparse takes the value for a flag ("expected one argument");
        say how to give it, with the user's own flag and value."""
        m = re.fullmatch(r"argument (\S+): expected one argument", message)
        given = getattr(self, "_given", [])
        for flag in (m.group(1).split("/") if m else ()):
            for k, a in enumerate(given[:-1]):
                if a == flag and given[k + 1].startswith("-") and len(given[k + 1]) > 1:
                    return f" (a value that starts with '-' is given as {flag}={given[k + 1]})"
        return ""

    def print_help(self, file=None):
        """argparse's, except that a failed write of ``--help`` to standard output (``> /dev/full``) is
        one error line and status 2; argparse ignored it and exited 0 with the text lost."""
        if file is not None or sys.stdout is None:
            return super().print_help(file)
        self.write_stdout(self.format_help())

    def write_stdout(self, text: str) -> None:
        """Write ``text`` to standard output; a failure (a full disk) is one error line and status 2."""
        try:
            sys.stdout.write(text)
            sys.stdout.flush()
        except BrokenPipeError:  # (`ffls --help | head -1`: the reader had what it wanted)
            _drop_stdout()
        except OSError as e:
            _drop_stdout()
            self.exit(2, f"{self.prog}: error: standard output: cannot write ({os_error_message(e)})\n")

    def error(self, message):
        message = " ".join(str(message).split())
        message += self._dash_value_hint(message)
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


class _StoreOnce(argparse.Action):
    """argparse's ``store``, except that a flag given twice with different values is refused
    (``-o a.exr ... -o b.exr`` kept the last silently): which one is meant? (as a key given twice
    in a JSON file is refused). The same value twice is no question and is read."""

    def __call__(self, parser, namespace, values, option_string=None):
        stored = getattr(parser, "_stored", None)
        if option_string is not None and stored is not None:
            if self.dest in stored and stored[self.dest][1] != values:
                first, before = stored[self.dest]
                parser.error(f"argument {'/'.join(self.option_strings)}: given twice, as {first} {before!s} and "
                             f"{option_string} {values!s}: which one is meant? give it once")
            stored[self.dest] = (option_string, values)
        setattr(namespace, self.dest, values)


class _Version(argparse.Action):
    """``--version``: argparse's, written as ``--help`` is (:meth:`OneLineParser.write_stdout`)."""

    def __init__(self, option_strings, version, dest=argparse.SUPPRESS, default=argparse.SUPPRESS,
                 help="show program's version number and exit"):
        super().__init__(option_strings=option_strings, dest=dest, default=default, nargs=0, help=help)
        self.version = version

    def __call__(self, parser, namespace, values, option_string=None):
        parser.write_stdout(self.version + "\n")
        parser.exit()


def _build() -> tuple[argparse.ArgumentParser, dict[str, argparse.ArgumentParser]]:
    from ffls import __version__

    parser = OneLineParser(prog="ffls", description="Free-form Light Stage: relight objects from photographs.")
    parser.add_argument("--version", action=_Version, version=f"ffls {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    parsers = {}
    for mod in command_modules():
        p = sub.add_parser(mod.NAME, help=mod.HELP, description=getattr(mod, "DESCRIPTION", mod.HELP))
        mod.add_arguments(p)
        p.set_defaults(handler=mod.run)  # "handler": no subcommand has an argument of that name
        parsers[mod.NAME] = p
    return parser, parsers


def build_parser() -> argparse.ArgumentParser:
    """The ``ffls`` parser with every subcommand (:func:`ffls.commands.command_modules`)."""
    return _build()[0]


def subcommands() -> dict[str, argparse.ArgumentParser]:
    """The parser of every subcommand of :func:`build_parser`, by name, in ``ffls --help`` order."""
    return _build()[1]


@contextlib.contextmanager
def _sigterm_as_interrupt():
    """SIGTERM raises :class:`Terminated` in the main thread (only there can Python install handlers)."""
    def handler(signum, frame):
        raise Terminated()

    try:
        old = signal.signal(signal.SIGTERM, handler)
    except ValueError:  # not the main thread: leave SIGTERM alone
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old)


@contextlib.contextmanager
def _one_line_warnings(command: str):
    """Show every Python warning as one line ``ffls COMMAND: warning: ...`` (each text once).

    The lines go through :func:`ffls.commands.common.print_notes`: inside ``deferred_notes`` a
    warning waits with the informational lines, so a command that then fails prints only its one
    error line (a warning about an input the failed command never used is no answer).
    """
    seen = set()

    def show(message, category, filename, lineno, file=None, line=None):
        text = " ".join(str(message).split())
        if text not in seen:
            seen.add(text)
            print_notes(command, f"warning: {text}")

    with warnings.catch_warnings():
        if not sys.warnoptions:
            warnings.simplefilter("default")
        old, warnings.showwarning = warnings.showwarning, show
        try:
            yield
        finally:
            warnings.showwarning = old


def _quiet_after_interrupt() -> None:
    """After an interrupt, the tasks a library left unfinished on its event loop (a Dask cluster
    starting, zarr's writes) are collected at exit, and asyncio logged each ("Task was destroyed but
    it is pending!", "Task exception was never retrieved") after the one line."""
    import logging

    logging.getLogger("asyncio").setLevel(logging.CRITICAL + 1)


def _drop_stdout() -> None:
    """Point standard output at the null device: what is still buffered for a reader that left or a
    full disk is dropped, not reported again by the interpreter at exit ("Exception ignored")."""
    import os

    with contextlib.suppress(OSError, ValueError, AttributeError):
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())


class _NamedStdout:
    """``sys.stdout`` whose write errors name it: ``ffls info > /dev/full`` said "file: no space left"."""

    def __init__(self, stream):
        self._stream = stream

    def _checked(self, op, *a):
        try:
            return op(*a)
        except BrokenPipeError:
            raise
        except OSError as e:
            _drop_stdout()
            raise FflsError(f"cannot write ({os_error_message(e)})", "standard output") from None

    def write(self, text):
        return self._checked(self._stream.write, text)

    def flush(self):
        return self._checked(self._stream.flush)

    def __getattr__(self, name):
        return getattr(self._stream, name)


@contextlib.contextmanager
def _named_stdout():
    """While active, a failed write to standard output is one error line naming it (flushed at the end,
    so a full disk behind ``>`` is found here, not by the interpreter's exit)."""
    if sys.stdout is None:  # (started with stdout closed: print writes nowhere)
        yield
        return
    with contextlib.redirect_stdout(_NamedStdout(sys.stdout)):
        yield
        sys.stdout.flush()


def _quiet_opencv() -> None:
    """OpenCV logs nothing to the terminal (its failures are reported by the reader, naming the file)."""
    import os

    os.environ.setdefault("OPENCV_LOG_LEVEL", "SILENT")  # read when cv2 is first imported
    if "cv2" in sys.modules:
        cv2 = sys.modules["cv2"]
        with contextlib.suppress(Exception):
            cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)


def _innermost(p: argparse.ArgumentParser, args) -> argparse.ArgumentParser:
    """A parser named after the deepest subcommand ``args`` went through (``ffls probe pocs``, not
    ``ffls probe``): a command module with subcommands names their attribute ``SUBCOMMAND_DEST``."""
    from ffls.commands import find_command

    mod = find_command(getattr(args, "command", None) or "")
    chosen = getattr(args, getattr(mod, "SUBCOMMAND_DEST", ""), None) if mod is not None else None
    return OneLineParser(prog=f"{p.prog} {chosen}") if isinstance(chosen, str) else p


#: The answer when standard output is closed at start (``ffls lights CAP >&-``): every command prints
#: its result there (a summary, the numbers), and with it closed they were lost under status 0;
#: nothing is run, as an output file opened then would take descriptor 1, where a library's
#: printing would land in it.
STDOUT_CLOSED = ("ffls: error: standard output: is closed, and the command's results are printed there; nothing "
                 "was done (give >/dev/null to discard them)")


def _stderr_to_null() -> None:
    """Standard error closed at start (``2>&-``): its lines are dropped, as asked (the status still
    says how the command ended). ``print(..., file=None)`` wrote them to standard output, among the
    results, and a file opened later would take descriptor 2, where a library's messages would land."""
    import os

    fd = os.open(os.devnull, os.O_WRONLY)
    if fd != 2:
        os.dup2(fd, 2)
        os.close(fd)
    sys.stderr = open(2, "w", closefd=False)


def main(argv: list[str] | None = None) -> int:
    """Run ``ffls ARGV``; the exit status (0, 2 for an error, 130 Ctrl-C, 143 SIGTERM).

    Standard output closed at start (:data:`STDOUT_CLOSED`) is one line, status 2, nothing run;
    standard error closed at start drops its lines (:func:`_stderr_to_null`).
    """
    if sys.stderr is None:  # (fd 2 closed at start, ``2>&-``)
        _stderr_to_null()
    if sys.stdout is None:  # (fd 1 closed at start, ``>&-``: Python set sys.stdout to None)
        print(STDOUT_CLOSED, file=sys.stderr)
        return 2
    try:
        return _main(argv)
    except KeyboardInterrupt:  # (Ctrl-C while the parser was built, before a command ran: a traceback)
        print(INTERRUPTED_LINE, file=sys.stderr)
        return 130


def _main(argv: list[str] | None = None) -> int:
    parser, parsers = _build()
    try:
        args, extra = parser.parse_known_args(argv)
        if extra:  # named by the (innermost) subcommand that was given them, not by ``ffls``
            _innermost(parsers.get(getattr(args, "command", None)) or parser, args).error(
                f"unrecognized arguments: {' '.join(extra)}")
    except SystemExit as e:  # a bad argument: one line already printed; --help and --version exit as usual
        if e.code in (0, None):
            raise
        return e.code if isinstance(e.code, int) else 2
    if getattr(args, "handler", None) is None:
        parser.print_help()
        return 2
    name = f"ffls {args.command}"
    _quiet_opencv()
    try:
        with _sigterm_as_interrupt(), _one_line_warnings(args.command), guard_inputs(), outputs_on_interrupt(), \
                deferred_notes(), _named_stdout():  # (innermost: its last flush fails before the notes are printed)
            return int(args.handler(args) or 0)
    except FflsError as e:
        print(f"{name}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as e:  # Ctrl-C, or SIGTERM (Terminated)
        _quiet_after_interrupt()
        term = isinstance(e, Terminated)
        print(f"{name}: {'terminated' if term else 'interrupted'}; {interrupt_note(e) or 'nothing partial was left'}",
              file=sys.stderr)
        return 143 if term else 130
    except BrokenPipeError:  # e.g. `ffls info | head`: the reader left; say nothing more
        _drop_stdout()
        return 141
    except MemoryError:
        print(f"{name}: error: out of memory; ask for a smaller size or resolution", file=sys.stderr)
        return 2
    except OSError as e:  # a file the library opened without its own check
        where = e.filename if e.filename is not None else "file"
        print(f"{name}: error: {where}: {os_error_message(e)}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
