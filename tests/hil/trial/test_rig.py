"""The rig (hil.trial.rig): the one lockstep loop built from what a trial varies."""

from __future__ import annotations

from controller.config import FirmwareConfig
from hil.sim.config import ArmConfig, ModelConfig, ObjectConfig
from hil.sim.spiral import SpiralDesign
from hil.trial.rig import Rig


def test_the_rig_runs_the_given_model_with_the_objects_appended() -> None:
    model = ModelConfig(arm=ArmConfig(base_stiffness_nm_per_rad=0.3))
    obj = ObjectConfig("can", radius_m=0.01, length_m=0.05, pos_m=(0.5, 0.0, 0.5), mass_kg=0.02)
    rig = Rig(SpiralDesign.paper_prototype(), FirmwareConfig(), [], objects=(obj,), model=model)
    used = rig.plant.config.model
    assert used.arm.base_stiffness_nm_per_rad == 0.3 and used.objects == (obj,)
    rig.close()
