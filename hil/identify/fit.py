"""Fit the plant's uncertain parameters to recordings, on MuJoCo's own system-identification toolbox.

The pieces are ``mujoco.sysid``'s: the parameters (:class:`mujoco.sysid.ParameterDict`, with bounds), the
measured data (:class:`mujoco.sysid.ModelSequences`: the arm's MJCF with the motors' view added as sensors,
and one measured sequence per recording), the residual (:func:`mujoco.sysid.build_residual_fn`) and the solver
(:func:`mujoco.sysid.optimize`, MuJoCo's Levenberg-Marquardt with a finite-difference Jacobian). Two hooks
are ours: the rollout (:mod:`hil.identify.rollout`: the project's :class:`~hil.sim.plant.Plant`, whose drives
and capstan friction live in Python, in worker processes) and the residual's shape (cable lengths measured
from each window's start, speeds, and the tracked tip when recorded).

Each parameter is optimized in units of its own size (a factor of the preset's value, or a stated scale),
so one finite-difference step (1 %) means the same for all. Every recording is simulated from its first
sample (the only instant whose state is known: friction keeps a bent arm where it was left), up to a share
of the budget of simulated seconds per evaluation; what comes after, and any recording beyond the budget,
is held out: the held-out error is measured on data the fit never saw, with each recording simulated
whole from its start.

**Intervals that are honest.** :func:`mujoco.sysid.calculate_intervals` assumes independent residuals;
a simulated arm's errors are smooth in time, so its intervals are far too narrow. Both are computed: the
toolbox's, and a heteroskedasticity-and-autocorrelation-consistent one (Newey-West sandwich around the same
Jacobian, with each window's bandwidth read from its residual's autocorrelation, and Student's t on the
effective number of samples), widened by how far the fit stopped from its minimum (a Gauss-Newton step:
:func:`~hil.identify.intervals.remaining_step`). The second is reported and decides whether a parameter is
identifiable (its half-width within 10 % of its value: :data:`~hil.identify.intervals.IDENTIFIED_WITHIN`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import math
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

import mujoco
import numpy as np
import scipy.stats
from mujoco import sysid
from numpy.typing import NDArray

from hil.errors import HilError
from hil.identify import scale_tie
from hil.identify.excitation import OPENING_S
from hil.identify.intervals import (
    ParamEstimate,
    estimates,
    fd_floor,
    hac_covariance,
    remaining_step,
    unexplained,
)
from hil.identify.motor_data import MotorData
from hil.identify.rollout import RolloutJob, RolloutPool
from hil.identify.starts import DELAY_CELLS_S, restarts, settled_m
from hil.identify.sysid_report import write_sysid_report
from hil.identify.windows import CH, LEN, Trace, Window, at_samples, prepare_window, rms_of_traces
from hil.sim.config import ModelConfig
from hil.sim.mjcf import build_mjcf
from hil.sim.spiral import SpiralDesign
from hil.sim.uncertain import ID_PARAMS, IdParam, apply, nominal

__all__ = ["FitError", "FitOptions", "FitResult", "fit", "objective_at"]

FloatArray = NDArray[np.float64]

SENSORS: Final = (*(f"{kind}_{i}" for kind in ("tension", "len", "vel") for i in range(3)), "tip")
"""The model's sensors: the cable tensions (not measured), the motors' view (wound cable and its speed per
spool) and the tracked tip."""


_SOLVER_TUNING: dict[str, Any] = {"mu_factor": 10.0, "x_scale": "jac"}
"""How MuJoCo's Levenberg-Marquardt (``mujoco.minimize.least_squares``) moves its regularizer. Its defaults
raise it by 10^0.1 after a failed step, from 1e-6, against a Hessian in the residual's own units: near the
optimum one iteration tried dozens of candidates. Scaled by the Jacobian's columns and raised tenfold, a fit
of four parameters on a ``tiny`` recording ran 62 rollouts instead of 146 for the same 11 iterations."""


START_OFF_BOUND: Final = {"delay": 0.002}
"""Where the search starts for a parameter whose preset sits on a search bound (the prototype has no
delay): two control periods, the command's way to the ESC and the ESC's own loop. Started just above 0,
the other parameters made up for a delay (joint friction, damping, capstan friction) and pressed it to 0
(docs/identify.md section 7)."""


class FitError(HilError):
    """A fit cannot start (one line: why)."""


@dataclass(frozen=True, slots=True)
class FitOptions:
    """How to fit.

    Attributes:
        params: the parameters to fit (names of :data:`~hil.sim.uncertain.ID_PARAMS`); the others
            keep the preset's values.
        budget_s: simulated seconds per evaluation of the residual, shared among the recordings (each
            fitted from its start up to its share, at least ``min_span_s``). Default: two recordings'
            openings, which two cores simulate side by side.
        min_span_s: the shortest stretch of a recording worth fitting (a recording that would get less is
            held out whole). Default: the excitation's opening, one segment of each kind (``OPENING_S``).
        max_iters: Levenberg-Marquardt iterations at most (the hidden-truth fits of one opening converge
            in 11-24, docs/identify.md section 7).
        fd_step: finite-difference step, in each parameter's own units (1 % of its size).
        jobs: worker processes for the rollouts (None: one per core).
        residual_period_s: the residual's sample period (the data are decimated to it).
        sigma_length_m: the length residual's unit (sets its weight against the others).
        sigma_speed_m_s: the speed residual's unit.
        sigma_tip_m: the tracked tip's unit (when recorded).
        use_speed: count the spools' speeds.
        use_tip: count the tracked tip when an recording has it.
        explained_within_m: the largest RMS error of the fitted cable lengths (on the samples the fit
            saw, as the restarts judge it) at which the fit still explains the data; above it no
            parameter is called identified. None (the default): the sensors' own noise (``settled_m``,
            about 0.6 um on the prototype). Every interval assumes the fit found the arm's own minimum,
            and a fit that leaves more than the sensors' noise did not, or has a model that cannot follow
            the arm: on hidden-truth draws the fits that left 1.7-88 um called a wrong value identified
            in 5 of 13, those that settled in none of 16 (docs/identify.md section 7). A larger bound
            (the twin's accuracy target, 0.3 mm) is the weaker claim of a lab that trusts its model.
        jacobian: the rollouts' constraint Jacobian (:attr:`~hil.sim.config.SolverConfig.jacobian`), or
            None to keep the preset's (a fit of a synthetic recording made on ``auto`` resolves the
            rounding between them). ``dense`` is about 1.5x faster here (docs/identify.md section 2).
        restarts: starts after the first, at most (:mod:`hil.identify.starts`: the delay in its other
            cells first, then scattered in the box), each a whole fit, taken
            while the best so far leaves more than the sensors' own noise (``settled_m``); the lowest
            objective is kept. The preset itself is one more start when it beats them all.
        horizons_s: horizon continuation: every start is first fitted to each recording's first
            seconds only, each of these horizons in turn (shortest first; those not shorter than the
            fitted span are skipped), each stage from the last one's values, then to the whole span. A slip
            that a parameter's change flips changes every length after it (friction holds the difference),
            so the objective of a long simulation is a field of pits; over a few seconds there are few
            slips to flip, and on hidden-truth draw 26 the objective falls smoothly from the stuck fit to the
            truth over 3 or 6 s but not over 10 or 14.5 s (docs/identify.md section 6). Empty: off.
        horizon_iters: Levenberg-Marquardt iterations at most in each horizon's stage.
        scale_coordinates: the solver walks the force scale as a coordinate (:mod:`.scale_tie`).
    """

    params: tuple[str, ...] = tuple(p.name for p in ID_PARAMS)
    budget_s: float = 2.0 * OPENING_S
    min_span_s: float = OPENING_S
    max_iters: int = 24
    fd_step: float = 0.01
    jobs: int | None = None
    residual_period_s: float = 0.005
    sigma_length_m: float = 1e-4
    sigma_speed_m_s: float = 5e-3
    sigma_tip_m: float = 1e-3
    use_speed: bool = True
    use_tip: bool = True
    explained_within_m: float | None = None
    jacobian: str | None = "dense"
    restarts: int = 0
    horizons_s: tuple[float, ...] = ()
    horizon_iters: int = 12
    scale_coordinates: bool = True


@dataclass(frozen=True)
class FitResult:
    """A finished fit.

    Attributes:
        estimates: one per identified parameter, in table order.
        model: the fitted model (the preset with every fitted value written in).
        preset_model: the model the fit started from.
        traces: every recording, simulated whole: its fitted and held-out samples.
        condition_number: of the scaled Jacobian at the optimum (large: parameters trade against each other).
        correlation: the parameters' correlation matrix (order of ``estimates``).
        iterations: the kept start's solver iterations (in the whole span, after any horizon stages).
        rollouts: simulations run.
        simulated_s: seconds simulated in all.
        wall_s: the fit's wall time.
        recordings: (name, sha256, duration) of each recording used.
        objective: the kept start's objective after each of its iterations, then at its end point.
        converged: the kept start had converged.
        starts: per start run, its final objective and its fitted cable lengths' RMS error [m] (the first
            start first; the kept one has the lowest objective).
    """

    estimates: tuple[ParamEstimate, ...]
    model: ModelConfig
    preset_model: ModelConfig
    traces: tuple[Trace, ...]
    condition_number: float
    correlation: FloatArray
    iterations: int
    rollouts: int
    simulated_s: float
    wall_s: float
    recordings: tuple[tuple[str, str, float], ...]
    objective: tuple[float, ...] = field(default=())
    converged: bool = True
    starts: tuple[tuple[float, float], ...] = field(default=())

    @property
    def last_reduction(self) -> float:
        """How much the last iteration lowered the objective, as a fraction of it (0: it stopped moving)."""
        if len(self.objective) < 2 or self.objective[-2] <= 0:
            return 0.0
        return 1.0 - self.objective[-1] / self.objective[-2]

    def rms_m(self, held_out: bool, which: str = "fitted") -> float:
        """RMS length error over the fitted (or held-out) samples of every recording, of the fitted or
        ``nominal`` model."""
        return rms_of_traces(self.traces, held_out, which)


def _spans(recordings: Sequence[MotorData], options: FitOptions) -> list[tuple[MotorData, int]]:
    """How far each fitted recording is simulated: the budget shared evenly, at least ``min_span_s`` each
    (the recordings that then get nothing are held out whole)."""
    fitted = list(recordings)
    while len(fitted) > 1 and options.budget_s / len(fitted) < options.min_span_s:
        fitted.pop()
    share = options.budget_s / len(fitted)
    return [(rec, rec.index_after(share)) for rec in fitted]


def _spec(design: SpiralDesign, model: ModelConfig) -> Any:
    spec = mujoco.MjSpec.from_string(build_mjcf(design, None, model))
    sensors = mujoco.mjtSensor
    for prefix, kind in (("len", sensors.mjSENS_JOINTPOS), ("vel", sensors.mjSENS_JOINTVEL)):
        for k in range(3):
            spec.add_sensor(
                name=f"{prefix}_{k}", type=kind, objtype=mujoco.mjtObj.mjOBJ_JOINT, objname=f"spool_{k}"
            )
    spec.add_sensor(
        name="tip",
        type=mujoco.mjtSensor.mjSENS_FRAMEPOS,
        objtype=mujoco.mjtObj.mjOBJ_SITE,
        objname="tip",
        reftype=mujoco.mjtObj.mjOBJ_BODY,
        refname="drone",
    )
    return spec


def _timeseries(t_s: FloatArray, data: FloatArray, model: Any) -> Any:
    return sysid.TimeSeries.from_names(t_s, data, model, list(SENSORS))


class _Problem:
    """The pieces the toolbox calls back: the model from a parameter vector, the rollout, the residual."""

    def __init__(
        self,
        design: SpiralDesign,
        preset: ModelConfig,
        rows: Sequence[IdParam],
        wins: list[Window],
        options: FitOptions,
        pool: RolloutPool,
    ) -> None:
        self.design = design
        self.preset = preset
        self.rows = list(rows)
        self.preset_values = nominal(preset)
        self.wins = wins
        self.options = options
        self.pool = pool
        self.spec = _spec(design, preset)
        self.mj_model = self.spec.compile()
        self._by_measured: dict[int, Window] = {}
        self._controls: dict[int, int] = {}
        self._cache: dict[tuple[int, tuple[float, ...]], FloatArray] = {}
        self.weights = np.array(
            [0.0] * 3
            + [1 / options.sigma_length_m] * 3
            + [1 / options.sigma_speed_m_s if options.use_speed else 0.0] * 3
            + [1 / options.sigma_tip_m if options.use_tip else 0.0] * 3
        )

    # Parameters in the optimizer's coordinates (hil.sim.uncertain.IdParam.to_x) <-> SI.
    def params(self, off_bounds: bool = True) -> Any:
        """The preset's values; with ``off_bounds``, :data:`START_OFF_BOUND`'s start for one on a bound."""
        pd = sysid.ParameterDict()
        for p in self.rows:
            v0 = self.preset_values[p.name]
            if p.relative and not v0 > 0:
                raise FitError(f"{p.name}: the preset's value {v0} cannot scale a relative search")
            lo, hi = p.x_bounds(v0)
            x0 = p.to_x(v0, v0)
            if off_bounds and p.name in START_OFF_BOUND and x0 in (lo, hi):
                x0 = p.to_x(START_OFF_BOUND[p.name], v0)
            pd.add(sysid.Parameter(p.name, x0, lo, hi))
        return pd

    def si_values(self, pd: Any) -> dict[str, float]:
        return {p.name: p.value_at(float(pd[p.name].value[0]), self.preset_values[p.name]) for p in self.rows}

    def model_for(self, pd: Any) -> ModelConfig:
        return self.for_rollout(apply(self.preset, self.si_values(pd)))

    def for_rollout(self, model: ModelConfig) -> ModelConfig:
        """``model`` with the fit's constraint Jacobian (:attr:`FitOptions.jacobian`)."""
        jac = self.options.jacobian
        if jac is None or model.solver.jacobian == jac:
            return model
        return dataclasses.replace(model, solver=dataclasses.replace(model.solver, jacobian=jac))

    def build_model(self, pd: Any, spec: Any) -> Any:
        return self.mj_model  # the rollout builds its own plant; the toolbox needs the layout only

    def measured(self) -> Any:
        m = self.mj_model
        initial = sysid.create_initial_state(m, m.qpos0, np.zeros(m.nv))
        series = [_timeseries(w.sample_t_s, w.measured, m) for w in self.wins]
        controls = [self._control(w) for w in self.wins]
        # The toolbox hands the hooks one window at a time, with that window's own series (the controls
        # are not resampled): the hooks find their window by identity.
        self._by_measured = {id(ts): w for ts, w in zip(series, self.wins, strict=True)}
        self._controls = {id(c): i for i, c in enumerate(controls)}
        return sysid.ModelSequences(
            "arm",
            self.spec,
            [w.recording.name for w in self.wins],
            [initial] * len(self.wins),
            controls,
            series,
        )

    def _control(self, w: Window) -> Any:
        t = w.t0_s + np.arange(len(w.currents_a)) * 1e-3
        return sysid.TimeSeries.from_control_names(t, w.currents_a, self.mj_model)

    def rollout(self, *, control_signal: Sequence[Any], param_dicts: Sequence[Any], **_: Any) -> list[Any]:
        """The toolbox asks for one window at a time (every candidate of a Jacobian at once): the first
        ask of a batch runs every window of every candidate in parallel, the others are then cached."""
        which = [self._controls[id(c)] for c in control_signal]
        keys = [(which[i % len(which)], self._key(pd)) for i, pd in enumerate(param_dicts)]
        missing = [k for k in keys if k not in self._cache]
        if missing:
            wanted = {key for _, key in keys}
            self._cache = {k: v for k, v in self._cache.items() if k[1] in wanted}
            batch = sorted({key for _, key in missing})
            vectors = {self._key(pd): pd for pd in param_dicts}
            jobs = [(i, key) for key in batch for i in range(len(self.wins))]
            outs = self.pool.map(
                [
                    RolloutJob(self.design, self.model_for(vectors[key]), self.wins[i].currents_a)
                    for i, key in jobs
                ]
            )
            self._cache.update(dict(zip(jobs, outs, strict=True)))
        trajs = []
        m = self.mj_model
        nstate = mujoco.mj_stateSize(m, mujoco.mjtState.mjSTATE_FULLPHYSICS)
        for key in keys:
            out = self._cache[key]
            w = self.wins[key[0]]
            t = np.asarray(w.t0_s + (np.arange(len(out)) + 1) * 1e-3, dtype=np.float64)
            state = np.zeros((2, 1 + nstate))
            state[:, 0] = t[:2]
            trajs.append(
                sysid.SystemTrajectory(
                    model=m,
                    control=self._control(w),
                    sensordata=_timeseries(t, out, m),
                    initial_state=np.zeros(nstate),
                    state=sysid.TimeSeries(t[:2], state, None),
                )
            )
        return trajs

    def _key(self, pd: Any) -> tuple[float, ...]:
        return tuple(float(v) for v in pd.as_vector())

    def residual(
        self, params: Any, pred: Any, measured: Any, model: Any, return_pred_all: bool, **_: Any
    ) -> Any:
        w = self._by_measured[id(measured)]
        sim = at_samples(w, pred.data)
        r = (sim - w.measured) * self.weights
        r[~np.isfinite(w.measured)] = 0.0
        r[~np.isfinite(r)] = 1e6  # a diverged rollout: a huge residual, never NaN
        pred_ts = sysid.TimeSeries(measured.times, sim, measured.signal_mapping)
        return r.ravel(), pred_ts, measured


ProgressFn = Callable[[str, float], None]
"""Called with a stage and the fraction of the fit done (0..1, estimated)."""


@dataclass(order=True)
class _Run:
    """One start's fit (ordered by its final objective: the least is kept)."""

    final: float
    params: Any = field(compare=False)
    result: Any = field(compare=False)
    objective: list[float] = field(compare=False)
    steps: list[FloatArray] = field(compare=False)
    res: list[Any] = field(compare=False)
    length_rms_m: float = field(compare=False)


def _solve(
    start: Any,
    residual_fn: Any,
    opts: FitOptions,
    say: ProgressFn,
    k: int,
    stage: str = "",
    part: tuple[float, float] = (0.0, 1.0),
) -> _Run:
    """MuJoCo's Levenberg-Marquardt from ``start`` (the ``k``-th restart, 0 the first start, one past the
    restarts the preset's own start; ``stage`` names a horizon's stage in the progress, ``part`` the share
    of the start's progress it runs in). The starts share the progress up to 0.9 (then the report): one
    slot each and one for the preset's, so it never passes 0.9 nor goes back."""
    objective: list[float] = []
    steps: list[FloatArray] = []
    label = (
        "from the preset: "
        if k > opts.restarts
        else (f"start {k + 1} of at most {opts.restarts + 1}: " if k else "")
    ) + stage
    slots = opts.restarts + 2

    def on_iter(trace: list[Any]) -> None:  # a log per iteration, then one at the end point (no step)
        n, last = len(trace), trace[-1].step is None
        objective.append(float(trace[-1].objective))
        if not last:
            steps.append(np.abs(np.asarray(trace[-1].step, dtype=np.float64).ravel()))
        done = part[0] + (part[1] - part[0]) * n / (opts.max_iters + 2)
        what = (
            f"the end point, after {n - 1} iterations"
            if last
            else f"iteration {n} of at most {opts.max_iters}"
        )
        say(label + what, 0.9 * (k + done) / slots)

    say(f"{label}first evaluation", 0.9 * (k + part[0]) / slots)
    params, result = (scale_tie.optimize if opts.scale_coordinates else sysid.optimize)(
        start,
        residual_fn,
        optimizer="mujoco",
        verbose=False,
        max_iters=opts.max_iters,
        eps=opts.fd_step,
        **_SOLVER_TUNING,
        iter_callback=on_iter,
        output=io.StringIO(),  # the solver's own per-iteration lines: the progress callback says it
    )
    res = residual_fn(params.as_vector(), params)[0]
    lengths = np.concatenate([r.reshape(-1, CH)[:, LEN].ravel() for r in res])
    rms = float(np.sqrt(np.mean(lengths**2))) * opts.sigma_length_m if lengths.size else math.nan
    final = objective[-1] if objective else math.inf
    return _Run(final, params, result, objective, steps, res, rms)


@contextlib.contextmanager
def _objective(
    recordings: Sequence[MotorData], preset: ModelConfig, opts: FitOptions, design: SpiralDesign | None
) -> Iterator[tuple[_Problem, Any, Any]]:
    """The fit's problem, its residual function (the toolbox's, around our rollout) and the measured
    sequences, with the rollouts' worker pool open."""
    if not recordings:
        raise FitError("no recordings")
    designs = {rec.design for rec in recordings if rec.design is not None}
    if design is None:
        if len(designs) > 1:
            raise FitError("the recordings were made with different arm designs")
        design = next(iter(designs)) if designs else SpiralDesign.paper_prototype()
    rows = [r for r in ID_PARAMS if r.name in opts.params]
    if not rows:
        raise FitError("no parameter to fit")
    chosen = [prepare_window(rec, end, opts.residual_period_s) for rec, end in _spans(recordings, opts)]
    with RolloutPool(opts.jobs) as pool:
        problem = _Problem(design, preset, rows, chosen, opts, pool)
        residual_fn, measured = _residual_fn(problem)
        yield problem, residual_fn, measured


def _residual_fn(problem: _Problem) -> tuple[Any, Any]:
    """The toolbox's residual function around ``problem``'s rollout, and its measured sequences."""
    measured = problem.measured()
    residual_fn = sysid.build_residual_fn(
        models_sequences=[measured],
        build_model=problem.build_model,
        custom_rollout=problem.rollout,
        modify_residual=problem.residual,
        n_threads=1,
        resample_true=False,
    )
    return residual_fn, measured


def _continued(start: Any, problem: _Problem, opts: FitOptions, say: ProgressFn, k: int) -> Any:
    """``start`` carried through the horizons' stages (:attr:`FitOptions.horizons_s`): each fits every
    window's first seconds from the last stage's values."""
    at = start
    stage_opts = dataclasses.replace(opts, max_iters=opts.horizon_iters)
    horizons = sorted(opts.horizons_s)
    for i, h in enumerate(horizons):
        wins = [
            prepare_window(w.recording, min(w.end, w.recording.index_after(h)), opts.residual_period_s)
            for w in problem.wins
        ]
        if all(w.end == full.end for w, full in zip(wins, problem.wins, strict=True)):
            break  # the horizon covers what the fit sees: the whole stage is next
        sub = _Problem(problem.design, problem.preset, problem.rows, wins, opts, problem.pool)
        part = (0.5 * i / len(horizons), 0.5 * (i + 1) / len(horizons))  # the stages: a start's first half
        at = _solve(at, _residual_fn(sub)[0], stage_opts, say, k, f"the first {h:g} s: ", part).params
        at = at.move_off_bounds()  # a stage may end on a bound (no delay): the next starts inside
    return at


def objective_at(
    recordings: Sequence[MotorData],
    preset: ModelConfig,
    options: FitOptions,
    points: Sequence[Mapping[str, float]],
    *,
    design: SpiralDesign | None = None,
) -> list[tuple[float, float]]:
    """The fit's objective and its cable-length RMS error [m] (on the samples the fit sees) at each of
    ``points`` (the fitted parameters' values, in their units; a parameter a point leaves out keeps the
    preset's): the landscape the solver walks, e.g. along the line from a fit to a hidden truth.

    Raises:
        FitError: as :func:`fit`.
    """
    out: list[tuple[float, float]] = []
    with _objective(recordings, preset, options, design) as (problem, residual_fn, _):
        at = problem.params(off_bounds=False)
        for point in points:
            x = np.array(
                [
                    r.to_x(point.get(r.name, problem.preset_values[r.name]), problem.preset_values[r.name])
                    for r in problem.rows
                ]
            )
            pd = at.copy()
            pd.update_from_vector(x)
            res = residual_fn(x, pd)[0]
            flat = np.concatenate([np.asarray(a, dtype=np.float64).ravel() for a in res])
            lengths = np.concatenate([np.asarray(a).reshape(-1, CH)[:, LEN].ravel() for a in res])
            rms = float(np.sqrt(np.mean(lengths**2))) * options.sigma_length_m if lengths.size else math.nan
            out.append((0.5 * float(flat @ flat), rms))
    return out


def fit(
    recordings: Sequence[MotorData],
    preset: ModelConfig,
    options: FitOptions | None = None,
    *,
    design: SpiralDesign | None = None,
    progress: ProgressFn | None = None,
    sysid_report: Path | None = None,
) -> FitResult:
    """Fit the plant to the recordings.

    Args:
        recordings: the recordings (each with its windows).
        preset: the model to start from (and to keep where a parameter is not fitted).
        options: how to fit.
        design: the arm (default: the one the first recording names, else the prototype).
        progress: told how far the fit has come.
        sysid_report: write MuJoCo's own report of the fit into this folder (``report.html``; two more
            evaluations of the residual).

    Raises:
        FitError: nothing to fit, or the recordings disagree on the arm.
    """
    opts = options or FitOptions()
    t_start = time.monotonic()
    say = progress or (lambda stage, frac: None)
    with _objective(recordings, preset, opts, design) as (problem, residual_fn, measured):
        pool = problem.pool
        rows = problem.rows
        # A parameter whose preset sits on a bound (no joint friction) starts a little inside:
        # Levenberg-Marquardt can stall in a corner of the box.
        initial = problem.params().move_off_bounds()
        last = (0.5, 1.0) if opts.horizons_s else (0.0, 1.0)  # the whole span's share of each start
        runs = [_solve(_continued(initial, problem, opts, say, 0), residual_fn, opts, say, 0, "", last)]
        settled = settled_m(recordings)
        lower, upper = initial.get_bounds()
        names = [r.name for r in rows]
        d = names.index("delay") if "delay" in names else -1  # the delay's other cells first (starts.py)
        cells = (
            None if d < 0 else (d, [rows[d].to_x(v, problem.preset_values["delay"]) for v in DELAY_CELLS_S])
        )
        for k, x in enumerate(restarts(initial.as_vector(), lower, upper, opts.restarts, cells), start=1):
            if not min(runs).length_rms_m > settled:  # explained to the sensors' noise, or unknown
                break
            start = initial.copy()
            start.update_from_vector(x)
            runs.append(_solve(_continued(start, problem, opts, say, k), residual_fn, opts, say, k, "", last))
        # The preset itself where the search started off a bound (no delay, no joint friction): on an arm
        # that is the preset (the virtual board) the search did not return to it (docs/identify.md 6).
        at_preset = problem.params(off_bounds=False)
        res0 = residual_fn(at_preset.as_vector(), at_preset)[0]
        if 0.5 * sum(float(np.sum(np.square(r))) for r in res0) < min(runs).final:
            runs.append(_solve(at_preset, residual_fn, opts, say, opts.restarts + 1))
        best = min(runs)
        opt_params, result, objective, steps = best.params, best.result, best.objective, best.steps
        converged_below = 1e-3  # an iteration that still lowered the objective more: not converged
        jac = np.asarray(result.jac, dtype=np.float64)
        x = opt_params.as_vector()
        _, naive = sysid.calculate_intervals(best.res, jac)
        firsts = np.cumsum([0] + [len(r) for r in best.res])
        blocks = [(int(a), len(r), CH) for a, r in zip(firsts[:-1], best.res, strict=True)]
        res_all = np.concatenate(best.res)
        cov, n_eff = hac_covariance(jac, res_all, blocks)
        more = remaining_step(jac, res_all, x, lower, upper)  # how far it stopped from the minimum
        dof = max(1.0, n_eff - len(rows))
        quant = float(scipy.stats.t.ppf(0.975, dof))
        sd = np.sqrt(np.maximum(np.diag(cov), 1e-300))
        half = quant * sd
        corr = cov / np.outer(sd, sd)
        cond = float(np.linalg.cond(jac)) if jac.size else math.nan
        fitted_si = problem.si_values(opt_params)
        fitted_model = apply(preset, fitted_si)
        # Converged: the solver stopped on its own, the objective no longer fell, the last step moved
        # every parameter by less than half its interval (further steps cannot take it out of it), or the
        # fit explains the data to the sensors' noise: what is left to explain is noise, its steps wander
        # in it, and the interval is widened by the step to the minimum anyway (``remaining_step``).
        converged = (
            len(objective) <= opts.max_iters
            or best.length_rms_m <= settled
            or (len(objective) >= 2 and 1.0 - objective[-1] / max(objective[-2], 1e-300) < converged_below)
            or (bool(steps) and len(steps[-1]) == len(half) and bool(np.all(steps[-1] <= 0.5 * half)))
        )
        if sysid_report is not None:
            say("MuJoCo's report", 0.9)
            write_sysid_report(
                sysid_report, problem.build_model, measured, initial, opt_params, residual_fn, result
            )
        say("measured against simulated", 0.95)
        traces = _traces(
            problem, recordings, {w.recording.name: w.end for w in problem.wins}, fitted_model, preset, pool
        )
        fitted_estimates = estimates(
            problem.preset_values,
            rows,
            x,
            half,
            np.asarray(naive, dtype=float),
            corr,
            None if converged else len(objective),
            unexplained(best.length_rms_m, opts.explained_within_m, settled),
            more,
            fd_floor(x, opts.fd_step),
        )
        return FitResult(
            estimates=fitted_estimates,
            model=fitted_model,
            preset_model=preset,
            traces=traces,
            condition_number=cond,
            correlation=corr,
            iterations=max(0, len(objective) - 1),  # the solver's last log is its end point
            rollouts=pool.rollouts,
            simulated_s=pool.simulated_s,
            wall_s=time.monotonic() - t_start,
            recordings=tuple((rec.name, rec.sha256, rec.duration_s) for rec in recordings),
            objective=tuple(objective),
            converged=converged,
            starts=tuple((r.final, r.length_rms_m) for r in runs),
        )


def _traces(
    problem: _Problem,
    recordings: Sequence[MotorData],
    fit_ends: dict[str, int],
    fitted: ModelConfig,
    preset: ModelConfig,
    pool: RolloutPool,
) -> tuple[Trace, ...]:
    """Every recording simulated whole from its start with the fitted and the preset model; a sample is
    held out when the fit never simulated it."""
    wins = [prepare_window(rec, len(rec.t_s), problem.options.residual_period_s) for rec in recordings]
    models = [problem.for_rollout(m) for m in (fitted, preset)]
    jobs = [RolloutJob(problem.design, m, w.currents_a) for m in models for w in wins]
    outs = pool.map(jobs)
    n = len(wins)
    traces = []
    for i, w in enumerate(wins):
        end = fit_ends.get(w.recording.name, 0)
        idx = np.searchsorted(w.recording.t_s, w.sample_t_s - 1e-9)
        traces.append(
            Trace(
                w.recording.name,
                w.sample_t_s,
                idx >= end,
                w.measured[:, LEN],
                at_samples(w, outs[i])[:, LEN],
                at_samples(w, outs[n + i])[:, LEN],
            )
        )
    return tuple(traces)
