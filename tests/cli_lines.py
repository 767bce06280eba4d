"""The bad-input tests' check of a command's answer: one line on stderr, no traceback."""
from __future__ import annotations

from ffls.cli import main


def one_line(capfd, argv) -> tuple[int, str]:
    """Run ``ffls ARGV`` in this process; its exit status and its only non-empty stderr line."""
    capfd.readouterr()
    rc = main([str(a) for a in argv])
    out, err = capfd.readouterr()
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert "Traceback" not in err + out
    assert len(lines) == 1, err
    return rc, lines[0]
