"""The import graph of servobus, from the code (docs/architecture.md).

``python -m tools.import_graph`` prints the graph of the packages (``servobus/<p>/``, and
``protocols/<name>``, ``families/<name>``, ``sim/<name>`` one level deeper) as a Mermaid
block; ``--modules`` lists the module-level edges, ``--cycles`` the import cycles.
Every import counts, lazy ones (inside a function) and ``TYPE_CHECKING`` ones included:
a cycle through a lazy import is still a cycle of the design.
"""

from __future__ import annotations

import argparse
import ast
import functools
import sys
from collections.abc import Iterable, Mapping
from pathlib import Path

import servobus

ROOT = Path(servobus.__file__).parent
#: Packages shown one level deeper (one node per protocol, family, simulated family).
SPLIT = ("protocols", "families", "sim")


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def modules() -> dict[str, Path]:
    return {module_name(p): p for p in sorted(ROOT.rglob("*.py"))}


def _resolve(name: str, known: Mapping[str, Path]) -> str | None:
    """The servobus module ``name`` refers to (``a.b.c`` may be attribute ``c`` of ``a.b``)."""
    while name:
        if name in known:
            return name
        name = name.rpartition(".")[0]
    return None


def _imported(path: Path, own: str, is_package: bool) -> Iterable[str]:
    package = own if is_package else own.rpartition(".")[0]
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            yield from (a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*anchor, base] if base else anchor)
            yield base
            yield from (f"{base}.{a.name}" for a in node.names)


def module_edges() -> dict[str, set[str]]:
    """Module -> the servobus modules it imports (itself and its own parents left out: a
    package ``__init__`` is loaded on the way to any of its modules)."""
    return {name: set(targets) for name, targets in _module_edges().items()}


@functools.cache
def _module_edges() -> dict[str, frozenset[str]]:
    """The sources are read once per process (the tests ask several times)."""
    known = modules()
    edges: dict[str, frozenset[str]] = {}
    for name, path in known.items():
        targets = {_resolve(t, known) for t in _imported(path, name, path.name == "__init__.py")
                   if t == "servobus" or t.startswith("servobus.")}
        edges[name] = frozenset(t for t in targets if t and t != name
                                and not name.startswith(t + "."))
    return edges


def package_of(module: str) -> str:
    """``servobus.protocols.enip.codec.cip`` -> ``protocols/enip``; ``servobus.errors`` ->
    ``errors``."""
    parts = module.split(".")[1:]
    if not parts:
        return "servobus"
    depth = 2 if parts[0] in SPLIT and len(parts) > 2 else 1
    if parts[0] in SPLIT and len(parts) == 2 and (ROOT / parts[0] / parts[1]).is_dir():
        depth = 2
    return "/".join(parts[:depth])


def package_edges() -> dict[str, set[str]]:
    edges: dict[str, set[str]] = {}
    for module, targets in module_edges().items():
        source = package_of(module)
        found = edges.setdefault(source, set())
        found.update(t for t in map(package_of, targets) if t != source)
    return edges


def cycles(edges: Mapping[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one node (Tarjan), sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for target in sorted(edges.get(node, ())):
            if target not in index:
                visit(target)
                low[node] = min(low[node], low[target])
            elif target in on_stack:
                low[node] = min(low[node], index[target])
        if low[node] == index[node]:
            component: list[str] = []
            while True:
                top = stack.pop()
                on_stack.discard(top)
                component.append(top)
                if top == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10_000))
    for node in sorted(edges):
        if node not in index:
            visit(node)
    return sorted(found)


def _node(package: str) -> str:
    return package.replace("/", "_")


def mermaid(edges: Mapping[str, set[str]] | None = None) -> str:
    """The package graph as a Mermaid flowchart, bottom layers last (sorted, stable)."""
    edges = package_edges() if edges is None else edges
    lines = ["```mermaid", "flowchart BT"]
    for package in sorted(edges):
        lines.append(f'    {_node(package)}["{package}"]')
    for source in sorted(edges):
        for target in sorted(edges[source]):
            lines.append(f"    {_node(source)} --> {_node(target)}")
    lines.append("```")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tools.import_graph", description=__doc__)
    parser.add_argument("--modules", action="store_true", help="module-level edges")
    parser.add_argument("--cycles", action="store_true", help="import cycles (exit 1 if any)")
    args = parser.parse_args(argv)
    if args.cycles:
        found = cycles(module_edges()) + cycles(package_edges())
        for component in found:
            print(" <-> ".join(component))
        return 1 if found else 0
    if args.modules:
        for source, targets in sorted(module_edges().items()):
            for target in sorted(targets):
                print(f"{source} -> {target}")
        return 0
    print(mermaid())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
