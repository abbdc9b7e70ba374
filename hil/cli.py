"""`spirob-hil` command line (subcommands are added by their issues)."""

from __future__ import annotations

import sys


def main(argv: list[str] | None = None) -> int:
    """Entry point of `spirob-hil`."""
    print("spirob-hil: not yet available", file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main())
