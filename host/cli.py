"""`spirob-host` command line."""

from __future__ import annotations

import sys


def main(argv: list[str] | None = None) -> int:
    """Entry point of `spirob-host`."""
    print("spirob-host: not yet available", file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main())
