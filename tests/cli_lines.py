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


def entries(folder: Path) -> set:
    """The names in ``folder`` (what a refused command must not have left there)."""
    return {p.name for p in folder.iterdir()}


def composite_set(root: Path) -> Path:
    """A small composite set (``ffls synth --composite-set sunrise``, 8 + 8 lights at 24 px) in
    ``root / 'set'``; its object capture states its spheres' world centres (as ``--fill`` reads them)."""
    assert main(["synth", str(root / "set"), "--composite-set", "sunrise", "--lights", "8", "--surface-lights", "8",
                 "--resolution", "24", "--truth-dirs", "32", "--quiet"]) == 0
    return root / "set"
