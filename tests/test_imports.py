"""No import circles among the modules of the hilcontact package: every ``import`` of
``python/hilcontact`` (lazy ones inside functions included, ``if TYPE_CHECKING:`` blocks
excluded) is an edge, and the graph must have no cycle."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "python" / "hilcontact"


def _module_name(path: Path, package: Path) -> str:
    parts = ["hilcontact", *path.relative_to(package).with_suffix("").parts]
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def _imports(tree: ast.AST) -> list[ast.Import | ast.ImportFrom]:
    """Every import statement of ``tree``, at any depth, outside ``if TYPE_CHECKING:``."""
    found: list[ast.Import | ast.ImportFrom] = []

    def visit(node: ast.AST) -> None:
        if isinstance(node, ast.If) and _is_type_checking(node.test):
            for child in node.orelse:
                visit(child)
            return
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            found.append(node)
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(tree)
    return found


def import_graph(package: Path = PACKAGE) -> dict[str, set[str]]:
    """Module -> the package's modules it imports (a ``from . import name`` counts as an import
    of the module ``name`` when there is one, else of the package that defines ``name``). The
    native extension (``_core``, known by its stub ``_core.pyi``) is a module that imports none."""
    paths = {_module_name(p, package): p for p in sorted(package.rglob("*.py"))}
    graph: dict[str, set[str]] = {_module_name(p, package): set() for p in package.rglob("*.pyi")}
    known = paths.keys() | graph.keys()
    for name, path in paths.items():
        is_package = path.name == "__init__.py"
        edges: set[str] = set()
        for node in _imports(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            if isinstance(node, ast.Import):
                edges.update(alias.name for alias in node.names if alias.name in known)
                continue
            if node.level:
                base = name.split(".") if is_package else name.split(".")[:-1]
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            submodules = {f"{target}.{alias.name}" for alias in node.names} & known
            edges.update(submodules)
            if target in known and len(submodules) < len(node.names):
                edges.add(target)
        graph[name] = edges - {name}
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """A cycle of ``graph`` as ``[a, b, ..., a]``, or None."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return path[path.index(nxt):] + [nxt]
            if nxt not in state and (cycle := visit(nxt)) is not None:
                return cycle
        path.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (cycle := visit(node)) is not None:
            return cycle
    return None


def test_the_cycle_finder_finds_a_cycle_and_only_one():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]


def test_the_graph_sees_lazy_imports_and_skips_type_checking(tmp_path):
    package = tmp_path / "hilcontact"
    package.mkdir()
    (package / "__init__.py").write_text("from .run import simulate\n")
    (package / "run.py").write_text("def plot():\n    from .plots import draw\n")
    (package / "plots.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .run import Run\nfrom . import scenario\n"
    )
    (package / "scenario.py").write_text("from . import __version__, _core\n")
    (package / "_core.pyi").write_text("from typing import Any\n")
    graph = import_graph(package)
    assert graph == {
        "hilcontact._core": set(),
        "hilcontact": {"hilcontact.run"},
        "hilcontact.run": {"hilcontact.plots"},
        "hilcontact.plots": {"hilcontact.scenario"},
        "hilcontact.scenario": {"hilcontact", "hilcontact._core"},
    }
    assert find_cycle(graph) == ["hilcontact", "hilcontact.run", "hilcontact.plots", "hilcontact.scenario", "hilcontact"]


def test_no_import_circles_in_the_package():
    graph = import_graph()
    assert {"hilcontact.run", "hilcontact.plots", "hilcontact.cli", "hilcontact.cli.options"} <= graph.keys()
    cycle = find_cycle(graph)
    assert cycle is None, "import circle: " + " -> ".join(cycle or [])
