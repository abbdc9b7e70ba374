"""host.panel.param_table: units and bounds from the firmware's own table, and the host-side check."""

from __future__ import annotations

import pytest

from host.panel.param_table import PARAM_NAMES, param_check, param_info


def test_units_kinds_and_bounds_come_from_the_firmware_table() -> None:
    t = param_info("TENSION_MAX_N")
    assert (t.unit, t.kind, t.field) == ("N", "float", "tension_max_n")
    assert t.bounds == "must be in (0, 1000] N"
    assert param_info("HOST_TIMEOUT_US").unit == "µs"
    assert param_info("HOST_TIMEOUT_US").kind == "int"
    assert param_info("HOST_REQUIRED").kind == "bool" and param_info("HOST_REQUIRED").bounds == "0 or 1"
    assert param_info("SLEW_N_S").unit == "N/s"
    assert param_info("GRASP_DIR_DEG").unit == "°"
    assert param_info("TORQUE_K_NM_A").unit == "N·m/A"
    assert param_info("HOLD_POS_KI").unit == "1/s²"
    assert param_info("GRASP_DECEL_M_S2").unit == "m/s²"
    for name in PARAM_NAMES:
        info = param_info(name)
        assert info.bounds, name
        assert param_check({}, name, info.default) is None, name
    with pytest.raises(KeyError):
        param_info("NOPE")


def test_check_uses_the_boards_other_values() -> None:
    why = param_check({}, "PRETENSION_N", 25.0)  # over the default ceiling, 20 N
    assert why == "pretension_n: must be 0..tension_max_n"
    assert param_check({"TENSION_MAX_N": 30.0}, "PRETENSION_N", 25.0) is None  # the board's ceiling
    assert param_check({}, "HOST_REQUIRED", 0.5) is not None
    assert param_check({}, "STICK_DEADBAND", 2.5) is not None  # an integer parameter
