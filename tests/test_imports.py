"""The package's import graph (issue 10): arrows only downstream, from the source text.

Every ``import`` in rtreflect/**.py is read with `ast` (also those inside functions, which
run later but still tie the modules together; not those under ``if TYPE_CHECKING:``, which
never run). Two rules: no cycle between modules, and no pipeline stage imports the command
line, the batch runner or the cluster path. The walker itself is tested on a planted cycle
and a planted upward import, so the rules cannot pass by reading nothing.
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "rtreflect"
#: The sub-packages of the pipeline stages: none may import `TOP_LEVEL_ONLY`.
STAGES = ("kernels", "geometry", "trace", "modes", "exchange", "integrator", "analysis", "output", "ci")
#: Modules at the top of the arrows: the command line and the runners that only it (and users) call.
TOP_LEVEL_ONLY = ("cli", "batch", "cluster")


def module_name(root: Path, file: Path) -> str:
    parts = list(file.relative_to(root.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _type_checking_only(node: ast.If) -> bool:
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or \
        (isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _imports(tree: ast.AST):
    """Import nodes, skipping ``if TYPE_CHECKING:`` bodies."""
    for node in ast.iter_child_nodes(tree):
        if isinstance(node, ast.If) and _type_checking_only(node):
            yield from (n for child in node.orelse for n in _imports(ast.Module(body=[child], type_ignores=[])))
            continue
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node
        yield from _imports(node)


def import_graph(root: Path) -> dict[str, set[str]]:
    """module → the package's modules it imports (``from . import x`` counts x when x is a module)."""
    files = {module_name(root, f): f for f in root.rglob("*.py")}
    graph: dict[str, set[str]] = {name: set() for name in files}
    for name, file in files.items():
        package = name if file.name == "__init__.py" else name.rpartition(".")[0]
        for node in _imports(ast.parse(file.read_text(), str(file))):
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            else:
                if node.level:
                    base = package.split(".")
                    base = base[:len(base) - node.level + 1]
                    origin = ".".join(base + ([node.module] if node.module else []))
                else:
                    origin = node.module or ""
                targets = [origin] + [f"{origin}.{alias.name}" for alias in node.names]
            graph[name] |= {t for t in targets if t in files and t != name}
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of the graph as [a, b, ..., a], or None (depth-first search with colours)."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                return path[path.index(nxt):] + [nxt]
            if nxt not in state and (found := visit(nxt)):
                return found
        path.pop()
        state[node] = 2
        return None

    for start in sorted(graph):
        if start not in state and (found := visit(start)):
            return found
    return None


def upward_imports(graph: dict[str, set[str]], package: str = "rtreflect") -> list[tuple[str, str]]:
    forbidden = {f"{package}.{name}" for name in TOP_LEVEL_ONLY}
    stages = tuple(f"{package}.{stage}." for stage in STAGES)
    return sorted((module, target) for module, targets in graph.items() for target in targets
                  if target in forbidden and module.startswith(stages))


def test_package_import_graph_has_no_cycle() -> None:
    graph = import_graph(PACKAGE)
    assert len(graph) > 30 and sum(map(len, graph.values())) > 50  # the walk read the package
    assert find_cycle(graph) is None, " → ".join(find_cycle(graph))


def test_no_stage_imports_the_command_line_or_batch() -> None:
    graph = import_graph(PACKAGE)
    assert upward_imports(graph) == []
    # Nothing imports the command line at all; the public API stays below the runners.
    assert [m for m, targets in graph.items() if "rtreflect.cli" in targets] == []
    assert not graph["rtreflect.api"] & {"rtreflect.cli", "rtreflect.batch", "rtreflect.cluster"}


def test_walker_finds_a_planted_cycle_and_upward_import(tmp_path: Path) -> None:
    root = tmp_path / "rtreflect"
    (root / "trace").mkdir(parents=True)
    (root / "__init__.py").write_text("")
    (root / "trace" / "__init__.py").write_text("")
    (root / "cli.py").write_text("from .trace import camera\n")
    (root / "trace" / "camera.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                                              "    from .. import cli\n")
    assert find_cycle(import_graph(root)) is None and upward_imports(import_graph(root)) == []
    (root / "trace" / "camera.py").write_text("def late():\n    from ..cli import main\n")
    graph = import_graph(root)
    assert find_cycle(graph) == ["rtreflect.cli", "rtreflect.trace.camera", "rtreflect.cli"]
    assert upward_imports(graph) == [("rtreflect.trace.camera", "rtreflect.cli")]
