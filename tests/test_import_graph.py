"""The package's import graph has no cycles: none between modules, none between rooms.

A *room* is a subpackage of ``awda_bench`` (``robot``, ``envs``, ``evaluation``, ...) or a top-level
module (``episode``, ``runtimes``, ...); rooms import only downward (docs/design.md, "Layout"). The graph
is read from the source with :mod:`ast`: every ``import`` and ``from ... import``, relative ones
and those inside functions or under ``TYPE_CHECKING`` included. ``from package import name``
counts as importing the submodule ``package.name`` when there is one, else the package itself.
A ``"awda_bench.module:attribute"`` string (what the method registry, ``evaluation.methods``,
loads a method's policy from at run time) counts as importing that module; other modules loaded by
name at run time (``importlib.import_module`` in ``cli`` and ``commands.bench``) are not imports
here.
"""

from __future__ import annotations

import ast
import re
from collections.abc import Iterator
from pathlib import Path

import awda_bench

PACKAGE_DIR = Path(awda_bench.__file__).parent
PACKAGE = PACKAGE_DIR.name


def _modules() -> dict[str, tuple[Path, bool]]:
    """Dotted module name -> (source file, is a package's ``__init__``)."""
    out: dict[str, tuple[Path, bool]] = {}
    for path in sorted(PACKAGE_DIR.rglob("*.py")):
        parts = list(path.relative_to(PACKAGE_DIR.parent).with_suffix("").parts)
        is_package = parts[-1] == "__init__"
        out[".".join(parts[:-1] if is_package else parts)] = (path, is_package)
    return out


def _owner(name: str, modules: dict[str, tuple[Path, bool]]) -> str | None:
    """The module ``name`` (a module, or a name inside one) lives in; ``None`` outside the package."""
    while name and name not in modules:
        name = name.rpartition(".")[0]
    return name or None


def _imported_names(tree: ast.AST, package: str) -> Iterator[tuple[str, list[str], int]]:
    """``(module named, names taken from it, line)`` of every import statement in ``tree``."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, [], node.lineno
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".")
                parts = parts[: len(parts) - node.level + 1]
                base = ".".join([*parts, node.module] if node.module else parts)
            else:
                base = node.module or ""
            yield base, [alias.name for alias in node.names], node.lineno
        elif isinstance(node, ast.Constant) and isinstance(node.value, str):
            named = LOADED_BY_NAME.fullmatch(node.value)
            if named is not None:
                yield named.group(1), [], node.lineno


LOADED_BY_NAME = re.compile(rf"({PACKAGE}(?:\.\w+)+):[\w.]+")
"""A ``"module:attribute"`` target inside the package (a registered method's policy)."""


def import_graph() -> dict[str, dict[str, int]]:
    """Module -> {module it imports: line of the first such import}, within the package."""
    modules = _modules()
    graph: dict[str, dict[str, int]] = {}
    for module, (path, is_package) in modules.items():
        package = module if is_package else module.rpartition(".")[0]
        edges = graph.setdefault(module, {})
        tree = ast.parse(path.read_text(), filename=str(path))
        for base, names, line in _imported_names(tree, package):
            targets = [f"{base}.{n}" if f"{base}.{n}" in modules else base for n in names]
            for target in targets or [base]:
                owner = _owner(target, modules)
                if owner is not None and owner != module:
                    edges.setdefault(owner, line)
    return graph


def room(module: str) -> str:
    """``awda_bench.evaluation.sweep`` -> ``evaluation``; ``awda_bench.episode`` -> ``episode``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else parts[0]


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one node (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for nxt in sorted(graph.get(node, ())):
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return found


def _where(module: str, line: int) -> str:
    path, _ = _modules()[module]
    return f"{path.relative_to(PACKAGE_DIR.parent)}:{line}"


def test_the_graph_sees_imports_at_every_depth() -> None:
    graph = import_graph()
    assert len(graph) > 100
    # module level, inside a function, relative to nothing: all seen
    assert f"{PACKAGE}.evaluation.sweep" in graph[f"{PACKAGE}.commands.run"]
    assert f"{PACKAGE}.reporting.videos" in graph[f"{PACKAGE}.commands.run"]  # inside run()
    assert f"{PACKAGE}.robot.demonstrator" in graph[f"{PACKAGE}.envs"]  # from robot import module
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    # what a method name loads: the registry's "module:attribute" targets
    methods = graph[f"{PACKAGE}.evaluation.methods"]
    for policy in ("tosvi_policy", "awda_policy", "gt_waypoints", "random_policy"):
        assert f"{PACKAGE}.policies.{policy}" in methods


def test_no_module_imports_itself_through_others() -> None:
    graph = import_graph()
    found = cycles({module: set(edges) for module, edges in graph.items()})
    lines = [
        f"{a} -> {b} ({_where(a, graph[a][b])})"
        for component in found
        for a in component
        for b in sorted(graph[a])
        if b in component
    ]
    assert not found, "module import cycles:\n" + "\n".join(lines)


def test_rooms_import_only_downward() -> None:
    graph = import_graph()
    rooms: dict[str, set[str]] = {}
    for module, edges in graph.items():
        rooms.setdefault(room(module), set()).update(
            room(target) for target in edges if room(target) != room(module)
        )
    found = cycles(rooms)
    lines = [
        f"{room(a)} -> {room(b)}: {a} -> {b} ({_where(a, line)})"
        for component in found
        for a, edges in sorted(graph.items())
        for b, line in sorted(edges.items())
        if room(a) in component and room(b) in component and room(a) != room(b)
    ]
    assert not found, "rooms importing each other (a cycle):\n" + "\n".join(lines)


NEVER_IMPORTS = {
    "execution": ("data", "evaluation", "reporting"),
    "data": ("evaluation", "reporting"),
    "evaluation": ("data", "reporting"),
}
"""Room -> rooms it must not import, whatever the rest of the graph allows: job execution knows no
job type; collection (``data``) and evaluation are two parallel rows over it; reporting reads
both from above."""


def test_evaluation_and_collection_are_two_rows_over_one_executor() -> None:
    graph = import_graph()
    assert {"execution", "evaluation", "reporting", "data"} <= {room(m) for m in graph}
    found = [
        f"{room(a)} -> {room(b)}: {a} -> {b} ({_where(a, line)})"
        for a, edges in sorted(graph.items())
        for b, line in sorted(edges.items())
        if room(b) in NEVER_IMPORTS.get(room(a), ())
    ]
    assert not found, "imports across the executor's rows:\n" + "\n".join(found)
