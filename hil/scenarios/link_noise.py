"""link-noise: byte errors on the board link: no corrupted command applied, telemetry keeps flowing."""

from __future__ import annotations

import math

import numpy as np

from controller.config import FailsafeConfig, FirmwareConfig
from hil.faults import Fault, FaultKind
from hil.run_record import Check, RunRecord
from hil.scenarios.base import FLOAT32_TOLERANCE_N, MS, Plan, Scenario, arm_then
from protocol.messages import Command, CommandCode, Mode

_HALF_S = 500 * MS


class LinkNoise(Scenario):
    """Armed; the host switches to DIRECT and sets tensions every 100 ms while 0.5 % of the link's bytes
    are lost and 0.5 % have a bit flipped, in both directions."""

    name = "link-noise"
    summary = "1% byte errors on the board link: no corrupted command applied, telemetry keeps flowing"
    duration_us = 5000 * MS

    def plan(self) -> Plan:
        values = [(2.0, 3.0, 4.0), (5.0, 1.5, 2.5), (3.5, 3.5, 1.0), (1.0, 6.0, 2.0)]
        host: list[tuple[int, Command]] = []
        for k, t in enumerate(range(500 * MS, 5000 * MS, 100 * MS)):
            if k % 5 == 0:
                host.append((t, Command(CommandCode.SET_MODE, (float(Mode.DIRECT), 0.0, 0.0))))
            host.append((t + 50 * MS, Command(CommandCode.SET_TENSIONS, values[k % len(values)])))
        return Plan(
            radio=arm_then(),
            faults=[
                Fault(FaultKind.LINK_BYTE_LOSS, 0, rate=0.005),
                Fault(FaultKind.LINK_BIT_FLIP, 0, rate=0.005),
            ],
            host=host,
            firmware=FirmwareConfig(failsafe=FailsafeConfig(host_required=True)),
        )

    def checks(self, run: RunRecord, plan: Plan) -> list[Check]:
        cfg = run.config
        s = run.samples
        lo, hi = cfg.mapping.pretension_n, cfg.mapping.tension_max_n
        sent = [
            tuple(min(hi, max(lo, v)) for v in m.args)
            for _, m in run.sent
            if isinstance(m, Command) and m.code == CommandCode.SET_TENSIONS
        ]
        sent.append((lo, lo, lo))  # the board's set-point before any SET_TENSIONS
        # A DIRECT sample whose targets did not move since the previous sample has finished slewing: its
        # targets are the set-point in force.
        applied: list[tuple[float, ...]] = []
        direct = s.mode == Mode.DIRECT
        for k in range(1, run.n):
            if direct[k] and direct[k - 1] and np.array_equal(s.target_n[k], s.target_n[k - 1]):
                point = tuple(float(x) for x in s.target_n[k])
                if not any(np.allclose(point, p, atol=FLOAT32_TOLERANCE_N, rtol=0) for p in applied):
                    applied.append(point)
        foreign = [
            p for p in applied if not any(np.allclose(p, q, atol=FLOAT32_TOLERANCE_N, rtol=0) for q in sent)
        ]
        # What the board sent is counted per window; what got through the noise on average: the noise is
        # random, so the per-window minimum of a ~27 % survival rate would fail now and then for no fault
        # of the board's.
        windows = range(0, run.duration_us, _HALF_S)
        board_t = np.asarray(run.telemetry_sent_us, dtype=np.int64)
        per_window = [int(np.count_nonzero((board_t >= t) & (board_t < t + _HALF_S))) for t in windows]
        delivered = run.received(0, run.duration_us) / max(1, len(windows))
        crc = s.link_crc_errors
        return [
            Check("direct-mode tension sets applied", float(len(applied)), 2, ">=", "sets"),
            Check("applied tension sets that the host never sent", float(len(foreign)), 0, "<=", "sets"),
            Check(
                "corrupted frames the board dropped (counted)",
                float(crc.max() - crc.min()) if crc.size else math.nan,
                1,
                ">=",
                "frames",
            ),
            Check(
                "fewest telemetry frames the board sent in any 0.5 s",
                float(min(per_window, default=0)),
                40,
                ">=",
                "frames",
            ),
            Check("telemetry frames delivered per 0.5 s through the noise", delivered, 5, ">=", "frames"),
            Check("host decode errors on delivered frames", float(run.decode_errors), 0, "<=", "frames"),
        ]
