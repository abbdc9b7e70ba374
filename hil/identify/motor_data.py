"""The motors' data of one recording: what the board commanded, and what its motors measured.

Two kinds of recording carry what a fit needs:

- the board's own wires (``spirob-hil run ... --record``, ``spirob-hil board`` recordings): every 0x200
  command the firmware sent and every 0x201-0x203 feedback frame it received, at 1 kHz, on the raw CAN
  channels. The rotor angles are unwrapped here (at 1 kHz a rotor turns at most a third of a turn between
  two frames, so the unwrapping is unambiguous);
- a host's view (``spirob-host --record``, a real board on a port): the board's ``Telemetry`` at 100 Hz on the
  link channel, with the commanded and measured currents, rotor speeds and the cable lengths the firmware
  unwrapped at 1 kHz itself.

Either way an :class:`MotorData` holds, per sample, the commanded current (the input), and the cable length
paid in, the cable speed and the measured current (the outputs), on the board's clock; plus the excitation
profile and when it started, if the recording says (``spirob-host --excite`` and the ``excitation``
scenario write it in the metadata). A fit simulates a recording from its first sample, where the arm hangs at
rest: friction holds a bent arm where a segment left it (a slack cable cannot be reeled in against the
drive's friction, the capstan friction holds the joints), so no later instant is a state a simulation
could start from.
A recording may also carry a tracked pose of the arm's tip (``foxglove.PoseInFrame`` on a topic ending in
``/tip``, in the drone's frame, as a motion-capture bridge publishes it): it becomes :attr:`MotorData.tip_m`.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray

from hil import recording
from hil.errors import HilError
from hil.identify.excitation import Profile
from hil.mcap_bounded import RecordingError
from hil.sim.spiral import SpiralDesign
from protocol.c610 import ANGLE_COUNTS, COMMAND_ID_LOW, FEEDBACK_ID_BASE, RAW_PER_AMP, MotorFeedback
from protocol.errors import DecodeError
from protocol.messages import Telemetry
from protocol.stream import MessageStream

__all__ = [
    "EXCITATION_KEY",
    "EXCITATION_TOPIC",
    "IdentifyDataError",
    "MotorData",
    "length_quantum_m",
    "load_motor_data",
]

FloatArray = NDArray[np.float64]

EXCITATION_KEY: Final = "excitation"
"""Metadata key of the excitation a recording holds: the profile's description
(:meth:`~hil.identify.excitation.Profile.describe`) and ``start_us``, the board time at which it began."""
EXCITATION_TOPIC: Final = "/excitation"
"""The same as a JSON message, for recordings whose metadata was written before the excitation began
(``spirob-host --excite``): the last message on it wins."""
TIP_SUFFIX: Final = "/tip"
CABLES: Final = 3


class IdentifyDataError(HilError):
    """A recording cannot be used for identification (one line: which file and why)."""


@dataclass(frozen=True)
class MotorData:
    """One recording's input and output, sampled on the board's clock.

    Attributes:
        name: the file's name.
        sha256: the file's SHA-256 (recorded in a fitted model).
        source: ``can`` (the board's 1 kHz wires) or ``telemetry`` (a host's 100 Hz view).
        t_s: sample times, seconds since the first sample.
        current_cmd_a: (n, 3) currents the firmware commanded [A].
        length_m: (n, 3) cable paid in since the first sample [m] (motor encoders).
        speed_m_s: (n, 3) cable speed [m/s] (rotor speed).
        current_a: (n, 3) currents the ESCs measured [A].
        tip_m: (n, 3) tracked tip position in the drone's frame [m], or None.
        stale: (n, 3) True where a moving motor's feedback frame repeats the previous sample's bit for bit:
            a frame that missed its tick (CAN arbitration, an ESC late), so what it holds was measured a
            period earlier (``can`` recordings; all False for ``telemetry``).
        profile: the excitation, or None when the recording does not say.
        profile_start_s: when it began (``t_s`` scale), or None.
        design: the arm's design, from the recording's metadata (None: not recorded).
        spool_radius_m: the firmware's spool radius (its lengths are angles times this).
        length_quantum_m: one encoder count as cable length (a rotor turn's 8192 counts, through the gear,
            on the spool); NaN when unknown.
    """

    name: str
    sha256: str
    source: str
    t_s: FloatArray
    current_cmd_a: FloatArray
    length_m: FloatArray
    speed_m_s: FloatArray
    current_a: FloatArray
    tip_m: FloatArray | None
    stale: NDArray[np.bool_]
    profile: Profile | None
    profile_start_s: float | None
    design: SpiralDesign | None
    spool_radius_m: float
    length_quantum_m: float = math.nan

    @property
    def duration_s(self) -> float:
        """From the first to the last sample."""
        return float(self.t_s[-1] - self.t_s[0]) if len(self.t_s) else 0.0

    @property
    def period_s(self) -> float:
        """The median sample period."""
        return float(np.median(np.diff(self.t_s))) if len(self.t_s) > 1 else math.nan

    def index_at(self, t_s: float) -> int:
        """The first sample at or after ``t_s``."""
        return int(np.searchsorted(self.t_s, t_s - 1e-9))

    def first_judged(self) -> int:
        """The first sample a fit counts: where the excitation starts (the arm hangs at rest on taut cables
        after the profile's first rest), or the first sample when the recording names no excitation."""
        if self.profile is None or self.profile_start_s is None:
            return 0
        first = self.profile.segments[0]
        return min(len(self.t_s) - 1, self.index_at(self.profile_start_s + first.end_s))

    def index_after(self, seconds: float) -> int:
        """One past the last sample within ``seconds`` of the first (at least two samples)."""
        return max(2, min(len(self.t_s), int(np.searchsorted(self.t_s, self.t_s[0] + seconds, side="right"))))


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def load_motor_data(path: str | Path) -> MotorData:
    """Read one recording.

    Raises:
        IdentifyDataError: not a recording, or it holds neither the board's CAN frames nor its telemetry,
            or the bounded reader refuses it (one line naming the file).
    """
    try:
        return _load(Path(path))
    except RecordingError as exc:
        raise IdentifyDataError(f"{path}: {exc}") from exc


def length_quantum_m(spool_radius_m: float, gear_ratio: float) -> float:
    """One encoder count as cable length: a rotor turn's counts, through the gear, on the spool."""
    return 2.0 * math.pi / (ANGLE_COUNTS * gear_ratio) * spool_radius_m


def _load(p: Path) -> MotorData:
    if not p.is_file():
        raise IdentifyDataError(f"{p}: no such file")
    if not recording.is_mcap(p):
        raise IdentifyDataError(f"{p}: not an MCAP recording")
    meta = recording.read_metadata(p)
    firmware = _json(meta.get("firmware"), p, "firmware")
    spool_r = float(firmware.get("spool_radius_m", 0.010)) if firmware else 0.010
    gear = float(firmware.get("gear_ratio", 36.0)) if firmware else 36.0
    quantum = length_quantum_m(spool_r, gear)
    signs = [int(s) for s in firmware.get("motor_signs", [1, 1, 1])] if firmware else [1, 1, 1]
    design_d = _json(meta.get("design"), p, "design")
    design = _design(design_d, p) if design_d else None
    profile, start_us = _excitation(meta, p)
    can, tel, tips, excitation = _read(p)
    if profile is None and excitation is not None:
        profile, start_us = _excitation({EXCITATION_KEY: excitation}, p)
    if can[0]:
        source = "can"
        t_us, cmd, fb_angle, fb_speed, fb_cur = _from_can(can, p)
        # A rotor at rest repeats its frame for real: only a moving one's repeat is a late frame.
        stale = _repeats(fb_angle, fb_speed, fb_cur) & (fb_speed != 0)
        length = _unwrap_counts(fb_angle) * quantum
        speed = fb_speed * (2.0 * math.pi / 60.0 / gear * spool_r)
    elif tel:
        source = "telemetry"
        t_us = np.array([m.time_us for m in tel], dtype=np.int64)
        cmd = np.array([m.commanded_current for m in tel], dtype=float)
        speed = np.array([m.motor_speed_rpm for m in tel], dtype=float) * (
            2.0 * math.pi / 60.0 / gear * spool_r
        )
        fb_cur = np.array([m.motor_current for m in tel], dtype=float)
        length = np.array([m.cable_length_m for m in tel], dtype=float)
        stale = np.zeros((len(t_us), CABLES), dtype=bool)
    else:
        raise IdentifyDataError(f"{p}: holds neither the board's CAN frames nor its telemetry")
    if len(t_us) < 10:
        raise IdentifyDataError(f"{p}: only {len(t_us)} samples")
    sign = np.array(signs[:CABLES], dtype=float)
    length = (length - length[0]) * (sign if source == "can" else 1.0)
    speed = speed * sign
    t0 = int(t_us[0])
    t_s = (t_us - t0) / 1e6
    tip = _tips_on(tips, t_us) if tips else None
    return MotorData(
        name=p.name,
        sha256=_sha256(p),
        source=source,
        t_s=t_s,
        current_cmd_a=cmd / RAW_PER_AMP * sign,
        length_m=length,
        speed_m_s=speed,
        current_a=fb_cur / RAW_PER_AMP * sign,
        tip_m=tip,
        stale=stale,
        profile=profile,
        profile_start_s=None if start_us is None else (start_us - t0) / 1e6,
        design=design,
        spool_radius_m=spool_r,
        length_quantum_m=quantum,
    )


def _json(text: str | None, p: Path, key: str) -> dict[str, Any] | None:
    if not text:
        return None
    try:
        value = json.loads(text)
    except json.JSONDecodeError as exc:
        raise IdentifyDataError(f"{p}: metadata {key!r} is not JSON ({exc.msg})") from exc
    if not isinstance(value, dict):
        raise IdentifyDataError(f"{p}: metadata {key!r} is not an object")
    return value


def _design(d: dict[str, Any], p: Path) -> SpiralDesign:
    try:
        return SpiralDesign.from_params(
            float(d["a_m"]),
            float(d["b"]),
            float(d["theta0_rad"]),
            float(d["dtheta_rad"]),
            int(d.get("cables", 3)),
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise IdentifyDataError(f"{p}: metadata 'design' is not a spiral design ({exc})") from exc


def _excitation(meta: dict[str, str], p: Path) -> tuple[Profile | None, int | None]:
    d = _json(meta.get(EXCITATION_KEY), p, EXCITATION_KEY)
    if d is None:
        return None, None
    try:
        return Profile.from_description(d), int(d["start_us"])
    except (KeyError, TypeError, ValueError) as exc:
        raise IdentifyDataError(f"{p}: metadata {EXCITATION_KEY!r}: {exc}") from exc


_CanLists = tuple[list[tuple[int, int, bytes]], list[tuple[int, int, bytes]]]


def _read(p: Path) -> tuple[_CanLists, list[Telemetry], list[tuple[int, FloatArray]], str | None]:
    tx: list[tuple[int, int, bytes]] = []
    rx: list[tuple[int, int, bytes]] = []
    tel: list[Telemetry] = []
    tips: list[tuple[int, FloatArray]] = []
    stream = MessageStream()
    excitation: str | None = None
    for rec in recording.read_records(p):
        if rec.topic == recording.CAN_TX or rec.topic == recording.CAN_RX:
            can_id, data = recording.unpack_can(rec.data)
            (tx if rec.topic == recording.CAN_TX else rx).append((rec.time_us, can_id, data))
        elif rec.topic == recording.LINK_TX:
            for _, msg in stream.feed(rec.data):
                if isinstance(msg, Telemetry):
                    tel.append(msg)
        elif rec.topic == EXCITATION_TOPIC:
            excitation = rec.data.decode("utf-8", errors="replace")
        elif rec.topic.endswith(TIP_SUFFIX):
            pos = _pose_position(rec.data)
            if pos is not None:
                tips.append((rec.time_us, pos))
    return (tx, rx), tel, tips, excitation


def _pose_position(data: bytes) -> FloatArray | None:
    """The position of a JSON ``foxglove.PoseInFrame`` (as Foxglove bridges publish it), or None."""
    try:
        pos = json.loads(data)["pose"]["position"]
        out = np.array([float(pos["x"]), float(pos["y"]), float(pos["z"])], dtype=np.float64)
    except (ValueError, KeyError, TypeError, UnicodeDecodeError):
        return None  # not a pose sample: skipped
    return out if np.isfinite(out).all() else None


def _from_can(
    can: _CanLists, p: Path
) -> tuple[NDArray[np.int64], FloatArray, FloatArray, FloatArray, FloatArray]:
    tx, rx = can
    cmd_by_t: dict[int, tuple[int, int, int]] = {}
    for t, can_id, data in tx:
        if can_id == COMMAND_ID_LOW and len(data) == 8:
            a = int.from_bytes(data[0:2], "big", signed=True)
            b = int.from_bytes(data[2:4], "big", signed=True)
            c = int.from_bytes(data[4:6], "big", signed=True)
            cmd_by_t[t] = (a, b, c)
    fb_by_t: dict[int, list[MotorFeedback | None]] = {}
    for t, can_id, data in rx:
        k = can_id - FEEDBACK_ID_BASE - 1
        if 0 <= k < CABLES:
            try:
                fb = MotorFeedback.unpack(data)
            except DecodeError:
                continue
            fb_by_t.setdefault(t, [None] * CABLES)[k] = fb
    times = sorted(t for t, fbs in fb_by_t.items() if all(f is not None for f in fbs))
    if not times or not cmd_by_t:
        raise IdentifyDataError(f"{p}: no complete set of motor feedback frames and commands")
    t_us = np.array(times, dtype=np.int64)
    # The command in force at each feedback time: the last one sent at or before it (the firmware sends
    # its command after reading the feedback of the same tick).
    cmd_times = np.array(sorted(cmd_by_t), dtype=np.int64)
    cmd_vals = np.array([cmd_by_t[t] for t in cmd_times], dtype=float)
    idx = np.searchsorted(cmd_times, t_us, side="right") - 1
    cmd = np.asarray(np.where(idx[:, None] >= 0, cmd_vals[np.clip(idx, 0, None)], 0.0), dtype=np.float64)
    frames = [[f for f in fb_by_t[t] if f is not None] for t in times]
    angle = np.array([[f.angle for f in fs] for fs in frames], dtype=np.float64)
    speed = np.array([[f.speed_rpm for f in fs] for fs in frames], dtype=np.float64)
    cur = np.array([[f.current for f in fs] for fs in frames], dtype=np.float64)
    return t_us, cmd, angle, speed, cur


def _repeats(*fields: FloatArray) -> NDArray[np.bool_]:
    """(n, 3): True where every field of a motor's frame equals the previous sample's. A moving rotor's
    angle, speed and measured current never all repeat from one millisecond to the next; a frame that
    missed its tick does, and the firmware read the previous one again."""
    out = np.zeros(fields[0].shape, dtype=bool)
    same = np.ones((len(fields[0]) - 1, fields[0].shape[1]), dtype=bool)
    for f in fields:
        same &= f[1:] == f[:-1]
    out[1:] = same
    return out


def _unwrap_counts(angle: FloatArray) -> FloatArray:
    """Rotor counts unwrapped along time (a jump of more than half a turn is a wrap)."""
    d = np.diff(angle, axis=0)
    d -= ANGLE_COUNTS * np.round(d / ANGLE_COUNTS)
    out = np.empty_like(angle)
    out[0] = 0.0
    np.cumsum(d, axis=0, out=out[1:])
    return out


def _tips_on(tips: list[tuple[int, FloatArray]], t_us: NDArray[np.int64]) -> FloatArray:
    """Tracked tip positions at the sample times (linear interpolation; NaN outside)."""
    tt = np.array([t for t, _ in tips], dtype=float)
    pos = np.stack([v for _, v in tips])
    out = np.full((len(t_us), 3), np.nan)
    for k in range(3):
        out[:, k] = np.interp(t_us.astype(float), tt, pos[:, k], left=np.nan, right=np.nan)
    return out
