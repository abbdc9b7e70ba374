"""End to end: a real MAVProxy talks to a real `spirob-host` whose virtual board runs the firmware and plant.

`spirob-host --headless --virtual-rc grasp --mavlink udpout:...` drives the virtual radio through the
start-up gate into GRASP mode; MAVProxy (headless, loopback) must detect component 25, fetch the
firmware's parameters, set one that the board confirms, and see DO_GRIPPER answered IN_PROGRESS and
then with a final result, while the .tlog of the run is readable by pymavlink's mavlogdump.
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from controller.params import PARAMS
from tests.support.mavproxy_proc import MavProxy, host_under_mavproxy

pytestmark = pytest.mark.mavproxy


@pytest.fixture
def host_and_proxy(tmp_path: Path) -> Iterator[tuple[MavProxy, Path]]:
    with host_under_mavproxy(tmp_path) as (proxy, record, _host):
        yield proxy, record


def test_mavproxy_commands_the_arm_through_spirob_host(host_and_proxy: tuple[MavProxy, Path]) -> None:
    proxy, record = host_and_proxy
    proxy.expect(r"Detected vehicle 1:25", timeout=60)
    proxy.expect(rf"Received {len(PARAMS)} parameters", timeout=60)

    start = len(proxy.lines())
    proxy.send("param set PRETENSION_N 0.8")
    i = proxy.expect(r"PRETENSION_N = 0\.8", start, timeout=30)  # the board's confirmation reached MAVProxy
    proxy.send("param fetch PRETENSION_N")
    proxy.expect(r"PRETENSION_N = 0\.80000", i + 1, timeout=30)

    proxy.expect(r"AP: mode GRASP", timeout=60)  # the virtual radio's lever is UP: a grab may be taken
    start = len(proxy.lines())
    proxy.send("long DO_GRIPPER 25 1")
    i = proxy.expect(r"Got COMMAND_ACK: DO_GRIPPER: IN_PROGRESS", start, timeout=30)
    # No object hangs in reach of the default virtual board: the strategy ends with or without a grip;
    # either way the final answer must come.
    proxy.expect(r"Got COMMAND_ACK: DO_GRIPPER: (ACCEPTED|FAILED)", i + 1, timeout=60)

    start = len(proxy.lines())
    proxy.send("watch NAMED_VALUE_FLOAT")
    proxy.expect(r"NAMED_VALUE_FLOAT \{.*name : ARM_T1_N", start, timeout=30)
    proxy.send("watch")

    tlog = record.with_suffix(".tlog")
    assert tlog.exists() and tlog.stat().st_size > 0
    dump = subprocess.run(
        [
            sys.executable,
            str(Path(sys.executable).with_name("mavlogdump.py")),
            "--types",
            "HEARTBEAT,COMMAND_ACK",
            str(tlog),
        ],
        capture_output=True,
        text=True,
        timeout=60,
        env=dict(os.environ, MAVLINK20="1"),
    )
    assert dump.returncode == 0, dump.stderr
    assert "COMMAND_ACK" in dump.stdout and "HEARTBEAT" in dump.stdout
