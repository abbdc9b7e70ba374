"""excitation: an identification excitation played in DIRECT mode, within every limit, to be recorded.

What ``spirob-host --excite`` does against a real board, played by the scripted host against the virtual
board: the radio arms (right lever DOWN, then MIDDLE: the pilot's enable), the host asks for DIRECT, then
sends the profile's per-cable tensions (:mod:`hil.identify.excitation`) 50 times a second. The recording
(``spirob-hil run excitation --record excite.mcap``) names the profile and when it began, so
``spirob-hil identify`` finds its segments. With ``tip_noise_m`` a motion-capture tracker
(:class:`hil.identify.tracker.TipTracker`) also records the tip, as a lab's tracker would.
"""

from __future__ import annotations

import json
import math
from typing import Final

import numpy as np

from hil.environment import Environment
from hil.identify.excitation import Profile, profile
from hil.identify.motor_data import EXCITATION_KEY
from hil.identify.tracker import TipTracker
from hil.run_record import Check, RunRecord
from hil.scenarios.base import MS, SAFE, Plan, Scenario, rc
from protocol.dbus import Lever
from protocol.messages import Command, CommandCode, Mode

DIRECT_AT_US: Final = 400 * MS
"""The host asks for DIRECT once the lever has been MIDDLE for 200 ms."""
PROFILE_AT_US: Final = 600 * MS
"""The profile starts (board time)."""
SEND_PERIOD_US: Final = 20 * MS
"""Tensions go out at 50 Hz: the firmware slews them at 50 N/s, so finer steps change nothing it sends."""
TAIL_US: Final = 400 * MS
FLOAT32_N: Final = 1e-4
"""Tensions travel as float32: values this close are the same set-point."""


class Excitation(Scenario):
    """The ``standard`` profile (or another, ``spirob-hil run excitation --excite NAME``) in DIRECT mode.

    Args:
        profile_name: the excitation profile.
        tip_noise_m: with a value, a tracker records the tip with this noise per axis (None: no tracker).
        tip_seed: the tracker noise's seed.
    """

    name = "excitation"
    summary = "an identification excitation in DIRECT mode within every limit, for spirob-hil identify"
    duration_us = PROFILE_AT_US + round(profile("standard").duration_s * 1e6) + TAIL_US
    needs_plant = False

    def __init__(
        self, profile_name: str = "standard", tip_noise_m: float | None = None, tip_seed: int = 0
    ) -> None:
        self.profile: Profile = profile(profile_name)
        self.duration_us = PROFILE_AT_US + round(self.profile.duration_s * 1e6) + TAIL_US
        self.tracker = None if tip_noise_m is None else TipTracker(noise_m=tip_noise_m, seed=tip_seed)

    def after_tick(self, env: Environment) -> None:
        if self.tracker is not None:
            self.tracker.after_tick(env)

    def plan(self) -> Plan:
        p = self.profile
        host: list[tuple[int, Command]] = [
            (DIRECT_AT_US, Command(CommandCode.SET_MODE, (float(Mode.DIRECT), 0.0, 0.0)))
        ]
        end_us = PROFILE_AT_US + round(p.duration_s * 1e6)
        for t_us in range(PROFILE_AT_US, end_us + 1, SEND_PERIOD_US):
            tensions = p.tensions_n((t_us - PROFILE_AT_US) / 1e6)
            host.append((t_us, Command(CommandCode.SET_TENSIONS, tensions)))
        return Plan(radio=[(0, SAFE), (200 * MS, rc(Lever.MIDDLE))], host=host)

    def recording_metadata(self) -> dict[str, str]:
        return {EXCITATION_KEY: json.dumps({**self.profile.describe(), "start_us": PROFILE_AT_US})}

    def checks(self, run: RunRecord, plan: Plan) -> list[Check]:
        p = self.profile
        start = PROFILE_AT_US + 2 * SEND_PERIOD_US  # the first tensions have arrived
        end = PROFILE_AT_US + round(p.duration_s * 1e6)
        window = run.window(start, end)
        s = run.samples
        direct = float(np.mean(s.mode[window] == int(Mode.DIRECT))) if window.any() else math.nan
        targets = s.target_n[window]
        return [
            Check("share of the profile played in DIRECT mode", direct, 1.0, ">=", ""),
            Check(
                "largest tension target (the profile's peak)",
                float(targets.max()) if targets.size else math.nan,
                p.peak_n + FLOAT32_N,
                "<=",
                "N",
            ),
            Check(
                "smallest tension target (the profile's rest)",
                float(targets.min()) if targets.size else math.nan,
                p.rest_n - FLOAT32_N,
                ">=",
                "N",
            ),
            Check("largest |current| sent", run.max_current(0), run.limit_raw, "<=", "raw"),
        ]
