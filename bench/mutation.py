"""Mutation benchmark of the safety-critical code: how many deliberate bugs on its safety lines do the tests
catch? (issue 26: "a green suite can hide a board that stalls itself", the tests' strength measured).

Cosmic Ray (``cosmic-ray``) makes the mutants: a comparison flipped, a number changed, a ``not`` added or
dropped, ``and`` for ``or``, an operator swapped. This benchmark keeps the mutants on the *safety lines*
(:data:`TARGETS`: the failsafe's phase logic, the current clamp and the tension governor, the motor bus's
limit and shutdown, the parameters' type/bounds checks, the link parser and its CRCs, the panel's Origin
and token guard) and, for arithmetic, one swap per site (``+``/``-``, ``*``/``/``, ...) rather than
Cosmic Ray's every operator. Each mutant runs the module's own tests (:data:`TARGETS`' ``tests``); a
mutant is *killed* when a test fails or it hangs past the time-out, *survived* when every test passes.

Cosmic Ray edits the module in place, so the run works on a copy of the repository's tracked files (``git
ls-files``) in a temporary directory, never on the working tree.

Prints per module: mutants, killed, survived, kill rate with its Wilson 95 % interval, and every survivor
(file:line, operator, the line). Rows go to ``--out`` (JSON lines). Goal: no surviving mutant on a safety
line; each survivor is either killed by a new test or explained in docs/security.md.

Usage: ``.venv/bin/python bench/mutation.py [--module controller/failsafe.py ...] [--sample N] [--jobs 2]``
"""

from __future__ import annotations

import argparse
import ast
import concurrent.futures
import dataclasses
import json
import os
import shutil
import sqlite3
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
# Run as a script, this file's directory comes first on sys.path, where bench/protocol.py would shadow
# the protocol package; benchmarks import the project only.
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != ROOT / "bench"]

from hil.experiments.stats import wilson_interval  # noqa: E402


@dataclasses.dataclass(frozen=True)
class Target:
    """A module's safety lines (its classes, functions or ``Class.method``s) and the tests that guard them."""

    names: tuple[str, ...]
    tests: tuple[str, ...]


_FW = "tests/controller/test_firmware.py"
"""The firmware's own tests: every safety module runs inside it."""

TARGETS: dict[str, Target] = {
    "controller/failsafe.py": Target(
        ("Failsafe",), ("tests/controller/test_failsafe.py", "tests/controller/test_modes.py", _FW)
    ),
    "controller/cables.py": Target(
        (
            "CableMapper._clamp",
            "CableMapper.direct",
            "TensionSlew.step",
            "MotorModel.govern",
            "MotorModel.tension_to_raw",
            "MotorModel.tensions_to_raw",
        ),
        ("tests/controller/test_cables.py", "tests/controller/test_hot_path_equivalence.py", _FW),
    ),
    "controller/motorbus.py": Target(
        (
            "MotorBus.__init__",
            "MotorBus.current_limit_raw",
            "MotorBus.send_currents",
            "MotorBus.read_feedback",
            "MotorBus.shutdown",
        ),
        ("tests/controller/test_motorbus.py", _FW),
    ),
    "controller/params.py": Target(
        ("Range.contains", "Param.check_type", "Param.check_bounds", "Param.coerce", "Param.from_wire"),
        ("tests/controller/test_params.py", "tests/controller/test_commands.py"),
    ),
    "protocol/link.py": Target(
        ("crc8", "crc16", "encode_frame", "LinkParser.feed"),
        ("tests/protocol/test_link.py", "tests/protocol/test_stream.py", "tests/controller/test_hostlink.py"),
    ),
    "host/panel/guard.py": Target(
        (
            "_host_name",
            "_host_port",
            "request_token",
            "PanelGuard._token_ok",
            "PanelGuard._origin_ok",
            "PanelGuard.check",
        ),
        ("tests/host/panel/test_guard.py",),
    ),
}
"""Each module's safety lines and the tests that guard them (its own, and the firmware's that run it)."""

KEPT_BINARY = {
    "Add_Sub",
    "Sub_Add",
    "Mul_Div",
    "Div_Mul",
    "FloorDiv_Mul",
    "Mod_FloorDiv",
    "BitAnd_BitOr",
    "BitOr_BitAnd",
    "BitXor_BitOr",
    "LShift_RShift",
    "RShift_LShift",
    "Pow_Mul",
}
"""The one arithmetic swap kept per operator site (Cosmic Ray makes a dozen; most are equivalent noise)."""

_NOT_WALL = "'not realtime and not browser and not mavproxy and not ray'"
"""The mutants run the tests that judge logic; wall-clock tests would turn load into kills."""

TIMEOUT_S = 120.0
"""A mutant whose tests run longer than this is killed (a hang the suite's time-out would catch)."""


def line_ranges(path: Path, names: tuple[str, ...]) -> list[tuple[int, int]]:
    """The 1-based line ranges of ``names`` (``Class``, ``func`` or ``Class.method``) in ``path``.

    Raises:
        SystemExit: a name is not defined there (the table above is out of date).
    """
    tree = ast.parse(path.read_text())
    found: dict[str, tuple[int, int]] = {}
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            found[node.name] = (node.lineno, node.end_lineno or node.lineno)
        if isinstance(node, ast.ClassDef):
            for sub in node.body:
                if isinstance(sub, ast.FunctionDef):
                    # A property's setter shares its getter's name: keep the widest span.
                    key = f"{node.name}.{sub.name}"
                    lo, hi = sub.lineno, sub.end_lineno or sub.lineno
                    if sub.decorator_list:
                        lo = min(d.lineno for d in sub.decorator_list)
                    old = found.get(key)
                    found[key] = (min(lo, old[0]), max(hi, old[1])) if old else (lo, hi)
    missing = [n for n in names if n not in found]
    if missing:
        raise SystemExit(f"bench/mutation.py: {path}: no {', '.join(missing)} (update TARGETS)")
    return [found[n] for n in names]


def kept(operator: str) -> bool:
    """Cosmic Ray's operator name is one this benchmark runs."""
    prefix = "core/ReplaceBinaryOperator_"
    return not operator.startswith(prefix) or operator[len(prefix) :] in KEPT_BINARY


def copy_tracked(dst: Path) -> None:
    """Copy the repository's tracked files (and the working tree's versions of them) into ``dst``."""
    files = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, check=True, capture_output=True).stdout
    for rel in files.decode().split("\0"):
        if not rel:
            continue
        src = ROOT / rel
        if src.is_file():
            (dst / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dst / rel)


def run_module(module: str, target: Target, work: Path, sample: int | None, seed: int) -> dict[str, Any]:
    """Make, filter and run one module's mutants in its own copy of the repository; its row."""
    import random

    repo = work / module.replace("/", "_")
    copy_tracked(repo)
    python = sys.executable
    tests = " ".join(target.tests)
    config = repo / "cosmic-ray.toml"
    config.write_text(
        "[cosmic-ray]\n"
        f'module-path = "{module}"\n'
        f"timeout = {TIMEOUT_S}\n"
        "excluded-modules = []\n"
        f'test-command = "{python} -m pytest -x -q -p no:cacheprovider -o addopts= -m {_NOT_WALL} {tests}"\n'
        '[cosmic-ray.distributor]\nname = "local"\n'
    )
    session = repo / "session.sqlite"
    cosmic = str(Path(python).parent / "cosmic-ray")
    subprocess.run([cosmic, "init", str(config), str(session)], cwd=repo, check=True, capture_output=True)
    ranges = line_ranges(repo / module, target.names)
    with sqlite3.connect(session) as db:
        rows = db.execute("select job_id, operator_name, start_pos_row from mutation_specs").fetchall()
        keep = [j for j, op, row in rows if kept(op) and any(lo <= row <= hi for lo, hi in ranges)]
        if sample is not None and len(keep) > sample:
            keep = random.Random(seed).sample(keep, sample)
        drop = set(j for j, _, _ in rows) - set(keep)
        db.executemany("delete from mutation_specs where job_id = ?", [(j,) for j in drop])
        db.executemany("delete from work_items where job_id = ?", [(j,) for j in drop])
    t0 = time.monotonic()
    subprocess.run([cosmic, "exec", str(config), str(session)], cwd=repo, check=True, capture_output=True)
    wall_s = time.monotonic() - t0
    lines = (repo / module).read_text().splitlines()
    with sqlite3.connect(session) as db:
        results = db.execute(
            "select s.operator_name, s.start_pos_row, s.definition_name, r.worker_outcome, r.test_outcome "
            "from mutation_specs s join work_results r on s.job_id = r.job_id"
        ).fetchall()
    # Cosmic Ray's outcomes: worker NORMAL / ABNORMAL (a hang past the time-out) / EXCEPTION / NO_TEST;
    # test KILLED / SURVIVED / INCOMPETENT. A hang is a kill: the suite's time-out would fail it.
    results = [(op, row, fn, str(w).upper(), str(t).upper()) for op, row, fn, w, t in results]
    killed = [r for r in results if r[4] == "KILLED" or r[3] == "ABNORMAL"]
    survived = [r for r in results if r[4] == "SURVIVED" and r[3] == "NORMAL"]
    other = len(results) - len(killed) - len(survived)
    lo, hi = wilson_interval(len(killed), len(killed) + len(survived))
    return {
        "module": module,
        "mutants": len(results),
        "killed": len(killed),
        "survived": len(survived),
        "not_run": other,
        "kill_rate": len(killed) / max(1, len(killed) + len(survived)),
        "kill_rate_wilson95": [lo, hi],
        "sampled": sample,
        "wall_s": wall_s,
        "survivors": [
            {"line": row, "operator": op, "function": fn, "source": lines[row - 1].strip()}
            for op, row, fn, _, _ in sorted(survived, key=lambda r: r[1])
        ],
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--module", action="append", choices=sorted(TARGETS), help="only these (default: all)")
    ap.add_argument("--sample", type=int, default=None, help="at most N mutants per module (seeded sample)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1), help="modules run at once")
    ap.add_argument("--out", type=Path, default=Path("runs/bench-mutation.jsonl"))
    args = ap.parse_args()
    if shutil.which("cosmic-ray", path=str(Path(sys.executable).parent)) is None:
        print("bench/mutation.py: cosmic-ray is not installed (pip install -e '.[test]')", file=sys.stderr)
        return 2
    modules = args.module or sorted(TARGETS)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    rows: list[dict[str, Any]] = []
    with (
        tempfile.TemporaryDirectory(prefix="bench-mutation-") as tmp,
        concurrent.futures.ProcessPoolExecutor(max_workers=args.jobs) as pool,
    ):
        futures = {
            pool.submit(run_module, m, TARGETS[m], Path(tmp), args.sample, args.seed): m for m in modules
        }
        for fut in concurrent.futures.as_completed(futures):
            row = fut.result()
            rows.append(row)
            with args.out.open("a") as f:
                f.write(json.dumps(row) + "\n")
            lo, hi = row["kill_rate_wilson95"]
            print(
                f"{row['module']:<24} mutants {row['mutants']:4d}  killed {row['killed']:4d}  survived "
                f"{row['survived']:3d}  not run {row['not_run']:2d}  "
                f"kill rate {100 * row['kill_rate']:5.1f} % [{100 * lo:.0f}, {100 * hi:.0f}]  "
                f"({row['wall_s']:.0f} s)",
                flush=True,
            )
            for s in row["survivors"]:
                print(f"    survived {row['module']}:{s['line']} {s['operator']}: {s['source']}", flush=True)
    k = sum(r["killed"] for r in rows)
    n = k + sum(r["survived"] for r in rows)
    lo, hi = wilson_interval(k, n)
    print(
        f"all safety lines: {k} of {n} mutants killed, kill rate {100 * k / max(1, n):.1f} % "
        f"[{100 * lo:.0f}, {100 * hi:.0f}] (Wilson 95 %); goal: no survivor"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
