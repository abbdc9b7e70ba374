"""The solver's coordinates along the arm's force scale, when the torque constant is fitted.

Scaling the torque constant, every joint's stiffness, the spool's inertia and the drive's friction by one
factor changes a recording only through what does not scale (gravity on the arm's known mass, its own
inertia, the cable's stretch): on draw 106's truth, 1 % along that direction moves the cable lengths by
2.8 µm RMS, 1 % of the base stiffness alone by 44 µm (docs/identify.md section 3). In the fit's own
coordinates (each parameter's logarithm) that direction is a diagonal, the least singular direction of the
Jacobian, and a finite-difference Jacobian over a rough objective (stick-slip) gets it wrong: the solver
then walks the valley slowly or stops in it.

:class:`ScaleTie` gives the solver the direction as a coordinate of its own: ``z_s = x_s`` for the torque
constant and ``z_p = x_p - x_s`` for each partner fitted with it, so the force scale is one column of the
Jacobian, taken directly by finite differences, and the partners are their ratios to it. A linear change
of coordinates: the objective, its minimum and the intervals (computed back in the parameters' own
coordinates, ``J_x = J_z M^-1``) are the same. :func:`optimize` is :func:`mujoco.sysid.optimize` in them.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import Any, Final

import numpy as np
from mujoco import sysid
from numpy.typing import NDArray

__all__ = ["PARTNERS", "SCALE", "ScaleTie", "optimize"]

FloatArray = NDArray[np.float64]

SCALE: Final = "torque_scale"
PARTNERS: Final = ("base_stiffness", "rotor_inertia", "drive_friction")
"""The parameters whose effects scale with the torque constant's (all in logarithmic coordinates)."""


class ScaleTie:
    """``x = M z``: the fitted parameters' coordinates from the solver's (identity when the torque
    constant or all its partners are not fitted)."""

    def __init__(self, names: Sequence[str]) -> None:
        names = list(names)
        n = len(names)
        self.s = names.index(SCALE) if SCALE in names else -1
        self.partners = [names.index(p) for p in PARTNERS if p in names] if self.s >= 0 else []
        self.m = np.eye(n)
        for p in self.partners:
            self.m[p, self.s] = 1.0
        self.m_inv = np.linalg.inv(self.m)

    @property
    def active(self) -> bool:
        """The coordinates differ from the parameters' own."""
        return bool(self.partners)

    def to_z(self, x: FloatArray) -> FloatArray:
        return np.asarray(self.m_inv @ np.asarray(x, dtype=np.float64), dtype=np.float64)

    def to_x(self, z: FloatArray) -> FloatArray:
        return np.asarray(self.m @ np.asarray(z, dtype=np.float64), dtype=np.float64)

    def z_bounds(self, lower: FloatArray, upper: FloatArray) -> tuple[FloatArray, FloatArray]:
        """A box in ``z`` that holds every ``x`` of the box ``lower..upper`` (a partner's ratio spans its
        own range less the scale's); an ``x`` outside the box is clipped to it (:func:`optimize`)."""
        lo = np.asarray(lower, dtype=np.float64).copy()
        hi = np.asarray(upper, dtype=np.float64).copy()
        if self.active:
            s_lo, s_hi = lo[self.s], hi[self.s]
            for p in self.partners:
                lo[p], hi[p] = lower[p] - s_hi, upper[p] - s_lo
        return lo, hi

    def jacobian_x(self, jac_z: FloatArray) -> FloatArray:
        """The residual's Jacobian in the parameters' coordinates: ``dr/dx = dr/dz M^-1``."""
        return np.asarray(np.asarray(jac_z, dtype=np.float64) @ self.m_inv, dtype=np.float64)


def optimize(
    start: Any,
    residual_fn: Callable[..., Any],
    *,
    iter_callback: Callable[[list[Any]], None],
    **kwargs: Any,
) -> tuple[Any, Any]:
    """:func:`mujoco.sysid.optimize` from ``start`` in :class:`ScaleTie`'s coordinates (as it is when they
    are the parameters' own): the parameters, and the result with its ``x`` and ``jac`` in the
    parameters' coordinates; the steps the callback sees are too."""
    tie = ScaleTie(list(start.keys()))
    if not tie.active:
        out: tuple[Any, Any] = sysid.optimize(start, residual_fn, iter_callback=iter_callback, **kwargs)
        return out
    lower, upper = (np.asarray(b, dtype=np.float64) for b in start.get_bounds())
    z_lo, z_hi = tie.z_bounds(lower, upper)
    z0 = tie.to_z(start.as_vector())
    z_start = sysid.ParameterDict()
    for i, name in enumerate(start.keys()):
        z_start.add(sysid.Parameter(f"z_{name}", float(z0[i]), float(z_lo[i]), float(z_hi[i])))
    at = start.copy()

    def x_of(z: FloatArray) -> FloatArray:
        """Columns of ``z`` (a candidate, or the finite differences' batch) as clipped ``x``."""
        z = np.asarray(z, dtype=np.float64)
        x = tie.to_x(z.reshape(len(lower), -1))
        return np.clip(x, lower[:, None], upper[:, None]).reshape(z.shape)

    def in_z(z: FloatArray, _: Any) -> Any:
        return residual_fn(x_of(z), at)

    def on_iter(trace: list[Any]) -> None:
        last = trace[-1]
        if last.step is not None:
            step = tie.to_x(np.asarray(last.step, dtype=np.float64).ravel())
            trace = [*trace[:-1], dataclasses.replace(last, step=step)]
        iter_callback(trace)

    z_params, result = sysid.optimize(z_start, in_z, iter_callback=on_iter, **kwargs)
    x = x_of(np.asarray(z_params.as_vector(), dtype=np.float64).ravel())
    params = start.copy()
    params.update_from_vector(x)
    result.x = x
    result.jac = tie.jacobian_x(result.jac)
    return params, result
