"""Scenarios: scripted runs of the virtual board, each with measured checks, one module each.

A scenario (:class:`~hil.scenarios.base.Scenario`) is an episode with a plan and checks. :func:`run_scenario`
runs it in lockstep through the one loop (:class:`~hil.environment.Environment`) and is a pure function of
(scenario name, design, seed, extra faults): picklable inputs, a picklable
:class:`~hil.run_record.ScenarioResult` out, no global state, so campaigns can fan out over a process pool or
a distributed engine unchanged. :func:`hil.realtime.run_scenario_on_port` plays the same plan against a
board link in real time and judges it with the same checks.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

from hil.board import BoardConfig
from hil.environment import Environment, Episode
from hil.faults import Fault
from hil.radio import RadioScript
from hil.recording import Recorder
from hil.run_record import TICK_US, Check, RunRecord, ScenarioResult
from hil.scenarios.base import (
    MANUAL,
    MS,
    RC_GAP_CHECK,
    SAFE,
    Plan,
    Scenario,
    largest_unplanned_gap_us,
    rc,
    rc_gap_check,
)
from hil.scenarios.drone_manoeuvre import DroneManoeuvre
from hil.scenarios.excitation import Excitation
from hil.scenarios.grasp import Grasp
from hil.scenarios.host_loss import HostLoss
from hil.scenarios.link_disconnect import LinkDisconnect
from hil.scenarios.link_noise import LinkNoise
from hil.scenarios.manual_teleop import ManualTeleop
from hil.scenarios.motor_silence import MotorSilence
from hil.scenarios.overcurrent import Overcurrent
from hil.scenarios.rc_garbage import RcGarbage
from hil.scenarios.rc_loss import RcLoss
from hil.scenarios.rc_out_of_range import RcOutOfRange
from hil.scenarios.startup_gate import StartupGate
from hil.sim.config import ModelConfig
from hil.sim.spiral import SpiralDesign
from hil.sim.types import PlantConfig

__all__ = [
    "MANUAL",
    "MS",
    "RC_GAP_CHECK",
    "SAFE",
    "SCENARIOS",
    "TICK_US",
    "Check",
    "Plan",
    "Scenario",
    "ScenarioResult",
    "board_config",
    "judge",
    "largest_unplanned_gap_us",
    "rc",
    "run_scenario",
    "scenario_names",
]

SCENARIOS: dict[str, type[Scenario]] = {
    s.name: s
    for s in (
        StartupGate,
        ManualTeleop,
        RcLoss,
        RcGarbage,
        RcOutOfRange,
        MotorSilence,
        LinkNoise,
        LinkDisconnect,
        HostLoss,
        Overcurrent,
        Grasp,
        DroneManoeuvre,
        Excitation,
    )
}
"""The catalogue, in the order ``spirob-hil list`` shows it."""


def scenario_names() -> list[str]:
    """Every scenario, in the order of the catalogue."""
    return list(SCENARIOS)


def board_config(
    plan: Plan, seed: int, design: SpiralDesign | None = None, model: ModelConfig | None = None
) -> BoardConfig:
    """The virtual board a plan runs on (objects added to the scene, the plan's firmware settings);
    ``model`` is the plant model (default: the prototype's, ``hil.sim.presets``)."""
    plant = PlantConfig() if model is None else PlantConfig(model=model)
    if plan.objects:
        plant = dataclasses.replace(plant, model=plant.model.with_objects(*plan.objects))
    return BoardConfig(
        design=design if design is not None else SpiralDesign.paper_prototype(),
        plant=plant,
        firmware=plan.firmware,
        rc="radio",
        seed=seed,
        start_packed=plan.start_packed,
    )


def judge(scenario: Scenario, run: RunRecord, plan: Plan) -> tuple[Check, ...]:
    """The scenario's checks, then the run's own validity (the RC stream had no unplanned gap)."""
    return (*scenario.checks(run, plan), rc_gap_check(run, plan))


def run_scenario(
    name: str,
    *,
    seed: int = 0,
    design: SpiralDesign | None = None,
    model: ModelConfig | None = None,
    faults: Sequence[Fault] = (),
    record: str | Path | None = None,
    progress: Callable[[int, int], None] | None = None,
    report_dir: str | Path | None = None,
    options: Mapping[str, object] | None = None,
) -> ScenarioResult:
    """Run one scenario in lockstep and measure its checks.

    Args:
        name: a name from :data:`SCENARIOS`.
        seed: seed of every random choice in the run.
        design: the arm (default: the paper's 3-cable prototype).
        model: the plant model (default: the prototype's; see :mod:`hil.sim.presets`).
        faults: faults added to the scenario's own.
        record: write an MCAP recording of every byte in and out of the board.
        progress: called as ``progress(ticks_done, ticks_total)`` every 100 ticks.
        report_dir: write the run's report there: a PNG of its signals (``NAME.png``), pictures of its
            moments rendered from the run's own states and, where the arm moves, a GIF
            (:mod:`hil.render`), listed in ``NAME.md``.
        options: the scenario's own options (``excitation``: ``profile_name``, ``tip_noise_m``, ``tip_seed``).

    Raises:
        KeyError: unknown scenario name.
        TypeError: an option the scenario does not take.
        ValueError: an option value it refuses.
    """
    scenario = SCENARIOS[name](**(options or {}))
    plan = scenario.plan()
    plan = dataclasses.replace(plan, faults=(*plan.faults, *faults))
    config = board_config(plan, seed, design, model)
    recorder = None
    if record is not None:
        meta = {"scenario": name, **config.describe()}
        meta["faults"] = ";".join(repr(f) for f in plan.faults)
        if plan.drone is not None:  # only then: every other recording stays byte-identical
            meta["drone"] = repr(plan.drone)
        meta.update(scenario.recording_metadata())
        recorder = Recorder(record, metadata=meta)
    watcher = None
    report_lines: tuple[str, ...] = ()
    episode: Episode = scenario
    if report_dir is not None:  # the report's pictures are of this run's own states
        from hil.render import Film, FilmingEpisode, MomentWatcher

        watcher = MomentWatcher(Film())
        episode = FilmingEpisode(scenario, watcher)
    try:
        env = Environment(
            config,
            episode=episode,
            faults=plan.faults,
            radio=RadioScript(plan.radio),
            host_script=plan.host,
            heartbeats=plan.heartbeats,
            recorder=recorder,
            record_ticks=scenario.duration_us // config.plant.control_period_us,
            drone=plan.drone,
        )
        with env:
            env.run(scenario.duration_us, progress=progress)
            run = env.record(scenario.duration_us)
            if watcher is not None:
                watcher.finish(env)
        checks = judge(scenario, run, plan)
        if report_dir is not None and watcher is not None:
            from hil.report import write_run_report  # matplotlib only when a report is asked for

            report_lines = tuple(write_run_report(run, watcher.film, report_dir, name).lines())
    finally:
        if recorder is not None:
            recorder.close()
    return ScenarioResult(name, seed, checks, scenario.duration_us, run.counters, run.extremes, report_lines)
