"""``python -m viewer CAPTURE [options]``: the same as ``ffls view CAPTURE [options]``."""
from __future__ import annotations

import sys


def main(argv: list[str] | None = None) -> int:
    """Run ``ffls view`` with ``argv`` (default ``sys.argv[1:]``)."""
    from ffls.cli import main as ffls_main

    return ffls_main(["view", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":
    sys.exit(main())
