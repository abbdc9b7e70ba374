"""What the panel's screenshot tests share: one page of a module's host, the 3-D view's pixels, the arm's
blue, and the leak guard of a module whose host lives across its tests."""

from __future__ import annotations

import contextlib
import io
import multiprocessing
import shutil
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.support.chromium import CHROMIUM, chromium_context, page_load, page_load_ms

SCENE_BOX_JS = """() => {
    const r = Array.from(document.querySelectorAll('canvas')).map(c => c.getBoundingClientRect())
        .sort((a, b) => b.width * b.height - a.width * a.height)[0];
    return {x: r.x, y: r.y, width: r.width, height: r.height};
}"""
"""The 3-D view's box: the largest canvas on the page."""


def require_chromium() -> None:
    """Fail the module (never skip it) where the browser is missing."""
    if shutil.which(CHROMIUM) is None:
        pytest.fail(f"{CHROMIUM} is not installed: the browser tests need it", pytrace=False)


@contextlib.contextmanager
def no_leaks_since_now() -> Iterator[None]:
    """tests/conftest.py's guard, judged against what ran before: a module's one host (its threads, the
    virtual board's and the link's processes) lives across the tests by design."""
    threads = {t.ident for t in threading.enumerate()}
    children = {p.pid for p in multiprocessing.active_children()}
    yield
    new_threads = [t for t in threading.enumerate() if t.ident not in threads and t.is_alive()]
    for t in new_threads:
        t.join(timeout=2.0)
    new_children = [p for p in multiprocessing.active_children() if p.pid not in children]
    for p in new_children:
        p.join(timeout=2.0)
    leaked = [t.name for t in new_threads if t.is_alive() and not isinstance(t, threading._DummyThread)]
    alive = [p for p in new_children if p.is_alive()]
    for p in alive:
        p.kill()
    assert not leaked, f"test left threads running: {leaked}"
    assert not alive, f"test left child processes running: {[p.name for p in alive]}"


@contextlib.contextmanager
def panel_page(url: str, user_dir: Path, viewport: dict[str, int]) -> Iterator[Any]:
    """The panel at ``url`` loaded in headless Chromium (its E-stop shown), the software-WebGL toast
    closed; closed on exit."""
    with chromium_context(user_dir) as ctx:
        p = ctx.new_page()
        p.set_viewport_size(viewport)
        with page_load("the panel page"):
            p.goto(url + ("&" if "?" in url else "?") + "fixedDpr=1", timeout=page_load_ms())
            p.get_by_role("button", exact=True, name="E-STOP [Space]").wait_for(timeout=page_load_ms())
        with contextlib.suppress(Exception):  # the software-WebGL toast covers the scene
            p.locator(".mantine-Notification-closeButton").first.click(timeout=3_000)
        yield p


def scene_pixels(page: Any, margin_px: int = 10) -> Any:
    """The 3-D view's pixels left of the panel (``margin_px`` short of its title), from a screenshot of
    that region only, as an RGB PIL image."""
    from PIL import Image

    box = page.evaluate(SCENE_BOX_JS)  # the largest canvas: the 3-D view (the charts' are small)
    panel = page.get_by_text("SpiRob teleop").first.bounding_box()
    right = panel["x"] - margin_px if panel else box["x"] + box["width"]
    clip = {"x": box["x"], "y": box["y"], "width": right - box["x"], "height": box["height"]}
    return Image.open(io.BytesIO(page.screenshot(clip=clip))).convert("RGB")


def arm_blue_mask(img: Any) -> np.ndarray:
    """Pixels of the arm's blue (its units, base 40,110,200 to tip 120,210,255, shaded)."""
    a = np.asarray(img, dtype=np.int32)
    r, g, b = a[..., 0], a[..., 1], a[..., 2]
    return np.asarray((b > 150) & (b > r + 60) & (g > 80))
