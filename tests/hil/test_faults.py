"""Fault specifications and their effect on each wire, in simulated time."""

from __future__ import annotations

import numpy as np
import pytest

from hil.faults import Fault, FaultKind, FaultSet
from protocol.c610 import MotorFeedback
from protocol.dbus import RcFrame

FB = MotorFeedback(angle=100, speed_rpm=5, current=300, temperature=30)


def faults(*items: Fault, seed: int = 0) -> FaultSet:
    return FaultSet(items, np.random.default_rng(seed))


@pytest.mark.parametrize(
    ("spec", "expected"),
    [
        ("rc-silence@1", Fault(FaultKind.RC_SILENCE, 1_000_000)),
        ("motor-silence@2-2.5:motor=2", Fault(FaultKind.MOTOR_SILENCE, 2_000_000, 2_500_000, motor=2)),
        ("link-byte-loss@0-3:rate=0.01", Fault(FaultKind.LINK_BYTE_LOSS, 0, 3_000_000, rate=0.01)),
        ("link-delay@0.5-1:delay=0.02", Fault(FaultKind.LINK_DELAY, 500_000, 1_000_000, delay_us=20_000)),
    ],
)
def test_parse(spec: str, expected: Fault) -> None:
    assert Fault.parse(spec) == expected


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("nonsense", "expected KIND@START"),
        ("rc-typo@1", "unknown kind"),
        ("link-byte-loss@1", "rate must be in"),
        ("rc-silence@2-1", "end must be after start"),
        ("motor-silence@1:motor=7", "motor must be 1..3"),
        ("rc-silence@1:motor=1", "only for motor faults"),
        ("motor-stuck@1:colour=red", "unknown option"),
        ("link-delay@1:delay=abc", "bad value for delay"),
    ],
)
def test_parse_errors_name_the_problem(spec: str, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        Fault.parse(spec)


def test_window_is_half_open() -> None:
    f = Fault(FaultKind.HOST_LOSS, 100, 200)
    assert [f.active(t) for t in (99, 100, 199, 200)] == [False, True, True, False]
    fs = faults(f)
    assert fs.heartbeat_blocked(150) and not fs.heartbeat_blocked(250)


def test_motor_faults_per_motor() -> None:
    fs = faults(
        Fault(FaultKind.MOTOR_SILENCE, 0, 10, motor=2),
        Fault(FaultKind.MOTOR_STUCK, 20, 30, motor=1),
        Fault(FaultKind.MOTOR_WRONG, 40, 50),
    )
    assert fs.feedback(5, 1, FB) == FB
    assert fs.feedback(5, 2, FB) is None
    assert fs.feedback(20, 1, FB) == FB
    moved = MotorFeedback(angle=200, speed_rpm=0, current=0, temperature=30)
    assert fs.feedback(25, 1, moved) == FB  # stuck at the frame seen when the fault began
    assert fs.feedback(35, 1, moved) == moved
    wrong = [fs.feedback(45, m, FB) for m in (1, 2, 3)]
    assert all(w is not None and w != FB for w in wrong)


def test_can_bus_off_silences_everyone() -> None:
    fs = faults(Fault(FaultKind.CAN_BUS_OFF, 0, 10))
    assert fs.bus_off(0) and all(fs.feedback(1, m, FB) is None for m in (1, 2, 3))
    assert not fs.bus_off(10)


def test_rc_override_kinds() -> None:
    frame = RcFrame.neutral()
    moved = RcFrame((100, 0, 0, 0), 3, 2)
    fs = faults(
        Fault(FaultKind.RC_SILENCE, 0, 10),
        Fault(FaultKind.RC_GARBAGE, 10, 20),
        Fault(FaultKind.RC_FROZEN, 20, 30),
        Fault(FaultKind.RC_OUT_OF_RANGE, 30, 40),
    )
    assert fs.rc_override(0, frame) is None
    assert isinstance(fs.rc_override(10, frame), bytes)
    assert fs.rc_override(20, frame) == frame
    assert fs.rc_override(25, moved) == frame
    bad = fs.rc_override(30, frame)
    assert isinstance(bad, RcFrame) and not bad.is_valid()
    assert fs.rc_override(40, moved) == moved


def test_link_loss_and_flips_are_seeded_and_counted() -> None:
    data = bytes(range(256)) * 40

    def run(seed: int) -> tuple[bytes, dict[str, int]]:
        fs = faults(
            Fault(FaultKind.LINK_BYTE_LOSS, 0, rate=0.01),
            Fault(FaultKind.LINK_BIT_FLIP, 0, rate=0.01),
            seed=seed,
        )
        return fs.link_bytes(0, data, "tx"), fs.injected

    out1, n1 = run(1)
    out2, n2 = run(1)
    assert out1 == out2 and n1 == n2
    assert len(out1) == len(data) - n1["link_bytes_lost"]
    assert 40 < n1["link_bytes_lost"] < 200 and 40 < n1["link_bits_flipped"] < 200
    assert run(2)[0] != out1


def test_link_delay_and_disconnect() -> None:
    fs = faults(
        Fault(FaultKind.LINK_DELAY, 0, 1000, delay_us=300), Fault(FaultKind.LINK_DISCONNECT, 2000, 3000)
    )
    assert fs.link_bytes(0, b"abc", "rx") == b""
    assert fs.link_bytes(299, b"", "rx") == b""
    assert fs.link_bytes(300, b"d", "rx") == b"abc"
    assert fs.link_bytes(600, b"", "rx") == b"d"
    assert fs.link_bytes(1500, b"e", "rx") == b"e"  # window over, queue drained: straight through
    assert fs.link_bytes(2500, b"lost", "tx") == b""
    assert fs.injected["link_bytes_disconnected"] == 4
    assert fs.link_bytes(3000, b"back", "tx") == b"back"


def test_loop_delay_and_jitter() -> None:
    fs = faults(
        Fault(FaultKind.LOOP_DELAY, 0, 10, delay_us=500), Fault(FaultKind.LOOP_JITTER, 10, 20, delay_us=300)
    )
    assert fs.tick_delay_us(5) == 500
    assert all(0 <= fs.tick_delay_us(15) <= 300 for _ in range(50))
    assert fs.tick_delay_us(25) == 0
