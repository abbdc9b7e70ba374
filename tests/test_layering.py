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
    bad.write_text("import os\nfrom host.cli import main\nimport hil.sim.plant as p\n", encoding="utf-8")
    assert imported_top_levels(bad) == {"os", "host", "hil"}


# ---------------------------------------------------------------------- module size and import cycles

PACKAGES = ("protocol", "controller", "hil", "host")
MAX_MODULE_LINES = 700


def _sources() -> list[Path]:
    return sorted(f for package in PACKAGES for f in (ROOT / package).rglob("*.py"))


def physical_lines(path: Path) -> int:
    """Lines of a source file as an editor counts them."""
    return len(path.read_text(encoding="utf-8").splitlines())


def test_no_module_over_the_line_limit() -> None:
    sizes = {str(f.relative_to(ROOT)): physical_lines(f) for f in _sources()}
    over = {name: n for name, n in sizes.items() if n > MAX_MODULE_LINES}
    assert not over, f"modules over {MAX_MODULE_LINES} lines (split them along their seams): {over}"


def module_name(path: Path, root: Path) -> str:
    """Dotted module name of a source file under ``root`` (``pkg/__init__.py`` -> ``pkg``)."""
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def imported_modules(path: Path, name: str, known: set[str]) -> set[str]:
    """The modules of ``known`` that one source file imports, anywhere in it (functions included).

    Relative imports are resolved against the file's package; ``from pkg import name`` counts as an
    import of ``pkg.name`` when that is a module, else of ``pkg``; ``import a.b.c`` counts as the
    longest known prefix of ``a.b.c``.
    """
    is_package = path.name == "__init__.py"
    package = name if is_package else name.rpartition(".")[0]
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))

    def longest_known(dotted: str) -> str | None:
        parts = dotted.split(".")
        for n in range(len(parts), 0, -1):
            candidate = ".".join(parts[:n])
            if candidate in known:
                return candidate
        return None

    found: set[str | None] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(longest_known(alias.name) for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base_parts = package.split(".") if package else []
                base_parts = base_parts[: len(base_parts) - (node.level - 1)]
                base = ".".join([*base_parts, node.module] if node.module else base_parts)
            else:
                base = node.module or ""
            for alias in node.names:
                sub = f"{base}.{alias.name}" if base else alias.name
                found.add(sub if sub in known else longest_known(base))
    return {m for m in found if m is not None and m != name}


def import_cycles(root: Path, packages: tuple[str, ...]) -> list[list[str]]:
    """Every import circle among the modules of ``packages`` under ``root`` (Tarjan's SCCs of size > 1)."""
    files = {module_name(f, root): f for p in packages for f in sorted((root / p).rglob("*.py"))}
    known = set(files)
    graph = {name: sorted(imported_modules(f, name, known)) for name, f in files.items()}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            scc: list[str] = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                scc.append(w)
                if w == v:
                    break
            if len(scc) > 1:
                cycles.append(sorted(scc))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(cycles)


def test_no_import_cycle() -> None:
    cycles = import_cycles(ROOT, PACKAGES)
    assert not cycles, f"import circles (break them; a function-local import still counts): {cycles}"


def test_cycle_checker_sees_a_circle(tmp_path: Path) -> None:
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("", encoding="utf-8")
    (pkg / "sub" / "__init__.py").write_text("from .b import thing\n", encoding="utf-8")
    (pkg / "a.py").write_text("import os\n\ndef f():\n    from pkg.sub import b\n", encoding="utf-8")
    (pkg / "sub" / "b.py").write_text("from .. import c\nthing = 1\n", encoding="utf-8")
    (pkg / "c.py").write_text("from pkg import a\n", encoding="utf-8")
    (pkg / "d.py").write_text("import pkg.c\n", encoding="utf-8")
    assert import_cycles(tmp_path, ("pkg",)) == [["pkg.a", "pkg.c", "pkg.sub.b"]]
