"""host.panel.param_table: the editor's metadata from the firmware's table, and the host-side check."""

from __future__ import annotations

import pytest

from host.panel.param_table import PARAM_NAMES, param_check, param_info


def test_units_kinds_and_bounds_come_from_the_firmware_table() -> None:
    t = param_info("TENSION_MAX_N")
    assert (t.unit, t.kind, t.field, t.safety) == ("N", "float", "tension_max_n", True)
    assert t.bounds == "must be in (0, 1000] N"
    assert t.doc == "per-cable tension ceiling"
    assert param_info("HOST_TIMEOUT_US").unit == "µs"
    assert param_info("HOST_TIMEOUT_US").kind == "int"
    assert param_info("HOST_REQUIRED").kind == "bool" and param_info("HOST_REQUIRED").bounds == "0 or 1"
    assert param_info("SLEW_N_S").unit == "N/s" and not param_info("SLEW_N_S").safety
    assert param_info("GRASP_DIR_DEG").unit == "°"
    assert param_info("HOLD_POS_KI").unit == "1/s²"
    assert param_info("GRASP_DECEL_M_S2").unit == "m/s²"
    torque = param_info("TORQUE_K_NM_A")
    assert (torque.unit, torque.bounds) == (
        "N·m/A",
        "must be 0.1..0.5 N·m/A (M2006 P36)",
    )  # the run-time range
    for name in PARAM_NAMES:
        info = param_info(name)
        assert info.bounds and info.doc, name
        assert param_check({}, name, info.default) is None, name
    with pytest.raises(KeyError):
        param_info("NOPE")


def test_check_uses_the_boards_other_values() -> None:
    why = param_check({}, "PRETENSION_N", 25.0)  # over the default ceiling, 20 N
    assert why == "pretension_n: must be 0..tension_max_n"
    assert param_check({"TENSION_MAX_N": 30.0}, "PRETENSION_N", 25.0) is None  # the board's ceiling
    assert param_check({}, "HOST_REQUIRED", 0.5) is not None
    assert param_check({}, "STICK_DEADBAND", 2.5) is not None  # an integer parameter
    # A partial read that does not fit the defaults (the ceiling under the default pack tension): the
    # defaults' bounds, and the board has the last word.
    assert param_check({"TENSION_MAX_N": 5.0}, "PRETENSION_N", 10.0) is None


def test_check_is_the_boards_rule_with_its_hardware_ceilings() -> None:
    """The same rule a ParamSet meets on the board: the run-time ranges too, in the board's words."""
    assert (
        param_check({}, "TORQUE_K_NM_A", 0.05)
        == "torque_constant_nm_per_a: must be 0.1..0.5 N·m/A (M2006 P36)"
    )
    assert param_check({}, "PAYIN_MAX_M_S", 0.6) == (
        "payin_limit_m_per_s: must be <= 0.524 m/s (M2006 no-load speed on the spool)"
    )
    assert param_check({"SPOOL_RADIUS_M": 0.02}, "PAYIN_MAX_M_S", 0.6) is None  # the board's spool
    assert param_check({}, "CURRENT_LIMIT_A", 2.0) is None  # SAFE-only is the board's to judge
