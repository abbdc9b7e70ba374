"""The panel of `spirob-host --arms 4`, judged from a screenshot (headless Chromium, Playwright).

The host is built from the command line's own options (``--arms 4 --ui-port 0``: four 2-cable arms on a
ring, the virtual board in its own process). Seen from below, along the drone's axis, the four arms are
four separate patches of the arms' blue in the pixels of the 3-D view, each where its arm hangs on the
ring; and the panel says in words that the board is an array of four arms.
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest

from host.app import HostApp
from host.options import HostOptions, build_parser
from host.panel.teleop import PanelConfig
from tests.support.chromium import page_load, page_load_ms
from tests.support.panel_view import (
    arm_blue_mask,
    no_leaks_since_now,
    panel_page,
    require_chromium,
    scene_pixels,
)
from tests.support.realtime_guard import timed_out, wait_for

pytestmark = pytest.mark.browser

ARMS = 4
PANEL = PanelConfig(scene_hz=4.0, plot_hz=1.0, health_hz=4.0, shadows=False)
VIEWPORT = {"width": 1280, "height": 640}
"""Wide enough that the middle of the 3-D view (where the camera looks) is left of the panel."""
BLOB_MIN_PX = 60
"""A patch of arm blue this large is an arm (an arm seen end-on from 0.45 m: several hundred pixels);
smaller ones are edges and specks."""
GROW_PX = 5
"""Each patch grown by this much before telling them apart."""
NEAR_PX = 150
"""The camera looks at the arms' middle, which the view draws at its centre; from 0.45 m below, the four
arms stand 45-50 px from it. A blue patch farther than this is not one of the array's arms: under load a
toast's blue icon or a button can enter the shot (a fifth patch of 302 px once, the arms' 173-291)."""
require_chromium()


@pytest.fixture(autouse=True)
def _no_leaked_threads_or_processes() -> Iterator[None]:
    with no_leaks_since_now():
        yield


@pytest.fixture(scope="module")
def app() -> Iterator[HostApp]:
    options = HostOptions.from_args(build_parser().parse_args(["--arms", str(ARMS), "--ui-port", "0"]))
    with HostApp(options, panel_config=PANEL) as host:
        host.start()
        if not _wait(lambda: host.panel is not None and host.panel.board.telemetry is not None, 60.0):
            timed_out("the first telemetry from the board")
        yield host


@pytest.fixture(scope="module")
def page(app: HostApp, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Any]:
    with panel_page(app.url, tmp_path_factory.mktemp("chromium"), VIEWPORT) as p:
        yield p


@pytest.fixture(scope="module")
def view_from_below(app: HostApp, page: Any) -> Any:
    """The 3-D view's pixels once every arm is drawn, the camera below the ring looking up it.

    A module fixture, like the host and the page: the viser server answers the camera with a worker
    thread of its own event loop that lives as long as the server (not a leak of the test's)."""

    panel = app.panel
    assert panel is not None and app.server is not None and app.board_state is not None
    # Every arm's poses arrived and were drawn.
    assert _wait(lambda: f"{ARMS} of {ARMS} arms drawn" in panel.pose_source, 30.0), panel.pose_source
    (cid,) = panel.controls()
    client = app.server.get_clients()[cid]
    # From below, nearly along the drone's axis: each arm is seen end-on at its place on the ring.
    bodies = app.board_state.bodies()
    assert bodies is not None and bodies[2] == ARMS
    centre = np.mean(bodies[0][1:], axis=0)  # the middle of the arms' units
    below = (float(centre[0]), float(centre[1]) - 0.02, float(centre[2]) - 0.45)
    # The pose-source label (an HTML overlay drawn over everything, at the drone's centre) would cover
    # an arm seen from below; its words are checked in the page by the other test.
    panel.scene.handles.label.visible = False
    with client.atomic():
        client.camera.up_direction = (0.0, 1.0, 0.0)
        client.camera.position = below
        client.camera.look_at = tuple(float(x) for x in centre)
    assert _wait(lambda: math.dist(tuple(client.camera.position), below) < 0.02, 15.0), (
        f"the camera is at {client.camera.position}, not {below}"
    )
    time.sleep(1.0)  # let the software renderer draw the new view
    with contextlib.suppress(Exception):  # a toast shown since (software WebGL) would cover the scene
        page.locator(".mantine-Notification-closeButton").first.click(timeout=2_000)
        time.sleep(0.5)
    # The panel's frame and blue buttons start ~40 px left of its title. Under load the software
    # renderer can still be drawing (a frame between two camera poses shows an arm twice): take the view
    # once two shots 0.5 s apart have the same arm-blue pixels, at most 12 shots.
    shot = scene_pixels(page, margin_px=60)
    for _ in range(12):
        time.sleep(0.5)
        again = scene_pixels(page, margin_px=60)
        if np.count_nonzero(arm_blue_mask(shot) != arm_blue_mask(again)) <= 20:
            return again
        shot = again
    return shot


def test_the_panel_says_the_board_is_an_array(page: Any) -> None:
    with page_load("the array's health line"):
        page.get_by_text(f"the board is an array of {ARMS} arms x 2 cable(s)").first.wait_for(
            timeout=page_load_ms()
        )
    assert page.get_by_text(f"ArmPoses: {ARMS} of {ARMS} arms drawn").count() >= 1


def test_the_panel_draws_every_arm_of_the_array_in_its_own_place(view_from_below: Any) -> None:
    from scipy import ndimage

    blue = arm_blue_mask(view_from_below)
    # Grown by a few pixels so that the cable lines drawn over an arm do not cut it in two; the arms
    # themselves stand 50+ px apart.
    labels, n = ndimage.label(ndimage.binary_dilation(blue, iterations=GROW_PX))
    sizes = ndimage.sum_labels(blue, labels, range(1, n + 1))  # each patch's own blue pixels
    big = [i + 1 for i, s in enumerate(sizes) if s >= BLOB_MIN_PX]
    where = np.asarray(ndimage.center_of_mass(blue, labels, big)).reshape(-1, 2)  # (row, column) px
    centre = 0.5 * np.array([VIEWPORT["height"], VIEWPORT["width"]])  # the 3-D view fills the page
    near = np.linalg.norm(where - centre, axis=1) < NEAR_PX
    arms = [i for i, ok in zip(big, near, strict=True) if ok]
    assert len(arms) == ARMS, (
        f"arm-blue patches (px) near the view's centre {centre.tolist()}: "
        f"{[(int(sizes[i - 1]), where[k].round().tolist()) for k, i in enumerate(big)]}"
    )
    # Where they are: around one middle, at the ring's quarter turns (four arms: two pairs facing).
    pts = where[near]
    radii = np.linalg.norm(pts - pts.mean(axis=0), axis=1)
    assert radii.min() > 0.5 * radii.max() > 10, f"patch centres (px): {pts.tolist()}"


# ---------------------------------------------------------------------- helpers


def _wait(cond: Callable[[], Any], timeout_s: float = 20.0) -> bool:
    return wait_for(lambda: bool(cond()), timeout_s, 0.05)
