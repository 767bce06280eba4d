"""The subcommands of ``ffls``: one module per subcommand, and those that other packages register.

A command module defines ``NAME``, ``HELP``, ``add_arguments(parser)``, ``run(args) -> int`` and
optionally ``DESCRIPTION``; ``run`` is one library call that a test can make without a
subprocess. The modules of this package are listed in :data:`BUILTIN`. Other packages register
theirs under the entry-point group :data:`ENTRY_POINT_GROUP` (the Python plug-in convention);
the viewer registers ``view`` in ``pyproject.toml``::

    [project.entry-points."ffls.commands"]
    view = "viewer.command"

so that ``ffls`` never imports ``viewer`` by name.
"""
from __future__ import annotations

import importlib
from importlib.metadata import entry_points
from types import ModuleType

__all__ = ["BUILTIN", "ENTRY_POINT_GROUP", "builtin_commands", "registered_commands", "command_modules",
           "find_command"]

#: The subcommand modules of this package, in the order ``ffls --help`` lists them.
BUILTIN = ("demo", "synth", "relight", "render", "composite", "lights", "probe", "calibrate", "info", "lightmap",
           "ingest")
#: Entry-point group through which other packages add subcommands (``name = "package.module"``).
ENTRY_POINT_GROUP = "ffls.commands"


def builtin_commands() -> list[ModuleType]:
    """The modules of :data:`BUILTIN`, imported, in that order."""
    return [importlib.import_module(f"{__name__}.{name}") for name in BUILTIN]


def registered_commands() -> list[ModuleType]:
    """The command modules registered under :data:`ENTRY_POINT_GROUP`, sorted by name.

    Raises
    ------
    RuntimeError
        An entry point whose name is not its module's ``NAME``, or that takes a built-in name.
    """
    mods, seen = [], set()
    for ep in sorted(entry_points(group=ENTRY_POINT_GROUP), key=lambda e: e.name):
        if ep.name in seen:  # the same distribution found twice on sys.path
            continue
        seen.add(ep.name)
        if ep.name in BUILTIN:
            raise RuntimeError(f"entry point {ep.name} = {ep.value} ({ENTRY_POINT_GROUP}) takes a built-in command's name")
        mod = ep.load()
        if getattr(mod, "NAME", None) != ep.name:
            raise RuntimeError(f"entry point {ep.name} = {ep.value} ({ENTRY_POINT_GROUP}): "
                               f"the module's NAME is {getattr(mod, 'NAME', None)!r}")
        mods.append(mod)
    return mods


def command_modules() -> list[ModuleType]:
    """Every subcommand: :func:`builtin_commands`, then :func:`registered_commands`."""
    return builtin_commands() + registered_commands()


def find_command(name: str) -> ModuleType | None:
    """The command module called ``name`` (built in or registered), or None where none is installed."""
    if name in BUILTIN:
        return importlib.import_module(f"{__name__}.{name}")
    for ep in entry_points(group=ENTRY_POINT_GROUP, name=name):
        return ep.load()
    return None
