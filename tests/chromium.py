"""Debian's Chromium as the browser tests and ``bench/ui.py`` launch it (never ``playwright install``)."""

from __future__ import annotations

CHROMIUM = "/usr/bin/chromium"
"""Installed by ``scripts/setup.sh --system`` with apt-get."""

CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
"""Headless in a container: no sandbox, no GPU, nothing fetched from the network."""
