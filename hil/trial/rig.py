"""The rig: a virtual board (firmware + plant + radio) in lockstep with a scripted host, built from what a
trial varies, and the same rig put in DIRECT mode for a host that commands cable tensions."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

from controller.config import FirmwareConfig
from hil.board import BoardConfig
from hil.environment import Environment
from hil.radio import RadioScript
from hil.sim.config import ModelConfig, ObjectConfig
from hil.sim.plant import Plant
from hil.sim.spiral import SpiralDesign
from hil.sim.types import PlantConfig, RingConfig
from hil.trial.scene import MS
from protocol.c610 import MotorFeedback
from protocol.dbus import Lever, RcFrame
from protocol.messages import Command, CommandCode, Mode


def rc_frame(right: int = Lever.DOWN, left: int = Lever.DOWN) -> RcFrame:
    """A radio frame with centred sticks and the two levers at ``right`` and ``left``."""
    return RcFrame((0, 0, 0, 0), int(right), int(left))


class _ThreeMotors:
    """The C610 trio seen by the firmware when the arm has fewer cables: the spare motor idles.

    The terminal always has three M2006 motors (Note S6); on a 2-cable arm the third has no cable, so it
    answers with still feedback and its current goes nowhere.
    """

    def __init__(self, plant: Plant) -> None:
        self.plant = plant
        self._spare = MotorFeedback(0, 0, 0, 30)

    def apply_currents(self, raw: Sequence[int]) -> object:
        return self.plant.apply_currents(list(raw))

    def feedback(self) -> Sequence[MotorFeedback]:
        fb = tuple(self.plant.feedback())
        return fb + (self._spare,) * (3 - len(fb))


class Rig(Environment):
    """A trial's environment: a virtual board (firmware + plant + radio) and a scripted host in
    the one lockstep loop, built from what an experiment varies.

    Args:
        design: the arm.
        firmware: firmware configuration.
        radio: the pilot's lever script.
        objects: objects in the scene.
        start_packed: start with the arm coiled on cable 0.
        seed: seed of the board's random choices.
        model: the plant's model (a preset or a sensitivity variant; None = ``ModelConfig()``); the
            objects are appended to its own.
        ring: where an array's arms hang (the firmware's layout gives their number; None = the
            default ring for an array, or the one arm).
    """

    def __init__(
        self,
        design: SpiralDesign,
        firmware: FirmwareConfig,
        radio: Sequence[tuple[int, RcFrame]],
        *,
        objects: Sequence[ObjectConfig] = (),
        start_packed: bool = False,
        seed: int = 0,
        model: ModelConfig | None = None,
        ring: RingConfig | None = None,
    ) -> None:
        base = model if model is not None else ModelConfig()
        plant = dataclasses.replace(PlantConfig(), model=base.with_objects(*objects), ring=ring)
        cfg = BoardConfig(
            design=design, plant=plant, firmware=firmware, rc="radio", seed=seed, start_packed=start_packed
        )
        super().__init__(cfg, radio=RadioScript(list(radio)))
        if design.cables < 3 and firmware.arm_count == 1:
            self.board.bus.motors = _ThreeMotors(self.board.plant)
        self.plant = self.board.plant
        self.firmware = self.board.firmware

    def command(self, code: CommandCode, *args: float) -> None:
        """Send a host command now (it reaches the board on the next tick)."""
        a = [*args, 0.0, 0.0, 0.0][:3]
        self.host.send(self.board.now_us, Command(code, (a[0], a[1], a[2])))

    def set_tensions(self, tensions_n: Sequence[float]) -> None:
        """DIRECT-mode cable tensions (the firmware clamps them to [pretension, tension_max])."""
        t = [*tensions_n, 0.0, 0.0, 0.0][:3]
        self.command(CommandCode.SET_TENSIONS, *t)


def direct_rig(
    design: SpiralDesign,
    firmware: FirmwareConfig,
    *,
    objects: Sequence[ObjectConfig] = (),
    start_packed: bool = False,
    seed: int = 0,
    model: ModelConfig | None = None,
) -> Rig:
    """A rig in DIRECT mode: lever DOWN (arm), MIDDLE at 20 ms, then the host's SET_MODE DIRECT."""
    rig = Rig(
        design,
        firmware,
        [(0, rc_frame()), (20 * MS, rc_frame(Lever.MIDDLE))],
        objects=objects,
        start_packed=start_packed,
        seed=seed,
        model=model,
    )
    for _ in range(200):
        rig.step()
        if rig.firmware.mode == Mode.MANUAL:
            break
    rig.command(CommandCode.SET_MODE, float(Mode.DIRECT))
    for _ in range(50):
        rig.step()
        if rig.firmware.mode == Mode.DIRECT:
            return rig
    raise RuntimeError("the firmware did not enter DIRECT mode")
