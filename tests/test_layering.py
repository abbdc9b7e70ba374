"""The house's rules: packages import only downward (protocol <- controller <- hil <- host), no module over
700 lines, no import circle, no folder crowded with modules sharing a prefix, physics that knows no harness,
and one import path per name (docs/architecture.md)."""

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


# ---------------------------------------------------------------- folders, physics, import paths


def _sibling_modules(folder: Path) -> list[str]:
    """Module names in one folder: its .py files (not __init__) and its sub-packages."""
    names = [f.stem for f in folder.glob("*.py") if f.name != "__init__.py"]
    names += [d.name for d in folder.iterdir() if d.is_dir() and (d / "__init__.py").exists()]
    return sorted(names)


def crowded_prefixes(folder: Path, exempt: frozenset[str] = frozenset()) -> dict[str, list[str]]:
    """Name prefixes (the part before the first ``_``) shared by more than two sibling modules of ``folder``.

    A folder whose modules share a prefix is a package waiting to be made (``drone_link``,
    ``drone_params``, ``drone_servo`` -> ``drone/``); ``exempt`` names (modules named after what they
    implement, such as scenarios) do not count.
    """
    groups: dict[str, list[str]] = {}
    for name in _sibling_modules(folder):
        if name not in exempt:
            groups.setdefault(name.split("_")[0], []).append(name)
    return {prefix: names for prefix, names in groups.items() if len(names) > 2}


def _scenario_modules() -> frozenset[str]:
    from hil.scenarios import SCENARIOS

    return frozenset(name.replace("-", "_") for name in SCENARIOS)


def test_no_folder_has_three_modules_sharing_a_prefix() -> None:
    scenario_modules = _scenario_modules()
    crowded = {}
    for package in PACKAGES:
        for folder in [ROOT / package, *(p.parent for p in (ROOT / package).rglob("*/__init__.py"))]:
            found = crowded_prefixes(folder, scenario_modules if folder.name == "scenarios" else frozenset())
            if found:
                crowded[str(folder.relative_to(ROOT))] = found
    assert not crowded, f"sibling modules sharing a name prefix (make the package): {crowded}"


def test_prefix_checker_sees_a_crowd(tmp_path: Path) -> None:
    for name in ("drone_link", "drone_params", "drone_servo", "panel", "panel_plots", "scene"):
        (tmp_path / f"{name}.py").write_text("", encoding="utf-8")
    (tmp_path / "drone").mkdir()
    (tmp_path / "drone" / "__init__.py").write_text("", encoding="utf-8")
    assert crowded_prefixes(tmp_path) == {"drone": ["drone", "drone_link", "drone_params", "drone_servo"]}
    assert crowded_prefixes(tmp_path, frozenset({"drone", "drone_link"})) == {}


PHYSICS = "hil.sim"
"""The simulated arm: MuJoCo, the drives, the design math. It knows no harness (faults, recordings,
the simulated CAN bus where bytes cross, the board, scenarios)."""
PHYSICS_MAY_IMPORT = ("hil.sim", "hil.errors", "controller", "protocol")


def test_physics_imports_no_harness() -> None:
    files = {module_name(f, ROOT): f for p in PACKAGES for f in sorted((ROOT / p).rglob("*.py"))}
    known = set(files)
    offenders = {}
    for name, path in files.items():
        if name != PHYSICS and not name.startswith(PHYSICS + "."):
            continue
        bad = sorted(
            m
            for m in imported_modules(path, name, known)
            if not any(m == ok or m.startswith(ok + ".") for ok in PHYSICS_MAY_IMPORT)
        )
        if bad:
            offenders[name] = bad
    assert not offenders, f"physics modules import the harness: {offenders}"


def _definitions(path: Path) -> tuple[set[str], dict[str, tuple[str, str]]]:
    """Names a module defines at top level, and the names it imports (name -> (module, original name))."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    defined: set[str] = set()
    imported: dict[str, tuple[str, str]] = {}
    for node in tree.body:
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            defined.add(node.name)
        elif isinstance(node, ast.Assign | ast.AnnAssign):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            defined.update(n.id for t in targets for n in ast.walk(t) if isinstance(n, ast.Name))
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            imported.update({a.asname or a.name: (node.module, a.name) for a in node.names})
    return defined, imported


def import_paths(root: Path, packages: tuple[str, ...], importers: list[Path]) -> dict[str, set[str]]:
    """For every name of ``packages`` imported by ``importers``: the module paths it is imported through.

    A name counts where it is defined (followed through the modules that import it); imports inside the
    defining module's own package (a package's modules reaching a sibling) are the package's business and
    do not count.
    """
    mods = {module_name(f, root): _definitions(f) for p in packages for f in sorted((root / p).rglob("*.py"))}

    def defined_in(module: str, name: str, depth: int = 0) -> str:
        if module not in mods or depth > 20:
            return module
        defined, imported = mods[module]
        if name in defined or name not in imported or f"{module}.{name}" in mods:
            return module
        src, original = imported[name]
        return defined_in(src, original, depth + 1) if src in mods else module

    paths: dict[str, set[str]] = {}
    for path in importers:
        me = module_name(path, root)
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node in ast.walk(tree):
            if not (isinstance(node, ast.ImportFrom) and node.module and node.level == 0):
                continue
            if node.module.split(".")[0] not in packages:
                continue
            for alias in node.names:
                if f"{node.module}.{alias.name}" in mods:
                    continue  # a module imported by name
                home = defined_in(node.module, alias.name)
                package = home.rpartition(".")[0]
                if (me == package or me.startswith(package + ".")) and package not in packages:
                    continue
                paths.setdefault(f"{home}.{alias.name}", set()).add(node.module)
    return paths


def test_one_import_path_per_name() -> None:
    importers = sorted(
        f for d in (*PACKAGES, "tests", "bench", "examples", "scripts") for f in (ROOT / d).rglob("*.py")
    )
    doubled = {name: sorted(p) for name, p in import_paths(ROOT, PACKAGES, importers).items() if len(p) > 1}
    assert not doubled, f"names imported through more than one module (import from one place): {doubled}"


def test_no_module_re_exports_what_it_imports() -> None:
    shims = {}
    for path in _sources():
        if path.name == "__init__.py":
            continue
        defined, _ = _definitions(path)
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node in tree.body:
            targets = node.targets if isinstance(node, ast.Assign) else []
            if any(isinstance(t, ast.Name) and t.id == "__all__" for t in targets):
                assert isinstance(node, ast.Assign)
                exported = {e.value for e in ast.walk(node.value) if isinstance(e, ast.Constant)}
                extra = sorted(n for n in exported if n not in defined)
                if extra:
                    shims[str(path.relative_to(ROOT))] = extra
    assert not shims, f"modules whose __all__ hands on names they import (a second import path): {shims}"


def test_import_path_checker_sees_two_paths(tmp_path: Path) -> None:
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("", encoding="utf-8")
    (pkg / "core.py").write_text("class Thing: ...\n", encoding="utf-8")
    (pkg / "shim.py").write_text("from pkg.core import Thing\n__all__ = ['Thing']\n", encoding="utf-8")
    a, b = tmp_path / "a.py", tmp_path / "b.py"
    a.write_text("from pkg.core import Thing\n", encoding="utf-8")
    b.write_text("from pkg.shim import Thing\n", encoding="utf-8")
    assert import_paths(tmp_path, ("pkg",), [a, b]) == {"pkg.core.Thing": {"pkg.core", "pkg.shim"}}
