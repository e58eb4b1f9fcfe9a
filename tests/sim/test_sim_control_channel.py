"""The control channel's protocol through a real loopback socket (in-process server):
JSON lines, replies in order, every refusal answered and the session kept, bounds."""

from __future__ import annotations

import asyncio
import json
import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

import pytest

from servobus.families.dmm.registers import AlarmCode
from servobus.sim.control_server import MAX_LINE, ControlServer
from servobus.sim.dmm.control import COMMANDS, FAULTS, ControlError, DriveControl
from servobus.sim.dmm.drive import VirtualDrive

pytestmark = pytest.mark.timeout(30)


class Conn:
    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.reader, self.writer = reader, writer

    async def send_raw(self, data: bytes) -> None:
        self.writer.write(data)
        await self.writer.drain()

    async def reply(self) -> dict[str, Any]:
        line = await asyncio.wait_for(self.reader.readline(), 5)
        assert line.endswith(b"\n"), line
        out: dict[str, Any] = json.loads(line)
        return out

    async def ask(self, request: dict[str, Any]) -> dict[str, Any]:
        await self.send_raw(json.dumps(request).encode() + b"\n")
        return await self.reply()


@asynccontextmanager
async def channel(*ids: int, max_clients: int = 4) -> AsyncIterator[tuple[ControlServer,
                                                                           list[VirtualDrive]]]:
    drives = [VirtualDrive(i) for i in ids]
    server = ControlServer(DriveControl(drives), max_clients=max_clients)
    server.bind("127.0.0.1", 0)
    server.start()
    try:
        yield server, drives
    finally:
        await server.close()


@asynccontextmanager
async def connect(server: ControlServer) -> AsyncIterator[Conn]:
    assert server.address is not None
    reader, writer = await asyncio.open_connection(*server.address)
    try:
        yield Conn(reader, writer)
    finally:
        writer.close()


async def test_replies_in_order_with_seq_and_every_refusal_keeps_the_session() -> None:
    async with channel(1, 2) as (server, drives), connect(server) as conn:
        await conn.send_raw(b"not json\n[1, 2]\n\n{\"cmd\": \"nope\"}\n"
                            b"{\"cmd\": \"state\", \"id\": 9}\n{\"cmd\": \"state\"}\n"
                            b"{\"cmd\": \"analog\", \"id\": 1, \"volts\": 13}\n"
                            b"{\"cmd\": \"analog\", \"id\": 1, \"volts\": \"2\"}\n"
                            b"{\"cmd\": \"analog\", \"id\": 1, \"volts\": 2, \"amps\": 1}\n"
                            b"{\"cmd\": \"analog\", \"id\": 1, \"volts\": NaN}\n"
                            b"{\"cmd\": \"analog\", \"id\": true, \"volts\": 1}\n"
                            b"\xff\xfe\n"
                            b"{\"cmd\": \"analog\", \"id\": 1, \"volts\": 2.5, \"seq\": \"a7\"}\n")
        kinds = [(await conn.reply()).get("kind") for _ in range(12)]
        assert kinds == ["malformed", "malformed", "unknown_command", "unknown_id",
                         "unknown_id", "bad_argument", "bad_argument", "bad_argument",
                         "bad_argument", "unknown_id", "malformed", None]
        assert drives[0].analog_input == 2.5
        assert server.refused == 11


async def test_ok_reply_names_command_id_and_seq() -> None:
    async with channel(3) as (server, drives), connect(server) as conn:
        reply = await conn.ask({"cmd": "fault", "fault": "over_current", "seq": 41})
        assert list(reply)[:3] == ["ok", "cmd", "id"]
        assert reply["ok"] and reply["id"] == 3 and reply["seq"] == 41
        assert reply["alarm_code"] == AlarmCode.OVER_CURRENT == drives[0].alarm
        ping = await conn.ask({"cmd": "ping"})
        assert ping["ids"] == [3] and set(ping["commands"]) == set(COMMANDS)
        assert set(ping["faults"]) == set(FAULTS)


async def test_a_line_longer_than_the_bound_is_refused_and_skipped() -> None:
    async with channel(1) as (server, drives), connect(server) as conn:
        # arrives in pieces, no newline for a while: refused once, the rest skipped
        await conn.send_raw(b"{\"cmd\": \"analog\", \"volts\": 1, \"pad\": \"" + b"x" * MAX_LINE)
        assert (await conn.reply())["kind"] == "too_long"
        await conn.send_raw(b"y" * (3 * MAX_LINE) + b"\"}\n")
        await conn.send_raw(b"{\"cmd\": \"analog\", \"volts\": 3}\n")
        ok = await conn.reply()
        assert ok["ok"] and drives[0].analog_input == 3.0
        # one whole long line in one piece
        await conn.send_raw(b" " * (MAX_LINE + 1) + b"\n{\"cmd\": \"ping\"}\n")
        assert (await conn.reply())["kind"] == "too_long"
        assert (await conn.reply())["ok"]


async def test_connections_beyond_the_cap_are_told_busy_and_closed() -> None:
    async with channel(1, max_clients=1) as (server, _):
        async with connect(server) as first:
            assert (await first.ask({"cmd": "ping"}))["ok"]
            async with connect(server) as second:
                assert (await second.reply())["kind"] == "busy"
                assert await asyncio.wait_for(second.reader.read(), 5) == b""
            assert (await first.ask({"cmd": "ping"}))["ok"]
        assert server.cap.refused == 1


async def test_one_log_line_per_event_reads_at_debug(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.DEBUG, logger="servobus.sim")
    async with channel(1) as (server, _):
        async with connect(server) as conn:
            await conn.ask({"cmd": "analog", "volts": 1.5})
            await conn.ask({"cmd": "state"})
            await conn.ask({"cmd": "bogus"})
        await asyncio.sleep(0.05)  # the server notices the close
    lines = [(r.levelno, r.getMessage()) for r in caplog.records if "sim control" in r.getMessage()]
    assert [lvl for lvl, _ in lines] == [logging.INFO, logging.INFO, logging.DEBUG,
                                         logging.WARNING, logging.INFO]
    assert "analog volts=1.5" in lines[1][1] and "unknown_command" in lines[3][1]


async def test_bind_refuses_a_busy_port() -> None:
    async with channel(1) as (server, _):
        assert server.address is not None
        other = ControlServer(DriveControl([VirtualDrive(1)]))
        with pytest.raises(OSError, match="cannot serve sim control"):
            other.bind("127.0.0.1", server.address[1])


def test_python_api_raises_on_refusals_and_needs_an_id_with_several_drives() -> None:
    ctl = DriveControl([VirtualDrive(1), VirtualDrive(2)])
    with pytest.raises(ControlError) as exc:
        ctl.state()
    assert exc.value.kind == "unknown_id"
    ctl.analog(2, -3.0)
    assert ctl.state(2)["inputs"]["analog_v"] == -3.0
    with pytest.raises(ControlError, match="rate or seconds"):
        ctl.pulses(1, 10, rate=100, seconds=1)
    with pytest.raises(ControlError, match="exceed"):
        ctl.pulses(1, 10_000_000, seconds=1)
    with pytest.raises(ControlError, match="takes no argument 'volts'"):
        ctl.fault(1, "over_current", volts=90)
