"""Debian's Chromium as the browser tests and ``bench/ui.py`` launch it (never ``playwright install``)."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from tests.support.realtime_guard import scaled_s, starved_timeouts

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

PAGE_LOAD_S = 30.0
"""A page load's wait on a quiet machine (the panel renders its 3D scene in software on 2 cores)."""


def page_load_ms() -> float:
    """The page-load wait for Playwright's ``timeout=`` [ms]: :data:`PAGE_LOAD_S` scaled with the load."""
    return scaled_s(PAGE_LOAD_S) * 1000.0


@contextlib.contextmanager
def page_load(what: str) -> Iterator[None]:
    """Inside: a Playwright time-out on a starved machine skips the test as ``starved:`` (it fails otherwise).

    Args:
        what: the page being loaded, for the skip reason.
    """
    from playwright.sync_api import TimeoutError as PlaywrightTimeout  # only the browser tests need it

    with starved_timeouts(PlaywrightTimeout, what=what):
        yield


def lever_button(page: Any, lever: str, position: str) -> Any:
    """The panel's ``position`` button of the ``lever`` ("Right lever", "Left lever"), marked as selected
    (``● DOWN``) or not."""
    return page.locator(
        f"xpath=//*[normalize-space()='{lever}']/ancestor::div[contains(@class,'mantine-Flex-root')][1]"
        f"//button[normalize-space()='{position}' or normalize-space()='● {position}']"
    ).first


@contextlib.contextmanager
def chromium_context(user_dir: Path) -> Iterator[Any]:
    """A headless Chromium with its profile in ``user_dir``, a small window (every tab renders the 3D
    scene in software, SwiftShader, on this 2-core machine); closed on exit."""
    from playwright import sync_api

    with sync_api.sync_playwright() as p:
        ctx = p.chromium.launch_persistent_context(
            str(user_dir),
            executable_path=CHROMIUM,
            headless=True,
            args=CHROMIUM_ARGS,
            viewport={"width": 960, "height": 680},
        )
        try:
            yield ctx
        finally:
            ctx.close()
