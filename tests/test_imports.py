"""The package's import graph: no module imports, directly or through others, a module that
imports it back (issue 22: engines/storm.py imported strategy/deceptive.py, which imported
engines/storm.py), and only the Storm adapter knows stormpy.

Every import counts: at module level, inside functions and under TYPE_CHECKING, since any of
them ties the two modules together. A package's import of its own parent package is left out
(importing hg2prism.x runs hg2prism/__init__.py, which imports the API, by design).
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "hg2prism"


def _modules() -> dict[str, Path]:
    modules = {}
    for path in PACKAGE.rglob("*.py"):
        parts = ("hg2prism",) + path.relative_to(PACKAGE).with_suffix("").parts
        modules[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return modules


def _imported(path: Path, modules: set[str] | frozenset[str] = frozenset()) -> set[str]:
    """Every module `path` imports: `import m` imports m; `from p import x` imports p.x when
    p.x is one of `modules`, else p."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module:
            names |= {f"{node.module}.{alias.name}" if f"{node.module}.{alias.name}" in modules
                      else node.module for alias in node.names}
        elif isinstance(node, ast.Import):
            names |= {alias.name for alias in node.names}
    return names


def import_graph() -> dict[str, set[str]]:
    """Module -> the hg2prism modules it imports (its own parent packages left out)."""
    modules = _modules()
    return {name: {n for n in _imported(path, set(modules)) & set(modules)
                   if n != name and not name.startswith(n + ".")}
            for name, path in modules.items()}


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_the_cycle_finder_finds_a_cycle() -> None:
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_the_graph_sees_deferred_and_type_checking_imports() -> None:
    graph = import_graph()
    assert "hg2prism.analyses.baselines" in graph["hg2prism.pipeline"]      # inside run()
    assert "hg2prism.engines.engine" in graph["hg2prism.engines.storm"]
    assert "hg2prism.engines.storm" in graph["hg2prism.engines"]            # inside default()


def test_the_package_has_no_import_cycle() -> None:
    assert cycles(import_graph()) == []


def test_only_the_storm_adapter_imports_stormpy() -> None:
    users = {name for name, path in _modules().items()
             if any(n == "stormpy" or n.startswith("stormpy.") for n in _imported(path))}
    assert users == {"hg2prism.engines.storm"}


def test_hypergame_decoding_and_strategies_do_not_import_the_storm_adapter() -> None:
    graph = import_graph()
    for name in graph:
        if name.startswith(("hg2prism.prism", "hg2prism.strategy", "hg2prism.pipeline",
                            "hg2prism.experiments", "hg2prism.api", "hg2prism.analyses")):
            assert "hg2prism.engines.storm" not in graph[name], name


MAX_FUNCTION_LINES = 80     # issue 22: a function that does one thing fits on a screen


def long_functions(source: str) -> list[tuple[str, int]]:
    """(name, lines) of every function in `source` longer than MAX_FUNCTION_LINES."""
    return [(node.name, node.end_lineno - node.lineno + 1)
            for node in ast.walk(ast.parse(source))
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
            and node.end_lineno - node.lineno + 1 > MAX_FUNCTION_LINES]


def test_the_length_check_sees_a_long_function() -> None:
    body = "\n".join(f"    x{i} = {i}" for i in range(MAX_FUNCTION_LINES))
    assert long_functions(f"def f():\n{body}\n") == [("f", MAX_FUNCTION_LINES + 1)]
    assert long_functions(f"def f():\n{body[:body.rindex(chr(10))]}\n") == []


def test_no_function_of_the_package_is_longer_than_80_lines() -> None:
    found = {f"{path.relative_to(PACKAGE)}:{name}": lines
             for path in _modules().values() for name, lines in long_functions(path.read_text())}
    assert found == {}


# What only the grid front end may know (issue 23): its moves, its cells and its slip.
GRID_WORDS = re.compile(r"\bslip|\(x, ?y\)|\bCell\b|\bN/E/S/W\b|(?<!metavar=)[\"'][NESW][\"']|\bPERPENDICULAR\b"
                        r"|\boutcome_directions\b|\bgeometry\(|\bcell_index\b|\bnorth\b|\bwest\b")


def test_only_the_grid_front_end_knows_grids() -> None:
    """Below the front ends the pipeline sees arenas only: no module of the package but the
    grid front end (frontends/grid.py, its drawing and its generated worlds) names a move
    direction, a cell or the slip."""
    found = []
    for path in sorted(PACKAGE.rglob("*.py")) + sorted(PACKAGE.rglob("*.j2")):
        if path.parent.name == "frontends" and path.name.startswith("grid"):
            continue
        for n, line in enumerate(path.read_text().splitlines(), 1):
            if GRID_WORDS.search(line):
                found.append(f"{path.relative_to(PACKAGE)}:{n}: {line.strip()}")
    assert found == []


def test_the_grid_words_are_found_where_they_are() -> None:
    """The pattern above finds the grid front end's own words (so the test can fail)."""
    source = (PACKAGE / "frontends" / "grid.py").read_text()
    hits = {m.group(0) for m in GRID_WORDS.finditer(source)}
    assert {"slip", "Cell", '"N"', "PERPENDICULAR", "outcome_directions"} <= hits
