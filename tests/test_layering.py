"""Every import in cornerslam_cli points down a declared layer order, and none closes a cycle; a
module over 400 lines says why at its top.

The imports are read with ``ast`` from the source, function-level (deferred) ones included, so a cycle
cannot hide behind an import inside a function. Rules:

1. every module has a layer (``LAYERS``: the most specific dotted prefix wins), so a new module has to
   be placed;
2. a module imports only from lower layers, or from its own package (``logs.ros`` from ``logs.base``)
   on its own layer: stages on one layer do not import each other;
3. the module graph has no cycle (a package's ``__init__`` importing its modules counts as an edge);
4. no module imports another module's private name (``_fmt``).
"""

from __future__ import annotations

import ast
from pathlib import Path

import cornerslam_cli

PACKAGE = Path(cornerslam_cli.__file__).resolve().parent

# lowest first; a name is a module or package under cornerslam_cli ("" = the package's __init__)
LAYERS: list[tuple[str, ...]] = [
    # stdlib, numpy; features.jit: numba's njit with its cache (extraction's and scan matching's kernels)
    ("", "blas", "errors", "fpenv", "geometry", "ranges", "types", "workers", "features.jit"),
    (
        "textfile",
        "smallmat",  # compiled 3 × 3 algebra (features.jit's kernels) shared by association and filter
        "association.params",
        "features.params",
        "filter.params",
        "motion.params",
        "logs.params",
        "graph.params",
    ),
    ("report.tables", "results"),  # file formats (TUM, CSV, JSON); a run's results (summary.json's fields)
    ("logs", "features", "association", "filter", "motion", "simworld", "span"),  # the stages, independent
    ("config",),  # the stages' sections assembled, loaded, validated
    ("lasers", "evaluate", "extract", "graph"),  # a run's config; scoring; one scan's features; pose graph
    ("frontend",),  # a run's front end: log → synchronised frames → features → scan-matched motion
    ("slam",),  # the filter over the frames: steps, landmarks
    ("hierarchy",),  # local EKF submaps (slam) joined by the pose graph (graph)
    ("report",),  # run writer, figures, MCAP out, output directories, printed text, progress display
    ("pipeline", "simulate", "sweep", "compiled"),  # a run; the simulated log; a batch's plan; the kernels
    ("compare", "batch"),
    ("options",),  # the command line's shared options and option parsers
    ("cli",),
    ("entry",),
    ("__main__",),
]


def module_names(root: Path) -> dict[str, Path]:
    """Dotted names relative to the package ("" for its __init__, "logs" for logs/__init__.py)."""
    out = {}
    for f in sorted(root.rglob("*.py")):
        parts = list(f.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = f
    return out


def imports_of(name: str, path: Path, modules: dict[str, Path]) -> list[tuple[str, str, int]]:
    """(imported module, imported name or "", line) of every cornerslam_cli import in the file."""
    is_pkg = path.name == "__init__.py"
    here = name.split(".") if name else []
    package = here if is_pkg else here[:-1]
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name == "cornerslam_cli" or alias.name.startswith("cornerslam_cli."):
                    found.append((alias.name.removeprefix("cornerslam_cli").lstrip("."), "", node.lineno))
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            elif node.module and (node.module + ".").startswith("cornerslam_cli."):
                target = node.module.removeprefix("cornerslam_cli").lstrip(".")
            else:
                continue
            for alias in node.names:
                sub = f"{target}.{alias.name}" if target else alias.name
                if sub in modules:  # `from . import module`
                    found.append((sub, "", node.lineno))
                else:
                    found.append((target, alias.name, node.lineno))
    return found


def layer_of(name: str) -> int:
    best, where = -1, None
    for i, names in enumerate(LAYERS):
        for prefix in names:
            if (name == prefix or name.startswith(prefix + ".") or prefix == "" and name == "") and (
                len(prefix) > best
            ):
                best, where = len(prefix), i
    if where is None:
        raise KeyError(name)
    return where


def top_package(name: str, modules: dict[str, Path]) -> str:
    """The subpackage a module belongs to ("logs" for logs.ros); a top-level module is its own."""
    first = name.split(".")[0]
    return first if first and modules.get(first, Path()).name == "__init__.py" else name


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    state: dict[str, int] = {}  # 1 on the stack, 2 done
    stack: list[str] = []

    def visit(n: str) -> list[str] | None:
        state[n] = 1
        stack.append(n)
        for m in sorted(graph.get(n, ())):
            if state.get(m) == 1:
                return stack[stack.index(m) :] + [m]
            if m not in state and (c := visit(m)):
                return c
        stack.pop()
        state[n] = 2
        return None

    for n in sorted(graph):
        if n not in state and (c := visit(n)):
            return c
    return None


def layering_problems(root: Path = PACKAGE) -> list[str]:
    """What breaks the rules in the package at ``root``, one line each."""
    modules = module_names(root)
    problems, graph = [], {}
    for name, path in modules.items():
        try:
            mine = layer_of(name)
        except KeyError:
            problems.append(f"{name or '__init__'}: no layer (add it to LAYERS)")
            continue
        graph[name] = set()
        for target, imported, line in imports_of(name, path, modules):
            where = f"{path.relative_to(root.parent)}:{line}"
            shown = "cornerslam_cli" + (f".{target}" if target else "")
            if target not in modules:
                continue  # a mistyped module fails its own tests
            try:
                theirs = layer_of(target)
            except KeyError:
                continue  # reported as a module without a layer
            if target != name:
                graph[name].add(target)
            if imported.startswith("_") and not imported.startswith("__"):
                problems.append(f"{where}: imports the private name {imported} from {shown}")
            same_pkg = top_package(name, modules) == top_package(target, modules)
            problem = f"{where}: {name} (layer {mine}) imports {shown} (layer {theirs})"
            if (theirs > mine or (theirs == mine and not same_pkg)) and problem not in problems:
                problems.append(problem)
    cycle = find_cycle(graph)
    if cycle:
        problems.append("import cycle: " + " -> ".join(cycle))
    return problems


def test_every_import_points_down():
    assert layering_problems() == []


def test_the_check_sees_deferred_imports_cycles_and_private_names(tmp_path):
    """A package with a cycle through a function-level import, an upward import and a private name."""
    pkg = tmp_path / "cornerslam_cli"
    (pkg / "logs").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "logs" / "__init__.py").write_text("")
    (pkg / "logs" / "base.py").write_text("def f():\n    from .cdr import x\n")
    (pkg / "logs" / "cdr.py").write_text("from .base import f\nfrom ..errors import _hidden\n")
    (pkg / "errors.py").write_text("from .config import C\n_hidden = 1\n")
    (pkg / "config.py").write_text("C = 1\n")
    problems = layering_problems(pkg)
    assert "import cycle: logs.base -> logs.cdr -> logs.base" in problems
    assert any("private name _hidden" in p for p in problems)
    assert any("errors (layer 0) imports cornerslam_cli.config (layer 4)" in p for p in problems)
    assert len(problems) == 3


MAX_LINES = 400  # issue 14: a longer module says why at its top


def test_a_module_over_400_lines_says_why_at_its_top():
    """Every module over MAX_LINES lines has "Over 400 lines because ..." in its docstring."""
    silent = []
    for name, path in module_names(PACKAGE).items():
        text = path.read_text()
        doc = ast.get_docstring(ast.parse(text)) or ""
        if len(text.splitlines()) > MAX_LINES and "Over 400 lines because" not in doc:
            silent.append(f"{name}: {len(text.splitlines())} lines")
    assert silent == []
