"""The gateway knows no protocol and no simulator by name (docs/architecture.md)."""

from __future__ import annotations

import ast
from pathlib import Path

import servobus

GATEWAY = Path(servobus.__file__).parent / "gateway"


def imported(path: Path) -> list[str]:
    names: list[str] = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.append(node.module)
    return names


def test_the_gateway_imports_no_protocol_and_no_simulator() -> None:
    sources = sorted(GATEWAY.glob("*.py"))
    assert len(sources) > 5
    bad = [(p.name, n) for p in sources for n in imported(p)
           if n.startswith(("servobus.protocols", "servobus.sim"))]
    assert bad == []
