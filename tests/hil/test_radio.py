"""The virtual radio puts DBUS frames on the UART with real byte timing."""

from __future__ import annotations

import numpy as np
import pytest

from hil.faults import Fault, FaultKind, FaultSet
from hil.radio import RadioScript, VirtualRadio
from protocol.dbus import BYTE_TIME_US, FRAME_LEN, DbusFramer, Lever, RcFrame

ARMED = RcFrame.neutral(Lever.MIDDLE)


def drive(
    radio: VirtualRadio, until_us: int, step_us: int = 1000
) -> tuple[list[RcFrame], DbusFramer, list[int]]:
    framer = DbusFramer()
    frames: list[RcFrame] = []
    sizes: list[int] = []
    for t in range(0, until_us + 1, step_us):
        chunk = radio.read(t)
        if chunk:
            sizes.append(len(chunk))
        frames += framer.feed(chunk, t)
    return frames, framer, sizes


def test_frames_every_14_ms_in_chunks_the_framer_accepts() -> None:
    radio = VirtualRadio(RadioScript([(0, RcFrame.neutral()), (100_000, ARMED)]))
    frames, framer, sizes = drive(radio, 200_000)
    assert len(frames) == 200_000 // 14_000  # the last slot's burst is still open at 200 ms
    assert frames[0] == RcFrame.neutral() and frames[-1] == ARMED
    assert framer.frames_dropped == 0
    # A 1.98 ms frame read every 1 ms arrives in pieces, never all at once.
    assert max(sizes) < FRAME_LEN and sum(sizes) >= len(frames) * FRAME_LEN


def test_read_returns_only_finished_bytes() -> None:
    radio = VirtualRadio(RadioScript([(0, RcFrame.neutral())]))
    assert radio.read(BYTE_TIME_US - 1) == b""
    assert len(radio.read(BYTE_TIME_US * 5)) == 5
    frame = RcFrame.neutral().pack()
    assert radio.read(20_000) == frame[5:] + frame  # the rest of slot 0 and all of slot 14 ms
    assert len(radio.read(28_000 + FRAME_LEN * BYTE_TIME_US)) == FRAME_LEN


def test_nothing_before_the_script_starts_and_live_override() -> None:
    radio = VirtualRadio(RadioScript([(50_000, RcFrame.neutral())]))
    assert radio.read(49_000) == b""
    live = VirtualRadio(RadioScript([(50_000, RcFrame.neutral())]))
    live.set(ARMED)
    frames, _, _ = drive(live, 60_000)
    assert len(frames) == 4 and all(f == ARMED for f in frames)


def test_silence_fault_stops_frames() -> None:
    fs = FaultSet([Fault(FaultKind.RC_SILENCE, 50_000, 100_000)], np.random.default_rng(0))
    radio = VirtualRadio(RadioScript([(0, RcFrame.neutral())]), faults=fs)
    frames, framer, _ = drive(radio, 140_000)
    assert len(frames) == 140_000 // 14_000 - 100_000 // 14_000 + 50_000 // 14_000 + 0
    assert framer.frames_dropped == 0


def test_byte_loss_is_dropped_by_the_framer() -> None:
    fs = FaultSet([Fault(FaultKind.DBUS_BYTE_LOSS, 0, rate=0.2)], np.random.default_rng(3))
    radio = VirtualRadio(RadioScript([(0, RcFrame.neutral())]), faults=fs)
    frames, framer, _ = drive(radio, 1_000_000)
    assert framer.frames_dropped > 0
    assert all(f == RcFrame.neutral() for f in frames)


def test_script_must_be_ordered() -> None:
    with pytest.raises(ValueError):
        RadioScript([(10, ARMED), (5, ARMED)])
