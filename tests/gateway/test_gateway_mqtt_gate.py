"""The refusal rules of MQTT commands (servobus.gateway.mqtt_gate), without a broker."""

from __future__ import annotations

import asyncio
import json
import ssl
from pathlib import Path
from typing import Any

import pytest
from fake_machine import FakeMachine

from servobus.errors import ArgumentRangeError
from servobus.gateway.commands import Command, Commander, Refused
from servobus.gateway.identity import application_uri, check_prefix, client_id, gateway_id
from servobus.gateway.mqtt import MqttGateway, MqttOptions, parse_broker, state_json
from servobus.gateway.mqtt_gate import MAX_IDS, CommandGate
from servobus.gateway.sampler import Sample, Sampler

NOW = 1_800_000_000.0


def msg(**fields: object) -> bytes:
    return json.dumps(fields).encode()


def refused(gate: CommandGate, payload: bytes, *, retained: bool = False,
            now: float = NOW) -> str:
    with pytest.raises(Refused) as exc:
        gate.admit("x", payload, retained, now)
    return exc.value.code


def test_ack_needs_an_id_and_a_fresh_timestamp_as_motion_does() -> None:
    """ack allows motion again: a replayed or late one must never acknowledge a power
    loss its sender did not see (docs/gateway.md "Recovery")."""
    gate = CommandGate(max_age_s=5)
    assert refused(gate, msg(cmd="ack")) == "BadInvalidArgument"
    assert refused(gate, msg(id="k0", ts=NOW - 60, cmd="ack")) == "BadInvalidTimestamp"
    ok = gate.admit("x", msg(id="k1", ts=NOW, cmd="ack"), False, NOW)
    assert (ok.command.name, ok.command.value) == ("ack", None)
    assert refused(gate, msg(id="k1", ts=NOW, cmd="ack")) == "BadRequestNotAllowed"


def test_a_motion_command_runs_once() -> None:
    gate = CommandGate(max_age_s=5)
    ok = gate.admit("x", msg(id="a1", ts=NOW - 1, cmd="move_relative", value=2), False, NOW)
    assert (ok.id, ok.command.name, ok.command.value) == ("a1", "move_relative", 2.0)
    assert refused(gate, msg(id="a1", ts=NOW - 1, cmd="move_relative", value=2),
                   now=NOW + 1) == "BadRequestNotAllowed"  # a QoS 1 redelivery


def test_retained_stale_future_and_malformed_commands_are_refused() -> None:
    gate = CommandGate(max_age_s=5)
    good = {"id": "b", "ts": NOW, "cmd": "move_absolute", "value": 1.0}
    assert refused(gate, msg(**good), retained=True) == "BadRequestNotAllowed"
    assert refused(gate, msg(**{**good, "ts": NOW - 6})) == "BadInvalidTimestamp"
    assert refused(gate, msg(**{**good, "ts": NOW + 3})) == "BadInvalidTimestamp"
    assert refused(gate, msg(**{**good, "ts": "now"})) == "BadInvalidArgument"
    assert refused(gate, msg(cmd="move_absolute", value=1.0, ts=NOW)) == "BadInvalidArgument"
    assert refused(gate, msg(id="c", cmd="move_absolute", value=1.0)) == "BadInvalidArgument"
    assert refused(gate, msg(**{**good, "value": "far"})) == "BadInvalidArgument"
    assert refused(gate, msg(**{**good, "cmd": "explode"})) == "BadMethodInvalid"
    assert refused(gate, b"[1, 2]") == "BadDecodingError"
    assert refused(gate, b"\xff\xfe") == "BadDecodingError"
    assert refused(gate, b" " * 5000) == "BadRequestTooLarge"
    assert refused(gate, msg(**{**good, "id": "x" * 129})) == "BadInvalidArgument"
    # none of these used up the id: the good command still runs
    assert gate.admit("x", msg(**good), False, NOW).id == "b"
    # a stop needs no id and no timestamp
    assert gate.admit("x", msg(cmd="stop"), False, NOW).command.name == "stop"


def test_ids_are_remembered_longer_than_a_command_is_fresh_and_bounded() -> None:
    gate = CommandGate(max_age_s=5)
    gate.admit("x", msg(id="old", ts=NOW, cmd="enable"), False, NOW)
    # 9 s later the id is still known (its message would be stale anyway at 5 s)
    assert refused(gate, msg(id="old", ts=NOW + 9, cmd="enable"), now=NOW + 9) == \
        "BadRequestNotAllowed"
    for i in range(MAX_IDS - 1):
        gate.admit("x", msg(id=f"n{i}", ts=NOW + 9, cmd="enable"), False, NOW + 9)
    assert refused(gate, msg(id="full", ts=NOW + 9, cmd="enable"), now=NOW + 9) == \
        "BadTooManyOperations"
    # after 2 x max_age the old ids are gone and room is made
    assert gate.admit("x", msg(id="later", ts=NOW + 30, cmd="enable"), False, NOW + 30).id


def test_commands_need_the_brokers_authentication() -> None:
    machine = FakeMachine()
    sampler = Sampler(machine, 10)  # type: ignore[arg-type]
    commander = Commander(machine)  # type: ignore[arg-type]
    with pytest.raises(ArgumentRangeError, match="authentication"):
        MqttGateway(machine, sampler, commander,  # type: ignore[arg-type]
                    MqttOptions("mqtt://127.0.0.1:1883", commands=True))
    gw = MqttGateway(machine, sampler, commander,  # type: ignore[arg-type]
                     MqttOptions("mqtt://u:p%40ss@127.0.0.1:1884", commands=True))
    assert (gw.username, gw.password, gw.broker.port) == ("u", "p@ss", 1884)
    assert parse_broker("mqtts://h").port == 8883 and parse_broker("mqtts://h").tls
    with pytest.raises(ArgumentRangeError):
        parse_broker("http://h")
    bad = FakeMachine(name="cell/1")
    with pytest.raises(ArgumentRangeError, match="topic"):
        MqttGateway(bad, sampler, commander, MqttOptions("mqtt://h"))  # type: ignore[arg-type]


def test_state_json_has_the_named_fields() -> None:
    body = json.loads(state_json(Sample("x", NOW, False, "axis offline"), "mm"))
    assert {"position", "speed", "moving", "alarm", "unit"} <= set(body)
    assert body["ok"] is False and body["position"] is None and body["unit"] == "mm"


def test_tls_options_make_a_verifying_context(tmp_path: Path) -> None:
    machine = FakeMachine()
    sampler = Sampler(machine, 10)  # type: ignore[arg-type]
    commander = Commander(machine)  # type: ignore[arg-type]

    def gateway(url: str, **options: Any) -> MqttGateway:
        return MqttGateway(machine, sampler, commander,  # type: ignore[arg-type]
                           MqttOptions(url, **options))

    assert gateway("mqtt://127.0.0.1")._tls() is None  # plain TCP unless asked
    context = gateway("mqtts://broker.example")._tls()
    assert isinstance(context, ssl.SSLContext)
    assert context.verify_mode == ssl.CERT_REQUIRED and context.check_hostname
    ca = tmp_path / "ca.pem"
    ca.write_bytes(asyncio.run(_self_signed(tmp_path)))
    with_ca = gateway("mqtt://127.0.0.1:8883", ca=ca)._tls()  # a CA file turns TLS on
    assert with_ca is not None and with_ca.get_ca_certs()


async def _self_signed(folder: Path) -> bytes:
    from asyncua.crypto.cert_gen import setup_self_signed_certificate
    from cryptography.hazmat.primitives.serialization import Encoding
    from cryptography.x509 import load_der_x509_certificate
    from cryptography.x509.oid import ExtendedKeyUsageOID

    cert, key = folder / "c.der", folder / "k.pem"
    await setup_self_signed_certificate(key, cert, "urn:test:broker", "broker.example",
                                        [ExtendedKeyUsageOID.SERVER_AUTH], {"commonName": "ca"})
    return load_der_x509_certificate(cert.read_bytes()).public_bytes(Encoding.PEM)


def test_serve_refuses_half_given_options() -> None:
    from click.testing import CliRunner

    from servobus.cli.main import cli

    result = CliRunner().invoke(cli, ["serve", "--mqtt-commands"])
    assert result.exit_code == 2 and "--mqtt-commands needs --mqtt" in result.output
    result = CliRunner().invoke(cli, ["serve", "--opcua", "http://x:1"])
    assert result.exit_code != 0


async def test_set_speed_is_a_lease_of_its_client_with_a_checked_ttl() -> None:
    gate = CommandGate(max_age_s=5)
    plain = gate.admit("x", msg(id="s1", ts=NOW, cmd="set_speed", value=3), False, NOW)
    assert (plain.command.ttl, plain.owner) == (0.5, "mqtt")  # the default ttl and owner
    named = gate.admit("x", msg(id="s2", ts=NOW, cmd="set_speed", value=3, ttl=0.2,
                                client="line-3"), False, NOW)
    assert (named.command.ttl, named.owner) == (0.2, "mqtt:line-3")
    for bad in (msg(id="s3", ts=NOW, cmd="set_speed", value=3, ttl="0.2"),
                msg(id="s4", ts=NOW, cmd="set_speed", value=3, ttl=True),
                msg(id="s5", ts=NOW, cmd="set_speed", value=3, client=""),
                msg(id="s6", ts=NOW, cmd="set_speed", value=3, client="c" * 65)):
        assert refused(gate, bad) == "BadInvalidArgument"
    # NaN is no JSON number: refused while parsing (servobus.bounded_json)
    assert refused(gate, msg(id="s9", ts=NOW, cmd="set_speed", value=3, ttl=float("nan"))) \
        == "BadDecodingError"
    # the range is the commander's, as for OPC UA's Ttl; nothing reaches an axis
    machine = FakeMachine()
    commander = Commander(machine)  # type: ignore[arg-type]
    for payload, code in ((msg(id="s7", ts=NOW, cmd="set_speed", value=3, ttl=1.01),
                           "BadOutOfRange"),
                          (msg(id="s8", ts=NOW, cmd="set_speed", value=3, ttl=0),
                           "BadOutOfRange"),
                          (msg(id="s10", ts=NOW, cmd="move_relative", value=3, ttl=0.5),
                           "BadInvalidArgument")):
        accepted = gate.admit("a0", payload, False, NOW)
        with pytest.raises(Refused) as exc:
            await commander.run("mqtt:gateway", accepted.command, "mqtt", accepted.owner)
        assert exc.value.code == code, payload
    assert machine.log == []


HUGE = "9" * 400
CMD = '"id": "h1", "cmd": "move_relative"'
BEYOND = {
    "400-digit ts": f'{{{CMD}, "ts": {HUGE}, "value": 1}}',
    "400-digit value": f'{{{CMD}, "ts": {NOW}, "value": {HUGE}}}',
    "-400-digit value": f'{{{CMD}, "ts": {NOW}, "value": -{HUGE}}}',
    "1e400 value": f'{{{CMD}, "ts": {NOW}, "value": 1e400}}',
    "-1e999 ts": f'{{{CMD}, "ts": -1e999, "value": 1}}',
    "Infinity ttl": f'{{{CMD}, "ts": {NOW}, "value": 1, "ttl": Infinity}}',
    "1000-deep value": f'{{{CMD}, "ts": {NOW}, "value": {"[" * 1000}{"]" * 1000}}}',
    "1000-deep": "[" * 1000 + "]" * 1000,
}


@pytest.mark.parametrize("payload", BEYOND.values(), ids=BEYOND.keys())
def test_numbers_beyond_a_double_and_deep_nesting_are_refused_typed(payload: str) -> None:
    """Before issue 30 these raised OverflowError or RecursionError out of the gate."""
    gate = CommandGate(max_age_s=5)
    assert refused(gate, payload.encode()) == "BadDecodingError"
    assert gate.admit("x", msg(id="h1", ts=NOW, cmd="move_relative", value=1), False, NOW).id


class Published:
    """What the gateway publishes (an aiomqtt client's publish, recorded)."""

    def __init__(self) -> None:
        self.messages: list[tuple[str, dict[str, Any]]] = []

    async def publish(self, topic: str, payload: bytes, **options: object) -> None:
        self.messages.append((topic, json.loads(payload)))


@pytest.mark.parametrize("payload", BEYOND.values(), ids=BEYOND.keys())
async def test_the_command_handler_answers_them_on_reply(payload: str) -> None:
    """The handler (the one that reads the broker's messages) answers each such command on
    ``.../reply`` and nothing reaches an axis."""
    machine = FakeMachine()
    sampler = Sampler(machine, 10)  # type: ignore[arg-type]
    gw = MqttGateway(machine, sampler, Commander(machine),  # type: ignore[arg-type]
                     MqttOptions("mqtt://u:p@127.0.0.1:1884", commands=True))
    client = Published()
    await gw._command(client, "a0", payload.encode(), False)  # type: ignore[arg-type]
    [(topic, reply)] = client.messages
    assert topic.endswith("/a0/reply") and reply["ok"] is False
    assert reply["code"] == "BadDecodingError" and machine.log == []


def test_a_value_on_a_command_that_takes_none_is_ignored() -> None:
    """Found by the fuzz test (issue 30): a stop whose value was a list raised TypeError."""
    gate = CommandGate()
    for value in ([1], {"a": 1}, "far", 1.5, None):
        accepted = gate.admit("x", msg(cmd="stop", value=value), False, NOW)
        assert accepted.command == Command("x", "stop", None, None)


def test_gateway_ids_uris_and_prefixes() -> None:
    assert gateway_id("virtual-cell") == "virtual-cell"
    assert gateway_id("Cell 3 / Hall B") == "Cell-3---Hall-B"  # the default made fit
    assert gateway_id("x", "pc-7.line_2") == "pc-7.line_2"
    for bad in ("", "a b", "a/b", "x" * 65, "\u00fc"):
        with pytest.raises(ArgumentRangeError, match="--gateway-id"):
            gateway_id("x", bad)
    assert client_id("pc-7") == "servobus-pc-7"
    assert application_uri("pc-7") == "urn:servobus:gateway:pc-7"
    assert check_prefix("plant/line-2") == "plant/line-2"
    for bad in ("", "a/+", "#", "a//b", "/a"):
        with pytest.raises(ArgumentRangeError, match="--mqtt-prefix"):
            check_prefix(bad)


def test_serve_refuses_a_bad_gateway_id_or_prefix() -> None:
    from click.testing import CliRunner

    from servobus.cli.main import cli

    result = CliRunner().invoke(cli, ["serve", "--gateway-id", "cell 3"])
    assert result.exit_code == 2 and "--gateway-id 'cell 3'" in result.output
    result = CliRunner().invoke(cli, ["serve", "--mqtt-prefix", "plant/#"])
    assert result.exit_code == 2 and "--mqtt-prefix 'plant/#'" in result.output


async def test_an_unexpected_error_in_a_command_is_answered_and_the_next_runs(
        monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture) -> None:
    """The error boundary (issue 30): one bad command is answered BadInternalError with one
    log line; the handler takes the next one."""
    machine = FakeMachine()
    sampler = Sampler(machine, 10)  # type: ignore[arg-type]
    gw = MqttGateway(machine, sampler, Commander(machine),  # type: ignore[arg-type]
                     MqttOptions("mqtt://u:p@127.0.0.1:1884", commands=True))
    client = Published()
    admit = gw.gate.admit

    def broken(axis: str, payload: bytes, retained: bool, now: float | None = None) -> Any:
        if b"boom" in payload:
            raise RuntimeError("a bug")
        return admit(axis, payload, retained, now)

    monkeypatch.setattr(gw.gate, "admit", broken)
    with caplog.at_level("ERROR", logger="servobus.gateway.mqtt"):
        await gw._answer(client, "a0", msg(id="b1", cmd="boom"), False)  # type: ignore[arg-type]
    await gw._answer(client, "a0", msg(cmd="stop"), False)  # type: ignore[arg-type]
    assert [reply["code"] for _, reply in client.messages] == ["BadInternalError", "Good"]
    assert client.messages[0][1]["id"] == "b1"
    errors = [r for r in caplog.records if r.levelname == "ERROR"]
    assert len(errors) == 1 and "RuntimeError: a bug" in errors[0].getMessage()
    assert machine.log == ["a0 stop"]
