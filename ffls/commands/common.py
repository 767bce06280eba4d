"""Arguments shared by the subcommands that relight a capture (relight, render, view)."""
from __future__ import annotations


def add_capture_arguments(p, probe_required: bool = True, probe_default: str | None = None) -> None:
    """``CAPTURE``, ``--lights`` and ``--probe`` (and ``--layout`` for the map file)."""
    p.add_argument("capture", help="capture folder (with capture.json)")
    p.add_argument("--lights", default=None, help="lights.json (default: CAPTURE/lights.json)")
    p.add_argument("--probe", required=probe_required, default=probe_default, metavar="MAP",
                   help="HDR light map (.exr/.hdr) or a built-in name (courtyard, studio, sunrise, night, sky, paper)"
                        + (f"; default {probe_default}" if probe_default else ""))
    p.add_argument("--layout", default=None, help="light-map layout (default: detected from the file)")
