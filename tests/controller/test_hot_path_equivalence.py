"""The control tick's speed-written paths against plain reference versions of the same rules.

The failsafe's switch on its phase, the motor model's all-frames update and the batch current
conversion were rewritten for speed (issue 5). Each is checked here against the straightforward form it
replaced, over random event sequences: same phases, same events, same state.
"""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from controller.cables import MotorModel
from controller.config import MOTOR_COUNT, FirmwareConfig
from controller.events import EventQueue
from controller.failsafe import Failsafe
from protocol.c610 import ANGLE_COUNTS, MotorFeedback
from protocol.dbus import Lever
from protocol.messages import Phase


class ReferenceFailsafe(Failsafe):
    """The failsafe's update rule as one chain of early returns over latch flags (its earlier form)."""

    _motor_fault = False
    _lost: Phase | None = None
    _armed = False

    def estop(self, now_us: int) -> None:
        self._armed = False
        super().estop(now_us)

    def clear_estop(self, now_us: int) -> bool:
        if self.estop_latched:
            self._armed = False
        return super().clear_estop(now_us)

    def disarm(self, now_us: int) -> None:
        self.host_disarmed = True
        self._armed = False
        if self.phase != Phase.ESTOP and not self._motor_fault:
            self._set(now_us, Phase.GATE)

    def update(self, now_us: int) -> Phase:
        rc_ok = self._rc_seen and now_us - self._last_rc_us <= self._rc_timeout_us
        self.rc_ok = rc_ok
        host_ok = self._hb_seen and now_us - self._last_hb_us <= self._host_timeout_us
        self.host_ok = host_ok
        mask = 0
        for i in range(MOTOR_COUNT):
            if self._fb_seen[i] and now_us - self._last_fb_us[i] <= self._motor_timeout_us:
                mask |= 1 << i
        if mask != self.motors_online:
            self._motors_changed(now_us, self.motors_online, mask)
        motors_ok = mask == self._all_motors
        lever_down = rc_ok and self._right_lever == Lever.DOWN
        if self.estop_latched:
            return self._set(now_us, Phase.ESTOP)
        if self._motor_fault:
            if not (motors_ok and lever_down):
                return self._set(now_us, Phase.MOTOR_FAULT)
            self._motor_fault = False
        host_fine = host_ok or not self.host_required
        if self._lost is not None:
            back = rc_ok if self._lost == Phase.RC_LOST else host_fine
            if not (back and lever_down):
                return self._set(now_us, self._lost)
            self._lost = None
        if not self._armed:
            if rc_ok and lever_down and motors_ok and host_fine and not self.host_disarmed:
                self._armed = True
                return self._set(now_us, Phase.OK)
            return self._set(now_us, Phase.GATE)
        if not motors_ok:
            self._motor_fault = True
            self._armed = False
            return self._set(now_us, Phase.MOTOR_FAULT)
        if not rc_ok or not host_fine:
            self._lost = Phase.RC_LOST if not rc_ok else Phase.HOST_LOST
            self._armed = False
            return self._set(now_us, self._lost)
        return self._set(now_us, Phase.OK)


class ReferenceMotorModel(MotorModel):
    """The motor model's feedback rule written for one frame at a time (the readable form)."""

    def update(self, index: int, fb: MotorFeedback, now_us: int) -> None:
        sign = self._signs[index]
        speed = sign * fb.speed_rpm * self._m_s_per_rpm
        if self.seen[index]:
            d = fb.angle - self.angle[index]
            if d >= ANGLE_COUNTS // 2:
                d -= ANGLE_COUNTS
            elif d < -(ANGLE_COUNTS // 2):
                d += ANGLE_COUNTS
            self.counts[index] += d
            dt = now_us - self.last_feedback_us[index]
            if self._tau_us > 0 and dt > 0:
                prev = self.cable_speed_m_s[index]
                speed = prev + (speed - prev) * (dt / (self._tau_us + dt))
        self.seen[index] = True
        self.cable_speed_m_s[index] = speed
        self.angle[index] = fb.angle
        self.speed_rpm[index] = fb.speed_rpm
        self.current[index] = fb.current
        self.temperature[index] = fb.temperature
        self.last_feedback_us[index] = now_us
        self.cable_length_m[index] = sign * self.counts[index] * self._m_per_count
        self.tension_est_n[index] = sign * fb.current * self._n_per_raw


# One tick's inputs: a valid RC frame (its right lever) or none, the motors that answered, a heartbeat or
# not, an operator action, and the time since the previous tick (around each timeout: RC 30 ms, motors
# 10 ms, host 500 ms). Biased toward the healthy case so that runs arm and then lose something.
_LEVERS = st.sampled_from([Lever.DOWN, Lever.DOWN, Lever.MIDDLE, Lever.UP])
_MOTORS = st.one_of(
    st.just([0, 1, 2]), st.just([0, 1, 2]), st.lists(st.integers(0, MOTOR_COUNT - 1), max_size=3)
)
_ACTIONS = st.sampled_from(["nothing"] * 12 + ["estop", "clear", "disarm", "arm"])
_DT = st.sampled_from([1_000, 1_000, 1_000, 9_000, 11_000, 29_000, 31_000, 499_000, 501_000])
_TICK = st.tuples(st.one_of(st.none(), _LEVERS), _MOTORS, st.booleans(), _ACTIONS, _DT)
Tick = tuple[Lever | None, list[int], bool, str, int]


def _drive(fs: Failsafe, events: EventQueue, ticks: list[Tick]) -> list[object]:
    trace: list[object] = []
    now = 0
    for lever, motors, heartbeat, action, dt in ticks:
        now += dt
        if lever is not None:
            fs.on_rc_frame(now, lever)
        fs.on_motor_frames(now, [(i + 1, None) for i in motors])
        if heartbeat:
            fs.on_heartbeat(now)
        if action == "estop":
            fs.estop(now)
        elif action == "clear":
            fs.clear_estop(now)
        elif action == "disarm":
            fs.disarm(now)
        elif action == "arm":
            fs.arm()
        phase = fs.update(now)
        trace.append((phase, fs.rc_ok, fs.host_ok, fs.motors_online, fs.motor_offline_events))
    trace.append([(e.time_us, e.kind, e.code, e.text) for e in events.pop_all()])
    return trace


@settings(max_examples=400)
@given(st.booleans(), st.lists(_TICK, max_size=80))
def test_failsafe_decision_chain_matches_the_early_return_reference(
    host_required: bool, ticks: list[Tick]
) -> None:
    config = FirmwareConfig().replaced(host_required=host_required)
    fast_events, ref_events = EventQueue(256), EventQueue(256)
    fast = Failsafe(config, fast_events)
    ref = ReferenceFailsafe(config, ref_events)
    assert _drive(fast, fast_events, ticks) == _drive(ref, ref_events, ticks)


_FRAME = st.builds(
    MotorFeedback,
    st.integers(0, 8191),
    st.integers(-20_000, 20_000),
    st.integers(-10_000, 10_000),
    st.integers(0, 90),
)


@given(
    st.lists(
        st.tuples(st.lists(st.tuples(st.integers(1, MOTOR_COUNT), _FRAME), max_size=4), st.integers(0, 5000)),
        max_size=40,
    ),
    st.integers(0, 20_000),
)
def test_motor_model_all_frames_update_matches_the_one_frame_reference(
    ticks: list[tuple[list[tuple[int, MotorFeedback]], int]], tau_us: int
) -> None:
    config = FirmwareConfig().replaced(motor_signs=(1, -1, 1), speed_filter_tau_us=tau_us)
    batch, single = MotorModel(config), ReferenceMotorModel(config)
    now = 0
    for frames, dt in ticks:
        now += dt
        batch.update_frames(frames, now)
        for motor, fb in frames:
            single.update(motor - 1, fb, now)
    for name in ("seen", "angle", "speed_rpm", "current", "temperature", "counts", "last_feedback_us"):
        assert getattr(batch, name) == getattr(single, name), name
    for name in ("cable_length_m", "cable_speed_m_s", "tension_est_n"):
        assert getattr(batch, name) == getattr(single, name), name


@given(st.lists(st.floats(-100.0, 400.0), min_size=MOTOR_COUNT, max_size=MOTOR_COUNT), st.floats(0.5, 10.0))
def test_batch_current_conversion_matches_per_cable(tensions: list[float], limit_a: float) -> None:
    model = MotorModel(FirmwareConfig().replaced(motor_signs=(-1, 1, -1), current_limit_a=limit_a))
    out = [99] * MOTOR_COUNT
    assert model.tensions_to_raw(tensions, out) is out
    assert out == [model.tension_to_raw(i, t) for i, t in enumerate(tensions)]
