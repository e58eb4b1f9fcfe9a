"""The layering rules of docs/architecture.md, checked on the source (imports only).

A protocol never imports another protocol; the shared layers (axis, cli, families,
transport, sim, link) never import a protocol by name; a host client never imports the
simulator; ``transport/`` imports nothing above it; ``link/`` imports no simulator and, of
the Axis layer, only its argument checks and the drive URL.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import servobus

ROOT = Path(servobus.__file__).parent
SHARED = ("axis", "cli", "families", "transport", "sim", "gui", "link", "machine")
#: Everything above transport/: it moves bytes and frames and knows none of these.
ABOVE_TRANSPORT = ("sim", "axis", "protocols", "families", "cli", "gui", "link", "sniff",
                   "machine")
#: What link/ may take from the Axis layer (argument checks, the drive URL's type).
LINK_FROM_AXIS = ("servobus.checks", "servobus.axis.url")
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


def names_a_protocol(name: str) -> bool:
    """``servobus.protocols.<a protocol package>...``; the package's own ProtocolSpec (the
    registry's contract with every protocol) names none."""
    return any(name == f"servobus.protocols.{p}" or name.startswith(f"servobus.protocols.{p}.")
               for p in protocols())


@pytest.mark.parametrize("layer", SHARED)
def test_shared_layers_name_no_protocol(layer: str) -> None:
    bad = [(str(path.relative_to(ROOT)), name) for path in sources(ROOT / layer)
           for name in imports(path) if names_a_protocol(name)]
    assert bad == []


@pytest.mark.parametrize("protocol", protocols())
def test_host_clients_never_import_the_simulator(protocol: str) -> None:
    bad = [(path.name, name) for path in sources(ROOT / "protocols" / protocol)
           if path.name in CLIENT_MODULES
           for name in imports(path) if name.startswith("servobus.sim")]
    assert bad == []


def test_protocol_packages_stay_light() -> None:
    """A package's __init__ only declares its ProtocolSpec: importing it loads no codec or
    client (tests/axis/test_registry.py checks the loaded modules too)."""
    allowed = {"servobus.protocols", "servobus.protocols.ProtocolSpec"}
    for protocol in protocols():
        names = imports(ROOT / "protocols" / protocol / "__init__.py")
        assert [n for n in names if n.startswith("servobus") and n not in allowed] == [], \
            protocol


def test_the_gui_imports_no_simulator() -> None:
    """The GUI is an ordinary Axis client: virtual drives reach it only through sim:// URLs."""
    bad = [(str(path.relative_to(ROOT)), name) for path in sources(ROOT / "gui")
           for name in imports(path) if name.startswith("servobus.sim")]
    assert bad == []


def above(name: str, layers: tuple[str, ...]) -> bool:
    return any(name == f"servobus.{layer}" or name.startswith(f"servobus.{layer}.")
               for layer in layers)


def test_transport_imports_nothing_above_it() -> None:
    """No exception: the socketcand hub (a virtual CAN bus with drive FIFOs) lives in
    ``servobus/sim/`` since issue 19; its old path has no alias, which would itself import
    the simulator from transport/."""
    found = {(path.name, name) for path in sources(ROOT / "transport")
             for name in imports(path) if above(name, ABOVE_TRANSPORT)}
    assert found == set()


def test_link_imports_no_protocol_and_no_simulator() -> None:
    bad = [(path.name, name) for path in sources(ROOT / "link") for name in imports(path)
           if above(name, ("protocols", "sim", "cli", "gui", "families"))
           or (above(name, ("axis",)) and name != "servobus.axis"  # its submodules count
               and not name.startswith(LINK_FROM_AXIS))]
    assert bad == []


SIM_FAMILIES = ("dmm", "yzaim")


@pytest.mark.parametrize("family", SIM_FAMILIES)
def test_a_simulated_family_imports_no_other(family: str) -> None:
    """sim/dmm (the DMM drive) and sim/yzaim (the YZ-AIM motor) both sit on sim/core and
    never reach into each other (no switching the other vendor's features off)."""
    others = tuple(f"sim.{f}" for f in SIM_FAMILIES if f != family)
    bad = [(path.name, name) for path in sources(ROOT / "sim" / family)
           for name in imports(path) if above(name, others)]
    assert bad == []


def test_the_simulator_core_imports_no_family_simulator() -> None:
    layers = tuple(f"sim.{f}" for f in SIM_FAMILIES)
    bad = [(path.name, name) for path in sources(ROOT / "sim" / "core")
           for name in imports(path) if above(name, layers)]
    assert bad == []


#: One file-name scheme in every protocol package (issue 19), host and device side visible
#: by name: codec (a module or a package of pure wire formats), commands (pure request
#: builders), client (the transaction-level client only), axis (the Axis class), opener (URL
#: -> Axis), device (the virtual-drive front end), server, cli, sniff.
PROTOCOL_MODULES = ("codec", "commands", "client", "axis", "opener", "device", "server", "cli",
                    "sniff")


@pytest.mark.parametrize("protocol", protocols())
def test_every_protocol_package_has_the_same_module_names(protocol: str) -> None:
    package = ROOT / "protocols" / protocol
    missing = [m for m in PROTOCOL_MODULES if not (package / f"{m}.py").is_file()
               and not (package / m / "__init__.py").is_file()]
    assert missing == []


def defines_an_axis(path: Path) -> list[str]:
    """Classes in ``path`` deriving AsyncAxis or one of its servobus subclasses (by name:
    ``...Axis`` bases, CommandAxis, YzaimAxis)."""
    found: list[str] = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ClassDef):
            for base in node.bases:
                target = base.value if isinstance(base, ast.Subscript) else base
                name = target.attr if isinstance(target, ast.Attribute) else \
                    target.id if isinstance(target, ast.Name) else ""
                if name.endswith("Axis"):
                    found.append(node.name)
    return found


@pytest.mark.parametrize("protocol", protocols())
def test_no_axis_class_lives_in_a_client_module(protocol: str) -> None:
    client = ROOT / "protocols" / protocol / "client.py"
    assert defines_an_axis(client) == []
    assert defines_an_axis(ROOT / "protocols" / protocol / "axis.py") != []  # the rule bites


def test_every_family_is_a_package_with_a_family_module() -> None:
    packages = [p for p in (ROOT / "families").iterdir() if (p / "__init__.py").is_file()]
    assert {p.name for p in packages} == {"dmm", "dyn5", "yzaim"}
    assert all((p / "family.py").is_file() for p in packages)
