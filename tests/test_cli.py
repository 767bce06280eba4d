"""The CLI as a whole: every subcommand is registered, documents itself, and turns bad input
into one line on stderr with exit status 2 (no traceback)."""
from __future__ import annotations

import pytest

from ffls.cli import main, subcommands
from ffls.commands import BUILTIN, ENTRY_POINT_GROUP, command_modules, find_command

COMMANDS = [mod.NAME for mod in command_modules()]


def test_every_command_module_is_registered_and_complete():
    for mod in command_modules():
        assert mod.HELP and callable(mod.add_arguments) and callable(mod.run)
        assert find_command(mod.NAME) is mod
    assert COMMANDS[:len(BUILTIN)] == list(BUILTIN) and len(set(COMMANDS)) == len(COMMANDS)
    assert list(subcommands()) == COMMANDS
    assert find_command("no-such-command") is None


def test_the_viewer_registers_view_through_the_entry_point_group():
    from importlib.metadata import entry_points

    (ep,) = entry_points(group=ENTRY_POINT_GROUP, name="view")
    assert ep.value == "viewer.command" and "view" in COMMANDS and "view" not in BUILTIN
    assert callable(find_command("view").show_capture)


@pytest.mark.parametrize("name", COMMANDS)
def test_help(name, capsys):
    with pytest.raises(SystemExit) as e:
        main([name, "--help"])
    assert e.value.code == 0
    assert capsys.readouterr().out.startswith("usage: ffls " + name)


def test_no_command_prints_help(capsys):
    assert main([]) == 2
    assert "COMMAND" in capsys.readouterr().out


@pytest.mark.parametrize("argv", [
    ["info"],
    ["lights", "cap"],
    ["relight", "cap", "--probe", "sky", "-o", "out.exr"],
    ["probe", "mirror", "folder", "-o", "map.exr"],
    ["view", "cap"],
    ["probe", "pocs", "folder", "-o", "map.exr"],
    ["lightmap", "info", "map.exr"],
    ["calibrate", "response", "folder"],
])
def test_an_unknown_flag_is_named_by_its_subcommand(argv, capsys):
    name = " ".join(argv[:2]) if argv[0] in ("probe", "lightmap", "calibrate") else argv[0]
    assert main(argv + ["--no-such-flag"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err
    assert err == f"ffls {name}: error: unrecognized arguments: --no-such-flag (see ffls {name} --help)"


def test_an_unknown_flag_before_the_command_is_named_by_ffls(capsys):
    assert main(["--no-such-flag"]) == 2
    assert capsys.readouterr().err.startswith("ffls: error: unrecognized arguments: --no-such-flag")


@pytest.mark.parametrize("argv", [
    ["relight", "{missing}", "--probe", "sky", "-o", "{tmp}/out.exr"],
    ["render", "{missing}", "--probe", "sky", "-o", "{tmp}/out.exr"],
    ["lights", "{missing}"],
    ["view", "{missing}", "--frames", "1", "--headless"],
    ["lightmap", "info", "{missing}.exr"],
])
def test_missing_input_is_one_line_naming_the_file(argv, tmp_path, capsys):
    missing = str(tmp_path / "nowhere")
    argv = [a.format(missing=missing, tmp=tmp_path) for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err
    assert err.startswith(f"ffls {argv[0]}: error: ") and "nowhere" in err
    assert not list(tmp_path.iterdir())  # no partial output
