"""The packages' import structure: no import circle in ``mpm`` or
``pipelines``, and a solver free of Hydra, OmegaConf and Rerun.

The graph is read from the sources (``ast``), every import statement
counted, at module level or inside a function: a module imports the project
module it names (``import pkg.mod``: ``pkg.mod``), a name that is a
submodule of the package it comes from (``from pkg import mod``:
``pkg.mod``), else the package itself (a package is its ``__init__``);
relative imports are resolved against the importing module's package. The
report imports every module of ``pipelines.report.sections`` by name
(pkgutil): it counts as importing each of them.

The packages of ``pipelines`` stand on floors (:data:`PIPELINES_FLOORS`):
every import from one package to another points down."""

from __future__ import annotations

import ast
import re
from collections import deque
from pathlib import Path


ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("mpm", "pipelines")
NOT_IN_THE_SOLVER = ("hydra", "omegaconf", "rerun")
DISCOVERS = {"pipelines.report": "pipelines.report.sections"}  # importer: package of modules it imports
# bottom to top: a package (or top-level module) of pipelines imports only those on floors below its own
PIPELINES_FLOORS = [
    ("pipelines",),  # the package's own __init__
    ("pipelines.config",),  # the config groups, their checks, RunSpec
    ("pipelines.recording",),  # logging a run, reading a recording back, drawing it
    ("pipelines.run",),  # one job: the run (or stability map) of one config, and the Hydra entry
    ("pipelines.report",),  # the report of a sweep's jobs
    ("pipelines.sweeps",),  # the end of a multirun: its report and outcomes
    ("pipelines.bench", "pipelines.replay", "pipelines.export", "pipelines.material_point", "pipelines.granular",
     "pipelines.cfl_bound", "pipelines.kills"),  # the other commands
]


def find_modules(root: Path, packages=PACKAGES) -> dict[str, tuple[Path, bool]]:
    """Module name -> (file, is a package) for every module below ``root``'s ``packages``."""
    out = {}
    for package in packages:
        for path in sorted((root / package).rglob("*.py")):
            parts = list(path.relative_to(root).with_suffix("").parts)
            is_package = parts[-1] == "__init__"
            out[".".join(parts[:-1] if is_package else parts)] = (path, is_package)
    return out


def imported_names(name: str, path: Path, is_package: bool) -> list[tuple[str, str | None, int]]:
    """(module, imported name or None, line) of every import statement of a module."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(alias.name, None, node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            module = node.module or ""
            if node.level:
                package = name.split(".") if is_package else name.split(".")[:-1]
                if node.level - 1 > len(package) - 1:
                    raise ValueError(f"{path}:{node.lineno}: relative import beyond the top-level package")
                base = package[:len(package) - (node.level - 1)]
                module = ".".join(base + ([node.module] if node.module else []))
            out += [(module, alias.name, node.lineno) for alias in node.names]
    return out


def import_graph(modules: dict[str, tuple[Path, bool]], root: Path = ROOT) -> dict[str, dict[str, str]]:
    """module -> {imported project module: where ("file:line", the first import of it)}."""
    graph: dict[str, dict[str, str]] = {m: {} for m in modules}
    for name, (path, is_package) in modules.items():
        for module, imported, line in imported_names(name, path, is_package):
            target = f"{module}.{imported}" if imported and f"{module}.{imported}" in modules else module
            while target and target not in modules:
                target = target.rpartition(".")[0]
            if target and target != name:
                graph[name].setdefault(target, f"{path.relative_to(root).as_posix()}:{line}")
    for importer, package in DISCOVERS.items():
        if importer in graph:
            graph[importer].update({m: f"{package} (every module)" for m in modules if m.startswith(package + ".")})
    return graph


def strongly_connected(graph: dict[str, dict[str, str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def cycle_through(graph: dict[str, dict[str, str]], component: list[str]) -> list[str]:
    """A shortest import cycle from the component's first module back to it."""
    start, members = component[0], set(component)
    parent: dict[str, str | None] = {start: None}
    queue = deque([start])
    while queue:
        v = queue.popleft()
        for w in sorted(graph[v]):
            if w == start:
                path = [v]
                while parent[path[-1]] is not None:
                    path.append(parent[path[-1]])
                return path[::-1] + [start]
            if w in members and w not in parent:
                parent[w] = v
                queue.append(w)
    raise AssertionError(f"no cycle through {start}")


def describe_cycles(graph: dict[str, dict[str, str]]) -> list[str]:
    out = []
    for component in strongly_connected(graph):
        cycle = cycle_through(graph, component)
        steps = " -> ".join(f"{a} ({graph[a][b]})" for a, b in zip(cycle, cycle[1:])) + f" -> {cycle[-1]}"
        out.append(f"import circle among {len(component)} modules ({', '.join(component)}): {steps}")
    return out


def test_no_import_circle():
    graph = import_graph(find_modules(ROOT))
    assert {"mpm", "pipelines", "pipelines.report", "pipelines.run.runner"} <= set(graph)
    assert "pipelines.report.sections.runs" in graph["pipelines.report"]
    cycles = describe_cycles(graph)
    assert not cycles, "\n".join(cycles)


def test_the_check_finds_a_circle(tmp_path):
    """A package whose modules import each other (one of them inside a
    function, relatively, and by a submodule's name) is a circle."""
    pkg = tmp_path / "mpm" / "sub"
    pkg.mkdir(parents=True)
    (tmp_path / "mpm" / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("from .a import f\n")
    (pkg / "a.py").write_text("def f():\n    from .. import other\n")
    (pkg / "b.py").write_text("VALUE = 1\n")
    (tmp_path / "mpm" / "other.py").write_text("from mpm.sub import b\n")
    graph = import_graph(find_modules(tmp_path, ("mpm",)), tmp_path)
    assert graph["mpm.other"] == {"mpm.sub.b": "mpm/other.py:1"}  # the submodule, not the package
    assert describe_cycles(graph) == []
    (pkg / "b.py").write_text("from mpm.sub import a\n")
    cycles = describe_cycles(import_graph(find_modules(tmp_path, ("mpm",)), tmp_path))
    assert len(cycles) == 1 and "mpm.other, mpm.sub.a, mpm.sub.b" in cycles[0], cycles


def pipelines_unit(module: str) -> str | None:
    """The package or top-level module of ``pipelines`` holding ``module``
    (``pipelines.run.runner``: ``pipelines.run``; ``pipelines`` itself: ``pipelines``), else None."""
    parts = module.split(".")
    return ".".join(parts[:2]) if parts[0] == "pipelines" else None


def floor_violations(graph: dict[str, dict[str, str]], floors=PIPELINES_FLOORS) -> list[str]:
    """What breaks the floors of ``pipelines``, a line each. The package
    graph has an edge A -> B for every module of package A importing a
    module of another package B (:func:`import_graph`: imports inside
    functions and the report's discovery of its sections count); each edge
    must go from a higher floor to a lower one, so two packages on one floor
    import neither each other. A package on no floor breaks them too."""
    floor = {unit: i for i, units in enumerate(floors) for unit in units}
    out = [f"{unit} is on no floor: add it to PIPELINES_FLOORS"
           for unit in sorted({pipelines_unit(m) for m in graph} - {None} - set(floor))]
    for importer in sorted(graph):
        a = pipelines_unit(importer)
        for imported, where in sorted(graph[importer].items()):
            b = pipelines_unit(imported)
            if a is None or b is None or a == b or a not in floor or b not in floor or floor[a] > floor[b]:
                continue
            out.append(f"{importer} ({where}) imports {imported}: {a} (floor {floor[a]}) may import only "
                       f"packages on floors below its own, and {b} is on floor {floor[b]}")
    return out


def test_pipelines_packages_point_down():
    graph = import_graph(find_modules(ROOT))
    units = {pipelines_unit(m) for m in graph} - {None}
    assert {"pipelines.run", "pipelines.sweeps", "pipelines.report", "pipelines.replay"} <= units
    declared = [unit for units in PIPELINES_FLOORS for unit in units]
    assert len(declared) == len(set(declared)) and set(declared) <= units, declared
    violations = floor_violations(graph)
    assert not violations, "imports between pipelines packages that do not point down " \
                           "(tests/test_imports.py: PIPELINES_FLOORS):\n" + "\n".join(violations)


def test_the_check_finds_an_import_up_a_floor(tmp_path):
    """An import inside a function from a lower package up to a higher one,
    an import between two packages of one floor and a package on no floor
    are each said, with the importing module and where."""
    root = tmp_path / "pipelines"
    for pkg in ("low", "high"):
        (root / pkg).mkdir(parents=True)
        (root / pkg / "__init__.py").write_text("")
    (root / "__init__.py").write_text("")
    (root / "low" / "a.py").write_text("VALUE = 1\n")
    (root / "high" / "b.py").write_text("from ..low import a\n")
    (root / "tool.py").write_text("import pipelines.high.b\n")
    floors = [("pipelines",), ("pipelines.low",), ("pipelines.high",), ("pipelines.tool",)]

    def violations(floors=floors):
        return floor_violations(import_graph(find_modules(tmp_path, ("pipelines",)), tmp_path), floors)

    assert violations() == []
    (root / "low" / "a.py").write_text("VALUE = 1\n\n\ndef f():\n    from ..high import b\n")
    found = violations()
    assert len(found) == 1 and found[0].startswith(
        "pipelines.low.a (pipelines/low/a.py:5) imports pipelines.high.b: pipelines.low (floor 1)"), found
    (root / "low" / "a.py").write_text("VALUE = 1\n")
    same = violations([("pipelines",), ("pipelines.low",), ("pipelines.high", "pipelines.tool")])
    assert len(same) == 1 and same[0].startswith("pipelines.tool (pipelines/tool.py:1) imports pipelines.high.b"), same
    (root / "new.py").write_text("")
    assert violations() == ["pipelines.new is on no floor: add it to PIPELINES_FLOORS"]


def test_solver_imports_neither_hydra_omegaconf_nor_rerun():
    bad = [f"{path.relative_to(ROOT)}:{line}: {module}"
           for name, (path, is_package) in find_modules(ROOT, ("mpm",)).items()
           for module, _, line in imported_names(name, path, is_package)
           if module.split(".")[0] in NOT_IN_THE_SOLVER]
    assert not bad, "\n".join(bad)


def test_solver_package_imports_neither_hydra_nor_rerun():
    import subprocess
    import sys

    code = ("import sys, mpm; bad = [m for m in sys.modules if m.split('.')[0] in "
            "('hydra', 'omegaconf', 'rerun')]; print(bad); sys.exit(1 if bad else 0)")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stdout + p.stderr


MAX_LINES = 500  # a module holds one concept: a reader finds it by its file name
MAX_SOLVER_LINES = 250  # the Solver is a list of stages over public parts


def test_no_module_over_500_lines_and_a_short_solver():
    """Every module of ``mpm`` and ``pipelines`` is under 500 lines, and the
    Solver class under 250 (its parts are modules of their own)."""
    long = {name: n for name, (path, _) in find_modules(ROOT).items()
            if (n := len(path.read_text().splitlines())) > MAX_LINES}
    assert not long, long
    tree = ast.parse((ROOT / "mpm" / "solver.py").read_text())
    solver = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == "Solver")
    assert solver.end_lineno - solver.lineno + 1 < MAX_SOLVER_LINES


LAYOUT = ROOT / "docs" / "layout.md"


def listed_in_layout(package: str, relpath: str, text: str) -> bool:
    """Whether docs/layout.md's section of ``package`` (its ``## `package/` ``
    heading) lists the module at ``relpath`` (relative to the package): as
    `relpath` itself, as `name.py` in a table under a ``### `folder/` ``
    heading of its first folder or in a row naming its folder, or, for a
    module at the package's top, as `name.py` in a row's first cell."""
    section = next((s for s in re.split(r"^## ", text, flags=re.M) if s.startswith(f"`{package}/`")), "")
    folder, _, name = relpath.rpartition("/")
    rows = lambda part: [line for line in part.splitlines() if line.startswith("|")]  # noqa: E731
    parts = re.split(r"^### ", section, flags=re.M)
    if not folder:  # in a row's first cell, outside the subsections of folders
        top = parts[:1] + [s for s in parts[1:] if not re.search(r"`\w+/`", s.split("\n")[0])]
        return any(f"`{name}`" in row.split("|")[1] for part in top for row in rows(part))
    if f"`{relpath}`" in section:
        return True
    first = relpath.split("/")[0]
    subsections = [s for s in parts[1:] if f"`{first}/`" in s.split("\n")[0]]
    return (any(f"`{name}`" in row for part in subsections for row in rows(part))
            or any(f"`{folder}/`" in row and f"`{name}`" in row for row in rows(section)))


def test_every_module_is_in_the_layout_guide():
    """docs/layout.md lists every module of mpm and pipelines (package
    __init__ files aside, but a package's __main__ counts)."""
    text = LAYOUT.read_text()
    missing = []
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            if path.name == "__init__.py":
                continue
            rel = path.relative_to(ROOT / package).as_posix()
            if not listed_in_layout(package, rel, text):
                missing.append(f"{package}/{rel}")
    assert not missing, f"not in docs/layout.md: {missing}"


def test_the_layout_check_reads_rows_and_folders():
    text = ("## `pkg/`: x\n\n| a | b |\n|---|---|\n| `sub/` | `one.py` (one), `two.py` |\n"
            "| `top.py` | top |\n| `sub/three.py` | three |\n\n### `deep/`: y\n\n| `five.py` | five |\n"
            "\n| `inner/` | what |\n|---|---|\n| `six.py` | six |\n\n## `other/`\n\n| `seven.py` | x |\n")
    assert listed_in_layout("pkg", "sub/one.py", text) and listed_in_layout("pkg", "sub/two.py", text)
    assert listed_in_layout("pkg", "top.py", text) and listed_in_layout("pkg", "sub/three.py", text)
    assert listed_in_layout("pkg", "deep/five.py", text) and listed_in_layout("pkg", "deep/inner/six.py", text)
    assert not listed_in_layout("pkg", "sub/four.py", text) and not listed_in_layout("pkg", "one.py", text)
    assert not listed_in_layout("pkg", "five.py", text) and not listed_in_layout("pkg", "sub/five.py", text)
    assert not listed_in_layout("other", "top.py", text) and not listed_in_layout("pkg", "deep/seven.py", text)
