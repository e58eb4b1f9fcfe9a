"""``servobus sim control``: a client of a virtual drive server's control channel.

    servobus sim dyn232 --control tcp://127.0.0.1:4003 &
    servobus sim control --to tcp://127.0.0.1:4003 --id 1 analog 2.5
    servobus sim control --to tcp://127.0.0.1:4003 --id 1 fault over_current
    servobus sim control --to tcp://127.0.0.1:4003 --id 1 state

Every sub-command sends one request of the protocol in docs/sim-control.md and prints the
reply (``--json``: as it came). An error reply ends with one ``error:`` line, exit code 2.
Protocol-free: it talks to whatever server serves the channel.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any

import click

from servobus.cli.command_class import ServobusCommand
from servobus.cli.context import CliContext
from servobus.cli.failures import CliError
from servobus.cli.param_types import Seconds
from servobus.sim.control_client import DEFAULT_TIMEOUT_S, FAULTS, ControlClient
from servobus.sim.core.control import Arg, ControlError, Reply
from servobus.sim.core.io import PulseFormat
from servobus.sim.core.loads import PRESETS

CONTROL_ENV = "SERVOBUS_CONTROL"
_META = "servobus.sim_control"


@click.group("control")
@click.option("--to", "url", envvar=CONTROL_ENV, required=True, metavar="tcp://HOST:PORT",
              help=f"the simulator's control channel (its --control address; or {CONTROL_ENV})")
@click.option("--id", "drive_id", type=click.IntRange(0, 255), default=None,
              help="the drive [default: the only drive the channel serves]")
@click.option("--timeout", type=Seconds(), default=DEFAULT_TIMEOUT_S, show_default=True,
              help="reply deadline in seconds")
@click.pass_context
def control_group(ctx: click.Context, url: str, drive_id: int | None, timeout: float) -> None:
    """The world around a running simulator's drives: JP3 inputs and outputs (DMM), supply
    and battery (YZ-AIM), loads, internal state and faults (docs/sim-control.md)."""
    ctx.meta[_META] = (url, drive_id, timeout)


def _send(cmd: str, **args: Any) -> None:
    ctx = click.get_current_context()
    url, drive_id, timeout = ctx.meta[_META]
    request: dict[str, Any] = {"cmd": cmd, **{k: v for k, v in args.items() if v is not None}}
    if drive_id is not None:
        request["id"] = drive_id
    try:
        with ControlClient(url, timeout=timeout) as client:
            reply = client.request(request)
    except ControlError as exc:  # pragma: no cover - request() answers error replies
        raise CliError(str(exc), "see docs/sim-control.md") from None
    if not reply.get("ok"):
        raise CliError(f"{reply.get('error', reply)} ({reply.get('kind', '?')})",
                       f"see `servobus sim control {cmd} --help` and docs/sim-control.md")
    obj = ctx.find_object(CliContext)
    if obj is not None and obj.json:
        click.echo(json.dumps(reply))
    else:
        for line in _lines(reply):
            click.echo(line)


def _lines(reply: Reply, prefix: str = "") -> list[str]:
    out: list[str] = []
    for key, value in reply.items():
        if key in ("ok", "seq") or (not prefix and key == "cmd"):
            continue
        if isinstance(value, dict):
            out += _lines(value, f"{prefix}{key}.")
        elif isinstance(value, list):
            out.append(f"{prefix}{key}: {', '.join(str(v) for v in value)}")
        else:
            out.append(f"{prefix}{key}: {json.dumps(value)}")
    return out


def _command(name: str) -> Callable[[Callable[..., None]], click.Command]:
    return control_group.command(name, cls=ServobusCommand)


@_command("ping")
def ping_cmd() -> None:
    """The drive ids, commands and faults the channel serves."""
    _send("ping")


@_command("state")
def state_cmd() -> None:
    """Internal state: reference, following error, speed, current, bus, temperature, ..."""
    _send("state")


@_command("outputs")
def outputs_cmd() -> None:
    """JP3 outputs: ALM (8), ONPOS or BKO (9), ZRI (10), by meaning and pin level."""
    _send("outputs")


@_command("analog")
@click.argument("volts", type=float)
def analog_cmd(volts: float) -> None:
    """Set the analog input JP3-2 (-12..12 V)."""
    _send("analog", volts=volts)


@_command("pulses")
@click.argument("count", type=int)
@click.option("--rate", type=float, default=None, help="pulses per second [default 500 kHz]")
@click.option("--seconds", type=float, default=None, help="spread over this long instead")
@click.option("--format", "fmt", type=click.Choice([f.value for f in PulseFormat]),
              default=None, help="[default: the format the drive decodes]")
def pulses_cmd(count: int, rate: float | None, seconds: float | None, fmt: str | None) -> None:
    """Feed COUNT signed pulses on JP3-3..6 (4 x GEAR_NUM per revolution)."""
    _send("pulses", count=count, rate=rate, seconds=seconds, format=fmt)


@_command("ena")
@click.argument("state", type=click.Choice(["enable", "disable"]))
def ena_cmd(state: str) -> None:
    """The ENA input JP3-11: disable frees the motor and clears commands and error."""
    _send("ena", enabled=state == "enable")


@_command("bus")
@click.argument("volts", type=float)
def bus_cmd(volts: float) -> None:
    """Set the supply / DC bus voltage (DMM: over voltage above 80 V; YZ-AIM: above the
    model's supply range + 10 %)."""
    _send("bus", volts=volts)


@_command("battery")
@click.argument("state", type=click.Choice(["ok", "flat"]))
def battery_cmd(state: str) -> None:
    """YZ-AIM: the multi-turn backup battery (flat: warning 0x13, the motor keeps running)."""
    _send("battery", ok=state == "ok")


@_command("load")
@click.option("--torque", "torque_nm", type=float, default=None, help="external torque, N m")
@click.option("--friction", type=float, default=None, help="Coulomb friction, N m")
@click.option("--load", "preset", type=click.Choice(sorted(PRESETS)), default=None,
              help="a sample load (docs/tuning.md)")
@click.option("--inertia", type=float, default=None, help="load inertia / rotor inertia")
@click.option("--resonance", type=float, default=None,
              help="resonance of a compliant coupling, Hz (0: rigid)")
@click.option("--load-torque", "load_torque", type=float, default=None,
              help="torque on the load side, N m, against +")
def load_cmd(torque_nm: float | None, friction: float | None, preset: str | None,
             inertia: float | None, resonance: float | None,
             load_torque: float | None) -> None:
    """External torque and friction at the shaft; the load to tune on (docs/tuning.md)."""
    _send("load", torque_nm=torque_nm, friction=friction, load=preset, inertia=inertia,
          resonance=resonance, load_torque=load_torque)


@_command("block")
@click.argument("state", type=click.Choice(["on", "off"]))
def block_cmd(state: str) -> None:
    """Block the shaft (on) or free it (off)."""
    _send("block", blocked=state == "on")


def _fault_options() -> list[click.Option]:
    """One option per fault argument of the FAULTS table (--volts, --seconds, ...)."""
    args: dict[str, list[tuple[str, Arg]]] = {}
    for fault in FAULTS.values():
        for arg in fault.args:
            args.setdefault(arg.name, []).append((fault.name, arg))
    options = []
    for name, uses in args.items():
        arg = uses[0][1]
        kind: Any = click.Choice(arg.choices) if arg.choices else arg.kind
        text = "; ".join(f"{fault}: {a.doc} [{'required' if a.required else a.default}]"
                         for fault, a in uses)
        options.append(click.Option([f"--{name.replace('_', '-')}", name], type=kind,
                                    default=None, help=text))
    return options


@click.argument("name", type=click.Choice(sorted(FAULTS)))
def fault_cmd(name: str, **params: Any) -> None:
    """Inject a fault (docs/sim-control.md has what each does and how it clears)."""
    _send("fault", fault=name, **params)


fault_cmd.__click_params__ += _fault_options()  # type: ignore[attr-defined]
fault_cmd = _command("fault")(fault_cmd)


@_command("clear")
def clear_cmd() -> None:
    """Remove every fault cause (encoder, blocked shaft, load torque, bus back to 60 V);
    a latched alarm stays until a power cycle (6.1)."""
    _send("clear")


@_command("power-cycle")
@click.option("--off", "off_s", type=float, default=None, help="seconds without power [0]")
def power_cycle_cmd(off_s: float | None) -> None:
    """Power off, then on: clears a latched alarm (6.1)."""
    _send("power_cycle", off_s=off_s)


@_command("send")
@click.argument("request")
def send_cmd(request: str) -> None:
    """Send one raw JSON request, e.g. '{"cmd": "state", "id": 1}'."""
    try:
        obj = json.loads(request)
    except ValueError as exc:
        raise click.BadParameter(f"not JSON: {exc}", param_hint="REQUEST") from None
    if not isinstance(obj, dict):
        raise click.BadParameter("a request is a JSON object", param_hint="REQUEST")
    _send(str(obj.pop("cmd", "")), **obj)
