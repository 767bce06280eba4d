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
    try:
        from ffls.cli import main as cli_main
    except KeyboardInterrupt:
        print(INTERRUPTED_LINE, file=sys.stderr)
        return 130
    return cli_main()


if __name__ == "__main__":
    sys.exit(main())
