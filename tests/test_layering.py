"""The packages import only downward: protocol <- controller <- hil <- host (docs/architecture.md)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# What each package must never import (its own layer's superiors and the heavy libraries it must not see).
FORBIDDEN: dict[str, set[str]] = {
    "protocol": {"controller", "hil", "host", "serial", "can", "mujoco", "viser"},
    "controller": {"hil", "host", "mujoco", "viser", "pymavlink"},
    "hil": {"host", "viser"},
    "host": set(),
}


def imported_top_levels(path: Path) -> set[str]:
    """Top-level module names imported anywhere in one source file (absolute imports only)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_package_imports_only_downward(package: str) -> None:
    files = sorted((ROOT / package).rglob("*.py"))
    assert files, f"package {package} has no sources"
    offenders = {str(f.relative_to(ROOT)): sorted(imported_top_levels(f) & FORBIDDEN[package]) for f in files}
    offenders = {k: v for k, v in offenders.items() if v}
    assert not offenders, f"{package} imports upward or forbidden modules: {offenders}"


def test_checker_sees_a_violation(tmp_path: Path) -> None:
    bad = tmp_path / "bad.py"
    bad.write_text("import os\nfrom host.cli import main\nimport hil.plant as p\n", encoding="utf-8")
    assert imported_top_levels(bad) == {"os", "host", "hil"}
