"""05: identification without hardware: a plant whose damping and base stiffness you do not know,
recorded through the real sensors' limits, fitted back, and the fitted model used as a preset.

The hidden plant's base joint is 30 % stiffer than the prototype's and its joints 50 % more damped. A 5 s
excitation (the ``tiny`` profile: a ramp and steps, in DIRECT mode) is recorded on the virtual board;
``hil.identify.fit`` recovers the two numbers with their 95 % intervals; the model file it writes is a
preset like any other (``--preset arm.toml`` on every command).

Run: ``.venv/bin/python examples/05_identify.py`` (about a minute on two cores). The lab's version of the
same is three commands: ``spirob-host --port /dev/ttyACM0 --excite --record excite.mcap``, ``spirob-hil
identify excite.mcap -o arm.toml --report fit/``, ``spirob-hil run grasp --preset arm.toml``.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

from hil.identify.fit import FitOptions, fit
from hil.identify.motor_data import load_motor_data
from hil.identify.synthetic import SensorLimits, record_truth
from hil.scenarios import run_scenario
from hil.sim.config import ModelConfig
from hil.sim.model_file import FittedParameter, ModelFile, write_model_file
from hil.sim.presets import resolve


def main() -> int:
    preset = ModelConfig()
    truth = {
        "base_stiffness": 1.3 * preset.arm.base_stiffness_nm_per_rad,
        "damping_ratio": 1.5 * preset.arm.damping_ratio,
    }
    with tempfile.TemporaryDirectory() as tmp:
        recording = Path(tmp) / "excite.mcap"
        record_truth(recording, truth, seed=1, profile_name="tiny", limits=SensorLimits(20.0, 0.0, 0))
        data = load_motor_data(recording)
        print(f"recorded {data.duration_s:.1f} s of the board's CAN frames ({recording.name})")
        result = fit(
            [data], preset, FitOptions(params=tuple(truth), budget_s=6.0, min_span_s=4.0, max_iters=8)
        )
        for e in result.estimates:
            lo, hi = e.interval
            print(
                f"{e.name:15s} preset {e.preset:.4g}  truth {truth[e.name]:.4g}  fitted {e.value:.4g} "
                f"[{lo:.4g}, {hi:.4g}] {e.unit}  "
                + ("identified" if e.identifiable else f"not identified: {e.why}")
            )
        print(
            f"cable lengths, fitted model: {result.rms_m(False) * 1e3:.3f} mm RMS "
            f"(the prototype's: {result.rms_m(False, 'nominal') * 1e3:.3f} mm)"
        )
        model_file = Path(tmp) / "arm.toml"
        write_model_file(
            model_file,
            ModelFile(
                "prototype",
                data.design or resolve("prototype").spiral(),
                {
                    e.name: FittedParameter(
                        e.name, e.value, e.unit, e.interval, e.identifiable, e.preset, e.why
                    )
                    for e in result.estimates
                },
            ),
        )
        fitted = resolve(str(model_file))
        check = run_scenario("manual-teleop", model=fitted.model, design=fitted.spiral())
        print(
            f"manual-teleop on the fitted model ({model_file.name}): {'passed' if check.passed else 'FAILED'}"
        )
        ok = all(abs(e.value / truth[e.name] - 1.0) < 0.1 for e in result.estimates) and check.passed
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
