"""overcurrent: a mapping that asks for 8 A is clamped to the 3 A limit on the wire and at the drives."""

from __future__ import annotations

import math

from controller.config import FirmwareConfig, MappingConfig
from hil.run_record import Check, RunRecord
from hil.scenarios.base import MS, Plan, Scenario, arm_then


class Overcurrent(Scenario):
    """A configuration that asks for more tension than the motors may carry: 150 N on a 10 mm spool at
    0.18 N·m/A is 8.3 A, far above the 3 A limit; the curl stick goes full up."""

    name = "overcurrent"
    summary = "a mapping that asks for 8 A is clamped to the 3 A limit on the wire and at the drives"
    duration_us = 1500 * MS

    def plan(self) -> Plan:
        cfg = FirmwareConfig(
            mapping=MappingConfig(common_max_n=150.0, tension_max_n=200.0, slew_n_per_s=1000.0)
        )
        return Plan(radio=arm_then(ch3=660), firmware=cfg)

    def checks(self, run: RunRecord, plan: Plan) -> list[Check]:
        cfg = run.config
        asked = (
            cfg.mapping.common_max_n * cfg.motor.spool_radius_m / cfg.motor.torque_constant_nm_per_a * 1000
        )
        checks = [
            Check("current the mapping asks for", asked, run.limit_raw, ">=", "raw"),
            Check("largest |current| sent", run.max_current(0), run.limit_raw, "<=", "raw"),
            Check(
                "the clamp engaged (largest |current| sent)", run.max_current(0), run.limit_raw, ">=", "raw"
            ),
        ]
        if run.plant is not None:
            applied = run.plant.applied_a
            checks.append(
                Check(
                    "largest current a drive delivered",
                    float(applied.max()) if applied.size else math.nan,
                    cfg.motor.current_limit_a + 1e-9,
                    "<=",
                    "A",
                )
            )
        return checks
