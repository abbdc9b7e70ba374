"""The board's end of the link: per-id lengths (no header stalls it) and the per-tick budget."""

from __future__ import annotations

import struct

import pytest

from controller.commands import PARAM_VALUES_PER_TICK
from controller.hostlink import RX_BYTES_PER_TICK, RX_FRAMES_PER_TICK, RX_PRIORITY_PER_TICK, BoardLink
from controller.transport import MemoryTransport
from protocol.link import SOF, crc8
from protocol.messages import (
    HOST_TO_BOARD_LENGTHS,
    Event,
    EventKind,
    Heartbeat,
    ParamRequest,
    ParamValue,
    Phase,
    VirtualRc,
    encode,
)
from tests.support.controller_harness import Rig, frame, link_rc_rig

RC_PERIOD_MS = 14


def long_header(n: int = 500, seq: int = 1) -> bytes:
    """``A5 <n> <seq> <crc8>``: a valid header announcing ``n`` bytes (the issue's ``A5 F4 01 ..``)."""
    head = bytes([SOF]) + struct.pack("<HB", n, seq)
    return head + bytes([crc8(head)])


def test_the_issue_header_bytes() -> None:
    assert long_header()[:3] == bytes.fromhex("a5f401")


def test_board_link_refuses_a_long_header_and_keeps_the_next_frame() -> None:
    host, board = MemoryTransport.pair()
    link = BoardLink(board)
    host.write(long_header() + encode(Heartbeat(1, 1), 2))
    assert [r.msg for r in link.receive()] == [Heartbeat(1, 1)]
    assert link.stream.id_errors == 1 and link.stream.pending == 0


def test_board_link_refuses_board_to_host_ids() -> None:
    host, board = MemoryTransport.pair()
    link = BoardLink(board)
    host.write(encode(Event(0, EventKind.INFO, 0, 0.0, "x"), 0) + encode(Heartbeat(1, 1), 1))
    assert [r.msg for r in link.receive()] == [Heartbeat(1, 1)]
    assert link.stream.id_errors == 1 and link.decode_errors == 0


def test_lengths_table_is_every_host_to_board_message() -> None:
    assert max(HOST_TO_BOARD_LENGTHS.values()) + 9 == 29  # the longest a header can hold the board


def test_receive_budget_drops_and_counts() -> None:
    host, board = MemoryTransport.pair()
    link = BoardLink(board)
    flood = encode(ParamRequest(), 0) * 200  # 27 bytes each
    host.write(flood)
    got = link.receive()
    assert len(got) == RX_FRAMES_PER_TICK
    assert link.rx_bytes_dropped == len(flood) - RX_BYTES_PER_TICK
    assert link.rx_frames_dropped == RX_BYTES_PER_TICK // len(encode(ParamRequest(), 0)) - RX_FRAMES_PER_TICK
    assert link.rx_over_budget == 1
    with pytest.raises(ValueError):
        BoardLink(board, rx_frames_per_tick=0)


def _host_tick(rig: Rig, ms: int) -> None:
    """One lockstep tick of a host: virtual RC every 14 ms (levers DOWN), a heartbeat every 100 ms."""
    if ms % RC_PERIOD_MS == 0:
        rig.send(VirtualRc.from_frame(frame()))
    if ms % 100 == 0:
        rig.send(Heartbeat(ms * 1000, ms // 100))
    rig.tick()


def _phases(rig: Rig) -> list[int]:
    return [m.code for m in rig.received if isinstance(m, Event) and m.kind == EventKind.PHASE]


def _ok_rig() -> tuple[Rig, int]:
    """A lockstep board past its start-up gate (phase OK) under a scripted host; the host's next ms."""
    rig = link_rc_rig()
    assert rig.host is not None
    ms = 0
    while rig.fw.phase != Phase.OK:
        _host_tick(rig, ms)
        ms += 1
        assert ms < 200
    rig.drain()
    return rig, ms


def test_long_header_does_not_stall_a_lockstep_board() -> None:
    rig, ms = _ok_rig()
    # the header right after a VirtualRc: the next RC frame must still be taken on its own tick
    while ms % RC_PERIOD_MS != 1:
        _host_tick(rig, ms)
        ms += 1
    rig.host.write(long_header())
    ok_before = rig.fw.rc_frames_ok
    for _ in range(RC_PERIOD_MS):
        _host_tick(rig, ms)
        ms += 1
    assert rig.fw.rc_frames_ok == ok_before + 1  # the next frame, on time
    for _ in range(300):
        _host_tick(rig, ms)
        ms += 1
    rig.drain()
    assert Phase.RC_LOST not in _phases(rig)
    assert rig.fw.phase == Phase.OK
    assert rig.fw.counters["link_id_errors"] == 1


def test_param_request_flood_spends_only_the_budget() -> None:
    rig = link_rc_rig()
    assert rig.host is not None
    ms = 0
    while rig.fw.phase != Phase.OK:
        _host_tick(rig, ms)
        ms += 1
    flood = encode(ParamRequest(), 0) * 100  # 2.7 kB per tick: 2.7 MB/s
    ticks = 500
    control = rig.fw.scheduler["control"]
    runs_before = control.runs
    sent_before = rig.fw.link.frames_sent if rig.fw.link else 0
    for _ in range(ticks):
        rig.host.write(flood)
        rig.tick()
        ms += 1
    counters = rig.fw.counters
    assert control.runs - runs_before == ticks  # the control task ran on every tick
    assert control.late == 0
    assert counters["link_rx_bytes_dropped"] == ticks * (len(flood) - RX_BYTES_PER_TICK)
    assert counters["link_rx_frames_dropped"] > 0
    # answers are bounded per tick too: the restarted list streams PARAM_VALUES_PER_TICK values
    values = [m for m in rig.drain() if isinstance(m, ParamValue)]
    assert 0 < len(values) <= ticks * PARAM_VALUES_PER_TICK
    assert rig.fw.link is not None
    assert rig.fw.link.frames_sent - sent_before <= ticks * PARAM_VALUES_PER_TICK + ticks // 10 * 8


def test_radio_and_heartbeat_pass_the_frame_budget_but_only_two_per_tick() -> None:
    host, board = MemoryTransport.pair()
    link = BoardLink(board)
    rc = encode(VirtualRc.from_frame(frame()), 0)
    # ten ParamRequests (over the 8-frame budget), then the radio, a heartbeat and two more radio frames
    burst = encode(ParamRequest(), 0) * 10 + rc + encode(Heartbeat(0, 0), 0) + rc * 2
    assert len(burst) <= RX_BYTES_PER_TICK
    host.write(burst)
    got = [r.msg for r in link.receive()]
    assert sum(isinstance(m, ParamRequest) for m in got) == RX_FRAMES_PER_TICK
    assert [type(m) for m in got[RX_FRAMES_PER_TICK:]] == [VirtualRc, Heartbeat][:RX_PRIORITY_PER_TICK]
    assert link.rx_frames_dropped == 2 + (4 - RX_PRIORITY_PER_TICK)


def test_a_flood_of_other_frames_does_not_latch_rc_loss() -> None:
    """Safety: a host flooding ParamRequests (within the byte budget) keeps its radio: no RC_LOST."""
    rig, ms = _ok_rig()
    flood = encode(ParamRequest(), 0) * 12  # 12 frames before every tick's own: over the frame budget
    for _ in range(1000):
        rig.host.write(flood)
        _host_tick(rig, ms)
        ms += 1
    rig.drain()
    assert rig.fw.counters["link_rx_frames_dropped"] > 0  # the budget did act
    assert Phase.RC_LOST not in _phases(rig) and Phase.HOST_LOST not in _phases(rig)
    assert rig.fw.phase == Phase.OK
