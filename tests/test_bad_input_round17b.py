"""Round 17's leftovers (briefs s17/atk17b, docs/reliability.md "Round 17b").

Input the round-17 attack found read without a word: an ``.lp`` file that is not UTF-8, a
``--memory`` budget above the machine's memory, ``lights.json`` ``frame`` keys, masks whose
values are not a mask's, and the Ctrl-C line after a finished output. The promise checked is the
one of ``tests/test_bad_input.py``: exit status 2, one stderr line naming the flag or file,
nothing left.
"""
from __future__ import annotations

import pytest

from cli_lines import entries, one_line, tiny_capture


@pytest.fixture(scope="module")
def cap(tmp_path_factory):
    return tiny_capture(tmp_path_factory.mktemp("r17b"), seed=171)


# ----------------------------------------------------------------------------- an .lp file not in UTF-8
def test_an_lp_file_in_latin1_is_refused_as_not_utf8(cap, tmp_path, capfd):
    """``im\\xe9.exr`` saved by a Windows tool in latin-1 was decoded with U+FFFD and the command
    then failed on the name (``image 'im\\ufffd.exr' is not in the capture``)."""
    lp = tmp_path / "lat.lp"
    lp.write_bytes(b"1\nim\xe9.exr 0 0 1\n")
    before = entries(tmp_path)
    rc, line = one_line(capfd, ["relight", cap, "--lights", lp, "--probe", "sky", "-o", tmp_path / "o.png"])
    assert rc == 2
    assert "lat.lp" in line and "not UTF-8" in line and "\ufffd" not in line
    assert entries(tmp_path) == before


# ----------------------------------------------------------------------------- --memory above the machine
def test_a_memory_budget_above_the_machines_memory_is_refused(cap, tmp_path, capfd):
    """``--memory 1T`` on a 24 GiB machine was read as no limit (the photos held in memory)."""
    from ffls.errors import physical_memory

    have = physical_memory()
    if have is None:
        pytest.skip("this system does not say its memory")
    size = f"{have // 2 ** 20 + 1024}M"
    rc, line = one_line(capfd, ["relight", cap, "--probe", "sky", "-o", tmp_path / "o.png", "--memory", size])
    assert rc == 2
    assert "--memory" in line and size in line and "memory this machine has" in line
    assert not (tmp_path / "o.png").exists()
