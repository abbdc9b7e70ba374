"""The contact detector's rules on scripted cable speeds."""

from __future__ import annotations

from controller.config import FirmwareConfig
from controller.contact import ContactDetector

DT = 1000


def _run(det: ContactDetector, t: int, payouts: list[float], ramping: bool) -> tuple[int, bool]:
    for p in payouts:
        t += DT
        if det.update(t, DT, ramping, -p, 2.0, 0.0):
            return t, True
    return t, False


def test_free_slowdown_after_the_ramp_is_not_contact_but_an_impact_is() -> None:
    det = ContactDetector(FirmwareConfig())
    det.reset(0)
    t, hit = _run(det, 0, [0.0005 * k for k in range(200)], ramping=True)  # speeding up to 0.1 m/s
    assert not hit
    # Free rest: 0.1 m/s to 0 in 200 ms (0.5 m/s², like the prototype's 0.66 at most).
    t, hit = _run(det, t, [0.1 - 0.0005 * k for k in range(200)], ramping=False)
    assert not hit
    det.reset(t)
    t, hit = _run(det, t, [0.0005 * k for k in range(200)], ramping=False)
    t, hit = _run(det, t, [0.1 - 0.005 * k for k in range(20)], ramping=False)  # stopped in 20 ms: 5 m/s²
    assert hit and det.reason == "decel"


def test_old_rule_alone_when_the_new_ones_are_off() -> None:
    det = ContactDetector(
        FirmwareConfig().replaced(grasp_contact_decel_m_per_s2=0.0, grasp_contact_rest_m=0.0)
    )
    det.reset(0)
    t, _ = _run(det, 0, [0.0005 * k for k in range(200)], ramping=False)
    t, hit = _run(det, t, [0.1 - 0.005 * k for k in range(20)] + [0.0] * 100, ramping=False)
    assert not hit  # after the ramp the stall rule is silent
    t, hit = _run(det, t, [0.0] * 100, ramping=True)
    assert hit and det.reason == "stall"


def test_an_arm_at_rest_after_the_ramp_short_of_its_unroll_has_met_something() -> None:
    rest_m = FirmwareConfig().grasp.contact_rest_m
    det = ContactDetector(FirmwareConfig())
    det.reset(0)
    # 0.05 m/s for 0.6 s while the ramp runs: 30 mm paid out, then still after the ramp
    t, hit = _run(det, 0, [0.05] * 600, ramping=True)
    assert not hit and abs(det.paid_out_m - 0.03) < 1e-9 and det.paid_out_m < rest_m
    dwell = FirmwareConfig().grasp.contact_dwell_us // DT
    t, hit = _run(det, t, [0.0] * (dwell - 1), ramping=False)
    assert not hit  # still for less than the dwell time
    t, hit = _run(det, t, [0.0] * 2, ramping=False)
    assert hit and det.reason == "rest"


def test_a_free_arm_at_rest_past_its_unroll_is_not_contact() -> None:
    det = ContactDetector(FirmwareConfig())
    det.reset(0)
    t, _ = _run(det, 0, [0.05] * 1400, ramping=True)  # 70 mm: the free arm's full unroll
    t, hit = _run(det, t, [0.0] * 1000, ramping=False)
    assert not hit
