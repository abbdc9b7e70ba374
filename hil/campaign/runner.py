"""Running a campaign: one run (:func:`run_one`, a pure function of a :class:`~hil.campaign.spec.Run`), the
JSON-lines results file it streams into (:class:`ResultsFile`), and the executors that fan runs out:
local processes (:func:`execute_local`, the default, no Ray needed) or Ray (:func:`execute_ray`: a local
Ray, or a cluster by address; imported only then).

Each executor yields rows as runs finish, in any order; a row carries its run's key, so the file and
``--resume`` do not care about the order. The same run gives the same row (but its ``run_time_s``) on
every executor: each run builds its own board from its inputs and seed, and shares nothing.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import os
import signal
import socket
import stat
import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import IO, Any

import numpy as np

from hil.campaign.provenance import UNKNOWN, row_stamp
from hil.campaign.spec import CampaignError, Run, build_design, build_firmware
from hil.sim.spiral import SpiralDesign
from hil.trial.array_grasp import ArrayGraspSetup, array_grasp_trial
from hil.trial.grasp import GraspSetup, grasp_trial

__all__ = [
    "MAX_RETRIES_N",
    "POLL_S",
    "RAY_MISSING",
    "ResultsFile",
    "array_setup",
    "check_ray_address",
    "execute_local",
    "execute_ray",
    "grasp_setup",
    "run_one",
    "scenario_measured",
    "stable_row",
]

POLL_S = 0.5
"""How often a waiting executor looks at the stop flag (Ctrl-C) [s]."""

MAX_RETRIES_N = 3
"""Default times a run whose worker died is started again before it is recorded as an error."""

RunFn = Callable[[Run], dict[str, Any]]


def run_one(run: Run) -> dict[str, Any]:
    """Run one campaign run and return its results row (JSON-ready; NaN as null).

    A run that raises is an ``error`` row with the message: one bad run costs that run only.
    """
    t0 = time.perf_counter()
    try:
        kind = run.inputs["kind"]
        measured = _grasp(run) if kind == "grasp" else _array(run) if kind == "array" else _scenario(run)
        outcome = "success" if measured["success"] else "failure"
        error = None
    except Exception as exc:  # a run's failure is data: the campaign goes on
        measured, outcome, error = {}, "error", f"{type(exc).__name__}: {exc}"
    row: dict[str, Any] = {
        "key": run.key,
        "inputs": dict(run.inputs),
        "outcome": outcome,
        "measured": _clean(measured),
        "run_time_s": round(time.perf_counter() - t0, 3),
        "made_by": row_stamp(run.inputs),
    }
    if error is not None:
        row["error"] = error
    return row


def grasp_setup(i: Mapping[str, Any]) -> tuple[GraspSetup, SpiralDesign]:
    """The grasp trial and the arm of a grasp run's inputs."""
    design, model = build_design(i, physics="fine")
    optional = {
        "mass_kg": i.get("object.mass_kg"),
        "length_m": i.get("object.length_m"),
        "object_friction": i.get("object.friction"),
        "release_at_touch": i.get("object.release_at_touch"),
        "strategy_on": i.get("controller.strategy_on"),
        "contact_oracle": i.get("controller.contact_oracle"),
    }
    setup = GraspSetup(
        x_m=i["object.x_m"],
        z_m=i["object.z_m"],
        diameter_m=i["object.diameter_m"],
        firmware=build_firmware(i),
        model=model,
        seed=i["seed"],
        **{k: v for k, v in optional.items() if v is not None},
    )
    return setup, design


def _grasp(run: Run) -> dict[str, Any]:
    setup, design = grasp_setup(run.inputs)
    out = grasp_trial(setup, design).as_dict()
    del out["setup"]  # the row's inputs say it
    return out


def array_setup(i: Mapping[str, Any]) -> ArrayGraspSetup:
    """The array grasp of an array run's inputs: its jitter drawn from the run's seed, its ring the array
    experiment's for the object unless ``array.ring_radius_m`` says (:mod:`hil.experiments.array`)."""
    from hil.experiments.array import ArrayParams, ring_radius_m

    design, model = build_design(i, physics="fine")
    design = design.with_cables(1)
    defaults = ArrayParams()
    jitter = i.get("array.jitter_m", defaults.jitter_m)
    key = i["array.object"]
    rng = np.random.default_rng([i["seed"], i["array.arms"], sum(map(ord, key))])
    offset = tuple(float(v) for v in rng.uniform(-jitter, jitter, 3))
    radius = i.get("array.ring_radius_m")
    if radius is None:
        radius = ring_radius_m(key, dataclasses.replace(defaults, jitter_m=jitter), design)
    return ArrayGraspSetup(
        i["array.arms"],
        key,
        depth_m=i.get("array.depth_m", defaults.depth_m),
        offset_m=(offset[0], offset[1], offset[2]),
        ring_radius_m=radius,
        tilt_rad=math.radians(i.get("array.tilt_deg", 0.0)),
        hold_s=i.get("array.hold_s", defaults.hold_s),
        firmware=build_firmware(i),
        model=model,
        seed=i["seed"],
        design=design,
    )


def _array(run: Run) -> dict[str, Any]:
    setup = array_setup(run.inputs)
    out = array_grasp_trial(setup).as_dict()
    out["ring_radius_m"] = setup.ring_radius_m
    out["offset_m"] = list(setup.offset_m)
    del out["setup"]
    return out


def _scenario(run: Run) -> dict[str, Any]:
    return scenario_measured(run.inputs)[0]


def scenario_measured(
    i: Mapping[str, Any], report_dir: Path | None = None
) -> tuple[dict[str, Any], tuple[str, ...]]:
    """Run a scenario run's inputs: what its row records, and (with ``report_dir``) its report's lines."""
    from hil.faults import Fault
    from hil.scenarios import run_scenario  # the catalogue imports every scenario: only for a scenario run

    design, model = build_design(i)
    faults = [Fault.parse(s) for s in i.get("scenario.faults", [])]
    result = run_scenario(
        i["scenario.name"], seed=i["seed"], design=design, model=model, faults=faults, report_dir=report_dir
    )
    out = result.as_dict()
    for k in ("name", "seed"):
        del out[k]
    out["success"] = out.pop("passed")
    return out, result.report_lines


def _clean(value: Any) -> Any:
    """JSON has no NaN or infinity (null instead), no tuples, no numpy scalars."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_clean(v) for v in value]
    if hasattr(value, "item"):  # a numpy scalar
        return _clean(value.item())
    return value


def stable_row(row: Mapping[str, Any]) -> dict[str, Any]:
    """A row without what differs between executors and machines (its run time): what must be equal."""
    return {k: v for k, v in row.items() if k != "run_time_s"}


# ---------------------------------------------------------------------- the results file


class ResultsFile:
    """A JSON-lines results file, one row per finished run, appended and flushed to disk as each finishes.

    Opening it for a resume reads the rows already there: a torn last line (the writer was killed in the
    middle of it) is cut off, so the next row starts on a line of its own; other unreadable lines are
    counted and left alone (never a crash on bad bytes). A row made by other code or from another model
    file than this process would use (its ``made_by`` is not :func:`~hil.campaign.provenance.row_stamp`
    of its inputs, or it has none) is stale: kept in the file, not done. A run's last row counts, so a
    stale run run again is done.

    Attributes:
        done: the rows already in the file that this code would make, by run key.
        stale: the rows made by other code or from another model file, by run key (none also in ``done``).
        unreadable_n: lines that were not a row (a torn last line included).
    """

    def __init__(self, path: Path, *, resume: bool) -> None:
        """Open ``path`` for appending rows.

        Raises:
            CampaignError: the file exists, is not empty and ``resume`` is False, or cannot be opened.
        """
        self.path = path
        self.done: dict[str, dict[str, Any]] = {}
        self.stale: dict[str, dict[str, Any]] = {}
        self.unreadable_n = 0
        try:
            exists = path.is_file() and path.stat().st_size > 0
            if exists and not resume:
                raise CampaignError(f"{path} already has results: --resume to go on with it, or remove it")
            if exists:
                self._read_and_repair()
            self._out: IO[bytes] = path.open("ab")
            self._probe()
        except OSError as exc:
            raise CampaignError(f"cannot write {path}: {exc.strerror or exc}") from None

    def _probe(self) -> None:
        """Write one byte through to the device before the first run (``-o /dev/full`` opens fine and
        fails only on its first write, which used to come after the first trial), then take it back."""
        fd = self._out.fileno()
        size = os.fstat(fd).st_size
        try:
            self._out.write(b"\n")  # a blank line, which a reader skips, should the truncate not apply
            self._out.flush()
            if stat.S_ISREG(os.fstat(fd).st_mode):
                os.fsync(fd)
                os.ftruncate(fd, size)
        except OSError:
            self._out.close()
            raise

    def _read_and_repair(self) -> None:
        data = self.path.read_bytes()
        end = data.rfind(b"\n") + 1
        if end < len(data):  # a torn last line: cut it off, the run is simply not done
            self.unreadable_n += 1
            with self.path.open("r+b") as f:
                f.truncate(end)
        for line in data[:end].splitlines():
            if not line.strip():
                continue
            try:
                row = json.loads(line)
            except (json.JSONDecodeError, UnicodeDecodeError):
                self.unreadable_n += 1
                continue
            if not (isinstance(row, dict) and isinstance(row.get("key"), str)):
                self.unreadable_n += 1
                continue
            key = row["key"]
            inputs = row.get("inputs")
            stamp = row_stamp(inputs) if isinstance(inputs, dict) else UNKNOWN
            if stamp != UNKNOWN and row.get("made_by") == stamp:
                self.done[key] = row
                self.stale.pop(key, None)
            else:
                self.stale[key] = row
                self.done.pop(key, None)

    def append(self, row: Mapping[str, Any]) -> None:
        """Write one row as one line and push it to the disk (a kill now loses no finished run)."""
        self._out.write(json.dumps(row, allow_nan=False, separators=(",", ":")).encode() + b"\n")
        self._out.flush()
        os.fsync(self._out.fileno())
        self.done[row["key"]] = dict(row)
        self.stale.pop(row["key"], None)

    def close(self) -> None:
        """Close the file."""
        self._out.close()

    def __enter__(self) -> ResultsFile:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()


# ---------------------------------------------------------------------- executors


def _ignore_ctrl_c() -> None:
    """Workers leave Ctrl-C to the parent (a terminal sends it to the whole process group); SIGTERM ends
    them (a forked worker inherits the parent's ``stop_on_signals`` handler, which would make the parent's
    ``terminate()`` wait for the run in flight)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def execute_local(
    runs: Sequence[Run],
    jobs: int,
    stop: threading.Event,
    *,
    fn: RunFn = run_one,
    max_retries: int = MAX_RETRIES_N,
) -> Iterator[dict[str, Any]]:
    """Run ``runs`` over ``jobs`` local worker processes, yielding each row as it finishes.

    At most ``2 * jobs`` runs are in flight. A worker that dies (killed, out of memory) breaks the whole
    pool, and the pool cannot say which run killed it: the runs it held are started again one at a time
    in a new pool, where a death is that run's own; a run whose worker died alone more than
    ``max_retries`` times is an ``error`` row. Stops (terminating its workers) once ``stop`` is set.
    """
    todo = list(reversed(runs))  # popped from the end: the campaign's order
    suspects: list[Run] = []  # in flight when a pool broke: run alone until cleared
    tries: dict[str, int] = {}
    while (todo or suspects) and not stop.is_set():
        pool = ProcessPoolExecutor(max_workers=jobs, initializer=_ignore_ctrl_c)
        running: dict[Future[dict[str, Any]], Run] = {}
        busy = True
        try:
            while (todo or suspects or running) and not stop.is_set():
                if suspects and not running:
                    run = suspects.pop()
                    running[pool.submit(fn, run)] = run
                while todo and not suspects and len(running) < 2 * jobs:
                    run = todo.pop()
                    running[pool.submit(fn, run)] = run
                finished, _ = wait(running, timeout=POLL_S, return_when=FIRST_COMPLETED)
                lost: list[Run] = []
                for fut in finished:
                    run = running.pop(fut)
                    try:
                        yield fut.result()
                    except BrokenProcessPool:
                        lost.append(run)
                if lost:
                    lost.extend(running.values())  # the whole pool is gone with what it held
                    running.clear()
                    yield from _requeue(lost, suspects, tries, max_retries)
                    break
            busy = bool(running)
        finally:
            _stop_pool(pool, busy)


def _requeue(
    lost: list[Run], suspects: list[Run], tries: dict[str, int], max_retries: int
) -> Iterator[dict[str, Any]]:
    """Queue the runs a broken pool held to run alone; a run that was alone when it broke pays a try."""
    if len(lost) > 1:
        suspects.extend(lost)
        return
    run = lost[0]
    tries[run.key] = tries.get(run.key, 0) + 1
    if tries[run.key] > max_retries:
        yield _lost_row(run, tries[run.key])
    else:
        suspects.append(run)


def _stop_pool(pool: ProcessPoolExecutor, busy: bool) -> None:
    """Shut ``pool`` down; ``busy`` (Ctrl-C, a broken pool): terminate its workers first.

    ``ProcessPoolExecutor.shutdown`` lets running runs finish (seconds to minutes each), and Python 3.11
    has no public call to stop them, hence its ``_processes``.
    """
    if busy:
        for p in list((pool._processes or {}).values()):
            if p.is_alive():
                p.terminate()
    pool.shutdown(wait=True, cancel_futures=True)


def _lost_row(run: Run, attempts: int) -> dict[str, Any]:
    return {
        "key": run.key,
        "inputs": dict(run.inputs),
        "outcome": "error",
        "measured": {},
        "run_time_s": 0.0,
        "made_by": row_stamp(run.inputs),
        "error": f"worker lost {attempts} times",
    }


_CONNECT_TIMEOUT_S = 5.0
"""How long ``--ray-address`` may take to accept a TCP connection [s]."""


def init_ray(ray: Any, address: str | None, jobs: int) -> str | None:
    """Start a local Ray of ``jobs`` CPUs on 127.0.0.1 (no dashboard, no usage statistics), or join the
    cluster at ``address``: what campaigns and ``spirob-hil tune --ray`` both do.

    Returns:
        Why Ray could not be started or joined (one line), or None.

    Raises:
        CampaignError: ``address`` is not ``HOST:PORT`` or ``ray://HOST:PORT``.
    """
    if address is not None:
        check_ray_address(address)
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")  # nobody is phoned
    try:
        if address is None:
            ray.init(
                address="local",  # a new node, never a cluster another `ray start` left running here
                num_cpus=jobs,
                include_dashboard=False,
                _node_ip_address="127.0.0.1",
                logging_level=logging.WARNING,
            )
        else:
            ray.init(address=address, logging_level=logging.WARNING)
    except Exception as exc:  # Ray reports a node that timed out starting with a bare Exception
        return f"cannot start or join Ray at {address or 'a local node'}: {exc}"
    return None


def check_ray_address(address: str) -> None:
    """A ``HOST:PORT`` that takes no connection is one line now, not Ray's minute of retries and warnings.

    Raises:
        CampaignError: nothing listens there (other address forms, ``auto`` or ``ray://``, are Ray's).
    """
    if "://" in address or address == "auto":
        return
    host, sep, port = address.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise CampaignError(
            f"--ray-address wants HOST:PORT (what 'ray start --head' printed), got {address!r}"
        )
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=_CONNECT_TIMEOUT_S).close()
    except OSError as exc:
        raise CampaignError(f"cannot reach Ray at {address}: {exc.strerror or exc}") from None


RAY_MISSING = "--ray and --ray-address need Ray: pip install 'spirob-teleop[ray]'"
"""The one line a Ray campaign prints when Ray is not installed."""


def execute_ray(
    runs: Sequence[Run],
    jobs: int,
    stop: threading.Event,
    *,
    address: str | None = None,
    max_retries: int = MAX_RETRIES_N,
) -> Iterator[dict[str, Any]]:
    """Run ``runs`` as Ray tasks, yielding each row as it finishes.

    ``address`` None starts a local Ray of ``jobs`` CPUs on 127.0.0.1 without a dashboard, and stops it at
    the end; otherwise joins the cluster at ``address`` (``ray start --head`` printed it). A task whose
    worker dies is retried by Ray ``max_retries`` times, then recorded as an ``error`` row. At most twice
    the cluster's CPUs are in flight; Ctrl-C (``stop``) cancels them.

    Raises:
        CampaignError: Ray is not installed, or the cluster cannot be reached.
    """
    try:
        import ray
        from ray.exceptions import RayError
    except ImportError:
        raise CampaignError(RAY_MISSING) from None
    why = init_ray(ray, address, jobs)
    if why is not None:
        raise CampaignError(why)
    try:
        task = ray.remote(num_cpus=1, max_retries=max_retries, retry_exceptions=False)(run_one)
        cpus = max(1, int(ray.cluster_resources().get("CPU", jobs)))
        todo = list(reversed(runs))
        running: dict[Any, Run] = {}
        while (todo or running) and not stop.is_set():
            while todo and len(running) < 2 * cpus:
                run = todo.pop()
                running[task.remote(run)] = run
            ready, _ = ray.wait(list(running), num_returns=1, timeout=POLL_S)
            for ref in ready:
                run = running.pop(ref)
                try:
                    yield ray.get(ref)
                except RayError:  # the worker died more than max_retries times
                    yield _lost_row(run, max_retries + 1)
        for ref in running:
            ray.cancel(ref, force=True)
    finally:
        ray.shutdown()
