"""manual-teleop: each stick bends the arm the right way; tensions and currents stay within limits."""

from __future__ import annotations

import math
from typing import Final

import numpy as np

from hil.run_record import Check, RunRecord
from hil.scenarios.base import FLOAT32_TOLERANCE_N, MANUAL, MS, SAFE, Plan, Scenario, rc
from protocol.dbus import CH_LIMIT, Lever, RcFrame

STEP_TAIL_US: Final = 500 * MS
"""Each stick step is judged over its last half second (the slew limiter has settled by then)."""


class ManualTeleop(Scenario):
    """Right stick right, left, forward (each for 1 s, back to centre between), then the curl stick up."""

    name = "manual-teleop"
    summary = "each stick bends the arm the right way; tensions and currents stay within limits"
    duration_us = 8000 * MS

    def plan(self) -> Plan:
        radio: list[tuple[int, RcFrame]] = [(0, SAFE), (200 * MS, MANUAL)]
        for start, sticks in (
            (500 * MS, {"ch0": 600}),
            (2500 * MS, {"ch0": -600}),
            (4500 * MS, {"ch1": 600}),
        ):
            radio += [(start, rc(Lever.MIDDLE, **sticks)), (start + 1000 * MS, MANUAL)]
        radio += [(6500 * MS, rc(Lever.MIDDLE, ch3=660)), (7500 * MS, MANUAL)]
        return Plan(radio=radio)

    def checks(self, run: RunRecord, plan: Plan) -> list[Check]:
        cfg = run.config
        s = run.samples
        angles = np.radians(np.asarray(cfg.mapping.cable_angles_deg, dtype=np.float64))
        unit = np.stack([np.cos(angles), np.sin(angles)], axis=1)
        steps = list(plan.radio)
        checks: list[Check] = []
        curl: tuple[int, int] | None = None
        for i, (start, frame) in enumerate(steps):
            end = steps[i + 1][0] if i + 1 < len(steps) else run.duration_us
            ch0, ch1, _, ch3 = frame.channels
            if frame.right_lever != Lever.MIDDLE:
                continue
            if ch3 > 0:
                curl = (end - STEP_TAIL_US, end)
            if not (ch0 or ch1):
                continue
            label = ", ".join(f"{k}={v:+d}" for k, v in (("ch0", ch0), ("ch1", ch1)) if v)
            want = math.atan2(ch1, ch0)
            # The board: the cables' resultant (tension x cable direction; a common tension cancels out).
            tail = run.window(max(start, end - STEP_TAIL_US), end)
            resultant = (s.target_n[tail] @ unit).mean(axis=0) if tail.any() else np.full(2, np.nan)
            err = abs(math.remainder(math.atan2(resultant[1], resultant[0]) - want, 2 * math.pi))
            deflection = (math.hypot(ch0, ch1) - cfg.mapping.stick_deadband) / (
                CH_LIMIT - cfg.mapping.stick_deadband
            )
            asked = cfg.mapping.bend_max_n * min(1.0, deflection)
            checks.append(
                Check(f"bending tension with {label}", float(np.hypot(*resultant)), asked / 2, ">=", "N")
            )
            checks.append(
                Check(f"bending tension direction error with {label}", math.degrees(err), 5, "<=", "deg")
            )
            if run.plant is not None:  # the arm itself: where did the tip go over the whole step?
                i0, i1 = np.flatnonzero(run.window(start)), np.flatnonzero(run.window(end))
                if i0.size and i1.size:
                    d = run.plant.tip_m[i1[0], :2] - run.plant.tip_m[i0[0], :2]
                    moved_mm, tip_err = float(np.hypot(*d)) * 1000, math.atan2(d[1], d[0]) - want
                else:
                    moved_mm = tip_err = math.nan
                checks.append(Check(f"tip moved with {label}", moved_mm, 10, ">=", "mm"))
                checks.append(
                    Check(
                        f"tip direction error with {label}",
                        math.degrees(abs(math.remainder(tip_err, 2 * math.pi))),
                        45,
                        "<=",
                        "deg",
                    )
                )
        if curl is not None:
            during = run.window(*curl)
            checks.append(
                Check(
                    "least target tension with the curl stick up",
                    float(s.target_n[during].min()) if during.any() else math.nan,
                    2.0,
                    ">=",
                    "N",
                )
            )
            if run.plant is not None:
                checks.append(
                    Check(
                        "least cable tension with the curl stick up",
                        float(run.plant.tension_n[during].min()) if during.any() else math.nan,
                        2.0,
                        ">=",
                        "N",
                    )
                )
        checks.append(
            Check(
                "largest target tension",
                float(s.target_n.max()) if run.n else math.nan,
                cfg.mapping.tension_max_n + FLOAT32_TOLERANCE_N,
                "<=",
                "N",
            )
        )
        checks.append(Check("largest |current|", run.max_current(0), run.limit_raw, "<=", "raw"))
        return checks
