"""The options every ``servobus sim <protocol>`` server shares, as data (servobus.axis.cli_spec),
and the lines each prints: a protocol's ``cli.py`` lists them in its commands."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

from servobus.axis.cli_spec import Option
from servobus.errors import ArgumentRangeError, ServobusError
from servobus.sim.core import loads
from servobus.sim.core.loads import PLANTS
from servobus.sim.core.motor import EngineShaft
from servobus.sim.line_server import parse_listen_url
from servobus.sim.server_limits import DEFAULT_MAX_CLIENTS
from servobus.sim.socketcand_hub import parse_socketcand_address


def sim_options(*, parse_ids: Callable[[str], Any], ids_default: str | None, ids_help: str,
                fast_help: str, state_help: str, models: Iterable[str], model_default: str,
                model_help: str, clients_help: str) -> tuple[Option, ...]:
    """``--ids``, ``--fast``, ``--state``, ``--model``, ``--duration``, ``--max-clients``
    (received as ``ids`` - ``parse_ids(text)``, None when not given and no default -,
    ``fast``, ``state``, ``model``, ``duration``, ``max_clients``), then
    :data:`LOAD_OPTIONS`. Only the help texts, defaults and id parsing differ between
    protocols."""
    return (
        Option("--ids", "ids", ids_help, default=ids_default,
               show_default=ids_default is not None, metavar="1,2,3", parse=parse_ids),
        Option("--fast", "fast", fast_help, type=bool),
        Option("--state", "state", state_help, metavar="FILE"),
        Option("--model", "model", model_help, choices=tuple(sorted(models)),
               default=model_default, show_default=True),
        Option("--duration", "duration",
               "stop by itself after this many seconds [default: run until Ctrl-C]",
               type=float, minimum=0.0, metavar="SECONDS"),
        Option("--max-clients", "max_clients", clients_help, type=int, minimum=1,
               default=DEFAULT_MAX_CLIENTS, show_default=True),
        *LOAD_OPTIONS,
    )


#: ``--load``, ``--inertia``, ``--resonance``, ``--load-torque``: the load every motor of the
#: server drives (servobus.sim.core.loads, docs/tuning.md); received as ``load``,
#: ``inertia``, ``resonance``, ``load_torque`` (None when not given), for :func:`apply_load`;
#: and ``--plant``, received as ``plant``.
LOAD_OPTIONS = (
    Option("--load", "load", "sample load: " + ", ".join(
        f"{k} ({p.doc})" for k, p in loads.PRESETS.items()), choices=tuple(loads.PRESETS)),
    Option("--inertia", "inertia", "load inertia / rotor inertia (overrides --load's)",
           type=float, minimum=loads.RANGES["inertia"][0], maximum=loads.RANGES["inertia"][1],
           metavar="RATIO"),
    Option("--resonance", "resonance", "resonance of a compliant coupling, Hz (0: rigid)",
           type=float, minimum=loads.RANGES["resonance"][0],
           maximum=loads.RANGES["resonance"][1], metavar="HZ"),
    Option("--load-torque", "load_torque", "torque on the load side, N m, against +",
           type=float, minimum=loads.RANGES["load_torque"][0],
           maximum=loads.RANGES["load_torque"][1], metavar="NM"),
    Option("--plant", "plant", "physics: the servo loop, motor and load; ideal: the shaft "
           "follows the reference exactly (no current, no loop alarms, no load; a turning "
           "drive costs next to nothing: for many drives behind a gateway or a benchmark)",
           choices=PLANTS, default="physics", show_default=True),
)


def apply_load(motors: Iterable[object], *, load: str | None, inertia: float | None,
               resonance: float | None, load_torque: float | None,
               plant: str = "physics") -> None:
    """Set the :data:`LOAD_OPTIONS` given on every motor (a core or a front with ``drive``);
    ArgumentRangeError for a bad combination (a load on the ideal plant, which has none)."""
    options = {"load": load, "inertia": inertia, "resonance": resonance,
               "load_torque": load_torque}
    if plant not in PLANTS:
        raise ArgumentRangeError(f"--plant {plant}: give one of {', '.join(PLANTS)}")
    try:
        settings = loads.load_settings(options)
    except ServobusError as exc:
        raise ArgumentRangeError(str(exc)) from None
    ideal = plant == "ideal"
    if ideal and not settings.empty:
        raise ArgumentRangeError("--plant ideal has no mechanics: leave out --load, "
                                 "--inertia, --resonance and --load-torque")
    if settings.empty and not ideal:
        return
    for motor in motors:
        shaft = motor if isinstance(motor, EngineShaft) else getattr(motor, "drive", None)
        if isinstance(shaft, EngineShaft):
            if ideal:
                shaft.set_ideal(True)
            else:
                shaft.set_mechanics(settings)


def listen_option(flag: str, dest: str, help: str) -> Option:
    """A ``tcp://HOST:PORT`` option, received as (host, port) or None."""
    return Option(flag, dest, help, metavar="tcp://HOST:PORT", parse=parse_listen_url)


#: ``--socketcand``: the CAN bus of a CAN protocol's virtual drives, served over socketcand.
SOCKETCAND = Option("--socketcand", "address",
                    "serve the CAN bus over socketcand; PORT 0 picks a free port",
                    metavar="HOST:PORT", default="127.0.0.1:0", show_default=True,
                    parse=parse_socketcand_address)

#: ``--control``: serve the control channel (servobus.sim.control_server.start_control).
CONTROL = listen_option(
    "--control", "control",
    "also serve the control channel here (JSON lines: analog input, pulse trains, ENA, "
    "outputs, internal state, faults; `servobus sim control`); PORT 0 picks a free port; a "
    "missing host means 127.0.0.1")

#: ``--control`` of the YZ-AIM simulators (servobus.sim.yzaim.control).
CONTROL_YZAIM = listen_option(
    "--control", "control",
    "also serve the control channel here (JSON lines: supply, battery, load, blocked "
    "shaft, internal state, faults; `servobus sim control`); PORT 0 picks a free port; a "
    "missing host means 127.0.0.1")


def serial_line_options(*, connects: str, tap_carries: str) -> tuple[Option, ...]:
    """``--listen``, ``--pty`` and ``--tap`` of a virtual serial line (``listen``, ``pty``,
    ``tap``; :func:`line_endpoint` completes ``listen``). ``connects`` names the client URL
    that reaches ``--listen``, ``tap_carries`` what the tap serves (``byte``, ``frame``)."""
    return (
        listen_option("--listen", "listen",
                      f"serve the line on TCP ({connects}://HOST:PORT connects); PORT 0 picks a "
                      "free port; a missing host means 127.0.0.1  [default: tcp://127.0.0.1:0, "
                      "or none with --pty]"),
        Option("--pty", "pty", "serve the line on a pseudo-terminal; prints its path",
               type=bool),
        listen_option("--tap", "tap",
                      f"also serve every {tap_carries} of the line (both directions) for "
                      "`servobus sniff`"),
    )


def line_endpoint(listen: tuple[str, int] | None, pty: bool) -> tuple[str, int] | None:
    """Where the line listens: ``--listen``, else 127.0.0.1 at a free port unless ``--pty``."""
    return ("127.0.0.1", 0) if listen is None and not pty else listen


def sim_banner(protocol: str, count: int, what: str, model: str, id_word: str,
               ids: Iterable[int], fast: bool, timing: str) -> str:
    """The stderr line a server prints once it is up, e.g. ``servobus sim dyn232: 2 DYN2
    drive(s), ids 1,2, paced at 38400 8N1`` (``unpaced (--fast)`` instead of ``timing``)."""
    return (f"servobus sim {protocol}: {count} {model} {what}(s), {id_word} "
            f"{','.join(str(i) for i in ids)}, {'unpaced (--fast)' if fast else timing}")


def stopped_line(*counts: str) -> str:
    """The last stderr line of a server: ``stopped: <count>, <count>, ...``."""
    return f"stopped: {', '.join(counts)}"
