"""The bad-input tests' check of a command's answer: one line on stderr, no traceback."""
from __future__ import annotations

import os
from pathlib import Path

from ffls.cli import main

ROOT = Path(__file__).resolve().parents[1]


def one_line(capfd, argv) -> tuple[int, str]:
    """Run ``ffls ARGV`` in this process; its exit status and its only non-empty stderr line."""
    capfd.readouterr()
    rc = main([str(a) for a in argv])
    out, err = capfd.readouterr()
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert "Traceback" not in err + out
    assert len(lines) == 1, err
    return rc, lines[0]


def child_env() -> dict:
    """The environment of an ``ffls`` child process in these tests: one thread, this tree first."""
    return dict(os.environ, OMP_NUM_THREADS="1", PYTHONPATH=str(ROOT))


def tiny_capture(root: Path, seed: int) -> Path:
    """A synthetic capture of 6 lights at 24 px in ``root / 'cap'`` (the bad-input rounds' fixture)."""
    from ffls.synth.scene import write_synthetic_capture

    write_synthetic_capture(root / "cap", n_lights=6, resolution=24, progress=False, seed=seed)
    return root / "cap"
