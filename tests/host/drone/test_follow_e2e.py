"""End to end: a stand-in autopilot drives a real `spirob-host` (virtual board) by its gripper servo.

The autopilot is pymavlink on ``udpin:127.0.0.1:PORT`` as system 1, component 1 (HEARTBEAT
``MAV_TYPE_QUADROTOR`` / ``MAV_AUTOPILOT_ARDUPILOTMEGA``), stepping output 9 of ``SERVO_OUTPUT_RAW``
between the release and grab PWM as ArduPilot's servo gripper does. `spirob-host --follow-servo 9`
must carry grab and release to the board (its grasp state, seen in the arm's ``ARM_GRASP`` telemetry
and heartbeat), hold while the output rests between the two, do nothing when the reports stop, and
leave the radio the master: with the right lever at MIDDLE a grab is refused.
"""

from __future__ import annotations

import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from pymavlink import mavutil

from protocol import mavlink as mav
from protocol import messages as bm
from tests.support.mavproxy_proc import free_udp_port, stop_host
from tests.support.realtime_guard import scaled_s, timed_out

pytestmark = pytest.mark.slow  # two `spirob-host` runs with the MuJoCo virtual board
ROOT = Path(__file__).resolve().parents[3]
D = mav.dialect()
OUTPUT_N, GRAB_PWM, RELEASE_PWM, BAND_PWM = 9, 1900, 1100, 1500
STALE_MS = 500
START_S = 90.0
"""How long the host may take to start the virtual board on a quiet machine (scaled with the load)."""


class Autopilot:
    """The stand-in ArduPilot: heartbeat at 1 Hz, SERVO_OUTPUT_RAW at 20 Hz, everything received kept."""

    def __init__(self, port: int) -> None:
        self.conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=1, source_component=1)
        self.pwm_us = RELEASE_PWM
        self.streaming = threading.Event()
        self.streaming.set()
        self.seen: list[Any] = []
        self.texts: list[str] = []
        self.grasp_state: int | None = None
        self._lock = threading.RLock()  # wait() holds it while its condition calls text_count()
        self._stop = threading.Event()
        self._heard = threading.Event()
        self._threads = [
            threading.Thread(target=self._send, daemon=True),
            threading.Thread(target=self._recv, daemon=True),
        ]
        for t in self._threads:
            t.start()

    def _send(self) -> None:
        n = 0
        while not self._stop.wait(0.05) and n < 100_000:
            n += 1
            if not self._heard.is_set():
                continue  # udpin: nowhere to send before the host's first packet
            if n % 20 == 0:
                self.conn.mav.heartbeat_send(D.MAV_TYPE_QUADROTOR, D.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 4)
            if self.streaming.is_set():
                servos = [1500] * 16
                servos[OUTPUT_N - 1] = self.pwm_us
                self.conn.mav.servo_output_raw_send((n * 50_000) & 0xFFFFFFFF, 0, *servos)

    def _recv(self) -> None:
        while not self._stop.is_set():
            m = self.conn.recv_match(blocking=True, timeout=0.1)
            if m is None or m.get_type() == "BAD_DATA" or m.get_srcComponent() != 25:
                continue
            self._heard.set()
            with self._lock:
                self.seen.append(m)
                if m.get_type() == "STATUSTEXT":
                    self.texts.append(m.text)
                elif m.get_type() == "NAMED_VALUE_FLOAT" and m.name == "ARM_GRASP":
                    self.grasp_state = int(m.value)

    def wait(self, cond: Callable[[], bool], what: str, timeout_s: float = 30.0) -> None:
        deadline = time.monotonic() + scaled_s(timeout_s)
        while time.monotonic() < deadline:
            with self._lock:
                if cond():
                    return
            time.sleep(0.05)
        with self._lock:
            timed_out(f"{what} (texts: {self.texts[-5:]}, grasp {self.grasp_state})")

    def text_count(self, contains: str) -> int:
        with self._lock:
            return sum(contains in t for t in self.texts)

    def close(self) -> None:
        self._stop.set()
        for t in self._threads:
            t.join(timeout=5.0)
        self.conn.close()


def start_host(port: int, lever: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [
            sys.executable,
            "-m",
            "host.cli",
            "--headless",
            "--virtual-rc",
            lever,
            "--mavlink",
            f"udpout:127.0.0.1:{port}",
            "--follow-servo",
            f"{OUTPUT_N},grab={GRAB_PWM},release={RELEASE_PWM},stale_ms={STALE_MS}",
            "--duration",
            "150",
        ],
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        text=True,
    )


@pytest.fixture
def run_host() -> Iterator[Callable[[str], Autopilot]]:
    procs: list[subprocess.Popen[str]] = []
    pilots: list[Autopilot] = []

    def run(lever: str) -> Autopilot:
        port = free_udp_port()
        pilot = Autopilot(port)  # its udpin socket exists before the host sends
        pilots.append(pilot)
        procs.append(start_host(port, lever))
        return pilot

    yield run
    for pilot in pilots:
        pilot.close()
    for proc in procs:
        stop_host(proc)


def ready(pilot: Autopilot, mode: bm.Mode) -> None:
    """The arm is up (armed, phase OK, in ``mode``) and the follower has its baseline reading."""

    def up() -> bool:
        for m in reversed(pilot.seen[-50:]):
            if m.get_type() == "HEARTBEAT":
                return bool(
                    m.custom_mode & 0xFF == mode
                    and m.custom_mode >> 8 & 0xFF == bm.Phase.OK
                    and m.base_mode & 128
                )
        return False

    pilot.wait(up, f"the arm armed in {mode.name}", START_S)
    time.sleep(0.5)  # a few SERVO_OUTPUT_RAW at RELEASE: the follower's baseline


def test_the_autopilot_servo_output_grabs_holds_and_releases_and_stale_is_safe(
    run_host: Callable[[str], Autopilot],
) -> None:
    pilot = run_host("grasp")
    ready(pilot, bm.Mode.GRASP)
    assert pilot.grasp_state == bm.GraspState.IDLE
    assert pilot.text_count("started") == 0  # the baseline at RELEASE sent nothing

    pilot.pwm_us = GRAB_PWM
    pilot.wait(lambda: pilot.text_count("grab started (autopilot servo)") == 1, "the grab to start")
    pilot.wait(lambda: pilot.grasp_state not in (None, bm.GraspState.IDLE), "the board's grasp to run")
    # No object hangs in reach of the default virtual board: the strategy ends holding or failed.
    pilot.wait(
        lambda: pilot.grasp_state in (bm.GraspState.HOLD, bm.GraspState.FAILED), "the grasp to end", 60.0
    )

    pilot.pwm_us = BAND_PWM  # the servo rests between the positions: hold, nothing sent
    time.sleep(1.0)
    assert pilot.text_count("started") == 1

    pilot.pwm_us = RELEASE_PWM
    pilot.wait(lambda: pilot.text_count("release started (autopilot servo)") == 1, "the release to start")
    pilot.wait(lambda: pilot.grasp_state == bm.GraspState.IDLE, "the board to release", 60.0)

    # The autopilot's reports stop with the output at GRAB: stale, said once, nothing sent.
    pilot.pwm_us = GRAB_PWM
    pilot.streaming.clear()
    pilot.wait(lambda: pilot.text_count("output 9 not reported, no command") == 1, "the stale notice")
    time.sleep(1.0)
    assert pilot.text_count("started") == 2
    assert pilot.grasp_state == bm.GraspState.IDLE
    # Reports return at GRAB: a baseline, not a grab.
    pilot.streaming.set()
    time.sleep(1.0)
    assert pilot.text_count("started") == 2
    assert pilot.grasp_state == bm.GraspState.IDLE


def test_the_radio_still_wins_over_the_autopilot_servo_output(run_host: Callable[[str], Autopilot]) -> None:
    pilot = run_host("manual")  # right lever MIDDLE
    ready(pilot, bm.Mode.MANUAL)
    pilot.pwm_us = GRAB_PWM
    pilot.wait(lambda: pilot.text_count("lever not UP") == 1, "the radio's refusal")
    time.sleep(1.0)
    assert pilot.text_count("started") == 0
    assert pilot.grasp_state == bm.GraspState.IDLE
