"""Sparkplug B (``servobus serve --sparkplug GROUP``): the schema reader against protoc, the
DCMD rules, and a gateway in this process on a real Mosquitto broker, read with classes that
protoc made from Tahu's schema (not the gateway's own)."""

from __future__ import annotations

import itertools
import time
from collections.abc import AsyncIterator, Iterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import pytest
from fake_machine import FakeMachine
from gateway_rig import BROKER_USERS, Mosquitto, mosquitto_broker
from google.protobuf import descriptor_pb2
from sparkplug_rig import Message, Observer, observing
from tahu_rig import dcmd, metrics, protoc, tahu, unit, value

from servobus.gateway.commands import Refused
from servobus.gateway.mqtt import MqttOptions
from servobus.gateway.opcua_server import OpcUaOptions
from servobus.gateway.serve import Gateway, GatewayOptions
from servobus.gateway.sparkplug.commands import DcmdGate
from servobus.gateway.sparkplug.schema import DESCRIPTOR, SchemaError, parse_proto

GROUP = "plant"
pytestmark = pytest.mark.timeout(120)


def normalized(proto: descriptor_pb2.FileDescriptorProto) -> bytes:
    """Without what the classes do not use: options, json names, source info, syntax."""
    out = descriptor_pb2.FileDescriptorProto()
    out.CopyFrom(proto)
    out.ClearField("options")
    out.ClearField("source_code_info")
    out.ClearField("syntax")

    def strip(message: descriptor_pb2.DescriptorProto) -> None:
        for field in message.field:
            field.ClearField("json_name")
        for nested in message.nested_type:
            strip(nested)
    for message in out.message_type:
        strip(message)
    return bytes(out.SerializeToString(deterministic=True))


def test_the_schema_reader_agrees_with_protoc(tmp_path: Path) -> None:
    protoc(tmp_path, f"--descriptor_set_out={tmp_path / 'set.pb'}")
    theirs = descriptor_pb2.FileDescriptorSet.FromString((tmp_path / "set.pb").read_bytes())
    assert normalized(DESCRIPTOR) == normalized(theirs.file[0])


@pytest.mark.parametrize("text", [
    'syntax = "proto3"; message A { string b = 1; }',
    'syntax = "proto2"; message A { map<string, string> b = 1; }',
    'syntax = "proto2"; message A { optional C b = 1; }',
    'syntax = "proto2"; service S { }',
])
def test_the_schema_reader_refuses_what_it_does_not_read(text: str) -> None:
    with pytest.raises(SchemaError):
        parse_proto(text)


def test_serve_refuses_sparkplug_without_a_broker_or_with_a_bad_group() -> None:
    from click.testing import CliRunner

    from servobus.cli.main import cli

    result = CliRunner().invoke(cli, ["serve", "--sparkplug", "plant"])
    assert result.exit_code == 2 and "--sparkplug needs --mqtt" in result.output
    result = CliRunner().invoke(cli, ["serve", "--mqtt", "mqtt://127.0.0.1:1",
                                      "--sparkplug", "line/3"])
    assert result.exit_code == 2 and "one topic level" in result.output


# ---------------------------------------------------------------- the DCMD rules
def admit(data: bytes, retained: bool = False, gate: DcmdGate | None = None) -> Any:
    return (gate or DcmdGate()).admit("a0", data, retained)


def refused(data: bytes, retained: bool = False, gate: DcmdGate | None = None) -> str:
    with pytest.raises(Refused) as caught:
        admit(data, retained, gate)
    return caught.value.code


def test_a_dcmd_is_one_command_metric() -> None:
    command = admit(dcmd(MoveAbsolute=12.5)[0])
    assert (command.axis, command.name, command.value, command.ttl) == \
        ("a0", "move_absolute", 12.5, None)
    command = admit(dcmd(SetSpeed=3.0, SetSpeedTtl=0.4)[0])
    assert (command.name, command.value, command.ttl) == ("set_speed", 3.0, 0.4)
    assert admit(dcmd(Stop=True)[0]).name == "stop"


def test_dcmds_outside_the_rules_are_refused() -> None:
    gate = DcmdGate()
    once = dcmd(MoveRelative=1.0)[0]
    admit(once, gate=gate)
    assert refused(once, gate=gate) == "BadRequestNotAllowed"  # a redelivery: never re-run
    assert refused(dcmd(Enable=True)[0], retained=True) == "BadRequestNotAllowed"
    assert refused(dcmd(Enable=False)[0]) == "BadInvalidArgument"
    assert refused(dcmd(Stop=True, Enable=True)[0]) == "BadInvalidArgument"
    assert refused(dcmd(Stop=True, SetSpeedTtl=0.3)[0]) == "BadInvalidArgument"
    assert refused(dcmd(Warp=1.0)[0]) == "BadMethodInvalid"
    assert refused(dcmd()[0]) == "BadMethodInvalid"
    assert refused(b"\xff\xff\xff") == "BadDecodingError"
    assert refused(b"\0" * 5000) == "BadRequestTooLarge"
    _, message = dcmd(MoveAbsolute=True)  # a Boolean where a Double belongs
    assert refused(message.SerializeToString()) == "BadInvalidArgument"
    _, message = dcmd(MoveAbsolute=1.0)
    message.timestamp = int((time.time() - 60) * 1000)
    assert refused(message.SerializeToString()) == "BadInvalidTimestamp"
    message.timestamp = int((time.time() + 60) * 1000)
    assert refused(message.SerializeToString()) == "BadInvalidTimestamp"
    message.ClearField("timestamp")  # a motion needs its time
    assert refused(message.SerializeToString()) == "BadInvalidArgument"
    _, message = dcmd(Stop=True)
    message.ClearField("timestamp")  # a stop may come without
    assert admit(message.SerializeToString()).name == "stop"


# ---------------------------------------------------------------- on a real broker
@pytest.fixture(scope="module")
def broker(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Mosquitto]:
    with mosquitto_broker(tmp_path_factory.mktemp("mosquitto")) as running:
        yield running


@asynccontextmanager
async def serving(port: int, commands: bool, machine: FakeMachine) -> AsyncIterator[Gateway]:
    mqtt = MqttOptions(f"mqtt://127.0.0.1:{port}", username="gateway",
                       password=BROKER_USERS["gateway"], commands=commands, rate_hz=20)
    gateway = Gateway(machine, GatewayOptions(OpcUaOptions("opc.tcp://127.0.0.1:0"), mqtt,  # type: ignore[arg-type]
                                              rate_hz=50, sparkplug=GROUP))
    await gateway.start()
    try:
        yield gateway
    finally:
        await gateway.close()


def seqs(observer: Observer) -> list[int]:
    return [m.payload.seq for m in observer.messages if m.kind not in ("NDEATH", "NCMD",
                                                                        "DCMD")]


def bd_seq(message: Message) -> int:
    return int(value(metrics(message.payload)["bdSeq"]))


async def births(observer: Observer, count: int) -> list[Message]:
    """The node's ``count``-th NBIRTH and the DBIRTHs after it (a0, a1)."""
    await observer.until(lambda: len(observer.of("NBIRTH")) >= count
                         and len(observer.of("DBIRTH")) >= 2 * count, "the births")
    return [observer.of("NBIRTH")[count - 1], *observer.of("DBIRTH")[2 * count - 2:2 * count]]


def position_is(observer: Observer, first: Message | None, axis: str, mm: float) -> bool:
    """Whether the device's last Position (in its DBIRTH or a DDATA) is ``mm``."""
    seen = [m for m in ([first] if first else []) + observer.of("DDATA", device=axis)
            if "Position" in metrics(m.payload)]
    return bool(seen) and value(metrics(seen[-1].payload)["Position"]) == mm


def in_order(observer: Observer) -> None:
    """seq goes up by one (mod 256) from each NBIRTH (seq 0) to the next."""
    order = seqs(observer)
    assert order and order[0] == 0, order
    for before, after in itertools.pairwise(order):
        assert after in (0, (before + 1) % 256), order


async def rebirth(observer: Observer, node: str) -> None:
    ncmd = tahu().Payload(timestamp=int(time.time() * 1000))
    ncmd.metrics.add(name="Node Control/Rebirth", datatype=tahu().Boolean, boolean_value=True)
    await observer.publish(f"spBv1.0/{GROUP}/NCMD/{node}", ncmd.SerializeToString())


@pytest.mark.slow  # a broker restart and the gateway's reconnection delay: 9 s
async def test_births_data_rebirth_and_bdseq_across_a_broker_restart(
        broker: Mosquitto) -> None:
    machine = FakeMachine("spb-cell")
    async with observing(broker.port, GROUP) as first, \
            serving(broker.port, False, machine) as gateway:
        node, a0, a1 = await births(first, 1)
        assert node.topic == "spBv1.0/plant/NBIRTH/spb-cell"
        assert (bd_seq(node), node.payload.seq) == (0, 0)
        flag = metrics(node.payload)["Node Control/Rebirth"]
        assert flag.datatype == tahu().Boolean and value(flag) is False
        assert [a0.topic, a1.topic] == ["spBv1.0/plant/DBIRTH/spb-cell/a0",
                                         "spBv1.0/plant/DBIRTH/spb-cell/a1"]
        assert [a0.payload.seq, a1.payload.seq] == [1, 2]
        born = metrics(a0.payload)
        assert born["Position"].datatype == tahu().Double and unit(born["Position"]) == "mm"
        assert unit(born["Speed"]) == "mm/s"
        assert born["Commands/MoveAbsolute"].datatype == tahu().Double
        assert born["Commands/Stop"].datatype == tahu().Boolean
        assert born["Alarm/Code"].datatype == tahu().Int32
        await first.until(lambda: position_is(first, a0, "a0", 5.0), "a0 at 5 mm")
        machine.axes["a0"].pos = 7.5
        await first.until(lambda: position_is(first, None, "a0", 7.5), "a0 at 7.5 mm (DDATA)")
        # without --mqtt-commands no DCMD is taken; a rebirth is
        await first.publish("spBv1.0/plant/DCMD/spb-cell/a0", dcmd(MoveAbsolute=9.0)[0])
        await rebirth(first, "spb-cell")
        again, _, _ = await births(first, 2)
        assert (bd_seq(again), again.payload.seq) == (0, 0)  # the same session, seq from 0
        assert not any("move_to" in line for line in machine.log)
        in_order(first)

        spb = gateway.sparkplug
        assert spb is not None
        born_before = spb.births
        broker.restart()  # the gateway's connection goes with it (and no will: no broker)
        async with observing(broker.port, GROUP) as second:
            await second.until(lambda: spb.births > born_before, "a birth after the restart")
            if not second.of("NBIRTH"):  # it came before this subscription: ask again
                await rebirth(second, "spb-cell")
            node, _, _ = await births(second, 1)
            assert (bd_seq(node), node.payload.seq) == (1, 0)  # a new connection, bdSeq + 1
            machine.axes["a0"].pos = 8.5
            await second.until(lambda: position_is(second, None, "a0", 8.5), "a0 at 8.5 mm")
            in_order(second)
            await gateway.close()  # a clean stop: the NDEATH of this session
            await second.until(lambda: second.of("NDEATH"), "the NDEATH")
            assert bd_seq(second.of("NDEATH")[0]) == 1
            assert second.of("NDEATH")[0].payload.HasField("seq") is False


async def test_dcmds_are_executed_or_refused_by_the_rules(broker: Mosquitto) -> None:
    machine = FakeMachine("spb-commands")
    topic = "spBv1.0/plant/DCMD/spb-commands/a0"
    async with observing(broker.port, GROUP) as seen, \
            serving(broker.port, True, machine):
        await births(seen, 1)

        async def answer(data: bytes, retain: bool = False) -> tuple[str, str]:
            count = len(results())
            await seen.publish(topic, data, retain)
            await seen.until(lambda: len(results()) > count, "the DCMD's result")
            return results()[-1]

        def results() -> list[tuple[str, str]]:
            return [(value(metrics(m.payload)["Commands/Result"]),
                     value(metrics(m.payload)["Commands/Error"]))
                    for m in seen.of("DDATA", device="a0")
                    if "Commands/Result" in metrics(m.payload)]

        move = dcmd(MoveAbsolute=42.0)[0]
        assert await answer(move) == ("Good", "")
        assert machine.log[-1] == "a0 move_to 42"
        code, why = await answer(move)  # the same message again: never re-run
        assert code == "BadRequestNotAllowed" and "seen before" in why
        code, why = await answer(dcmd(MoveAbsolute=500.0)[0])  # beyond the limits 0..100
        assert code == "BadOutOfRange" and "limits" in why
        _, stale = dcmd(MoveRelative=1.0)
        stale.timestamp = int((time.time() - 30) * 1000)
        assert (await answer(stale.SerializeToString()))[0] == "BadInvalidTimestamp"
        retained = dcmd(MoveRelative=2.0)[0]
        assert (await answer(retained, retain=True))[0] == "BadRequestNotAllowed"
        # the broker forgets it; the empty retained message is a refused DCMD too
        assert (await answer(b"", retain=True))[0] == "BadRequestNotAllowed"
        assert machine.log[-1] == "a0 move_to 42"  # nothing refused ran
        assert await answer(dcmd(Stop=True)[0]) == ("Good", "")
        assert machine.log[-1] == "a0 stop"
        machine.axes["a0"].drop()  # an offline axis: refused at once, as an OPC UA call
        assert (await answer(dcmd(Enable=True)[0]))[0] == "BadCommunicationError"
        in_order(seen)
