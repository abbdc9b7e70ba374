"""The default demo's object grasped from the panel, in real headless Chromium.

`spirob-host`'s default scene (the options the command line builds with no flags: the virtual board with
``host.object_spec.DEFAULT_OBJECT``), driven as a first-time pilot would: take control, right lever DOWN
(the start-up gate), UP (GRASP mode: the arm packs), then the *Grasp* button; the board's grasp state
machine reaches HOLD around the pole, and *Release* lets it go.
"""

from __future__ import annotations

import contextlib
import shutil
from collections.abc import Callable, Iterator
from typing import Any

import pytest

from host.app import HostApp
from host.object_spec import DEFAULT_OBJECT
from host.options import HostOptions, build_parser
from host.panel.teleop import PanelConfig
from protocol.messages import AckResult, CommandCode, GraspState, Mode, Phase
from tests.support.chromium import CHROMIUM, chromium_context, lever_button, page_load, page_load_ms
from tests.support.realtime_guard import timed_out, wait_for

pytestmark = pytest.mark.browser

TOKEN = "t0ken-for-test"
PANEL = PanelConfig(scene_hz=8.0, plot_hz=2.0, health_hz=4.0, shadows=False)

if shutil.which(CHROMIUM) is None:
    pytest.fail(f"{CHROMIUM} is not installed: the browser tests need it", pytrace=False)


@pytest.fixture
def app() -> Iterator[HostApp]:
    opts = HostOptions.from_args(build_parser().parse_args(["--ui-port", "0", "--token", TOKEN]))
    assert opts.objects == (DEFAULT_OBJECT,)  # the default scene, as `spirob-host` builds it
    with HostApp(opts, panel_config=PANEL) as host:
        host.start()
        if not _wait(lambda: host.panel.board.telemetry is not None, 60.0):
            timed_out("the first telemetry from the board")
        yield host


@pytest.fixture
def page(tmp_path_factory: pytest.TempPathFactory, app: HostApp) -> Iterator[Any]:
    with chromium_context(tmp_path_factory.mktemp("chromium")) as ctx:
        pg = ctx.new_page()
        with page_load("the panel page"):
            pg.goto(app.url + "&fixedDpr=1", timeout=page_load_ms())
            pg.get_by_role("button", exact=True, name="Grasp").wait_for(timeout=page_load_ms())
        with contextlib.suppress(Exception):  # the software-WebGL toast covers the scene
            pg.locator(".mantine-Notification-closeButton").first.click(timeout=3_000)
        yield pg


def test_the_default_scenes_object_is_grasped_from_the_panel(app: HostApp, page: Any) -> None:
    m, arb = app.board_state, app.arbiter
    assert m is not None and arb is not None
    assert [o.name for o in app.objects] == ["object1"]
    assert app.panel is not None and len(app.panel.scene.handles.objects) == 1

    def telemetry() -> Any:
        return m.telemetry

    page.get_by_role("button", exact=True, name="Take control").click()
    assert _wait(lambda: arb.holder is not None)
    lever_button(page, "Right lever", "DOWN").click()
    assert _wait(lambda: telemetry().phase == Phase.OK), telemetry()
    lever_button(page, "Right lever", "UP").click()
    assert _wait(lambda: telemetry().mode == Mode.GRASP), telemetry()
    # GRASP mode packs the arm (12 N/s up to 18 N): give it 3 s of board time, as the lockstep test does.
    packed_us = telemetry().time_us + 3_000_000
    assert _wait(lambda: telemetry().time_us >= packed_us, 10.0)
    assert telemetry().grasp_state == GraspState.IDLE

    page.get_by_role("button", exact=True, name="Grasp").click()
    assert _wait(lambda: telemetry().grasp_state != GraspState.IDLE, 10.0), telemetry()
    # Reach, contact, wrap, HOLD: about 4 s of board time in lockstep.
    assert _wait(lambda: telemetry().grasp_state in (GraspState.HOLD, GraspState.FAILED), 30.0), telemetry()
    t = telemetry()
    assert t.grasp_state == GraspState.HOLD, f"the grasp ended {t.grasp_state.name}: {t}"
    assert t.phase == Phase.OK
    # The board's final answer to the panel's GRASP (not its IN_PROGRESS, not another command's ack):
    # ACCEPTED "holding", sent when the grasp reached HOLD (it may arrive just after that telemetry).

    def grasp_held_ack() -> bool:
        ack = m.last_ack
        return ack is not None and (ack.command, ack.result, ack.text) == (
            CommandCode.GRASP,
            AckResult.ACCEPTED,
            "holding",
        )

    assert _wait(grasp_held_ack, 5.0), m.last_ack

    page.get_by_role("button", exact=True, name="Release").click()
    assert _wait(lambda: telemetry().grasp_state != GraspState.HOLD, 10.0), telemetry()


def _wait(cond: Callable[[], bool], timeout_s: float = 20.0) -> bool:
    return wait_for(cond, timeout_s, 0.05)
