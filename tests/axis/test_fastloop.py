"""servobus[fast] (issue 22): uvloop for the loops servobus owns, never for a user's loop."""

from __future__ import annotations

import asyncio
import sys

import pytest

from servobus import fastloop
from servobus.axis.sync import LoopThread
from servobus.transport.tcp_stream import TcpStream


def test_owned_loop_is_asyncio_without_uvloop(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "uvloop", None)  # import uvloop -> ImportError
    runner = LoopThread()
    try:
        assert fastloop.loop_name(runner.loop) == "asyncio"
        assert not fastloop.fast_available()
    finally:
        runner.stop()


def test_env_turns_it_off(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(fastloop.ENV, "asyncio")
    loop = fastloop.new_event_loop()
    try:
        assert fastloop.loop_name(loop) == "asyncio"
    finally:
        loop.close()


def test_owned_loop_is_uvloop_when_installed(monkeypatch: pytest.MonkeyPatch) -> None:
    pytest.importorskip("uvloop")
    monkeypatch.delenv(fastloop.ENV, raising=False)
    runner = LoopThread()
    try:
        assert fastloop.loop_name(runner.loop) == "uvloop"
        assert runner.run(_echo_on_loop()) == b"ping"  # our TCP stream works on it
    finally:
        runner.stop()


def test_users_loop_is_left_alone(monkeypatch: pytest.MonkeyPatch) -> None:
    """Making servobus's own loops installs no policy: a user's asyncio.run stays asyncio."""
    pytest.importorskip("uvloop")
    monkeypatch.delenv(fastloop.ENV, raising=False)
    policy = asyncio.get_event_loop_policy()
    assert fastloop.run(_echo_on_loop()) == b"ping"
    assert asyncio.get_event_loop_policy() is policy

    async def which() -> str:
        return fastloop.loop_name(asyncio.get_running_loop())

    assert asyncio.run(which()) == "asyncio"


async def _echo_on_loop() -> bytes:
    """TcpStream on the running loop against a one-shot echo server (uvloop's transports do
    not derive from asyncio.Transport: the stream must not assume they do)."""
    async def echo(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        writer.write(await reader.read(4))
        await writer.drain()
        writer.close()

    server = await asyncio.start_server(echo, "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    stream = await TcpStream.connect("127.0.0.1", port)
    try:
        await stream.write(b"ping")
        got = b""
        while len(got) < 4:
            got += await stream.read(4)
        return got
    finally:
        await stream.close()
        server.close()
        await server.wait_closed()
