"""controller.params: the table has one row per FirmwareConfig field, and the rows hold together."""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
from typing import Any

import pytest

from controller.config import FirmwareConfig
from controller.errors import ConfigError
from controller.params import (
    FIELD_ROWS,
    PARAM_FIELDS,
    PARAM_TABLE,
    PARAMS,
    SAFETY_PARAMS,
    WIRE_ROWS,
    Kind,
    Range,
    default,
    markdown,
)
from protocol.messages import NAME_LEN

_KIND_OF = {bool: Kind.BOOL, int: Kind.INT, float: Kind.FLOAT}


def _leaves(obj: Any, prefix: str = "") -> dict[str, Any]:
    """Dotted field path -> value of every non-dataclass field of a (nested) dataclass instance."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if dataclasses.is_dataclass(value):
            out.update(_leaves(value, f"{prefix}{f.name}."))
        else:
            out[prefix + f.name] = value
    return out


def test_every_config_field_is_one_row_and_its_default_comes_from_it() -> None:
    leaves = _leaves(FirmwareConfig())
    assert sorted(p.field for p in PARAM_TABLE) == sorted(leaves)
    assert list(FIELD_ROWS) == list(FirmwareConfig().to_dict())  # the flat order is the table's
    for p in PARAM_TABLE:
        value = leaves[p.field]
        assert value == p.default and type(value) is type(p.default), p.name
        assert default(p.field) is p.default
        section, _, field = p.field.rpartition(".")
        prefix = {"": "", "motor": "", "mapping": "", "failsafe": "", "grasp": "grasp_", "hold": "hold_"}
        assert p.name == prefix[section] + field, p.name
        if isinstance(p.default, tuple):
            elem = Kind.INTS if isinstance(p.default[0], int) else Kind.FLOATS
            assert p.kind is elem, p.name
        else:
            assert p.kind is _KIND_OF[type(p.default)], p.name


def test_defaults_meet_their_bounds_and_run_time_ranges() -> None:
    values = FirmwareConfig().to_dict()
    for p in PARAM_TABLE:
        p.check_type(p.coerce(values[p.name]))
        p.check_bounds(values)
        for r in (p.bounds, p.runtime):
            if r is not None:
                assert all(
                    end is None or not isinstance(end, str) or end in FIELD_ROWS for end in (r.lo, r.hi)
                )
        if p.runtime is not None:
            assert p.runtime.contains(p.default, values), p.name


def test_run_time_parameters_fit_the_wire_in_their_index_order() -> None:
    assert [p.index for p in WIRE_ROWS.values()] == list(range(len(PARAMS)))
    assert tuple(WIRE_ROWS) == PARAMS and len(set(PARAMS)) == len(PARAMS)
    for p in PARAM_TABLE:
        assert (p.wire is None) == (p.index is None), p.name
        if p.wire is None:
            assert not p.safety and p.runtime is None, p.name  # only a ParamSet has those rules
            continue
        assert len(p.wire) <= NAME_LEN and p.wire.isascii() and p.wire == p.wire.upper(), p.wire
        assert PARAM_FIELDS[p.wire] == p.name
        assert p.kind in (Kind.BOOL, Kind.INT, Kind.FLOAT), p.wire  # a tuple does not travel as one float
    # The board-link index order as shipped: recordings and ground stations keep their indices.
    assert PARAMS[:5] == (
        "HOST_TIMEOUT_US",
        "HOST_REQUIRED",
        "SPOOL_RADIUS_M",
        "TORQUE_K_NM_A",
        "CURRENT_LIMIT_A",
    )
    assert PARAMS[-5:] == (
        "GRASP_WRAP_M_S",
        "PAYIN_MAX_M_S",
        "GRASP_REST_M",
        "GRASP_HOLD_MIN_M",
        "GRASP_HOLD_MAX_M",
    )


def test_the_safety_parameters_are_the_documented_seven() -> None:
    """The specification, by hand on purpose: the armed-set tests (tests/controller/test_commands.py) take
    the SAFE-only rows from the table, so dropping a row's flag (HOST_TIMEOUT_US, TORQUE_K_NM_A,
    PAYIN_MAX_M_S, any of the seven) would pass them; it fails here."""
    assert {
        "CURRENT_LIMIT_A",
        "TENSION_MAX_N",
        "SPOOL_RADIUS_M",
        "TORQUE_K_NM_A",
        "HOST_TIMEOUT_US",
        "HOST_REQUIRED",
        "PAYIN_MAX_M_S",
    } == SAFETY_PARAMS


def test_every_row_describes_itself_on_one_line() -> None:
    for p in PARAM_TABLE:
        assert p.doc and "\n" not in p.doc and len(p.doc) <= 100 and not p.doc.endswith("."), p.name


@pytest.mark.parametrize(
    ("r", "unit", "text"),
    [
        (Range(0.0, "tension_max_n"), "N", "must be 0..tension_max_n"),
        (Range(0.0, 10.0, lo_open=True, source="C610"), "A", "must be in (0, 10] A (C610)"),
        (Range(0.0, 1.0, hi_open=True), "", "must be in [0, 1)"),
        (Range(0, 659), "counts", "must be 0..659 counts"),
        (Range(100, 1_000_000), "µs", "must be 100 µs..1 s"),
        (Range(10_000, 60_000_000), "µs", "must be 10 ms..60 s"),
        (Range(0.0), "N", "must be >= 0 N"),
        (Range(hi=1e12, hi_open=True), "", "must be < 1e12"),
        (Range(), "m", "any finite value"),
    ],
)
def test_range_words(r: Range, unit: str, text: str) -> None:
    assert r.text(unit) == text


def test_a_range_reads_named_ends_from_the_values() -> None:
    r = Range(0.0, "tension_max_n")
    assert r.contains(20.0, {"tension_max_n": 20.0}) and not r.contains(20.5, {"tension_max_n": 20.0})
    assert not Range(0.0, 1.0, lo_open=True).contains(0.0, {})
    assert not Range(0.0, 1.0, hi_open=True).contains(1.0, {})


def test_validation_words_come_from_the_rows() -> None:
    c = FirmwareConfig()
    for name, value, text in [
        ("tension_max_n", 2000.0, "tension_max_n: must be in (0, 1000] N"),
        ("pretension_n", 25.0, "pretension_n: must be 0..tension_max_n"),
        ("host_timeout_us", 5_000, "host_timeout_us: must be 10 ms..60 s"),
        ("rc_timeout_us", 1_000, "rc_timeout_us: must be at least 2 control periods (1000 µs)"),
        ("stick_deadband", 660, "stick_deadband: must be 0..659 counts"),
    ]:
        with pytest.raises(ConfigError) as err:
            c.replaced(**{name: value})
        assert str(err.value) == text


def test_with_param_is_the_rule_of_a_param_set() -> None:
    c = FirmwareConfig()
    with pytest.raises(ConfigError, match=r"^safety parameter: only in SAFE$"):
        c.with_param("CURRENT_LIMIT_A", 2.0, safe=False)
    assert c.with_param("SLEW_N_S", 80.0, safe=False).mapping.slew_n_per_s == 80.0
    assert c.with_param("CURRENT_LIMIT_A", 2.0, safe=True).motor.current_limit_a == 2.0
    with pytest.raises(
        ConfigError, match=r"torque_constant_nm_per_a: must be 0\.1\.\.0\.5 N·m/A \(M2006 P36\)"
    ):
        c.with_param("TORQUE_K_NM_A", 0.05)
    assert c.replaced(torque_constant_nm_per_a=0.05).motor.torque_constant_nm_per_a == 0.05  # a file may
    with pytest.raises(ConfigError, match=r"payin_limit_m_per_s: must be <= 0\.524 m/s"):
        c.with_param("PAYIN_MAX_M_S", 0.6)
    assert math.isclose(c.replaced(payin_limit_m_per_s=0.6).motor.payin_limit_m_per_s, 0.6)


def test_board_values_are_taken_together() -> None:
    c = FirmwareConfig().with_board_values({"TENSION_MAX_N": 30.0, "PRETENSION_N": 25.0, "NOT_OURS": 1.0})
    assert (c.mapping.tension_max_n, c.mapping.pretension_n) == (30.0, 25.0)
    with pytest.raises(ConfigError):
        FirmwareConfig().with_board_values({"HOST_REQUIRED": 0.5})


def test_the_docs_page_is_generated_by_the_module() -> None:
    out = subprocess.run(
        [sys.executable, "-m", "controller.params"], capture_output=True, text=True, check=True, timeout=60
    ).stdout
    assert out == markdown()
    assert all(f"`{name}`" in out for name in PARAMS) and all(f"`{p.name}`" in out for p in PARAM_TABLE)


# --- what the mutation benchmark found untested --------------------------------------------------


def test_an_open_upper_end_refuses_itself_and_everything_above() -> None:
    r = Range(0.0, 1.0, hi_open=True)
    assert r.contains(0.999, {}) and not r.contains(1.0, {}) and not r.contains(1.5, {})
    closed = Range(0.0, 1.0)
    assert closed.contains(1.0, {}) and not closed.contains(1.0001, {})


def test_file_values_are_coerced_to_their_kind_and_nothing_else() -> None:
    """A TOML or JSON file writes 30000.0 for an int and 1 for a float: taken as the kind says; a
    fractional value for an int stays a float, for check_type to refuse."""
    i = next(p for p in PARAM_TABLE if p.kind is Kind.INT)
    f = next(p for p in PARAM_TABLE if p.kind is Kind.FLOAT)
    got = i.coerce(3.0)
    assert got == 3 and type(got) is int
    assert type(i.coerce(3.5)) is float and type(i.coerce(3)) is int
    got = f.coerce(3)
    assert got == 3.0 and type(got) is float
    assert type(f.coerce(True)) is bool  # a bool is not an int here: check_type refuses it
