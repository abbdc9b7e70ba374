"""MuJoCo's own report of a fit (``mujoco.sysid.default_report``): its parameters, signals and covariance,
beside the project's (:mod:`hil.identify.report`)."""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path
from typing import Any

from mujoco import sysid

__all__ = ["write_sysid_report"]

_log = logging.getLogger(__name__)


def write_sysid_report(
    out: Path,
    build_model: Callable[[Any, Any], Any],
    measured: Any,
    initial: Any,
    fitted: Any,
    residual_fn: Any,
    result: Any,
) -> None:
    """Write ``report.html`` into ``out``; a failure of it is logged, never fatal (the fit stands
    without its view)."""
    try:
        out.mkdir(parents=True, exist_ok=True)
        builder = sysid.default_report(
            [measured],
            initial,
            fitted,
            residual_fn,
            result,
            title="SpiRob identification (mujoco.sysid)",
            save_path=out,  # it saves ``save_path / "report.html"`` itself: a Path, not a str
            build_model=build_model,
            generate_videos=False,
        )
        if not (out / "report.html").exists():
            builder.save(str(out / "report.html"))
    except Exception as exc:  # the report is a view of the fit, which stands without it
        _log.warning("MuJoCo's own report failed: %s: %s", type(exc).__name__, exc)
