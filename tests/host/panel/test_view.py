"""What a person sees in the panel, judged from screenshots (headless Chromium, Playwright).

One host (``HostApp`` with the virtual board in its own process) and one small page for the whole
module: the tab's title; every camera preset, chosen with its key, shows the arm (its blue in a
screenshot of the scene); the three charts still draw their traces across their width after stick moves
changed their y range (their canvases' pixels; viser 1.1.1 collapsed them to one dot at t = 0 until
reload: ``host.panel.plots``).

The page's input here is the hotkeys; the radio is driven through the arbiter on behalf of the tab
(the buttons and sliders are exercised by test_teleop.py).
"""

from __future__ import annotations

import base64
import io
import math
import time
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest

from host.app import HostApp
from host.options import HostOptions
from host.panel.camera import CAMERA_PRESETS, camera_view
from host.panel.teleop import PanelConfig
from protocol.dbus import Lever
from protocol.messages import Mode, TelemetryFlags
from tests.support.panel_view import (
    arm_blue_mask,
    no_leaks_since_now,
    panel_page,
    require_chromium,
    scene_pixels,
)
from tests.support.realtime_guard import timed_out, wait_for

pytestmark = pytest.mark.browser

PANEL = PanelConfig(scene_hz=4.0, plot_hz=2.0, health_hz=4.0, shadows=False)
VIEWPORT = {"width": 800, "height": 560}
ARM_BLUE_MIN = 40
"""Arm-coloured pixels a view of the arm shows at least (the hanging arm from the top view: ~150)."""
STROKES = ((220, 60, 60), (60, 170, 60), (230, 160, 30))
"""The charts' cable colours (``host.panel.plots``)."""

X_SCALES_JS = (
    "() => Object.values((window.__viserTestpoints||{}).uplots||{})"
    ".map(v => [v.chart.scales.x.min, v.chart.scales.x.max])"
)
"""Each chart's x range as uPlot holds it (viser's test point)."""
CANVASES_JS = "() => Array.from(document.querySelectorAll('.uplot canvas')).map(c => c.toDataURL())"
"""Each chart's canvas as a PNG data URL."""
require_chromium()


@pytest.fixture(autouse=True)
def _no_leaked_threads_or_processes() -> Iterator[None]:
    with no_leaks_since_now():
        yield


@pytest.fixture(scope="module")
def app() -> Iterator[HostApp]:
    with HostApp(HostOptions(ui_port=0), panel_config=PANEL) as host:
        host.start()
        if not _wait(lambda: host.panel is not None and host.panel.board.telemetry is not None, 60.0):
            timed_out("the first telemetry from the board")
        yield host


@pytest.fixture(scope="module")
def page(app: HostApp, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Any]:
    with panel_page(app.url, tmp_path_factory.mktemp("chromium"), VIEWPORT) as p:
        yield p


def test_the_tab_is_titled_spirob_teleop(page: Any) -> None:
    assert page.title() == "SpiRob Teleop"


def test_every_camera_preset_shows_the_arm(app: HostApp, page: Any) -> None:

    panel = app.panel
    assert panel is not None
    assert _wait(lambda: panel.scene.updates > 3)
    (cid,) = panel.controls()
    client = app.server.get_clients()[cid] if app.server is not None else None
    assert client is not None
    seen: dict[str, int] = {}
    for key, preset in enumerate(CAMERA_PRESETS, start=1):
        sv = panel.scene
        want, _ = camera_view(preset, sv.centre_m, sv.drone, sv.tip_m)
        page.evaluate("document.activeElement && document.activeElement.blur()")
        page.keyboard.press(str(key))
        # The browser reports its camera back: wait until it stands at the preset (the tip moves a little).
        moved = _wait(lambda w=want: math.dist(tuple(client.camera.position), w) < 0.05, 15.0)
        assert moved, f"{preset}: the camera is at {client.camera.position}, not {want}"
        time.sleep(0.5)  # let the software renderer draw the new view
        scene = scene_pixels(page)
        seen[preset] = int(arm_blue_mask(scene).sum())
    assert all(n >= ARM_BLUE_MIN for n in seen.values()), f"arm-blue pixels per preset: {seen}"


def test_plots_draw_across_their_width_after_the_range_changes(app: HostApp, page: Any) -> None:
    from PIL import Image

    panel, arb, board = app.panel, app.arbiter, app.board_state
    assert panel is not None and arb is not None and board is not None
    (cid,) = panel.controls()
    arb.request_control(cid)
    assert _wait(lambda: arb.holder == cid)
    arb.set_lever(cid, "right", Lever.DOWN)
    assert _wait(lambda: _flags(board) & TelemetryFlags.ARMED)
    # Armed: the Arm button has nothing to do, and says so by being disabled.
    arm = page.get_by_role("button", exact=True, name="Arm")
    assert _wait(lambda: arm.is_disabled(), 10.0)
    arb.set_lever(cid, "right", Lever.MIDDLE)
    assert _wait(lambda: board.telemetry is not None and board.telemetry.mode == Mode.MANUAL)
    # The window fills before judging how much of it is drawn.
    assert _wait(lambda: _history_s(board) >= 10.5, 30.0), f"history {_history_s(board):.1f} s"
    before = dict(panel._scales)
    for ch, value in ((3, 600), (0, 500)):  # tighten, then bend: every chart's range moves
        arb.set_stick(cid, ch, value)
        time.sleep(1.5)
    assert _wait(lambda: all(panel._scales[c][:2] != before[c][:2] for c in before), 20.0), (
        f"ranges did not change: {before} -> {panel._scales}"
    )
    time.sleep(2.0)  # a few more data pushes after the last range change
    panel.plots.pause.value = True  # frozen: no chart is rebuilt while it is photographed
    time.sleep(1.0)
    assert page.evaluate(X_SCALES_JS) == [[-10, 0]] * 3
    # Each chart's canvas as drawn (its own pixels: no scrolling the panel to photograph each one).
    urls = page.evaluate(
        "() => Array.from(document.querySelectorAll('.uplot canvas')).map(c => c.toDataURL())"
    )
    widths = [
        _drawn_fraction(Image.open(io.BytesIO(base64.b64decode(u.split(",", 1)[1]))).convert("RGB"))
        for u in urls
    ]
    assert len(widths) == 3
    # The plot area is the canvas minus its y axis (~15 %): a collapsed chart draws a dot at one edge.
    assert all(w > 0.6 for w in widths), f"fraction of each chart's columns with a trace: {widths}"
    panel.plots.pause.value = False
    arb.set_lever(cid, "right", Lever.DOWN)
    arb.release_control(cid)


# ---------------------------------------------------------------------- helpers


def _wait(cond: Callable[[], Any], timeout_s: float = 20.0) -> bool:
    return wait_for(lambda: bool(cond()), timeout_s, 0.05)


def _flags(board: Any) -> int:
    t = board.telemetry
    return int(t.flags) if t is not None else 0


def _history_s(board: Any) -> float:
    data = board.history.snapshot(max_points=None)
    return float(data[-1, 0] - data[0, 0]) if len(data) > 1 else 0.0


def _drawn_fraction(img: Any) -> float:
    """Fraction of the chart's columns holding a pixel of a cable's colour (a trace drawn there)."""
    a = np.asarray(img, dtype=np.int32)
    hit = np.zeros(a.shape[:2], dtype=bool)
    for stroke in STROKES:
        hit |= np.abs(a - np.asarray(stroke)).max(axis=2) < 40
    return float(np.count_nonzero(hit.any(axis=0))) / a.shape[1]
