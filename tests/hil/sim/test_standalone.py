"""The exported model (hil.sim.standalone, build_mjcf(standalone=True)): the drives as dcmotors, the command
delay, the capstan stand-in, and the file stepped in plain MuJoCo against the Plant (docs/plant.md, "The
exported model")."""

from __future__ import annotations

import dataclasses
import difflib
import math
import re
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import pytest

from hil.sim.config import ActuatorConfig, ArmConfig, ModelConfig, MotorConfig
from hil.sim.drives import Drives
from hil.sim.mjcf import build_mjcf, unit_geometry, write_mjcf
from hil.sim.model_file import FittedParameter, ModelFile, write_model_file
from hil.sim.plant import Plant
from hil.sim.presets import resolve
from hil.sim.spiral import AUTHORS_DEFAULT, PAPER_PROTOTYPE
from hil.sim.standalone import (
    CAPSTAN_REFERENCE_TENSION_N,
    capstan_standin_nm,
    delay_attributes,
    drive_circuit,
)
from hil.sim.types import PlantConfig

FITTED = {"torque_scale": 1.2, "delay": 0.002, "joint_friction": 0.002}
"""A fitted-looking model: the identified parameters a lab's fit could move off the preset."""

MODELS = {
    "prototype": ModelConfig(),
    "fitted": ModelConfig(
        arm=ArmConfig(joint_friction_nm=0.002), motor=MotorConfig(torque_scale=1.2, command_delay_s=0.002)
    ),
}


def frictionless(model: ModelConfig) -> ModelConfig:
    """``model`` with no capstan friction (what is left is all MJCF)."""
    return dataclasses.replace(model, arm=dataclasses.replace(model.arm, cable_mu=0.0))


def exported(tmp_path: Path, model: ModelConfig, name: str = "arm.xml") -> Any:
    """The exported prototype loaded as a lab would: from the file, by plain MuJoCo."""
    path = write_mjcf(tmp_path / name, PAPER_PROTOTYPE, None, model, standalone=True)
    return mujoco.MjModel.from_xml_path(str(path))


def spool_addresses(m: Any, kind: str) -> list[int]:
    ids = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, f"spool_{k}") for k in range(m.nu)]
    table = m.jnt_qposadr if kind == "qpos" else m.jnt_dofadr
    return [int(table[j]) for j in ids]


# ---------------------------------------------------------------------- the pieces


@pytest.mark.parametrize("name", sorted(MODELS))
def test_the_dcmotor_delivers_what_the_drives_deliver(tmp_path: Path, name: str) -> None:
    """At every speed MuJoCo's dcmotor gives the current the plant's drives give: the command within the
    torque-speed line, the line at it, and beyond the no-load speed both brake, up to the current limit."""
    model = MODELS[name]
    motor = model.motor
    circuit = drive_circuit(motor)
    assert circuit.vmax_v * circuit.motorconst / circuit.resistance_ohm == pytest.approx(
        motor.stall_current_a
    )
    kt_s = motor.torque_constant_nm_per_a * motor.torque_scale
    assert circuit.motorconst**2 / circuit.resistance_ohm * kt_s == pytest.approx(
        motor.stall_current_a / motor.no_load_speed_rad_s
    )
    m = exported(tmp_path, dataclasses.replace(model, motor=dataclasses.replace(motor, command_delay_s=0.0)))
    d = mujoco.MjData(m)
    dof = spool_addresses(m, "qvel")[0]
    state, ctrl = np.zeros(2), np.zeros(1)
    drives = Drives(motor, 1, None)
    drives.attach(state[:1], state[1:], ctrl, [0], [0])
    omega_nl, i_stall, r = motor.no_load_speed_rad_s, motor.stall_current_a, motor.spool_radius_m
    braked = 0
    for command_a in (-10.0, -3.0, -0.05, 0.0, 0.05, 3.0, 10.0):
        for u in np.linspace(-2.5, 2.5, 51):
            omega = u * omega_nl
            d.qvel[dof] = omega * r
            d.ctrl[0] = command_a
            mujoco.mj_forward(m, d)
            mj_a = float(d.actuator_force[0])
            state[1] = omega * r
            drives.apply_currents([round(command_a * 1000), 0, 0][:1])
            drives.drive()
            assert mj_a == pytest.approx(circuit.delivered_a(command_a, omega), abs=1e-9)
            assert float(d.qfrc_actuator[dof]) == pytest.approx(
                mj_a * motor.delivered_force_per_amp_n, abs=1e-9
            )
            assert mj_a == pytest.approx(float(ctrl[0]), abs=1e-9), (command_a, u)
            lo = -omega_nl * (1.0 + max(command_a, 0.0) / i_stall)
            hi = omega_nl * (1.0 + max(-command_a, 0.0) / i_stall)
            if not lo <= omega <= hi:  # overrun: both brake, against the motion, within the current limit
                assert mj_a * omega < 0.0 and abs(mj_a) <= motor.current_limit_a + 1e-9, (command_a, u)
                braked += 1
    assert braked > 100


@pytest.mark.parametrize("delay_s", [0.002, 0.0025])
def test_the_delay_is_the_drives_delay(tmp_path: Path, delay_s: float) -> None:
    """The exported actuators' delay (a ctrl history, linear between samples) delivers each period what the
    drives deliver for the same setpoints: the setpoint ``command_delay_s`` ago, through the same line."""
    motor = MotorConfig(command_delay_s=delay_s)
    m = exported(tmp_path, ModelConfig(motor=motor))
    assert 'interp="linear"' in delay_attributes(delay_s, 0.001)
    d = mujoco.MjData(m)
    expected = np.zeros(m.nu)
    drives = Drives(motor, m.nu, None)
    drives.attach(d.qpos, d.qvel, expected, spool_addresses(m, "qpos"), spool_addresses(m, "qvel"))
    drives.reset()
    rng = np.random.default_rng(3)
    for step in range(200):
        raw = [int(v) for v in rng.integers(-3000, 3001, size=m.nu)] if step % 7 == 0 else None
        if raw is not None:
            drives.apply_currents(raw)
            d.ctrl[:] = np.array(raw) / 1000.0
        drives.drive()  # from the speeds MuJoCo's step starts with
        mujoco.mj_step(m, d)
        assert d.actuator_force == pytest.approx(expected, abs=1e-9), step
    assert delay_attributes(0.0, 0.001) == ""


def test_the_export_is_the_plants_model_but_for_the_drives_delay_and_friction() -> None:
    """Line by line, the exported file differs from the plant's model only in the actuators, the joints'
    dry friction, the added numerics and a comment; the plant builds what it always built."""
    changed = re.compile(r"^\s*(<dcmotor |<motor |<general |<muscle |<joint name=\"joint_|<numeric |<!-- )")
    fitted = MODELS["fitted"]
    cases = [
        (PAPER_PROTOTYPE, ModelConfig()),
        (PAPER_PROTOTYPE, fitted),
        (PAPER_PROTOTYPE.with_cables(2), dataclasses.replace(fitted, mounting="table")),
        (AUTHORS_DEFAULT, resolve("authors").model),
        (PAPER_PROTOTYPE, ModelConfig(actuator=ActuatorConfig(kind="tension"), motor=fitted.motor)),
    ]
    for design, model in cases:
        plant_xml = build_mjcf(design, None, model)
        assert (
            "dcmotor" not in plant_xml and "delay=" not in plant_xml and "spirob_standalone" not in plant_xml
        )
        export_xml = build_mjcf(design, None, model, standalone=True)
        diff = [
            line
            for line in difflib.unified_diff(
                plant_xml.splitlines(), export_xml.splitlines(), lineterm="", n=0
            )
            if line[:1] in "+-" and not line.startswith(("+++", "---"))
        ]
        assert diff
        assert all(changed.match(line[1:]) for line in diff), [ln for ln in diff if not changed.match(ln[1:])]
        without_friction = re.sub(r' frictionloss="[^"]*"', "", plant_xml)
        for line in diff:
            if "<joint " in line:  # the same joint, its friction apart
                assert re.sub(r' frictionloss="[^"]*"', "", line[1:]) in without_friction


def test_the_capstan_stand_in_is_the_plants_friction_at_the_reference() -> None:
    """Each joint's friction in the export: its own plus the plant's capstan friction with every joint
    bent to Δθ and 20 N on the cables (the plant's law, evaluated once)."""
    model = MODELS["fitted"]
    geo = unit_geometry(PAPER_PROTOTYPE, model.arm)
    radii = geo.cable_radius_base_side_m[1:]
    mu, alpha = model.arm.cable_mu, PAPER_PROTOTYPE.dtheta_rad
    stand_in = capstan_standin_nm(mu, radii, CAPSTAN_REFERENCE_TENSION_N, alpha)
    for i, (f, r) in enumerate(zip(stand_in, radii, strict=True)):
        arriving = CAPSTAN_REFERENCE_TENSION_N * math.exp(-mu * alpha * i)
        assert f == pytest.approx(arriving * (1.0 - math.exp(-mu * alpha)) * r)
    assert capstan_standin_nm(0.0, radii, 20.0, alpha) == (0.0,) * len(radii)
    m = mujoco.MjModel.from_xml_string(build_mjcf(PAPER_PROTOTYPE, None, model, standalone=True))
    own = model.arm.joint_friction_nm * np.array(geo.stiffness_nm_per_rad[1:]) / geo.stiffness_nm_per_rad[1]
    for i in range(1, PAPER_PROTOTYPE.units):
        j = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, f"joint_{i:02d}")
        dofs = m.dof_frictionloss[m.jnt_dofadr[j] : m.jnt_dofadr[j] + 3]
        assert dofs == pytest.approx([own[i - 1] + stand_in[i - 1]] * 3)


def test_a_fitted_model_file_exports_its_values(tmp_path: Path) -> None:
    """``--preset FILE.toml``'s model (presets.resolve) exported: the names a lab relies on, the current
    limit as the sliders' range, the torque scale in the gear, the delay, the joints' friction."""
    params = {name: FittedParameter(name, value) for name, value in FITTED.items()}
    toml = tmp_path / "arm.toml"
    write_model_file(toml, ModelFile("prototype", PAPER_PROTOTYPE, params))
    chosen = resolve(str(toml))
    m = exported(tmp_path, chosen.model)
    motor = chosen.model.motor
    for k in range(3):
        a = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, f"motor_{k}")
        assert m.actuator_trnid[a][0] == mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, f"spool_{k}")
        assert m.actuator_ctrlrange[a] == pytest.approx([-10.0, 10.0])
        assert m.actuator_forcerange[a] == pytest.approx([-10.0, 10.0])
        assert m.actuator_gear[a][0] == pytest.approx(18.0 * 1.2)
        assert m.actuator_delay[a] == pytest.approx(0.002)
        assert mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SENSOR, f"tension_{k}") >= 0
        assert mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_TENDON, f"cable_{k}") >= 0
    for name, value in (
        ("spirob_standalone", 1.0),
        ("spirob_torque_scale", 1.2),
        ("spirob_command_delay_s", 0.002),
    ):
        n = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_NUMERIC, name)
        assert m.numeric_data[m.numeric_adr[n]] == pytest.approx(value)
    assert motor.torque_scale == 1.2


# ---------------------------------------------------------------------- the file in plain MuJoCo

TENSION_BOUND_N = 1500.0
"""The largest tension random currents may raise in the exported file. The plant's own peaks under such
input are 400-860 N (docs/plant.md, section 4; 778 N for seed 0's currents here): the 1.3 kg reflected
spool, moving at up to its no-load speed, stopped by the cable, whose limit holds statically about 100x
stiffer than its 48 kN/m stretch. A diverging model passes 2 kN on its way to NaN: the plant's MJCF without
its drives reached 1.7, 2.1 and 64 kN in its last steps before MuJoCo's bad-acceleration warning."""


@pytest.mark.parametrize("seed", [0, 1])
def test_the_exported_file_survives_random_currents_in_its_ctrlrange(tmp_path: Path, seed: int) -> None:
    """The lab's slider test: currents uniform in ±10 A, each held 200 ms, 10 s, plain MuJoCo."""
    m = exported(tmp_path, ModelConfig())
    d = mujoco.MjData(m)
    rng = np.random.default_rng(seed)
    lo, hi = m.actuator_ctrlrange[:, 0], m.actuator_ctrlrange[:, 1]
    largest = 0.0
    for _ in range(50):
        d.ctrl[:] = rng.uniform(lo, hi)
        for _ in range(200):
            mujoco.mj_step(m, d)
            largest = max(largest, float(d.sensordata[: m.nu].max()))
    assert d.time == pytest.approx(10.0)
    assert d.warning[mujoco.mjtWarning.mjWARN_BADQACC].number == 0
    assert np.isfinite(d.qpos).all() and np.isfinite(d.qvel).all()
    assert 100.0 < largest < TENSION_BOUND_N


def random_holds(seed: int, low_a: float, high_a: float, seconds: float) -> np.ndarray:
    """Raw currents (one row per 1 ms period) of random levels in [low, high] A, each held 200 ms."""
    rng = np.random.default_rng(seed)
    levels = rng.integers(round(low_a * 1000), round(high_a * 1000) + 1, size=(round(seconds * 5), 3))
    return np.repeat(levels, 200, axis=0)


def slewed(raw: np.ndarray, a_per_s: float) -> np.ndarray:
    """``raw`` followed at most ``a_per_s`` (the firmware's 50 N/s slew is 2.78 A/s at 18 N/A)."""
    out = np.empty_like(raw)
    now = np.zeros(raw.shape[1])
    step = a_per_s  # raw units (mA) per 1 ms period
    for t, target in enumerate(raw):
        now = now + np.clip(target - now, -step, step)
        out[t] = np.round(now)
    return out


SEQUENCES = {
    # cable 0 at 10 A (the line holds it back), the others 50 mA, then down at the firmware's slew: 4 s
    "line": slewed(np.array([[10_000, 50, 50]] * 400 + [[50, 50, 50]] * 3600), 2.78),
    # random pulls up to the firmware's 3 A, 200 ms each, at the firmware's slew: 2 s
    "pulls": slewed(random_holds(1, 0.03, 3.0, 2.0), 2.78),
    # random currents in ±3 A, 200 ms each, stepped: 5 s
    "steps": random_holds(0, -3.0, 3.0, 5.0),
}


def compare(tmp_path: Path, model: ModelConfig, raw: np.ndarray) -> dict[str, Any]:
    """The same currents into the Plant and into its exported file in plain MuJoCo (ctrl = amps at the same
    times; the file's own delay delays them). Returns the spool positions' largest difference per period,
    the first period a drive is overrun past its no-load speed (where the two drive laws part; ``None``:
    never) and the most current the Plant's torque-speed line withheld."""
    plant = Plant(PAPER_PROTOTYPE, PlantConfig(model=model))
    m = exported(tmp_path, model)
    d = mujoco.MjData(m)
    qadr = spool_addresses(m, "qpos")
    plant_qadr = spool_addresses(plant.mj_model, "qpos")
    motor = model.motor
    periods = motor.command_delay_s / 1e-3
    lag = round(periods)
    assert abs(periods - lag) < 1e-9, "the overrun check delays by whole periods"
    commanded = np.vstack([np.zeros((lag, 3)), raw[: len(raw) - lag]]) / 1000.0
    omega_nl, i_stall = motor.no_load_speed_rad_s, motor.stall_current_a
    error = np.empty(len(raw))
    first = None
    withheld = 0.0
    for t, row in enumerate(raw):
        omega = plant.spool_speeds_rad_s()
        cmd = commanded[t]
        overrun = (omega > omega_nl * (1.0 + np.maximum(-cmd, 0.0) / i_stall)) | (
            omega < -omega_nl * (1.0 + np.maximum(cmd, 0.0) / i_stall)
        )
        if first is None and overrun.any():
            first = t
        plant.apply_currents([int(v) for v in row])
        plant.step()
        withheld = max(withheld, float(np.max(np.abs(cmd) - np.abs(plant.applied_currents_a()))))
        d.ctrl[:] = row / 1000.0
        mujoco.mj_step(m, d)
        error[t] = np.abs(plant.mj_data.qpos[plant_qadr] - d.qpos[qadr]).max()
    assert d.warning[mujoco.mjtWarning.mjWARN_BADQACC].number == 0
    return {"error_m": error, "first_overrun": first, "withheld_a": withheld}


EXACT_M = 1e-8
"""Where the two drive laws agree and μ = 0, the Plant and the file compute the same physics in other float
operations: the dcmotor's voltage and back-EMF (``(V − K·l̇)·K/R`` with ``V = (R/K)·I + K·l̇``: about 1e-16
of the current), and the delay read at float-accumulated times, which misses a sample's time stamp by
~1e-13 s and so mixes in ~1e-10 of the neighbouring setpoint. Measured: 3e-13 m over the 4 s line run,
3e-12 m over 2 s of pulls, 2e-9 m with the 2 ms delay."""


@pytest.mark.parametrize("name", sorted(MODELS))
def test_the_exported_file_is_the_plant_where_mjcf_can_say_it(tmp_path: Path, name: str) -> None:
    """μ = 0 (the capstan friction aside, everything is MJCF): the spools agree to 10 nm, on the
    torque-speed line, in random pulls, and in random ±3 A steps that overrun a spool past its no-load
    speed (both drive laws brake it there)."""
    model = frictionless(MODELS[name])
    line = compare(tmp_path, model, SEQUENCES["line"])
    assert line["withheld_a"] > 0.3  # the torque-speed line held the 10 A back (0.55 A at 0.24 m/s)
    assert line["first_overrun"] is None
    assert line["error_m"].max() < EXACT_M
    pulls = compare(tmp_path, model, SEQUENCES["pulls"])
    assert pulls["error_m"].max() < EXACT_M
    steps = compare(tmp_path, model, SEQUENCES["steps"])
    assert steps["first_overrun"] is not None  # the steps do overrun a spool ...
    assert steps["error_m"].max() < EXACT_M  # ... and the two still agree
    assert steps["withheld_a"] > 2.0  # -3 A paying out a slack cable runs into the line


STAND_IN_M = {"line": 12e-3, "pulls": 10e-3}
"""What freezing the capstan friction costs (μ = 0.3): measured 9.3 / 7.1 mm (prototype) and 8.6 / 4.3 mm
(fitted) on the line and pulls sequences."""


@pytest.mark.parametrize("name", sorted(MODELS))
def test_the_capstan_stand_in_costs_millimetres(tmp_path: Path, name: str) -> None:
    model = MODELS[name]
    assert model.arm.cable_mu == pytest.approx(0.3)
    for sequence, bound in STAND_IN_M.items():
        error = compare(tmp_path, model, SEQUENCES[sequence])["error_m"]
        assert 1e-4 < error.max() < bound, sequence
