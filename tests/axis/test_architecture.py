"""The layering rules of docs/architecture.md, checked on the source (imports only).

A protocol never imports another protocol; the shared layers (axis, cli, families,
transport, sim) never import a protocol by name; a host client never imports the simulator.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import servobus

ROOT = Path(servobus.__file__).parent
SHARED = ("axis", "cli", "families", "transport", "sim", "gui", "machine")
CLIENT_MODULES = ("client.py", "opener.py", "commands.py", "codec.py")


def imports(path: Path) -> list[str]:
    """Every module an ``import``/``from ... import`` in ``path`` names, lazy ones included."""
    names: list[str] = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.append(node.module)
            names += [f"{node.module}.{a.name}" for a in node.names]
    return names


def protocols() -> list[str]:
    return sorted(p.name for p in (ROOT / "protocols").iterdir()
                  if (p / "__init__.py").is_file())


def sources(under: Path) -> list[Path]:
    return sorted(under.rglob("*.py"))


def test_there_are_protocols_to_check() -> None:
    assert {"dyn232", "dyncan"} <= set(protocols())


@pytest.mark.parametrize("protocol", protocols())
def test_a_protocol_imports_no_other_protocol(protocol: str) -> None:
    others = [p for p in protocols() if p != protocol]
    bad = [(path.name, name) for path in sources(ROOT / "protocols" / protocol)
           for name in imports(path)
           if any(name.startswith(f"servobus.protocols.{o}") for o in others)]
    assert bad == []


@pytest.mark.parametrize("layer", SHARED)
def test_shared_layers_name_no_protocol(layer: str) -> None:
    bad = [(str(path.relative_to(ROOT)), name) for path in sources(ROOT / layer)
           for name in imports(path) if name.startswith("servobus.protocols.")]
    assert bad == []


@pytest.mark.parametrize("protocol", protocols())
def test_host_clients_never_import_the_simulator(protocol: str) -> None:
    bad = [(path.name, name) for path in sources(ROOT / "protocols" / protocol)
           if path.name in CLIENT_MODULES
           for name in imports(path) if name.startswith("servobus.sim")]
    assert bad == []


def test_protocol_packages_stay_light() -> None:
    """A package's __init__ only declares tables: importing it loads no codec or client."""
    for protocol in protocols():
        names = imports(ROOT / "protocols" / protocol / "__init__.py")
        assert [n for n in names if n.startswith("servobus")] == [], protocol


def test_the_gui_imports_no_simulator() -> None:
    """The GUI is an ordinary Axis client: virtual drives reach it only through sim:// URLs."""
    bad = [(str(path.relative_to(ROOT)), name) for path in sources(ROOT / "gui")
           for name in imports(path) if name.startswith("servobus.sim")]
    assert bad == []
