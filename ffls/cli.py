"""The ``ffls`` command: a thin layer over the library.

Each subcommand is a module (:mod:`ffls.commands`: built in, or registered by another package
under the entry-point group ``ffls.commands``, as the viewer registers ``view``) that defines
``NAME``, ``HELP``, ``add_arguments(parser)`` and ``run(args) -> int``; ``run`` is one library
call that a test can make without a subprocess. :class:`ffls.errors.FflsError` becomes one line
on stderr and exit status 2, never a traceback.
"""
from __future__ import annotations

import argparse
import sys

from ffls.commands import command_modules
from ffls.errors import FflsError

__all__ = ["build_parser", "subcommands", "main"]


def _build() -> tuple[argparse.ArgumentParser, dict[str, argparse.ArgumentParser]]:
    from ffls import __version__

    parser = argparse.ArgumentParser(prog="ffls", description="Free-form Light Stage: relight objects from photographs.")
    parser.add_argument("--version", action="version", version=f"ffls {__version__}")
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


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "handler", None) is None:
        parser.print_help()
        return 2
    try:
        return int(args.handler(args) or 0)
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
