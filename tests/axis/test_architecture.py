"""The layering rules of docs/architecture.md, checked on the source (imports only).

A protocol never imports another protocol, nor a front end (cli, gui, machine, gateway);
the shared layers never import a protocol by name; a host client never imports the
simulator; ``transport/`` imports nothing above it, ``link/`` nothing of the Axis and above,
``checks`` nothing but the errors; ``axis/`` names no family; no import cycle between
modules or packages (tools/import_graph.py, whose picture docs/architecture.md carries); no
module only re-exports another.
"""

from __future__ import annotations

import ast
import functools
import re
from pathlib import Path

import pytest

import servobus
from tools import import_graph as graph

ROOT = Path(servobus.__file__).parent
SHARED = ("axis", "cli", "families", "transport", "sim", "gui", "link", "machine", "gateway",
          "hal")
#: Everything above transport/: it moves bytes and frames and knows none of these.
ABOVE_TRANSPORT = ("sim", "axis", "protocols", "families", "cli", "gui", "link", "sniff",
                   "machine", "gateway", "hal")
#: Everything above link/: the rules of a conversation know no Axis, family or protocol.
ABOVE_LINK = ("axis", "protocols", "families", "sim", "cli", "gui", "machine", "gateway",
              "sniff", "hal")
FRONT_ENDS = ("cli", "gui", "machine", "gateway", "hal")
CLIENT_MODULES = ("client.py", "opener.py", "commands.py", "codec.py")


@functools.cache
def parsed(path: Path) -> ast.Module:
    """``path``'s syntax tree, parsed once per run: the rules below walk the same modules
    many times (about half of this file's CPU was parsing them again). Read only."""
    return ast.parse(path.read_text(encoding="utf-8"))


def imports(path: Path) -> list[str]:
    """Every module an ``import``/``from ... import`` in ``path`` names, lazy ones included."""
    return list(_imports(path))


@functools.cache
def _imports(path: Path) -> tuple[str, ...]:
    names: list[str] = []
    for node in ast.walk(parsed(path)):
        if isinstance(node, ast.Import):
            names += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.append(node.module)
            names += [f"{node.module}.{a.name}" for a in node.names]
    return tuple(names)


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


def test_link_sits_below_the_axis() -> None:
    """Issue 31: link/ took the argument checks (servobus.checks) and the drive URL's CAN
    channel (axis.url.can_spec) from below, so no arrow points back up to axis/."""
    bad = [(path.name, name) for path in sources(ROOT / "link") for name in imports(path)
           if above(name, ABOVE_LINK)]
    assert bad == []


def test_the_argument_checks_sit_below_the_link() -> None:
    names = [n for n in imports(ROOT / "checks.py") if n.startswith("servobus")]
    assert names and all(n.startswith("servobus.errors") for n in names)


def test_the_axis_names_no_family() -> None:
    """axis/ is the API (its value types in axis/types.py); the families write their Axis
    profiles on it, never the other way round."""
    bad = [(path.name, name) for path in sources(ROOT / "axis") for name in imports(path)
           if above(name, ("families",))]
    assert bad == []


@pytest.mark.parametrize("protocol", protocols())
def test_a_protocol_sits_below_the_front_ends(protocol: str) -> None:
    """Issue 31 item 2, without exception: a protocol's commands are data on its spec
    (servobus.axis.cli_spec), built by servobus.cli.protocol_cmds through the registry;
    no protocol imports the CLI, the GUI, the machine layer or the gateway."""
    bad = [(str(path.relative_to(ROOT)), name)
           for path in sources(ROOT / "protocols" / protocol) for name in imports(path)
           if above(name, FRONT_ENDS)]
    assert bad == []


def test_the_protocol_spec_sits_below_the_front_ends() -> None:
    """``servobus/protocols/*.py`` (ProtocolSpec) too."""
    bad = [(path.name, name) for path in sorted((ROOT / "protocols").glob("*.py"))
           for name in imports(path) if above(name, FRONT_ENDS)]
    assert bad == []


SIM_FAMILIES = ("dmm", "yzaim")


def families() -> list[str]:
    return sorted(p.name for p in (ROOT / "families").iterdir()
                  if (p / "__init__.py").is_file())


def names_a_family(name: str) -> bool:
    """``servobus.families.<f>...``, ``servobus.sim.<f>...`` (a family's tables, profile or
    virtual drive) or ``servobus.protocols.<p>...``. The family-neutral API of the
    ``servobus.families`` package (``family(name)``, ``FAMILIES``, ``params_file``: the
    parameter backup format of every family) is none."""
    layers = (*(f"families.{f}" for f in families()), *(f"sim.{f}" for f in SIM_FAMILIES))
    return above(name, layers) or names_a_protocol(name)


#: Front-end modules allowed to import a family or protocol module, each with its reason.
#: Empty since issue 31: what a front end needs of a family comes through the Axis, the
#: Family object (``axis.family``, ``Family.ptp_profile``) or a family-neutral module.
FAMILY_IMPORTS_ALLOWED: dict[tuple[str, str], str] = {}


def test_the_family_finder_bites() -> None:
    assert names_a_family("servobus.families.dmm.profile")
    assert names_a_family("servobus.sim.dmm.control.FAULTS")
    assert names_a_family("servobus.protocols.enip.discover")
    assert not names_a_family("servobus.families.params_file")
    assert not names_a_family("servobus.families.family")
    assert not names_a_family("servobus.sim.core.control")
    assert not names_a_family("servobus.sim.control_client")


@pytest.mark.parametrize("front_end", FRONT_ENDS)
def test_the_front_ends_know_no_family_or_protocol_by_name(front_end: str) -> None:
    """Issue 31: cli, gui, gateway and machine import no module of one family
    (``families/<f>``, ``sim/<f>``) nor of one protocol; they ask the Axis, its Family and
    the registry."""
    bad = [(str(path.relative_to(ROOT)), name) for path in sources(ROOT / front_end)
           for name in imports(path) if names_a_family(name)
           and (str(path.relative_to(ROOT)), name) not in FAMILY_IMPORTS_ALLOWED]
    assert bad == []


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
    for node in ast.walk(parsed(path)):
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


def test_every_family_is_one_package_with_its_family_and_its_axis() -> None:
    """Issue 31: a family is one place - its tables, family.py (the Family) and axis.py (its
    Axis profile over a few wire hooks); a protocol's axis.py gives the hooks only."""
    packages = [p for p in (ROOT / "families").iterdir() if (p / "__init__.py").is_file()]
    assert {p.name for p in packages} == {"dmm", "dyn5", "yzaim"}
    assert all((p / "family.py").is_file() and (p / "axis.py").is_file() for p in packages)


# ---------------------------------------------------------------- cycles and the picture
def test_the_cycle_finder_bites() -> None:
    assert graph.cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert graph.cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycle_between_modules() -> None:
    """Every import counts, lazy and TYPE_CHECKING ones too: a cycle is one in the design."""
    assert graph.cycles(graph.module_edges()) == []


def test_no_import_cycle_between_packages() -> None:
    assert graph.cycles(graph.package_edges()) == []


def test_the_picture_in_the_docs_is_the_code() -> None:
    """docs/architecture.md shows the package graph the code has; when this fails, paste the
    output of ``python -m tools.import_graph`` over the Mermaid block there."""
    text = (ROOT.parent / "docs" / "architecture.md").read_text(encoding="utf-8")
    blocks = re.findall(r"^```mermaid\n.*?^```$", text, re.M | re.S)
    assert blocks == [graph.mermaid()]


# ---------------------------------------------------------------- one shape
def re_exports_only(tree: ast.Module) -> bool:
    """A module whose statements (docstring, ``__future__`` and ``__all__`` aside) are all
    imports from one other module: an alias of that module."""
    origins: set[str] = set()
    for node in tree.body:
        if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant):
            continue
        if isinstance(node, ast.ImportFrom) and node.module == "__future__":
            continue
        if isinstance(node, ast.Assign) and [ast.unparse(t) for t in node.targets] == [
                "__all__"]:
            continue
        if isinstance(node, ast.ImportFrom):
            origins.add(node.module or "")
        elif isinstance(node, ast.Import):
            origins.update(a.name for a in node.names)
        else:
            return False
    return len(origins) == 1


def test_the_alias_finder_bites() -> None:
    assert re_exports_only(ast.parse('"""Moved."""\nfrom a.b import C, D\n__all__ = ["C"]\n'))
    assert not re_exports_only(ast.parse("from a import b\nfrom c import d\n"))
    assert not re_exports_only(ast.parse("from a import b\n\nX = b.y\n"))


def old_names_kept(path: Path) -> list[str]:
    """How ``path`` keeps an old name alive: it only re-exports another module, it
    star-imports (``import *``), or it has a module ``__getattr__``."""
    tree = parsed(path)
    found = ["re-exports only"] if re_exports_only(tree) else []
    found += ["import *" for node in ast.walk(tree)
              if isinstance(node, ast.ImportFrom) and any(a.name == "*" for a in node.names)]
    found += ["__getattr__" for node in tree.body
              if isinstance(node, ast.FunctionDef) and node.name == "__getattr__"]
    return found


def test_no_alias_module_no_star_import_no_module_getattr() -> None:
    """Issue 31 removed the one-release aliases; none come back, in none of the three ways
    an old name stays alive."""
    bad = [(str(path.relative_to(ROOT)), how) for path in sources(ROOT)
           for how in old_names_kept(path)]
    assert bad == []


def test_bounded_json_imports_only_the_errors() -> None:
    """The JSON reader both front ends share (GUI, gateway) sits beside ``errors``: any
    layer may use it."""
    found = {name for name in imports(ROOT / "bounded_json.py") if name.startswith("servobus")}
    assert found == {"servobus.errors", "servobus.errors.JsonRefused"}


# ---------------------------------------------------------------- typed capabilities
#: Objects whose attributes are probed, by name in the source: an Axis, its core, its client.
AXIS_LIKE = re.compile(r"axis|core|client", re.I)
#: ``getattr(x, name)`` calls that dispatch a request to a method by its name (the name is
#: checked against a fixed list first): not a probe of what the Axis can do.
DISPATCH = {
    ("gui/api_axes.py", "getattr(h.axis, str(action))"):
        "runs the command action named in the request, checked against ACTIONS first",
    ("gui/sampler.py", "getattr(axis, call)"):
        "runs the read a POLLED_READS entry names (position, speed, current)",
}
#: ``hasattr``/``getattr`` with a default in the front ends on objects that are no Axis,
#: core or client of a drive; each with why it is not a capability probe.
NOT_AN_AXIS = {
    ("cli/decode_cmd.py", "hasattr(self._stream, 'read1')"):
        "a byte stream (stdin or a capture file): read1 where buffered",
    ("gui/traffic.py", "getattr(item, 'is_error', False)"):
        "a traced packet or frame of any protocol (the trace hook hands decoded objects)",
    ("gui/traffic.py", "getattr(item, 'describe', None)"): "a traced packet or frame",
    ("gui/traffic.py", "getattr(item, 'lines', None)"): "a traced packet or frame",
    ("gui/server.py", "getattr(exc, 'signal_name', 'Ctrl-C')"):
        "the stop exception of a signal handler",
    ("gui/server.py", "getattr(app.state, 'gui', None)"): "Starlette's app state",
    ("gui/fair.py", "getattr(scope['app'].state, 'gui', None)"): "Starlette's app state",
    ("gui/fleet.py", "getattr(AsyncAxis, name, None)"):
        "the offline stand-in asks the API class whether a name is a coroutine method, to "
        "fail it the way the API would (dispatch, not a capability probe)",
    ("gateway/mqtt_presence.py", "getattr(code, 'is_failure', False)"):
        "a paho reason code (an int or a ReasonCode by paho version)",
    ("gateway/opcua_model.py", "getattr(arg, 'Value', arg)"): "an OPC UA Variant or value",
    ("gateway/opcua_alarms.py", "getattr(args[0], 'Value', args[0])"):
        "an OPC UA Variant or value",
    ("gateway/opcua_alarms.py", "getattr(args[1], 'Value', args[1])"):
        "an OPC UA Variant or value",
    ("gateway/mqtt.py", "getattr(client, '_client', None)"):
        "the aiomqtt client's paho client (an MQTT client, not a drive's)",
    ("gateway/mqtt.py", "getattr(paho, 'publish', None)"): "the paho client",
    ("gateway/opcua_server.py",
     "getattr(ua.StatusCodes, code, ua.StatusCodes.BadInternalError)"):
        "an OPC UA status code by name",
    ("gateway/opcua_server.py", "getattr(self.server.iserver, 'time_task', None)"):
        "asyncua's internal server",
}


def probes(relative: str, source: str) -> list[str]:
    """Where ``source`` probes an object: every ``hasattr(...)``, every ``getattr`` with a
    default, and a two-argument ``getattr`` on an axis, core or client not in DISPATCH;
    minus the listed calls on objects that are no Axis (NOT_AN_AXIS)."""
    found: list[str] = []
    for node in ast.walk(ast.parse(source)):
        if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)):
            continue
        call = ast.unparse(node)
        if node.func.id == "hasattr" or (node.func.id == "getattr" and len(node.args) > 2):
            if (relative, call) not in NOT_AN_AXIS:
                found.append(f"{relative}:{node.lineno}: {call}")
        elif node.func.id == "getattr" and node.args and AXIS_LIKE.search(
                ast.unparse(node.args[0])) and (relative, call) not in DISPATCH:
            found.append(f"{relative}:{node.lineno}: {call}")
    return found


def test_the_probe_finder_bites() -> None:
    assert probes("cli/x.py", "hasattr(axis.core, 'move_to_command')\n")
    assert probes("gui/x.py", "getattr(getattr(axis, 'client', None), 'stats', None)\n")
    assert probes("machine/x.py", "home = getattr(self.core(), 'home')\n")
    assert probes("gui/api_axes.py", "getattr(h.axis, str(action))\n") == []
    assert probes("gui/x.py", "getattr(h.axis, str(action))\n")  # listed for one file only
    assert probes("cli/x.py", "axis.supports(Capability.HOMING)\n") == []


def test_the_front_ends_ask_for_capabilities_and_never_probe() -> None:
    """Issue 31: what an Axis can do is asked by name (``axis.supports(Capability.X)``,
    servobus.axis.capabilities), never probed with ``hasattr`` or ``getattr`` with a default
    on an Axis, its core or its client. A new call on an object that is no Axis goes into
    NOT_AN_AXIS with its reason; a dispatch by name into DISPATCH."""
    found = [hit for package in FRONT_ENDS for path in sources(ROOT / package)
             for hit in probes(str(path.relative_to(ROOT)), path.read_text(encoding="utf-8"))]
    assert found == []


def test_every_listed_call_is_still_there() -> None:
    """No stale entry in NOT_AN_AXIS or DISPATCH (it would let a later probe through)."""
    seen = {(where, ast.unparse(node)) for where in {w for w, _ in (*NOT_AN_AXIS, *DISPATCH)}
            for node in ast.walk(ast.parse((ROOT / where).read_text(encoding="utf-8")))
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name)}
    assert set(NOT_AN_AXIS) | set(DISPATCH) <= seen
