"""06 - A scripted radio: grasp the default pole headless, record it, exit 0 only if HOLD was reached.

Run: ``.venv/bin/python examples/06_scripted_grasp.py`` (the virtual board's start-up, then about 10 s
of board time). The same as the command line

    spirob-host --headless --virtual-rc-script examples/06_scripted_grasp.toml \\
        --record runs/06_scripted_grasp.mcap

What it shows:

1. ``--virtual-rc-script``: ``06_scripted_grasp.toml`` is a timeline of lever positions, each step
   waiting for board time and for what the board reports (the start-up gate, GRASP mode, the arm packed,
   the left lever UP until the grasp state machine reports HOLD, 2 s of HOLD); the run ends with it and
   exits 0 only if every step was reached (1 otherwise, with one line naming the step);
2. ``--record``: the run in MCAP (``runs/06_scripted_grasp.mcap``, under the current directory), which
   Foxglove opens and ``spirob-host --replay`` plays into the panel;
3. the recording read back: the grasp states the board reported, in order.
"""

from __future__ import annotations

import itertools
import sys
from pathlib import Path

from hil.foxglove_log import TELEMETRY
from hil.recording import read_records
from host.cli import main

SCRIPT = Path(__file__).with_suffix(".toml")
RECORDING = Path("runs") / "06_scripted_grasp.mcap"


def grasp_states(path: Path) -> list[str]:
    """The grasp states the recording's telemetry went through, in order (repeats folded)."""
    names = (rec.json()["grasp_state_name"] for rec in read_records(path, topics={TELEMETRY}))
    return [name for name, _ in itertools.groupby(names)]


def run() -> int:
    RECORDING.parent.mkdir(exist_ok=True)
    status = main(["--headless", "--virtual-rc-script", str(SCRIPT), "--record", str(RECORDING)])
    if status != 0:
        return status  # the host said why in one line
    states = grasp_states(RECORDING)
    print(f"06_scripted_grasp: {RECORDING} holds the grasp states {' -> '.join(states)}")
    if "HOLD" not in states:
        print(f"06_scripted_grasp: {RECORDING} shows no HOLD", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(run())
