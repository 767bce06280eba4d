"""The ``ffls`` command: a thin layer over the library.

Each subcommand lives in its own module under :mod:`ffls.commands` and defines ``NAME``, ``HELP``,
``add_arguments(parser)`` and ``run(args) -> int``; ``run`` is one library call that a test can
make without a subprocess. :class:`ffls.errors.FflsError` becomes one line on stderr and exit
status 2, never a traceback.
"""
from __future__ import annotations

import argparse
import importlib
import sys

from ffls.errors import FflsError

#: Subcommand modules, in the order ``ffls --help`` lists them.
COMMANDS = (
    "demo",
    "synth",
    "relight",
    "render",
    "lights",
    "calibrate",
    "view",
    "info",
    "lightmap",
)


def _load_commands():
    mods = []
    for name in COMMANDS:
        try:
            mods.append(importlib.import_module(f"ffls.commands.{name}"))
        except ModuleNotFoundError as e:  # a command whose module is not written yet
            if e.name != f"ffls.commands.{name}":
                raise
    return mods


def build_parser() -> argparse.ArgumentParser:
    from ffls import __version__

    parser = argparse.ArgumentParser(prog="ffls", description="Free-form Light Stage: relight objects from photographs.")
    parser.add_argument("--version", action="version", version=f"ffls {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for mod in _load_commands():
        p = sub.add_parser(mod.NAME, help=mod.HELP, description=getattr(mod, "DESCRIPTION", mod.HELP))
        mod.add_arguments(p)
        p.set_defaults(_run=mod.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "_run", None):
        parser.print_help()
        return 2
    try:
        return int(args._run(args) or 0)
    except FflsError as e:
        print(f"ffls {args.command}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"ffls {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # e.g. `ffls info | head`: the reader left; say nothing more
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
