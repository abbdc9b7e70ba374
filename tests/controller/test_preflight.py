"""``spirob-firmware --preflight``: the judgements on made-up figures, the whole run on an injected clock
(deterministic, lateness included), and the command line against real I/O: the fake C610 trio on a
python-can virtual bus, a DR16 stand-in on a real pty, the host's heartbeats on another pty.

No test asserts a wall-clock time: on real I/O only failures that timing cannot cause are asserted
(a silent motor, an absent radio, invalid frames, a silent host); the lateness verdict there is checked
for its form only, and the good rig's run is a real-time test that the machine can starve.
"""

from __future__ import annotations

import contextlib
import os
import re
import subprocess
import sys
import threading
import time
import tty
from collections.abc import Callable, Iterator

import can
import pytest

from controller.cli import main
from controller.clock import LockstepClock
from controller.config import FirmwareConfig
from controller.fake_c610 import FakeC610Set
from controller.motorbus import FakeMotorBus
from controller.preflight import run_preflight
from controller.preflight_checks import (
    LATENESS_P99_MAX_US,
    Check,
    LatenessStats,
    LinkStats,
    MotorStats,
    PreflightReport,
    RcStats,
    Status,
    judge_clock,
    judge_lateness,
    judge_link,
    judge_motor,
    judge_rc,
)
from controller.rc import LinkRcSource, ScriptedRcSource
from controller.transport import Transport
from protocol.c610 import MotorFeedback
from protocol.dbus import Lever, RcFrame
from protocol.messages import ClockKind, Heartbeat, VirtualRc, encode
from tests.support import bare_loop
from tests.support.c610_rigs import C610SetServer, SlcanAdapterProcess
from tests.support.realtime_guard import skip_if_others_were_busy

LINE = re.compile(r"^(PASS|FAIL|SKIP) [a-z0-9 ()x]+: .+$")
S = 1_000_000
_NEUTRAL = RcFrame.neutral()


# --- an injected clock and scripted peers --------------------------------------------------------------


class FakeRealtimeClock(LockstepClock):
    """A lockstep clock that says it is a real-time one, and wakes late where told to.

    Args:
        late_us: lateness added to the wake-up of the n-th sleep (0-based), by n.
        every_late_us: lateness added to every wake-up.
    """

    def __init__(self, late_us: dict[int, int] | None = None, every_late_us: int = 0) -> None:
        super().__init__(1_000)
        self.late_us = late_us or {}
        self.every_late_us = every_late_us
        self.sleeps = 0

    @property
    def kind(self) -> ClockKind:
        return ClockKind.REALTIME_FIFO

    def sleep_until_us(self, deadline_us: int) -> None:
        extra = self.late_us.get(self.sleeps, 0) + self.every_late_us
        self.sleeps += 1
        super().sleep_until_us(deadline_us + extra)


class ScriptedHost(Transport):
    """The host's end as the board reads it: a heartbeat every 100 ms (and VirtualRc every 14 ms) of
    ``clock``'s time, from ``start_us`` on."""

    def __init__(
        self, clock: LockstepClock, *, rc: RcFrame | None = None, silent_after_us: int | None = None
    ):
        super().__init__()
        self.clock = clock
        self.rc = rc
        self.silent_after_us = silent_after_us
        self._next_hb = clock.now_us()
        self._next_rc = clock.now_us()
        self._seq = 0
        self.written = bytearray()

    def _frame(self, msg: Heartbeat | VirtualRc) -> bytes:
        self._seq = (self._seq + 1) & 0xFF
        return encode(msg, self._seq)

    def _read(self) -> bytes:
        now = self.clock.now_us()
        if self.silent_after_us is not None and now >= self.silent_after_us:
            return b""
        out = b""
        if now >= self._next_hb:
            out += self._frame(Heartbeat(now, self._seq))
            self._next_hb += 100_000
        if self.rc is not None and now >= self._next_rc:
            out += self._frame(VirtualRc.from_frame(self.rc))
            self._next_rc += 14_000
        return out

    def _write(self, data: bytearray) -> int:
        self.written += data
        return len(data)


class ZeroWatchTrio(FakeC610Set):
    """The fake trio, remembering the largest |current| ever commanded to it."""

    def __init__(self) -> None:
        super().__init__()
        self.max_abs_raw = 0

    def handle_frame(self, can_id: int, data: bytes) -> None:
        super().handle_frame(can_id, data)
        self.max_abs_raw = max([self.max_abs_raw] + [abs(m.current_raw) for m in self.motors])


def _by_name(report: PreflightReport) -> dict[str, Check]:
    return {c.name: c for c in report.checks}


def _lockstep_run(
    clock: FakeRealtimeClock | None = None,
    *,
    trio: FakeC610Set | None = None,
    radio: RcFrame | None = _NEUTRAL,
    host: bool = True,
) -> tuple[PreflightReport, FakeMotorBus]:
    clock = clock or FakeRealtimeClock()
    bus = FakeMotorBus(trio or FakeC610Set())
    rc = ScriptedRcSource(radio)
    link = ScriptedHost(clock) if host else None
    report = run_preflight(
        clock, bus, rc, link, rc_name="pty-rc", link_name="pty-link", exec_timer_ns=lambda: 0
    )
    return report, bus


# --- the whole run on an injected clock --------------------------------------------------------------------


def test_an_eight_motor_board_judges_each_of_its_motors() -> None:
    clock = FakeRealtimeClock()
    c610s = FakeC610Set.of(8)
    c610s.silent.add(6)
    config = FirmwareConfig().with_arms(8, 1)
    report = run_preflight(
        clock,
        FakeMotorBus(c610s),
        ScriptedRcSource(_NEUTRAL),
        ScriptedHost(clock),
        config=config,
        rc_name="pty-rc",
        link_name="pty-link",
        exec_timer_ns=lambda: 0,
    )
    motors = [c for c in report.checks if c.name.startswith("motor ")]
    assert [c.name for c in motors] == [f"motor {n} (0x{0x200 + n:03X})" for n in range(1, 9)]
    assert [c.status for c in motors] == [Status.PASS] * 5 + [Status.FAIL] + [Status.PASS] * 2
    with pytest.raises(ValueError, match="the bus has 3 motors, the configuration 8"):
        run_preflight(clock, FakeMotorBus(), None, None, config=config)


def test_a_good_rig_passes_every_check_with_zero_current_throughout() -> None:
    trio = ZeroWatchTrio()
    for m in trio.motors:
        m.current_raw = 0
    report, bus = _lockstep_run(trio=trio)
    lines = report.lines()
    assert report.passed, lines
    assert [c.name for c in report.checks] == [
        "clock",
        "lateness",
        "can",
        "motor 1 (0x201)",
        "motor 2 (0x202)",
        "motor 3 (0x203)",
        "rc",
        "link",
    ]
    assert all(LINE.match(line) for line in lines[:-1]), lines
    assert lines[-1] == "preflight: 8 passed, 0 failed: ready"
    checks = _by_name(report)
    assert checks["lateness"].detail == "2000 of 2000 ticks, 0 late, p99 0 us, max 0 us"
    assert "one every 14.0 ms (median)" in checks["rc"].detail and "right lever DOWN" in checks["rc"].detail
    assert checks["link"].detail.startswith("20 heartbeats on pty-link")
    # Zero current on every one of the 2000 ticks (and once more on the way out); the limit is restored.
    assert trio.commands == 2001 and trio.max_abs_raw == 0
    assert bus.current_limit_raw == 10_000


def test_nothing_above_zero_leaves_the_bus_even_from_a_stale_command() -> None:
    """The run's limit of 0 clamps whatever the bus is asked to send; the fake motors never see current."""
    trio = ZeroWatchTrio()
    bus = FakeMotorBus(trio)
    bus.current_limit_raw = 3000
    clock = FakeRealtimeClock()
    original = bus.send_currents
    bus.send_currents = lambda currents: original((2500, -2500, 2500))  # type: ignore[method-assign]
    run_preflight(clock, bus, ScriptedRcSource(RcFrame.neutral()), None, exec_timer_ns=lambda: 0)
    assert trio.max_abs_raw == 0 and bus.current_limit_raw == 3000


def test_a_late_wake_up_fails_the_lateness_test_and_only_it() -> None:
    report, _ = _lockstep_run(FakeRealtimeClock(late_us={700: 3_500}))
    checks = _by_name(report)
    assert not report.passed
    assert checks["lateness"].failed
    assert checks["lateness"].detail.startswith("1997 of 2000 ticks, 1 late, ")
    assert "max 3500 us: 3 deadlines missed" in checks["lateness"].detail
    # The loop had gone to sleep in time: the wake-up was late, which the line says is not the program.
    assert "woken up to 3500 us late: the OS or the hypervisor, not this program" in checks["lateness"].detail
    assert "SCHED_FIFO thread on time" in checks["lateness"].fix
    assert [c.name for c in report.checks if c.failed] == ["lateness"]
    assert report.lines()[-1] == "preflight: 7 passed, 1 failed: NOT ready: do not arm"


class SlowBus(FakeMotorBus):
    """A motor bus whose n-th read takes ``stall_us`` of the clock's time (the loop's own work)."""

    def __init__(self, clock: LockstepClock, at: int, stall_us: int) -> None:
        super().__init__(FakeC610Set())
        self.clock, self.at, self.stall_us, self.reads = clock, at, stall_us, 0

    def read_feedback(self) -> list[tuple[int, MotorFeedback]]:
        self.reads += 1
        if self.reads == self.at:
            self.clock.advance(self.stall_us)
        return super().read_feedback()


def test_a_tick_whose_own_work_overruns_is_not_blamed_on_the_machine() -> None:
    clock = FakeRealtimeClock()
    bus = SlowBus(clock, 700, 3_500)
    report = run_preflight(
        clock,
        bus,
        ScriptedRcSource(_NEUTRAL),
        ScriptedHost(clock),
        rc_name="r",
        link_name="l",
        exec_timer_ns=lambda: 0,
    )
    lateness = _by_name(report)["lateness"]
    assert lateness.failed and "deadlines missed; own work per tick at most 3500 us" in lateness.detail
    assert "not this program" not in lateness.detail and "SCHED_FIFO thread on time" not in lateness.fix


def test_a_steady_small_lateness_passes_and_a_large_p99_fails() -> None:
    ok, _ = _lockstep_run(FakeRealtimeClock(every_late_us=50))
    assert ok.passed, ok.lines()
    assert "p99 50 us, max 50 us" in _by_name(ok)["lateness"].detail
    bad, _ = _lockstep_run(FakeRealtimeClock(late_us={n: 400 for n in range(0, 2000, 50)}))
    lateness = _by_name(bad)["lateness"]
    assert lateness.failed and f"p99 above {LATENESS_P99_MAX_US} us" in lateness.detail


def test_a_silent_motor_the_radio_and_the_host_fail_with_their_fixes() -> None:
    trio = FakeC610Set()
    trio.silent.add(2)
    report, _ = _lockstep_run(trio=trio, radio=None, host=False)
    checks = _by_name(report)
    assert checks["motor 2 (0x202)"].line() == (
        "FAIL motor 2 (0x202): no feedback in 2.0 s -> fix: set the C610's ID to 2 (its SET button, as the "
        "C610 manual says), power it, check its CAN cable in the chain"
    )
    assert checks["motor 1 (0x201)"].status is Status.PASS and checks["motor 3 (0x203)"].status is Status.PASS
    assert (
        checks["rc"].line().startswith("FAIL rc: no RC frames from pty-rc in 2.0 s -> fix: switch the DT7 on")
    )
    assert checks["link"].status is Status.SKIP


def test_the_host_going_silent_fails_the_link() -> None:
    clock = FakeRealtimeClock()
    bus = FakeMotorBus()
    link = ScriptedHost(clock, silent_after_us=800_000)
    report = run_preflight(
        clock, bus, ScriptedRcSource(RcFrame.neutral()), link, link_name="L", exec_timer_ns=lambda: 0
    )
    line = _by_name(report)["link"].line()
    assert line.startswith("FAIL link: 8 heartbeats on L, longest gap 1300.0 ms")
    assert "latches HOST_LOST after 500.0 ms" in line


def test_rc_from_the_host_link_is_judged_like_the_radio() -> None:
    clock = FakeRealtimeClock()
    host = ScriptedHost(clock, rc=RcFrame.neutral(right_lever=Lever.MIDDLE))
    report = run_preflight(
        clock, FakeMotorBus(), LinkRcSource(), host, rc_name="the host", exec_timer_ns=lambda: 0
    )
    assert report.passed, report.lines()
    assert "valid frames on the host, one every 14.0 ms" in _by_name(report)["rc"].detail
    assert "right lever MIDDLE" in _by_name(report)["rc"].detail


def test_ports_that_did_not_open_are_failed_checks() -> None:
    report = run_preflight(
        FakeRealtimeClock(),
        None,
        None,
        None,
        can_error="cannot open CAN socketcan channel can0: no such device",
        rc_error="cannot open RC port /dev/ttyAMA0: no such file",
        exec_timer_ns=lambda: 0,
    )
    checks = _by_name(report)
    assert checks["can"].failed and "can0" in checks["can"].detail
    assert [checks[f"motor {n} (0x20{n})"].status for n in (1, 2, 3)] == [Status.SKIP] * 3
    assert checks["rc"].failed and "dialout" in checks["rc"].fix
    assert not report.passed


# --- the judgements on made-up figures ---------------------------------------------------------------------


def test_clock_judgement() -> None:
    ok = judge_clock(ClockKind.REALTIME_FIFO, fifo_wanted=True, absolute_sleeps=True, backwards=0)
    assert ok.status is Status.PASS
    no_fifo = judge_clock(ClockKind.REALTIME_NORMAL, fifo_wanted=True, absolute_sleeps=True, backwards=0)
    assert no_fifo.failed and "CAP_SYS_NICE" in no_fifo.fix and "rtprio" in no_fifo.fix
    declined = judge_clock(ClockKind.REALTIME_NORMAL, fifo_wanted=False, absolute_sleeps=True, backwards=0)
    assert declined.status is Status.PASS and "--no-fifo" in declined.detail
    assert judge_clock(ClockKind.LOCKSTEP, fifo_wanted=True, absolute_sleeps=True, backwards=0).failed
    assert judge_clock(ClockKind.REALTIME_FIFO, fifo_wanted=True, absolute_sleeps=False, backwards=0).failed
    assert judge_clock(ClockKind.REALTIME_FIFO, fifo_wanted=True, absolute_sleeps=True, backwards=2).failed


def test_lateness_judgement() -> None:
    assert judge_lateness(LatenessStats(2000, 2000, 0, 0, 30, 300)).status is Status.PASS
    assert judge_lateness(LatenessStats(2000, 2000, 1, 5, 30, 6000)).failed
    assert judge_lateness(LatenessStats(2000, 2000, 0, 0, 201, 900)).failed
    behind = judge_lateness(LatenessStats(1500, 2000, 0, 0, 10, 10))
    assert behind.failed and "fell behind" in behind.detail


def _motor(frames: int = 2000, *, current: int = 0, temperature: int = 30, turn: int = 0) -> MotorStats:
    stats = MotorStats()
    for k in range(frames):
        stats.take((k * turn) % 8192, current, temperature)
    return stats


def test_motor_judgement() -> None:
    kw = {"ticks": 2000, "window_us": 2 * S}
    assert judge_motor(1, _motor(), **kw).status is Status.PASS
    assert judge_motor(1, _motor(temperature=0), **kw).status is Status.PASS  # a C610 may report 0
    hot = judge_motor(1, _motor(temperature=95), **kw)
    assert hot.failed and "too hot" in hot.detail
    driven = judge_motor(3, _motor(current=1200), **kw)
    assert driven.failed and "another controller" in driven.fix and "|current| <= 1.20 A" in driven.detail
    turning = judge_motor(2, _motor(turn=100), **kw)  # 100 counts a tick: 24 rotor turns in 2 s
    assert turning.failed and "moves or draws current" in turning.detail
    sparse = judge_motor(1, _motor(frames=600), **kw)
    assert sparse.failed and "fewer than half" in sparse.detail
    assert judge_motor(1, None, **kw).status is Status.SKIP


def _rc(times_us: list[int], *, invalid: int = 0, dropped: int = 0) -> RcStats:
    return RcStats(valid_us=times_us, invalid=invalid, bytes_dropped=dropped, last=RcFrame.neutral())


def test_rc_judgement() -> None:
    kw = {"source": "U", "from_link": False, "start_us": 0, "end_us": 2 * S, "rc_timeout_us": 30_000}
    steady = list(range(5_000, 2 * S, 14_000))
    assert judge_rc(_rc(steady), **kw).status is Status.PASS
    assert judge_rc(_rc(list(range(3_000, 2 * S, 7_000))), **kw).status is Status.PASS
    assert judge_rc(_rc(steady, dropped=18), **kw).status is Status.PASS  # one partial frame at opening
    invalid = judge_rc(_rc(steady, invalid=3), **kw)
    assert invalid.failed and "3 invalid" in invalid.detail and "rebind" in invalid.fix
    garbage = judge_rc(_rc([], dropped=400), **kw)
    assert garbage.failed and "100000 baud 8E1" in garbage.fix and "mini UART" in garbage.fix
    bursts = judge_rc(_rc(steady, dropped=36), **kw)
    assert bursts.failed and "not 18 bytes" in bursts.detail
    slow = judge_rc(_rc(list(range(0, 2 * S, 20_000))), **kw)
    assert slow.failed and "every 14 ms" in slow.detail
    gap = [t for t in steady if not 600_000 < t < 650_000]
    gappy = judge_rc(_rc(gap), **kw)
    assert gappy.failed and "RC_LOST" in gappy.detail and "latency timer" in gappy.fix
    stalled = judge_rc(_rc(steady, dropped=36), **kw, loop_stalled=True)
    assert stalled.failed and "the board's own loop stalled" in stalled.fix
    late_start = judge_rc(_rc([t for t in steady if t > 400_000]), **kw)
    assert late_start.failed and "longest gap" in late_start.detail


def test_link_judgement() -> None:
    kw = {"port": "P", "start_us": 0, "end_us": 2 * S, "host_timeout_us": 500_000}
    assert judge_link(LinkStats(list(range(0, 2 * S, 100_000)), 20, 0), **kw).status is Status.PASS
    noise = judge_link(LinkStats([], 0, 300), **kw)
    assert noise.failed and "300 bad bytes" in noise.detail
    silent = judge_link(LinkStats([], 0, 0), **kw)
    assert (
        silent.failed
        and "no bytes from the host on P" in silent.detail
        and "spirob-host --port" in silent.fix
    )
    assert judge_link(None, **kw).status is Status.SKIP


# --- the command line against real I/O: a python-can virtual bus and ptys -----------------------------


class PtyWriter:
    """A peer writing ``frame(k)`` to a pty master every ``period_s`` (a thread; no catch-up bursts)."""

    def __init__(self, period_s: float, frame: Callable[[int], bytes] | None) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.path = os.ttyname(self.slave)
        self.period_s = period_s
        self.frame = frame
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="pty-writer", daemon=True)

    def _run(self) -> None:
        k = 0
        while self.frame is not None and not self._stop.wait(self.period_s) and k < 10_000:
            try:
                os.write(self.master, self.frame(k))
            except OSError:  # the reader closed its end: nothing more to write
                return
            k += 1

    def __enter__(self) -> PtyWriter:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)
        for fd in (self.master, self.slave):
            with contextlib.suppress(OSError):
                os.close(fd)


def _dbus(frame: RcFrame) -> Callable[[int], bytes]:
    data = frame.pack()
    return lambda _k: data


def _heartbeats(k: int) -> bytes:
    return encode(Heartbeat(k * 100_000, k), k & 0xFF)


@pytest.fixture
def trio_bus(request: pytest.FixtureRequest) -> Iterator[tuple[str, FakeC610Set]]:
    """The fake C610 trio answering on a python-can virtual bus; yields (channel, trio)."""
    channel = f"preflight-{os.getpid()}-{request.node.name}"
    trio = FakeC610Set()
    with C610SetServer(can.Bus(interface="virtual", channel=channel), trio):
        yield channel, trio


def _fifo_permitted() -> bool:
    """SCHED_FIFO may be had here (tried on a short-lived thread, which dies with it)."""
    got: list[bool] = []

    def attempt() -> None:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
        except OSError:
            got.append(False)
        else:
            got.append(True)

    probe = threading.Thread(target=attempt)
    probe.start()
    probe.join(timeout=5.0)
    return got == [True]


def _preflight(
    capsys: pytest.CaptureFixture[str], channel: str, *extra: str, fifo: bool = False
) -> tuple[int, dict[str, str]]:
    flags = [] if fifo else ["--no-fifo"]
    code = main(["--preflight", "--can-interface", "virtual", "--can-channel", channel, *flags, *extra])
    return code, _parse(capsys.readouterr().out.splitlines())


def _parse(out: list[str]) -> dict[str, str]:
    """The report's lines by check name, each checked for its form."""
    assert out and out[-1].startswith("preflight: "), out
    assert all(LINE.match(line) for line in out[:-1]), out
    lines = {line.split(":", 1)[0].split(" ", 1)[1]: line for line in out[:-1]}
    lateness = lines["lateness"]  # load decides its verdict here: only its form is checked
    assert re.match(r"^(PASS|FAIL) lateness: \d+ of \d+ ticks, \d+ late, p99 \d+ us, max \d+ us", lateness)
    return lines


def test_cli_a_missing_motor_fails_with_its_id_and_fix(
    trio_bus: tuple[str, FakeC610Set], capsys: pytest.CaptureFixture[str]
) -> None:
    channel, trio = trio_bus
    trio.silent.add(2)
    with PtyWriter(0.014, _dbus(RcFrame.neutral())) as radio, PtyWriter(0.1, _heartbeats) as host:
        code, lines = _preflight(capsys, channel, "--rc", radio.path, "--link", host.path)
    assert code == 1
    assert lines["motor 2 (0x202)"].startswith(
        "FAIL motor 2 (0x202): no feedback in 2.0 s -> fix: set the C610"
    )
    assert lines["motor 1 (0x201)"].startswith("PASS motor 1 (0x201): ")
    assert lines["motor 3 (0x203)"].startswith("PASS motor 3 (0x203): ")
    assert lines["can"].startswith("PASS can: ")
    assert trio.commands > 0 and all(m.current_raw == 0 for m in trio.motors)


def test_cli_an_absent_radio_and_a_silent_host_fail(
    trio_bus: tuple[str, FakeC610Set], capsys: pytest.CaptureFixture[str]
) -> None:
    channel, _ = trio_bus
    with PtyWriter(0.014, None) as radio, PtyWriter(0.1, None) as host:
        code, lines = _preflight(capsys, channel, "--rc", radio.path, "--link", host.path)
    assert code == 1
    assert lines["rc"].startswith(
        f"FAIL rc: no RC frames from {radio.path} in 2.0 s -> fix: switch the DT7 on"
    )
    assert lines["link"].startswith(f"FAIL link: no bytes from the host on {host.path} in 2.0 s -> fix: ")
    assert all(lines[f"motor {n} (0x20{n})"].startswith("PASS") for n in (1, 2, 3))


def test_cli_invalid_radio_frames_fail(
    trio_bus: tuple[str, FakeC610Set], capsys: pytest.CaptureFixture[str]
) -> None:
    channel, _ = trio_bus
    bad = RcFrame((0, 0, 0, 0), Lever.DOWN, 0)  # left lever 0: what a receiver never sends
    with PtyWriter(0.014, _dbus(bad)) as radio:
        code, lines = _preflight(capsys, channel, "--rc", radio.path)
    assert code == 1
    assert re.match(r"^FAIL rc: 0 valid frames on \S+, \d+ invalid \(a channel beyond", lines["rc"]), lines[
        "rc"
    ]
    assert "-> fix: rebind the DR16" in lines["rc"]
    assert lines["link"] == "SKIP link: no --link: the board runs without a host"


def test_cli_rc_from_the_host_link_without_virtual_rc_fails(
    trio_bus: tuple[str, FakeC610Set], capsys: pytest.CaptureFixture[str]
) -> None:
    channel, _ = trio_bus
    with PtyWriter(0.1, _heartbeats) as host:
        code, lines = _preflight(capsys, channel, "--link", host.path)
    assert code == 1
    assert lines["rc"].startswith(f"FAIL rc: no RC frames from the host (VirtualRc on {host.path})")
    assert lines["link"].startswith("PASS link: ") and f"heartbeats on {host.path}" in lines["link"]


def test_cli_ports_that_do_not_open_are_failed_checks(capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["--preflight", "--can-interface", "fake", "--rc", "/dev/ttyNOSUCHRC", "--no-fifo"])
    out = capsys.readouterr().out.splitlines()
    assert code == 1
    rc = next(line for line in out if line.startswith("FAIL rc: "))
    assert "/dev/ttyNOSUCHRC" in rc and "-> fix: " in rc


def test_cli_refuses_a_duration_with_preflight(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["--preflight", "--can-interface", "fake", "--rc", "x", "--duration", "5"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--duration does not apply to --preflight" in err


_GOOD_RIG_RUNS = 3
"""Runs of the good rig before a machine that keeps missing isolated deadlines is given up on."""


def _good_rig_once() -> tuple[int, dict[str, str], dict[str, object], bool]:
    """One preflight of the good rig, the firmware in a process of its own; (exit, lines, adapter, fifo)."""
    fifo = _fifo_permitted()  # as the product runs where it may: SCHED_FIFO
    with (
        SlcanAdapterProcess() as adapter,
        PtyWriter(0.014, _dbus(RcFrame.neutral())) as radio,
        PtyWriter(0.1, _heartbeats) as host,
    ):
        flags = [] if fifo else ["--no-fifo"]
        argv = ["--preflight", "--can-interface", "slcan", "--can-channel", adapter.path, *flags]
        argv += ["--rc", radio.path, "--link", host.path]
        proc = subprocess.run(
            [sys.executable, "-m", "controller", *argv], capture_output=True, text=True, timeout=60
        )
    assert adapter.summary and adapter.summary["error"] is None, (adapter.summary, proc.stderr)
    return proc.returncode, _parse(proc.stdout.splitlines()), adapter.summary, fifo


@pytest.mark.realtime
def test_cli_a_good_rig_passes() -> None:
    """Everything wired: every check passes and the exit status is 0.

    The firmware runs in its own process, as it is deployed: its 1 kHz loop shares the interpreter with
    nothing. In-process stand-ins hold the interpreter's lock for up to its switch interval (5 ms), which
    made a loop sharing it miss deadlines that the product, alone in its process, does not. The USB-CAN
    adapter (slcan on a pty, the fake trio behind it) runs in a process of its own too: as a thread here
    it answered in bursts of dozens of frames, whose parsing made a tick late. The DR16 and the host's
    heartbeats are threads of this process writing to two more ptys.

    Timing: a check that timing decides failing while others were busy skips the run as starved; on an
    idle machine it fails, with two exceptions, after which the run is repeated and only a machine that
    did one of them on every run skips the test (not as starved):
    - the lateness check alone failed and a bare loop (``tests.support.bare_loop``: the same clock, period
      and judgement, no work), run at once in a process of its own, fails it too: the machine cannot keep
      the bound in that minute (CI's VM once gave the firmware p99 439 us and 5 late ticks, every one
      woken late; this machine's quiet bare loop misses 3-5 deadlines per 2 s on some days);
    - a few isolated late ticks in a loop that kept up with its p99 within bound (``_ISOLATED_MISSES_MAX``).
    Any other failure fails it: a loop that fell behind, a lateness failure that a bare loop on the same
    machine does not share, or any other check."""
    woken_late: list[str] = []
    for _ in range(_GOOD_RIG_RUNS):
        since = time.monotonic()
        code, lines, adapter, fifo = _good_rig_once()
        assert ("SCHED_FIFO in force" in lines["clock"]) == fifo, lines["clock"]
        # Never a matter of load: a motor that never answered, an invalid radio frame, a silent host.
        for name in ("motor 1 (0x201)", "motor 2 (0x202)", "motor 3 (0x203)"):
            assert "no feedback" not in lines[name], lines[name]
        assert "invalid" not in lines["rc"] and "no bytes" not in lines["link"], (lines["rc"], lines["link"])
        assert "S8" in adapter["lines"] and adapter["currents_raw"] == [0, 0, 0]  # zero current only
        assert isinstance(adapter["commands"], int) and adapter["commands"] > 0
        # The rest is timing: the loop's own (lateness), or the stand-ins' (the radio's gaps and bursts,
        # the heartbeats' gaps, the trio's answers); a machine others starved voids the run.
        timing = [
            lines[n]
            for n in ("lateness", "rc", "link", "motor 1 (0x201)", "motor 2 (0x202)", "motor 3 (0x203)")
        ]
        failed = [t for t in timing if t.startswith("FAIL")]
        if failed == [lines["lateness"]] and "fell behind" not in failed[0]:
            # The machine's own timing, in the same minute: a loop that does nothing, run as the firmware is.
            bare = bare_loop.measure_in_process_of_its_own(fifo=fifo)
            if not bare["passed"] or _isolated_misses(failed[0]):
                why = "a bare loop failed too: " if not bare["passed"] else "isolated misses: "
                woken_late.append(why + failed[0].split(" -> ")[0] + " | bare loop: " + str(bare["line"]))
                continue  # the machine's doing, or a few isolated misses in a loop that kept up: run again
        if failed:
            skip_if_others_were_busy(since, "a check that timing decides failed: " + " | ".join(failed))
        assert all(line.startswith("PASS ") for line in lines.values()), "\n".join(lines.values())
        assert code == 0
        return
    pytest.skip(f"not real-time: this machine missed deadlines on every run: {woken_late}")


_ISOLATED_MISSES_MAX = 5
"""Late ticks in a 2 s window that a machine, not the program, is taken to explain when the loop kept up
and its p99 stayed within bound. A bare SCHED_FIFO sleep loop on this project's VM missed 1-2 per 2 s
in 4 of 10 runs, with 1.1-2.2 ms stalls; the guest counts those stalls as the thread's own CPU time, so
neither the wake-up attribution nor CPU time can tell a stall in a tick's work from the work itself."""


def _isolated_misses(lateness: str) -> bool:
    """The lateness line failed on a few isolated late ticks only: kept up, p99 within its bound."""
    m = re.match(r"^FAIL lateness: (\d+) of (\d+) ticks, (\d+) late, p99 (\d+) us", lateness)
    if m is None or "fell behind" in lateness:
        return False
    late, p99 = int(m.group(3)), int(m.group(4))
    return 0 < late <= _ISOLATED_MISSES_MAX and p99 <= LATENESS_P99_MAX_US
