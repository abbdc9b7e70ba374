"""The teleop panel in real headless Chromium (Debian's /usr/bin/chromium driven by Playwright).

Against a real `spirob-host` (``HostApp``, in-process) connected to the real virtual board
(``hil.board``, its own process) on loopback: the page loads, the canvas renders the arm, a stick moved
in the page changes the commanded tensions the board reports, a second tab cannot take control
silently, and E-stop (Space) zeroes the currents. Against a host on ``loop://``: a page from another
origin cannot open the panel's websocket (even with the token, even with the panel's cookie), the
panel refuses a browser without the token, and the printed URL opens it.

``SPIROB_BROWSER_FAKE_BOARD=1`` runs it against the scripted fake board of tests/support/link_peer.py instead
(for developing the panel without the plant). Without Chromium the module fails, it does not skip: CI
installs it, and a silent skip would hide the panel's only end-to-end test.
"""

from __future__ import annotations

import contextlib
import http.server
import io
import os
import shutil
import threading
import time
import urllib.parse
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import viser
from playwright import sync_api

from host.app import HostApp
from host.options import HostOptions
from host.panel.teleop import PanelConfig
from protocol.messages import Phase, TelemetryFlags
from tests.support.chromium import (
    CHROMIUM,
    CHROMIUM_ARGS,
    chromium_context,
    lever_button,
    page_load,
    page_load_ms,
)
from tests.support.realtime_guard import timed_out, wait_for

pytestmark = pytest.mark.browser

# Slow panel rates and no shadow maps: the viser client renders on demand, so fewer scene updates (and
# no three cascaded shadow passes per frame) = less software
# rendering competing for the 2 cores with everything else under test.
TOKEN = "t0ken-for-test"
PANEL = PanelConfig(scene_hz=8.0, plot_hz=2.0, health_hz=4.0, shadows=False)
FAKE = os.environ.get("SPIROB_BROWSER_FAKE_BOARD") == "1"

if shutil.which(CHROMIUM) is None:
    pytest.fail(
        f"{CHROMIUM} is not installed: the browser tests need it (scripts/setup.sh --system, or "
        "apt-get install chromium)",
        pytrace=False,
    )


@pytest.fixture
def app() -> Iterator[HostApp]:
    with contextlib.ExitStack() as stack:
        if FAKE:
            from tests.support.link_peer import LinkPeerProcess

            peer = stack.enter_context(LinkPeerProcess("socket"))
            opts = HostOptions(port=peer.url, ui_port=0, token=TOKEN)
        else:
            # No --port: the virtual board in its own process. A token (honoured on loopback too) so the
            # same run also checks that a tab without it can only watch.
            opts = HostOptions(ui_port=0, token=TOKEN)
        host = stack.enter_context(HostApp(opts, panel_config=PANEL))
        host.start()
        if not _wait(lambda: host.panel.board.telemetry is not None, 60.0):
            timed_out("the first telemetry from the board")  # start-up: skipped if the machine starved it
        yield host


@pytest.fixture
def browser(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Any]:
    with chromium_context(tmp_path_factory.mktemp("chromium")) as ctx:
        yield ctx


def open_panel(browser: Any, app: HostApp) -> Any:
    page = browser.new_page()
    with page_load("the panel page"):
        page.goto(app.url + ("&" if "?" in app.url else "?") + "fixedDpr=1", timeout=page_load_ms())
        page.wait_for_selector("canvas", timeout=page_load_ms())
        page.get_by_role("button", exact=True, name="E-STOP [Space]").wait_for(timeout=page_load_ms())
    with contextlib.suppress(Exception):  # the software-WebGL toast covers the scene
        page.locator(".mantine-Notification-closeButton").first.click(timeout=3_000)
    return page


def client_of(app: HostApp, before: set[int]) -> int:
    assert app.panel is not None
    assert _wait(lambda: len(set(app.panel.controls()) - before) == 1)
    (cid,) = set(app.panel.controls()) - before
    return cid


def stick_input(page: Any, label: str) -> Any:
    return page.locator(
        f"xpath=//label[normalize-space()='{label}']/ancestor::div[contains(@class,'mantine-Flex-root')][1]//input[not(@type='hidden')]"
    ).first


def state_bar(page: Any) -> str:
    return str(page.locator("[data-testid=state-bar]").first.inner_text())


def wait_bar(page: Any, *texts: str) -> str:
    """Wait until the state bar shows every one of ``texts``; returns its text."""
    ok = _wait(lambda: all(t in state_bar(page) for t in texts), 20.0)
    text = state_bar(page)
    assert ok, f"state bar {text!r} lacks {texts}"
    return text


def test_panel_end_to_end(app: HostApp, browser: Any, tmp_path: Path) -> None:
    from PIL import Image, ImageStat

    m, arb = app.board_state, app.arbiter
    assert m is not None and arb is not None
    assert f"token={TOKEN}" in app.url
    page_a = open_panel(browser, app)  # the printed URL: the page sets the cookie the websocket carries
    a = client_of(app, set())
    assert arb.is_authorised(a)

    # The canvas renders the scene: after the poses arrive, the screenshot is not blank and shows arm blue.
    assert _wait(lambda: app.panel is not None and app.panel.scene.updates > 10)
    time.sleep(1.0)
    # A page screenshot cropped to the scene (a locator screenshot waits ~10 s for "stability" here).
    box = page_a.locator("canvas").first.bounding_box()
    assert box is not None
    png = page_a.screenshot()
    (tmp_path / "panel.png").write_bytes(png)
    panel_left = page_a.get_by_text("SpiRob teleop").first.bounding_box()
    right = panel_left["x"] - 10 if panel_left else box["x"] + box["width"]
    img = (
        Image.open(io.BytesIO(png))
        .convert("RGB")
        .crop((int(box["x"]), int(box["y"]), int(right), int(box["y"] + box["height"])))
    )
    assert max(ImageStat.Stat(img).stddev) > 5.0, "blank canvas"
    small = img.resize((img.width // 2, img.height // 2))
    blue = sum(1 for r, g, b in small.get_flattened_data() if b > 150 and b > r + 60 and g > 80)
    assert blue > 20, f"no arm-coloured pixels in the screenshot ({blue})"

    # Take control, pass the gate (right lever DOWN: the board arms itself), MANUAL (MIDDLE).
    page_a.get_by_role("button", exact=True, name="Take control").click()
    assert _wait(lambda: arb.holder == a)
    page_a.get_by_text("You hold control.").wait_for(timeout=10_000)
    lever_button(page_a, "Right lever", "DOWN").click()
    assert _wait(lambda: m.telemetry is not None and m.telemetry.phase == Phase.OK)
    lever_button(page_a, "Right lever", "MIDDLE").click()
    assert _wait(lambda: m.telemetry is not None and m.telemetry.mode.name == "MANUAL")
    # Armed already: the Arm button (for a board the host disarmed) is greyed out, not a false step.
    assert page_a.get_by_role("button", exact=True, name="Arm").is_disabled()
    base = m.telemetry
    assert base is not None

    # Move the left stick up in the page: the board's commanded tensions and currents follow.
    curl = stick_input(page_a, "Left ↕ tighten all cables")
    curl.fill("500")
    curl.press("Enter")
    assert _wait(lambda: arb.operator_input()[0][3] == 500, 10.0)

    def tensions_up() -> bool:
        t = m.telemetry
        return t is not None and min(t.tension_target_n) > max(base.tension_target_n) + 1.0

    assert _wait(tensions_up), f"tensions did not rise: {m.telemetry}"
    t = m.telemetry
    assert t is not None and any(c > 0 for c in t.commanded_current)

    # The per-cable "hold length" toggle (Direct mode folder): the board reports cable 1 held.
    def held() -> bool:
        t = m.telemetry
        return t is not None and bool(t.flags & TelemetryFlags.HOLD_1)

    page_a.get_by_text("Direct mode", exact=True).first.click()
    hold_box = stick_input(page_a, "Cable 1 hold length")
    hold_box.click()
    assert _wait(held), f"cable 1 not held: {m.telemetry}"

    # A second (authorised) tab watches; asking for control does not take it.
    page_b = open_panel(browser, app)
    b = client_of(app, {a})
    page_b.get_by_role("button", exact=True, name="Take control").click()
    assert _wait(lambda: arb.pending == b)
    # Polled, not slept: the first sample in 1 s where the holder is not A fails at once.
    assert _stays(lambda: arb.holder == a, 1.0), f"a second tab took control silently: {arb.holder}"
    page_b.get_by_text("Request sent; waiting for the holder.").wait_for(timeout=10_000)
    # The holder hands it over explicitly; the new holder starts from SAFE.
    page_a.get_by_role("button", exact=True, name="Hand control over").click(timeout=10_000)
    assert _wait(lambda: arb.holder == b)
    frame = arb.rc_frame()
    assert frame is not None and frame.right_lever == 2 and frame.channels == (0, 0, 0, 0)

    # E-stop on the hotkey (Space) from the new holder's tab: currents go to zero.
    page_b.evaluate("document.activeElement && document.activeElement.blur()")
    page_b.keyboard.press("Space")

    def stopped() -> bool:
        t = m.telemetry
        return t is not None and t.phase == Phase.ESTOP and all(c == 0 for c in t.commanded_current)

    assert _wait(stopped), f"E-stop did not zero the currents: {m.telemetry}"
    assert not held()  # SAFE dropped the hold, and the toggle follows the board
    assert _wait(lambda: not hold_box.is_checked(), 10.0)
    page_b.get_by_text("E-STOP pressed").first.wait_for(timeout=10_000)
    page_a.close()
    page_b.close()
    assert _wait(lambda: arb.holder is None)


def test_state_bar_toasts_space_and_parameters(app: HostApp, browser: Any) -> None:
    """A first-time pilot's steps, each said by the panel: the state bar's next step in each phase, the
    board's reason for a refused command, the control request toast, the parameter editor's round trip
    through the board, and Space with the focus in a number box."""
    m, arb, params = app.board_state, app.arbiter, app.board_params
    assert m is not None and arb is not None and params is not None
    page_a = open_panel(browser, app)
    a = client_of(app, set())
    # Nobody drives yet: the idle radio (levers DOWN) has passed the gate, SAFE; the bar says how to start.
    text = wait_bar(page_a, "OK · SAFE", "Take control")
    assert text.split(" · ")[0] == "OK", text
    page_a.get_by_role("button", exact=True, name="Take control").click()
    assert _wait(lambda: arb.holder == a)
    # The new holder sends the right lever DOWN: the gate opens, SAFE; the lever button shows it.
    wait_bar(page_a, "OK · SAFE", "ARMED", "move the right lever to MIDDLE to drive")
    assert lever_button(page_a, "Right lever", "DOWN").inner_text().strip() == "● DOWN"

    # A refused command: DIRECT with the lever DOWN. The board's reason arrives as a toast.
    page_a.get_by_text("Direct mode", exact=True).first.click()
    page_a.get_by_role("button", exact=True, name="Enter DIRECT mode").click()
    page_a.get_by_text("Board refused SET_MODE").first.wait_for(timeout=15_000)
    page_a.get_by_text("DIRECT needs phase OK and the right lever MIDDLE").first.wait_for(timeout=5_000)
    assert any("SET_MODE REJECTED" in e.text for e in app.notices.events.entries())

    # MIDDLE: MANUAL, and the bar says how to drive.
    lever_button(page_a, "Right lever", "MIDDLE").click()
    wait_bar(page_a, "OK · MANUAL", "driving")
    assert lever_button(page_a, "Right lever", "MIDDLE").inner_text().strip() == "● MIDDLE"

    # Another tab asks for control: the holder gets a toast naming it, and keeps control.
    page_b = open_panel(browser, app)
    b = client_of(app, {a})
    page_b.get_by_role("button", exact=True, name="Take control").click()
    page_a.get_by_text(f"Tab {b} asks for control").first.wait_for(timeout=15_000)
    page_a.get_by_role("button", exact=True, name="Keep control").click()
    assert _wait(lambda: arb.pending is None) and arb.holder == a
    page_b.close()

    # The parameter editor: set STICK_DEADBAND, the board reads it back, the page shows it confirmed.
    page_a.get_by_text("Parameters", exact=True).first.click()
    page_a.get_by_label("Parameter").first.click()
    page_a.get_by_role("option", name="STICK_DEADBAND", exact=True).click()
    page_a.get_by_text("Bounds: must be 0..659 counts").first.wait_for(timeout=10_000)
    old = params.params.get("STICK_DEADBAND")
    new = 17 if old != 17 else 18
    box = stick_input(page_a, "Value")
    box.fill(str(new))
    box.press("Enter")
    page_a.get_by_role("button", exact=True, name="Set on board").click()
    assert _wait(lambda: params.params.get("STICK_DEADBAND") == new), params.params.get("STICK_DEADBAND")
    page_a.get_by_text(f"Set to {new}: confirmed by the board").first.wait_for(timeout=10_000)

    # Space with the focus in that number box: E-stop, the banner and the way out.
    box.focus()
    assert page_a.evaluate("document.activeElement.tagName") == "INPUT"
    page_a.keyboard.press("Space")
    assert _wait(lambda: m.telemetry is not None and m.telemetry.phase == Phase.ESTOP), m.telemetry
    page_a.get_by_text("E-STOP LATCHED").first.wait_for(timeout=10_000)
    wait_bar(page_a, "ESTOP", "E-stop latched: clear it (Clear E-stop), then re-arm through SAFE")
    page_a.close()


OPEN_WS_JS = """([url, protocol]) => new Promise(done => {
    const ws = new WebSocket(url, [protocol]);
    ws.onopen = () => { ws.close(); done("open"); };
    ws.onerror = () => done("refused");
    setTimeout(() => done("timeout"), 15000);
})"""
"""Opens a websocket the way viser's client does (its subprotocol) and says whether it opened."""


def try_websocket(page: Any, url: str) -> str:
    """The outcome ("open", "refused", "timeout") of a websocket to ``url`` opened by ``page``."""
    return str(page.evaluate(OPEN_WS_JS, [url, f"viser-v{viser.__version__}"]))


class _AttackerPage(http.server.BaseHTTPRequestHandler):
    def do_GET(self) -> None:
        body = b"<!doctype html><title>elsewhere</title><p>another origin"
        self.send_response(200)
        self.send_header("Content-Type", "text/html")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, *_args: Any) -> None:
        return


def test_panel_refuses_other_origins_and_missing_tokens() -> None:
    other = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _AttackerPage)
    threading.Thread(target=other.serve_forever, daemon=True).start()
    opts = HostOptions(port="loop://", ui_port=0, token=TOKEN)
    with HostApp(opts, panel_config=PANEL) as app, sync_api.sync_playwright() as p:
        app.start()
        assert app.url.endswith(f"/?token={TOKEN}")
        parts = urllib.parse.urlsplit(app.url)
        ws = f"ws://{parts.netloc}/"
        guard = app.guard
        assert guard is not None and app.panel is not None
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS)
        try:
            # The operator's browser: the printed URL opens a working panel (and leaves the cookie).
            operator = browser.new_context(viewport={"width": 960, "height": 680})
            panel = operator.new_page()
            with page_load("the panel page"):
                panel.goto(app.url, timeout=page_load_ms())
                panel.get_by_role("button", exact=True, name="E-STOP [Space]").wait_for(
                    timeout=page_load_ms()
                )
            (cid,) = app.panel.controls()
            assert app.arbiter is not None and app.arbiter.is_authorised(cid)

            # A page from another port on 127.0.0.1 in that same browser: refused, with the token in
            # the URL and with the panel's cookie (cookies ignore ports; the Origin does not).
            evil = operator.new_page()
            with page_load("the other origin's page"):
                evil.goto(f"http://127.0.0.1:{other.server_address[1]}/", timeout=page_load_ms())
            assert try_websocket(evil, f"{ws}?token={TOKEN}") == "refused"
            assert try_websocket(evil, ws) == "refused"
            assert guard.stats.origin_refused_n >= 2
            assert len(app.panel.controls()) == 1

            # A browser without the token: the page is refused, and so is its own-origin websocket;
            # the same page's websocket with the token opens.
            stranger = browser.new_context().new_page()
            with page_load("the refused panel page"):
                response = stranger.goto(f"http://{parts.netloc}/", timeout=page_load_ms())
            assert response is not None and response.status == 403
            assert "URL printed at start" in stranger.content()
            assert try_websocket(stranger, ws) == "refused"
            assert guard.stats.token_refused_n >= 2
            assert try_websocket(stranger, f"{ws}?token={TOKEN}") == "open"
        finally:
            browser.close()
            other.shutdown()
            other.server_close()


def _wait(cond: Callable[[], bool], timeout_s: float = 20.0) -> bool:
    return wait_for(cond, timeout_s, 0.05)


def _stays(cond: Callable[[], bool], duration_s: float) -> bool:
    """``cond`` holds at every sample (every 20 ms) for ``duration_s``; False at the first that fails."""
    deadline = time.monotonic() + duration_s
    while time.monotonic() < deadline:
        if not cond():
            return False
        time.sleep(0.02)
    return bool(cond())
