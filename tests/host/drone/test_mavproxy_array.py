"""End to end: MAVLink DO_GRIPPER closes every arm of an array (issue 27).

A real MAVProxy talks to a real `spirob-host --arms 4 --headless --virtual-rc grasp` (the virtual board
laid out as four 2-cable arms on a ring, eight motors). DO_GRIPPER grab must be answered IN_PROGRESS and
then with a final result, and the board link the host recorded must show the one grasp driving every arm:
each motor's tension target is its cable's target on arm 0 (the array is one gripper, ``controller.grasp``)
and every motor carried current while the grasp ran.
"""

from __future__ import annotations

import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest

from controller.params import PARAMS
from hil import recording
from protocol.messages import ArmsTelemetry, GraspState, Telemetry
from protocol.stream import MessageStream
from tests.support.mavproxy_proc import MavProxy, host_under_mavproxy, stop_host

pytestmark = pytest.mark.mavproxy
ARMS, CABLES = 4, 2


@pytest.fixture
def host_and_proxy(tmp_path: Path) -> Iterator[tuple[MavProxy, Path, subprocess.Popen[str]]]:
    with host_under_mavproxy(tmp_path, ["--arms", str(ARMS)]) as (proxy, record, host):
        yield proxy, record, host


def test_do_gripper_closes_every_arm_of_an_array(
    host_and_proxy: tuple[MavProxy, Path, subprocess.Popen[str]],
) -> None:
    proxy, record, host = host_and_proxy
    proxy.expect(r"Detected vehicle 1:25", timeout=60)
    proxy.expect(rf"Received {len(PARAMS)} parameters", timeout=60)
    # The board's own word that its virtual radio put it in GRASP mode: fetching the parameters took
    # less time than that once (CI: DO_GRIPPER DENIED "mode SAFE, lever not UP").
    proxy.expect(r"AP: mode GRASP", timeout=60)
    start = len(proxy.lines())
    proxy.send("long DO_GRIPPER 25 1")
    i = proxy.expect(r"Got COMMAND_ACK: DO_GRIPPER: IN_PROGRESS", start, timeout=30)
    proxy.expect(r"Got COMMAND_ACK: DO_GRIPPER: (ACCEPTED|FAILED)", i + 1, timeout=60)
    stop_host(host)  # the recording is complete once the host has exited
    assert host.returncode == 0

    grasping = _arms_telemetry_while_grasping(record)
    assert grasping, "no ArmsTelemetry while the grasp ran"
    assert {(m.arms, m.cables_per_arm) for m in grasping} == {(ARMS, CABLES)}
    for m in grasping:  # one gripper: every arm takes arm 0's targets, cable by cable
        for motor in range(ARMS * CABLES):
            assert m.tension_target_n[motor] == pytest.approx(m.tension_target_n[motor % CABLES])
    worked = [any(m.commanded_current[k] != 0 for m in grasping) for k in range(ARMS * CABLES)]
    assert all(worked), f"motors that carried current while grasping: {worked}"


def _arms_telemetry_while_grasping(path: Path) -> list[ArmsTelemetry]:
    """``ArmsTelemetry`` the board sent while its ``Telemetry`` said a grasp was running."""
    stream = MessageStream()
    state = GraspState.IDLE
    out: list[ArmsTelemetry] = []
    for rec in recording.read_records(path, topics={recording.LINK_TX}):
        for _, msg in stream.feed(rec.data):
            if isinstance(msg, Telemetry):
                state = msg.grasp_state
            elif isinstance(msg, ArmsTelemetry) and state in (GraspState.REACH, GraspState.WRAP):
                out.append(msg)
    return out
