"""``python -m ffls`` and the ``ffls`` console script (``[project.scripts]``).

:func:`main` imports :mod:`ffls.cli` (and, through it, the commands) only once it can answer
Ctrl-C: the console script imports its entry point before anything runs, and a Ctrl-C in those
first 0.05 to 0.1 s was a ``KeyboardInterrupt`` traceback. This module imports nothing but
``sys`` and the ``ffls`` package (its version and that line).
"""
import sys

from ffls import INTERRUPTED_LINE


def main() -> int:
    """Run ``ffls`` with ``sys.argv``; its exit status (:func:`ffls.cli.main`)."""
    import atexit

    atexit.register(_ignore_signals)  # (first registered: it runs after every other exit callback)
    try:
        from ffls.cli import main as cli_main
    except KeyboardInterrupt:
        print(INTERRUPTED_LINE, file=sys.stderr)
        return 130
    rc = None
    try:
        rc = cli_main()
        _exit_at_once_on_signal(rc)
    except KeyboardInterrupt:  # (a Ctrl-C in the instant between the command's return and the handler)
        if rc is None:
            print(INTERRUPTED_LINE, file=sys.stderr)
            return 130
        _flush_and_exit(rc)
    return rc


def _flush_and_exit(rc: int) -> None:
    """End the process at once with ``rc``, the standard streams flushed (never the interpreter's
    exit: its thread joins and exit callbacks can wait on anything)."""
    import os

    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except Exception:  # (closed, or a full disk: the command already said what it could)
            pass
    os._exit(rc)


def _exit_at_once_on_signal(rc: int) -> None:
    """Once the command has returned: a Ctrl-C or SIGTERM while the interpreter shuts down (its
    threads joined, zarr's and Dask's among them; ``atexit``) ended the process by the signal, with
    no line, although every output was complete and its status known (``ingest`` interrupted 0.9 to
    1.1 s after its start ended so in 5 of 20 runs). Now it ends the exit at once, with that status.
    """
    import signal

    def finish(signum, frame):
        _flush_and_exit(rc)

    for sig in (signal.SIGINT, signal.SIGTERM):
        try:
            signal.signal(sig, finish)
        except (ValueError, OSError):  # (not the main thread)
            pass


def _ignore_signals() -> None:
    """The last exit callback: the interpreter then tears its modules down, and restores the
    default action of a signal whose handler is Python's (a Ctrl-C there killed the process, status
    -2); an ignored signal stays ignored. Nothing after this point can wait on anything."""
    import signal

    for sig in (signal.SIGINT, signal.SIGTERM):
        try:
            signal.signal(sig, signal.SIG_IGN)
        except (ValueError, OSError):
            pass


if __name__ == "__main__":
    sys.exit(main())
