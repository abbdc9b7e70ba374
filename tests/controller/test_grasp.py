"""Grasp state machine (the paper's Note S4): pack, reach, contact, wrap, hold, release; the "off" variant."""

from __future__ import annotations

import math

import pytest

from controller.config import FirmwareConfig
from controller.errors import ConfigError
from controller.events import EventQueue
from controller.grasp import GraspMachine
from protocol.dbus import Lever
from protocol.messages import AckResult, Command, CommandAck, CommandCode, GraspState, Mode
from tests.support.controller_harness import Rig, frame

MOVING = [-0.05, -0.05, -0.05]  # cable paying out while the arm unrolls
STALLED = [0.0, 0.0, 0.0]
TAUT = [2.0, 2.0, 2.0]


def machine(**cfg: object) -> tuple[GraspMachine, FirmwareConfig]:
    config = FirmwareConfig.from_dict(cfg)
    return GraspMachine(config, EventQueue(64)), config


def run(g: GraspMachine, t: int, ms: int, speed: list[float] = MOVING, tension: list[float] = TAUT) -> int:
    for _ in range(ms):
        g.step(t, 1000, speed, tension)
        t += 1000
    return t


def start_reach(g: GraspMachine, t: int = 0, direction: float | None = 0.0) -> int:
    """Pack (the arm settles: cable still), request a grasp, run until the reach starts."""
    t = run(g, t, 2000, speed=STALLED)
    assert g.request_grasp(t, direction) == AckResult.ACCEPTED
    for _ in range(3000):
        if g.state == GraspState.REACH:
            return t
        t = run(g, t, 1, speed=STALLED)
    raise AssertionError("the reach never started")


def test_idle_packs_then_reach_ramps_down_then_contact_wraps_and_holds() -> None:
    g, c = machine()
    t = run(g, 0, 2000, speed=STALLED)
    assert g.state == GraspState.IDLE and g.curl_n == c.grasp.pack_n
    assert g.direction_rad == 0.0 and g.target_rad == 0.0
    assert g.request_grasp(t, 0.0) == AckResult.ACCEPTED
    t = run(g, t, 1, speed=STALLED)
    assert g.state == GraspState.IDLE  # settling first: the pack-side cable must be still for the dwell
    t = run(g, t, c.grasp.contact_dwell_us // 1000 + 1, speed=STALLED)
    assert g.state == GraspState.REACH
    t0_curl = g.curl_n
    t = run(g, t, 300)  # unrolling: tension falls at the reach rate
    assert g.curl_n == pytest.approx(t0_curl - c.grasp.reach_rate_n_per_s * 0.300, abs=1e-6)
    assert g.state == GraspState.REACH and g.direction_rad == 0.0
    # contact: the pack-side cable stalls while the ramp still runs, for the dwell time
    t = run(g, t, c.grasp.contact_dwell_us // 1000 + 1, speed=STALLED)
    assert g.state == GraspState.WRAP
    # the wrap pulls the cables on the coil's outer face, from 0 N
    assert g.direction_rad == pytest.approx(math.pi) and g.target_rad == 0.0
    assert g.curl_n < 0.1
    t = run(g, t, 3000, speed=STALLED)
    assert g.state == GraspState.HOLD and g.curl_n == c.grasp.wrap_n
    assert g.request_release(t) == AckResult.ACCEPTED
    assert g.state == GraspState.RELEASE
    t = run(g, t, 3000, speed=STALLED)
    assert g.state == GraspState.IDLE and g.direction_rad == 0.0


def test_a_slowdown_of_the_pay_out_is_contact_a_steady_or_faster_one_is_not() -> None:
    # The stall rule alone: these speeds step from tick to tick (an impact to the deceleration rule).
    g, c = machine(grasp_contact_decel_m_per_s2=0.0)
    t = start_reach(g)
    fast = [-0.05, -0.05, -0.05]
    faster = [-0.08, -0.08, -0.08]
    t = run(g, t, 300, speed=fast)
    t = run(g, t, 300, speed=faster)  # speeding up: free space
    assert g.state == GraspState.REACH and g.detector.peak_payout_m_s == pytest.approx(0.08)
    slowed = [-0.08 * (c.grasp.contact_slow_ratio + 0.05)] * 3
    t = run(g, t, 300, speed=slowed)  # just above the ratio: still unrolling freely
    assert g.state == GraspState.REACH
    blocked = [-0.08 * (c.grasp.contact_slow_ratio - 0.1)] * 3  # well above the absolute stall speed
    t = run(g, t, c.grasp.contact_dwell_us // 1000 - 5, speed=blocked)
    assert g.state == GraspState.REACH  # not for the whole dwell yet
    t = run(g, t, 10, speed=blocked)
    assert g.state == GraspState.WRAP


def test_the_pack_side_is_the_target_side() -> None:
    g, c = machine()
    t = start_reach(g, direction=math.radians(120.0))  # cable 2 (at 120°) packs and pays out
    t = run(g, t, 300, speed=[0.0, -0.05, 0.0])
    t = run(g, t, 40, speed=[-0.05, 0.0, -0.05])  # the other cables moving do not count
    assert g.state == GraspState.REACH
    t = run(g, t, c.grasp.contact_dwell_us // 1000 + 1, speed=[-0.05, 0.0, -0.05])
    assert g.state == GraspState.WRAP
    assert g.direction_rad == pytest.approx(math.radians(-60.0))


def test_no_contact_during_the_grace_period_or_when_slack() -> None:
    g, c = machine()
    t = start_reach(g)
    t = run(g, t, c.grasp.contact_grace_us // 1000 - 1, speed=STALLED)  # not moving yet: ignored
    assert g.state == GraspState.REACH
    t = run(g, t, 200, speed=STALLED, tension=[0.0, 0.0, 0.0])  # stalled but slack: no contact
    assert g.state == GraspState.REACH


def test_reach_without_contact_fails_at_timeout() -> None:
    g, c = machine(grasp_reach_timeout_us=2_000_000)
    t = start_reach(g)
    start = t
    while g.state == GraspState.REACH:
        t = run(g, t, 1, speed=MOVING)
        assert t - start <= 2_000_000 + 2000
    assert g.state == GraspState.FAILED
    assert g.curl_n == c.grasp.reach_n
    # a stall after the ramp has ended is not contact (the arm is simply unrolled)
    g2, c2 = machine()
    t = start_reach(g2)
    ramp_ms = math.ceil((c2.grasp.pack_n - c2.grasp.reach_n) / c2.grasp.reach_rate_n_per_s * 1000)
    t = run(g2, t, ramp_ms + 10, speed=MOVING)
    assert g2.curl_n == c2.grasp.reach_n
    t = run(g2, t, 500, speed=STALLED)
    assert g2.state == GraspState.REACH


def test_strategy_off_is_a_plain_ramp_from_straight() -> None:
    g, c = machine(grasp_strategy_on=False)
    t = run(g, 0, 100)
    assert g.curl_n == 0.0  # straight
    g.request_grasp(t)
    t = run(g, t, 1)
    assert g.state == GraspState.WRAP
    t = run(g, t, 3000)  # the cable still moves: the arm is still closing
    assert g.state == GraspState.WRAP and g.curl_n == c.grasp.wrap_n
    t = run(g, t, c.grasp.contact_dwell_us // 1000 + 1, speed=STALLED)  # closed: hold
    assert g.state == GraspState.HOLD and g.curl_n == c.grasp.wrap_n


PAYING_IN = [0.02, 0.02, 0.02]  # the wrap curls the arm: its pulling cables reel in at 20 mm/s


def ramp_then_rest(ms_paying_in: int, **cfg: object) -> tuple[GraspMachine, list[str]]:
    """A ramp grasp whose pulling cables reel in for ``ms_paying_in`` ms, then rest: the events' texts."""
    events = EventQueue(64)
    g = GraspMachine(FirmwareConfig.from_dict({"grasp_strategy_on": False, **cfg}), events)
    t = run(g, 0, 100)
    g.request_grasp(t)
    t = run(g, t, ms_paying_in, speed=PAYING_IN)
    ramp_ms = int(1000 * g._wrap_n / (g._wrap_rate * 1e6)) + 1  # at rest until the wrap tension is reached
    run(g, t, ramp_ms + g._dwell_us // 1000 + 1, speed=STALLED)
    return g, [e.text for e in events.pop_all()]


def test_hold_needs_the_wrap_side_pay_in_that_says_the_wrap_closed() -> None:
    g, texts = ramp_then_rest(1000, grasp_hold_min_payin_m=0.030)  # 20 mm paid in: stalled open
    assert g.wrap_payin_m == pytest.approx(0.020, abs=5e-5)
    assert g.state == GraspState.FAILED and g.curl_n == g._wrap_n  # the tension is kept
    assert texts[-1] == "grasp FAILED: wrap stalled open: 20.0 mm paid in < 30.0"
    g, texts = ramp_then_rest(2000, grasp_hold_min_payin_m=0.030)  # 40 mm: closed
    assert g.state == GraspState.HOLD and "40.0 mm paid in" in texts[-1]


def test_an_empty_curl_is_not_a_hold() -> None:
    g, texts = ramp_then_rest(4000, grasp_hold_max_payin_m=0.060)  # 80 mm: nothing stopped the curl
    assert g.state == GraspState.FAILED
    assert texts[-1] == "grasp FAILED: empty curl: 80.0 mm paid in > 60.0"
    g, _ = ramp_then_rest(2000, grasp_hold_min_payin_m=0.030, grasp_hold_max_payin_m=0.060)
    assert g.state == GraspState.HOLD
    g, _ = ramp_then_rest(4000)  # both rules off (the default): a rest at the wrap tension is HOLD
    assert g.state == GraspState.HOLD


def test_the_pay_in_counts_from_each_wrap_take_up_included() -> None:
    g, c = machine(grasp_hold_min_payin_m=0.001)
    contact_ms = c.grasp.contact_dwell_us // 1000 + 1
    t = start_reach(g)
    t = run(g, run(g, t, 300), contact_ms, speed=STALLED)  # unrolling, then blocked: contact
    assert g.state == GraspState.WRAP and g.wrap_payin_m == 0.0
    t = run(g, t, 100, speed=[0.01, 0.01, 0.01])  # the take-up reels the wrap side in
    assert g.state == GraspState.WRAP and g.wrap_payin_m == pytest.approx(0.001, abs=2e-5)
    g.request_release(t)
    t = start_reach(g, run(g, t, 3000, speed=STALLED))
    run(g, run(g, t, 300), contact_ms, speed=STALLED)
    assert g.state == GraspState.WRAP and g.wrap_payin_m == 0.0  # a new wrap counts from zero


def test_the_pay_in_window_must_be_a_window() -> None:
    with pytest.raises(ConfigError, match="grasp_hold_max_payin_m"):
        FirmwareConfig().replaced(grasp_hold_min_payin_m=0.04, grasp_hold_max_payin_m=0.03)
    FirmwareConfig().replaced(grasp_hold_min_payin_m=0.04)  # the ceiling off


def test_requests_in_wrong_states() -> None:
    g, _ = machine()
    assert g.request_hold(0) == AckResult.REJECTED  # nothing to hold in IDLE
    t = start_reach(g)
    t = run(g, t, 10)
    assert g.request_grasp(t) == AckResult.REJECTED  # busy
    assert g.request_hold(t) == AckResult.ACCEPTED
    assert g.state == GraspState.HOLD
    assert g.request_grasp(t, math.nan) == AckResult.REJECTED


def test_grasp_after_failure_repacks_first() -> None:
    g, _ = machine(grasp_reach_timeout_us=500_000)
    t = start_reach(g)
    t = run(g, t, 700)
    assert g.state == GraspState.FAILED
    assert g.request_grasp(t) == AckResult.ACCEPTED
    assert g.state == GraspState.IDLE and g.pending
    t = run(g, t, 3000, speed=STALLED)
    assert g.state in (GraspState.REACH, GraspState.FAILED)


def test_a_new_target_side_repacks_from_zero() -> None:
    g, c = machine()
    t = run(g, 0, 2000, speed=STALLED)
    assert g.curl_n == c.grasp.pack_n
    g.request_grasp(t, math.pi / 2)
    assert g.curl_n == 0.0 and g.direction_rad == math.pi / 2  # no jump of the full pack to another side


def test_reach_floor_must_release_most_of_the_pack() -> None:
    with pytest.raises(ConfigError, match="grasp_reach_n"):
        FirmwareConfig().replaced(grasp_pack_n=18.0, grasp_reach_n=9.0)
    with pytest.raises(ConfigError, match="grasp_contact_slow_ratio"):
        FirmwareConfig().replaced(grasp_contact_slow_ratio=1.0)


# --- through the firmware -------------------------------------------------------------------------


def test_left_lever_edges_trigger_grasp_and_release_in_grasp_mode() -> None:
    rig = Rig()
    rig.arm()
    rig.set_rc(frame(right=Lever.UP, left=Lever.UP))  # already UP on entry: no edge, no grasp
    rig.until(lambda: rig.fw.mode == Mode.GRASP, 30)
    rig.tick(2000)
    assert rig.fw.grasp_state == GraspState.IDLE
    assert all(c > 0 for c in rig.currents)  # packed: the curl side pulls
    rig.set_rc(frame(right=Lever.UP, left=Lever.DOWN))
    rig.tick(30)
    rig.set_rc(frame(right=Lever.UP, left=Lever.UP))  # the edge
    # the fake trio's overdamped spring still winds in: the reach waits until the cable is still
    rig.until(lambda: rig.fw.grasp_state == GraspState.REACH, 8000)
    rig.set_rc(frame(right=Lever.UP, left=Lever.DOWN))
    rig.until(lambda: rig.fw.grasp_state == GraspState.RELEASE, 100)
    # leaving GRASP mode resets the machine
    rig.set_rc(frame(right=Lever.MIDDLE))
    rig.until(lambda: rig.fw.mode == Mode.MANUAL, 30)
    assert rig.fw.grasp_state == GraspState.IDLE


def test_host_grasp_command_acks_in_progress_then_result() -> None:
    rig = Rig(FirmwareConfig().replaced(grasp_reach_timeout_us=1_000_000), link=True)
    rig.arm()
    seq = rig.send(Command(CommandCode.GRASP, (math.nan, 0.0, 0.0)))
    rig.tick(5)
    acks = [m for m in rig.drain() if isinstance(m, CommandAck)]
    assert acks[-1].result == AckResult.REJECTED  # lever not UP
    rig.set_rc(frame(right=Lever.UP))
    rig.until(lambda: rig.fw.mode == Mode.GRASP, 30)
    seq = rig.send(Command(CommandCode.GRASP, (math.nan, 0.0, 0.0)))
    rig.tick(5)
    acks = [m for m in rig.drain() if isinstance(m, CommandAck)]
    assert (acks[-1].command, acks[-1].result, acks[-1].request_seq) == (
        CommandCode.GRASP,
        AckResult.IN_PROGRESS,
        seq,
    )
    # the fake trio's spring never stalls the cable like an object: the reach times out -> FAILED ack
    rig.until(lambda: rig.fw.grasp_state == GraspState.FAILED, 12000)
    rig.tick(5)
    final = [m for m in rig.drain() if isinstance(m, CommandAck) and m.request_seq == seq]
    assert final[-1].result == AckResult.FAILED
