"""The servo follower: the autopilot's gripper output channel turned into grab / release on the board.

An autopilot set up for a servo gripper (ArduPilot ``SERVOn_FUNCTION=28``, PX4's gripper output;
docs/mavlink.md) drives one output between a release and a grab PWM whenever a mission's
``DO_GRIPPER``, an RC switch or a ground station's gripper button asks. The autopilot reports that
output in ``SERVO_OUTPUT_RAW``; :class:`ServoFollower` watches it and says when the arm should grab or
release. The link then sends the same board commands a ``DO_GRIPPER`` would, through the same radio
gate (:class:`host.drone.gripper.GripperServer`), so the radio stays the master.

Rules, all chosen so that nothing unexpected moves:

- Hysteresis: the output counts as "grab" once it is within a quarter of the release-to-grab span of
  the grab PWM, as "release" within a quarter of the span of the release PWM; in between it keeps its
  last reading. A reading of 0 (output disabled) is no reading.
- Edges only: the first reading (and the first after a stale period) is a baseline, never a command,
  so a host started (or a telemetry link restored) with the output at "grab" does not grab. A change
  of reading is one request; a request refused by the radio is dropped, never retried later.
- Stale: no ``SERVO_OUTPUT_RAW`` for ``stale_us`` makes the follower stale: it says so once (log and
  ``STATUSTEXT``) and requests nothing; the board keeps doing what it does (a grasp stays held).

Pure logic, no I/O, no clock: the link feeds it messages and times.
"""

from __future__ import annotations

import argparse
import logging
from dataclasses import dataclass
from typing import Final

from protocol import mavlink as mav

__all__ = ["ServoFollowConfig", "ServoFollower", "parse_follow_servo"]

_US_PER_S: Final[int] = 1_000_000
_PWM_MIN_US: Final[int] = 500
_PWM_MAX_US: Final[int] = 2500
_MAX_OUTPUT: Final[int] = 2 * mav.SERVO_OUTPUTS_PER_PORT
_SPAN_FRACTION: Final[float] = 0.25

_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ServoFollowConfig:
    """Which autopilot output to follow and its two PWM positions (validated on creation).

    Attributes:
        output_n: The autopilot output number, 1..32 (ArduPilot's ``SERVOn``; ``SERVO_OUTPUT_RAW``
            port 0 has 1..16, port 1 17..32).
        grab_pwm_us: PWM of the grab position (ArduPilot ``GRIP_GRAB``).
        release_pwm_us: PWM of the release position (ArduPilot ``GRIP_RELEASE``).
        stale_us: No report of the output for this long makes the follower stale.
    """

    output_n: int
    grab_pwm_us: int = 1900
    release_pwm_us: int = 1100
    stale_us: int = 1 * _US_PER_S

    def __post_init__(self) -> None:
        if not 1 <= self.output_n <= _MAX_OUTPUT:
            raise ValueError(f"servo output must be 1..{_MAX_OUTPUT}: {self.output_n}")
        for name in ("grab_pwm_us", "release_pwm_us"):
            v = getattr(self, name)
            if not _PWM_MIN_US <= v <= _PWM_MAX_US:
                raise ValueError(
                    f"{name.removesuffix('_pwm_us')} PWM must be {_PWM_MIN_US}..{_PWM_MAX_US} µs: {v}"
                )
        if abs(self.grab_pwm_us - self.release_pwm_us) < 100:
            raise ValueError(
                "grab and release PWM must be at least 100 µs apart: "
                f"{self.grab_pwm_us}, {self.release_pwm_us}"
            )
        if self.stale_us <= 0:
            raise ValueError(f"stale_us must be > 0: {self.stale_us}")

    @property
    def port(self) -> int:
        """``SERVO_OUTPUT_RAW.port`` that carries the output."""
        return (self.output_n - 1) // mav.SERVO_OUTPUTS_PER_PORT

    @property
    def slot(self) -> int:
        """Index of the output in that message's ``servo_raw_us``."""
        return (self.output_n - 1) % mav.SERVO_OUTPUTS_PER_PORT


def _int(text: str, what: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise ValueError(f"{what} must be an integer, got {text!r}") from None


def parse_follow_servo(text: str) -> ServoFollowConfig:
    """Parse ``--follow-servo N[,grab=PWM][,release=PWM][,stale_ms=MS]``.

    Args:
        text: The option's value, e.g. ``9`` or ``9,grab=1900,release=1100``.

    Returns:
        The configuration.

    Raises:
        argparse.ArgumentTypeError: Malformed or out of range (one line saying why).
    """
    head, *rest = text.split(",")
    try:
        kwargs: dict[str, int] = {"output_n": _int(head, "output")}
        for item in rest:
            key, sep, value = item.partition("=")
            if not sep:
                raise ValueError(f"expected key=value, got {item!r}")
            if key == "grab":
                kwargs["grab_pwm_us"] = _int(value, "grab")
            elif key == "release":
                kwargs["release_pwm_us"] = _int(value, "release")
            elif key == "stale_ms":
                kwargs["stale_us"] = _int(value, "stale_ms") * 1000
            else:
                raise ValueError(f"unknown key {key!r} (grab, release, stale_ms)")
        return ServoFollowConfig(**kwargs)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(
            f"{text!r}: {exc} (syntax: N[,grab=PWM][,release=PWM][,stale_ms=MS])"
        ) from None


class ServoFollower:
    """Turns reports of the autopilot's gripper output into grab / release requests.

    Args:
        config: The output and its PWM positions.
    """

    def __init__(self, config: ServoFollowConfig) -> None:
        self.config = config
        span = abs(config.grab_pwm_us - config.release_pwm_us)
        self._band_us = span * _SPAN_FRACTION
        self._reading: mav.GripperAction | None = None
        self._last_report_us: int | None = None
        self._stale = True
        self.requests_n = 0
        """Requests made so far (grab or release)."""
        self.stale_periods_n = 0
        """Times the output reports stopped for longer than ``stale_us``."""

    @property
    def reading(self) -> mav.GripperAction | None:
        """The output's current reading (None before the first one and while stale)."""
        return self._reading

    @property
    def stale(self) -> bool:
        """No fresh report of the output (also true before the first one)."""
        return self._stale

    def classify(self, pwm_us: int) -> mav.GripperAction | None:
        """The reading of one PWM value: GRAB, RELEASE, or None inside the hysteresis band.

        Args:
            pwm_us: The output's PWM (0 = disabled).

        Returns:
            The reading, or None when the value decides nothing.
        """
        if pwm_us <= 0:
            return None
        if abs(pwm_us - self.config.grab_pwm_us) <= self._band_us:
            return mav.GripperAction.GRAB
        if abs(pwm_us - self.config.release_pwm_us) <= self._band_us:
            return mav.GripperAction.RELEASE
        return None

    def on_servo_output(self, msg: mav.ServoOutputRaw, now_us: int) -> mav.GripperAction | None:
        """Take one ``SERVO_OUTPUT_RAW`` from the autopilot.

        Args:
            msg: The report (other ports than the followed output's are ignored).
            now_us: Link-clock time in µs.

        Returns:
            The action to request now (a change of reading after a baseline), else None.
        """
        cfg = self.config
        if msg.port != cfg.port or cfg.slot >= len(msg.servo_raw_us):
            return None
        pwm_us = msg.servo_raw_us[cfg.slot]
        if pwm_us <= 0:
            return None  # a disabled output is no report
        self._last_report_us = now_us
        reading = self.classify(pwm_us)
        if reading is None:
            return None  # inside the hysteresis band: keep the last reading
        if self._stale:
            # First reading, or the first after reports stopped: a baseline, never a command.
            self._stale = False
            self._reading = reading
            _log.info("servo follower: output %d reads %s (baseline)", cfg.output_n, reading.name)
            return None
        if reading == self._reading:
            return None
        self._reading = reading
        self.requests_n += 1
        return reading

    def check_stale(self, now_us: int) -> bool:
        """Go stale when reports stopped for longer than ``stale_us``.

        Args:
            now_us: Link-clock time in µs.

        Returns:
            True exactly once per stale period, when it starts (the caller says so).
        """
        last = self._last_report_us
        if self._stale or last is None or now_us - last <= self.config.stale_us:
            return False
        self._stale = True
        self._reading = None
        self.stale_periods_n += 1
        _log.warning(
            "servo follower: no report of output %d for %d ms; no command until it returns",
            self.config.output_n,
            (now_us - last) // 1000,
        )
        return True
