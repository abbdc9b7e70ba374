"""Refresh the panel screenshots of docs/host.md (docs/figures/panel-*.png).

Starts ``spirob-host`` in-process against the virtual board (no ``--port``), opens the panel in Debian's
headless Chromium (the browser tests' one: ``/usr/bin/chromium``, driven by Playwright) and walks a
first-time pilot's steps, one screenshot each: the first view (nobody holds control), control taken
(SAFE, lever DOWN), driving (MANUAL), and E-stop latched. The images are palette PNGs (small enough to
commit).

Usage: ``python scripts/screenshots.py [--out docs/figures]``; exits non-zero, with one line on stderr,
when a step does not happen within its time.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import sys
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
"""The checkout this script belongs to: its panel is the one photographed (not an installed copy)."""
CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-background-networking"]
STEP_S = 60.0
"""The longest wait for one step (the 3D scene renders in software; the machine may be loaded)."""


class StepFailed(Exception):
    """A step of the walk did not happen in time."""


def _wait(cond: Callable[[], bool], what: str, timeout_s: float = STEP_S) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if cond():
            return
        time.sleep(0.1)
    raise StepFailed(f"timed out waiting for {what}")


def _save(page: object, path: Path) -> None:
    from PIL import Image

    png = page.screenshot()  # type: ignore[attr-defined]
    img = Image.open(io.BytesIO(png)).convert("RGB").quantize(colors=64)
    img.save(path, optimize=True)
    print(f"wrote {path} ({path.stat().st_size // 1024} KiB)")


def take(out: Path) -> None:
    """Walk the steps and write the screenshots into ``out``.

    Raises:
        StepFailed: a step did not happen in time.
    """
    from playwright import sync_api

    from host.app import HostApp
    from host.options import HostOptions
    from host.panel.teleop import PanelConfig
    from protocol.messages import Mode, Phase

    out.mkdir(parents=True, exist_ok=True)
    with HostApp(HostOptions(ui_port=0), panel_config=PanelConfig(scene_hz=8.0, plot_hz=2.0)) as app:
        app.start()
        m, arbiter = app.board_state, app.arbiter
        assert m is not None and arbiter is not None
        _wait(lambda: m.telemetry is not None, "the first telemetry")
        with sync_api.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS)
            try:
                page = browser.new_page(viewport={"width": 1280, "height": 800})
                page.goto(app.url + ("&" if "?" in app.url else "?") + "fixedDpr=1", timeout=STEP_S * 1000)
                page.get_by_role("button", exact=True, name="E-STOP [Space]").wait_for(timeout=STEP_S * 1000)
                _wait(lambda: app.panel is not None and app.panel.scene.updates > 5, "the scene")
                with contextlib.suppress(sync_api.TimeoutError):  # toasts close themselves too
                    page.locator(".mantine-Notification-closeButton").first.click(timeout=3_000)
                time.sleep(2.0)
                _save(page, out / "panel-first-view.png")

                page.get_by_role("button", exact=True, name="Take control").click()
                _wait(lambda: arbiter.holder is not None, "control")
                page.get_by_role("button", name="DOWN").first.click()
                _wait(lambda: m.telemetry is not None and m.telemetry.phase == Phase.OK, "phase OK")
                time.sleep(1.5)
                _save(page, out / "panel-safe.png")

                page.get_by_role("button", name="MIDDLE").first.click()
                _wait(lambda: m.telemetry is not None and m.telemetry.mode == Mode.MANUAL, "MANUAL")
                bend = page.locator(  # the "Right ↔" slider's number box
                    "xpath=//label[starts-with(normalize-space(), 'Right ↔')]"
                    "/ancestor::div[contains(@class,'mantine-Flex-root')][1]//input[not(@type='hidden')]"
                ).first
                bend.fill("450")  # bend right: the arm curls toward the screen's right
                bend.press("Enter")
                page.mouse.move(5, 795)  # no tooltip in the picture
                time.sleep(4.0)
                _save(page, out / "panel-manual.png")

                page.evaluate("document.activeElement && document.activeElement.blur()")
                page.keyboard.press("Space")
                _wait(lambda: m.telemetry is not None and m.telemetry.phase == Phase.ESTOP, "E-stop")
                time.sleep(1.5)
                _save(page, out / "panel-estop.png")
            except sync_api.TimeoutError as exc:
                raise StepFailed(str(exc).splitlines()[0]) from exc
            finally:
                browser.close()


def main(argv: list[str] | None = None) -> int:
    """Parse the arguments and take the screenshots; returns the exit status."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("docs/figures"), help="directory of the PNGs")
    args = parser.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    try:
        take(args.out)
    except StepFailed as exc:
        print(f"screenshots: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
