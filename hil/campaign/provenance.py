"""What made a campaign row: the code and the model file behind its outcome.

A row is keyed by its run's inputs (:func:`~hil.campaign.spec.run_key`), so a ``--resume`` after the
plant, the firmware or MuJoCo changed would otherwise take rows the old code made for this code's. Each row
carries :func:`row_stamp` (``made_by``): a hash of the code that decides outcomes (:data:`OUTCOME_SOURCES`,
compared as syntax trees without docstrings, so comments, docstrings and formatting do not count), MuJoCo's
and NumPy's versions, and the bytes of a fitted model file the run names (``design.preset``), whose
contents can change under the same name. A results file's rows whose stamp is not this process's are
stale (:class:`~hil.campaign.runner.ResultsFile`).
"""

from __future__ import annotations

import ast
import functools
import hashlib
import importlib.util
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Final

import mujoco
import numpy as np

from hil.sim.presets import is_model_file

__all__ = ["OUTCOME_SOURCES", "UNKNOWN", "code_id", "row_stamp", "source_digest"]

UNKNOWN: Final = "unknown"
"""The stamp of a process that cannot read its outcome code: no row is ever taken as made by it."""

OUTCOME_SOURCES: Final = (
    ("protocol", True),
    ("controller", True),
    ("hil", False),
    ("hil.sim", True),
    ("hil.trial", True),
    ("hil.scenarios", True),
    ("hil.campaign", True),
)
"""The packages whose code decides a run's outcome, and whether their subpackages count too: the wire
formats, the firmware, the harness's top-level modules (board, bus, radio, faults), the plant, the trials,
the scenarios and how a campaign builds and measures a run. The command line, reports, experiments,
tuning and identification only choose runs or read rows."""


def _strip_docstrings(tree: ast.AST) -> ast.AST:
    for node in ast.walk(tree):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            first = node.body[0] if node.body else None
            value = first.value if isinstance(first, ast.Expr) else None
            if isinstance(value, ast.Constant) and isinstance(value.value, str):
                node.body = node.body[1:] or [ast.Pass()]
    return tree


def source_digest(text: str) -> str:
    """A hash of Python source that ignores comments, docstrings and layout (its syntax tree)."""
    tree = _strip_docstrings(ast.parse(text))
    return hashlib.sha256(ast.dump(tree).encode()).hexdigest()


def _package_files(name: str, recursive: bool) -> list[tuple[str, Path]]:
    spec = importlib.util.find_spec(name)
    if spec is None or not spec.submodule_search_locations:
        raise RuntimeError(f"cannot find the package {name!r} to stamp campaign rows with")
    root = Path(next(iter(spec.submodule_search_locations)))
    files = root.rglob("*.py") if recursive else root.glob("*.py")
    return [(f"{name}/{p.relative_to(root).as_posix()}", p) for p in sorted(files)]


@functools.cache
def code_id() -> str:
    """This process's outcome code: :data:`OUTCOME_SOURCES`' syntax trees and the physics libraries'
    versions, hashed (16 hex digits; computed once per process, about a third of a second).
    :data:`UNKNOWN` when the sources cannot be read."""
    h = hashlib.sha256(f"mujoco {mujoco.__version__}; numpy {np.__version__}\n".encode())
    try:
        for name, recursive in OUTCOME_SOURCES:
            for rel, path in _package_files(name, recursive):
                h.update(f"{rel} {source_digest(path.read_text(encoding='utf-8'))}\n".encode())
    except (OSError, RuntimeError, SyntaxError, UnicodeDecodeError, ValueError):
        return UNKNOWN  # e.g. an install without sources
    return h.hexdigest()[:16]


def row_stamp(inputs: Mapping[str, Any], code: str | None = None) -> str:
    """The stamp of a row with these inputs made by ``code`` (default: this process's :func:`code_id`):
    the code, and the bytes of the fitted model file ``design.preset`` names, if it names one (an
    unreadable file stamps as missing: the run itself reports the error); :data:`UNKNOWN` if the code is."""
    code = code or code_id()
    if code == UNKNOWN:
        return UNKNOWN
    h = hashlib.sha256(code.encode())
    preset = inputs.get("design.preset")
    if isinstance(preset, str) and is_model_file(preset):
        try:
            h.update(hashlib.sha256(Path(preset).read_bytes()).digest())
        except OSError:
            h.update(b"missing")
    return h.hexdigest()[:16]
