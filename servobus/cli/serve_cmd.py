"""``servobus serve``: expose a machine over OPC UA (and MQTT, and the web GUI) until stopped.

Exit: 130 after Ctrl-C/SIGTERM (every axis stopped first), 2 for a usage or start-up
problem (a port in use, a users file that cannot be read, a machine file mistake).
"""

from __future__ import annotations

import asyncio
import os
import sys
from pathlib import Path

import click

from servobus.cli.command_class import ServobusCommand
from servobus.cli.context import CliContext, pass_cli
from servobus.cli.event_log import log_events
from servobus.cli.failures import CliError, Interrupted

GATEWAY_LIBRARIES = ("asyncua", "aiomqtt", "protobuf")
#: the top-level module of each library (protobuf's is google.protobuf)
LIBRARY_MODULES = {"asyncua": "asyncua", "aiomqtt": "aiomqtt", "google": "protobuf"}


def _missing_library(exc: ModuleNotFoundError) -> Exception:
    """asyncua and aiomqtt are in the default install (pyproject.toml, issue 32): one missing
    means an environment installed otherwise (--no-deps, a broken venv); name the command
    that installs them rather than calling it a servobus bug."""
    library = LIBRARY_MODULES.get((exc.name or "").split(".")[0])
    if library is None:
        return exc
    return CliError(f"servobus serve needs the Python package {library!r}, which is not "
                    "installed in this environment",
                    f"install the gateway's libraries with `{sys.executable} -m pip install "
                    f"{' '.join(GATEWAY_LIBRARIES)}`")


SHUTDOWN_NOTE = "every axis was stopped and the gateway closed"
MQTT_PASSWORD_ENV = "SERVOBUS_MQTT_PASSWORD"
FILE = click.Path(dir_okay=False, path_type=Path)
EXISTING = click.Path(dir_okay=False, exists=True, path_type=Path)


@click.command("serve", cls=ServobusCommand)
@click.option("--machine", "machine_path", type=EXISTING, default=None,
              help="the machine file (TOML, docs/machine.md) [default: the global --machine, "
                   "SERVOBUS_MACHINE, else the built-in virtual machine]")
@click.option("--opcua", "endpoint", default="opc.tcp://127.0.0.1:4840", show_default=True,
              metavar="opc.tcp://HOST:PORT",
              help="OPC UA endpoint; beyond loopback Basic256Sha256 Sign&Encrypt only")
@click.option("--users", "users_path", type=EXISTING, default=None,
              help="users who may command (servobus users add); without it read-only")
@click.option("--cert", type=EXISTING, default=None,
              help="server certificate (DER) [default: generated next to the machine file "
                   "when serving beyond loopback]")
@click.option("--key", type=EXISTING, default=None, help="private key of --cert (PEM)")
@click.option("--rate", type=click.FloatRange(0.1, 1000), default=20.0, show_default=True,
              help="sampling rate per axis in Hz (at most; each link shares its capacity)")
@click.option("--mqtt", "mqtt_url", default=None, metavar="mqtt://HOST:PORT",
              help="publish to this broker (mqtts:// for TLS)")
@click.option("--mqtt-rate", type=click.FloatRange(0.1, 100), default=5.0, show_default=True,
              help="MQTT state messages per axis per second")
@click.option("--mqtt-commands", is_flag=True,
              help="take commands on servobus/<machine>/<axis>/cmd (needs --mqtt-user)")
@click.option("--mqtt-user", default=None, help="broker user name")
@click.option("--mqtt-password-file", type=EXISTING, default=None,
              help=f"broker password (first line) [default: {MQTT_PASSWORD_ENV}]")
@click.option("--mqtt-ca", type=EXISTING, default=None, help="CA certificate of the broker (TLS)")
@click.option("--mqtt-cert", type=EXISTING, default=None, help="client certificate (TLS)")
@click.option("--mqtt-key", type=EXISTING, default=None, help="client key (TLS)")
@click.option("--mqtt-prefix", default="servobus", show_default=True, metavar="PREFIX",
              help="first topic level(s): topics are PREFIX/<machine>/...")
@click.option("--gateway-id", default=None, metavar="ID",
              help="this gateway's name on the broker and in OPC UA: MQTT client id "
                   "servobus-ID, ApplicationUri urn:servobus:gateway:ID "
                   "[default: the machine's name]")
@click.option("--sparkplug", default=None, metavar="GROUP",
              help="be a Sparkplug B edge node on the --mqtt broker too: topics "
                   "spBv1.0/GROUP/.../ID/<axis> (DCMD with --mqtt-commands)")
@click.option("--gui", is_flag=True, help="serve the web GUI from this process too")
@click.option("--gui-port", type=click.IntRange(0, 65535), default=8080, show_default=True,
              help="port of the GUI on 127.0.0.1")
@pass_cli
def serve(ctx: CliContext, machine_path: Path | None, endpoint: str, users_path: Path | None,
          cert: Path | None, key: Path | None, rate: float, mqtt_url: str | None,
          mqtt_rate: float, mqtt_commands: bool, mqtt_user: str | None,
          mqtt_password_file: Path | None, mqtt_ca: Path | None, mqtt_cert: Path | None,
          mqtt_key: Path | None, mqtt_prefix: str, gateway_id: str | None,
          sparkplug: str | None, gui: bool, gui_port: int) -> None:
    """Serve a machine to OPC UA clients and an MQTT broker until Ctrl-C.

    Anonymous OPC UA clients may browse, read and subscribe; methods that command an axis
    need a user of --users. Ctrl-C or SIGTERM stops every axis, then the gateway.
    """
    try:
        from servobus.gateway.heap import collector_off
        from servobus.gateway.opcua_server import OpcUaOptions, parse_endpoint
        from servobus.gateway.serve import GatewayOptions, open_and_serve
        from servobus.gateway.users import Users

        if mqtt_url is not None:  # MQTT's libraries only when served (faster start)
            from servobus.gateway.mqtt import MqttOptions, parse_broker
        if sparkplug is not None:
            import servobus.gateway.sparkplug.node  # noqa: F401  (protobuf: said here)
    except ModuleNotFoundError as exc:
        raise _missing_library(exc) from exc

    if machine_path is None and ctx.machine_path is not None:
        machine_path = Path(ctx.machine_path)
        if not machine_path.is_file():
            raise click.BadParameter(f"{machine_path}: no such file", param_hint="--machine")
    if (cert is None) != (key is None):
        raise click.UsageError("give --cert and --key together")
    if mqtt_commands and mqtt_url is None:
        raise click.UsageError("--mqtt-commands needs --mqtt")
    if sparkplug is not None and mqtt_url is None:
        raise click.UsageError("--sparkplug needs --mqtt (the broker)")
    parse_endpoint(endpoint)
    if mqtt_url is not None:
        parse_broker(mqtt_url)  # a malformed URL: one line before anything starts
    check_identity(mqtt_prefix, gateway_id, sparkplug)
    users = Users.load(users_path) if users_path is not None else None
    stem = machine_path.stem if machine_path is not None else "servobus"
    opcua = OpcUaOptions(endpoint=endpoint, users=users, cert=cert, key=key,
                         cert_dir=machine_path.parent if machine_path else None,
                         cert_stem=stem, gateway_id=gateway_id)
    mqtt = None
    if mqtt_url is not None:
        password = os.environ.get(MQTT_PASSWORD_ENV)
        if mqtt_password_file is not None:
            lines = mqtt_password_file.read_text().splitlines()
            password = lines[0] if lines else ""
        mqtt = MqttOptions(url=mqtt_url, username=mqtt_user, password=password,
                           commands=mqtt_commands, rate_hz=mqtt_rate, ca=mqtt_ca,
                           cert=mqtt_cert, key=mqtt_key, prefix=mqtt_prefix,
                           gateway_id=gateway_id)
    options = GatewayOptions(opcua=opcua, mqtt=mqtt, rate_hz=rate,
                             gui_port=gui_port if gui else None, own_process=True,
                             sparkplug=sparkplug)
    _log_events()
    with collector_off():  # on again at "ready" (servobus.gateway.heap)
        name = asyncio.run(open_and_serve(
            machine_path, options, lambda line: click.echo(line, err=line.startswith("warning:"))))
    raise Interrupted("Ctrl-C" if name == "SIGINT" else name, SHUTDOWN_NOTE)


def check_identity(prefix: str, ident: str | None, group: str | None = None) -> None:
    """--mqtt-prefix, --gateway-id and --sparkplug, checked before anything starts (a usage
    error)."""
    from servobus.errors import ArgumentRangeError
    from servobus.gateway.identity import check_prefix, gateway_id

    try:
        check_prefix(prefix)
        if ident is not None:
            gateway_id("", ident)
        if group is not None:
            from servobus.gateway.sparkplug.node import check_group

            check_group(group)
    except ArgumentRangeError as exc:
        raise click.UsageError(str(exc)) from None


def _log_events() -> None:
    """The gateway's and the machine's events, one line each, on stderr (library chatter
    stays with servobus.cli.main's rule: only with --debug)."""
    log_events("servobus.gateway", "servobus.machine")


def register(group: click.Group) -> None:
    group.add_command(serve)
