"""An independent asyncua client on ``servobus serve`` (the built-in virtual machine)."""

from __future__ import annotations

import asyncio
import json
import math
import urllib.request
from collections.abc import Iterator
from pathlib import Path

import pytest
from asyncua import Client, Node, ua
from asyncua.ua.uaerrors import UaStatusCodeError
from gateway_rig import (
    PASSWORD,
    USER,
    RunningGateway,
    axes_of,
    machine_node,
    names,
    parameter,
    start_gateway,
    users_file,
)
from rig import wait_until_async

MACHINE = "virtual-cell"


@pytest.fixture(scope="module")
def gateway(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningGateway]:
    folder: Path = tmp_path_factory.mktemp("gateway")
    running = start_gateway("--users", str(users_file(folder)), "--rate", "50", "--gui",
                            "--gui-port", "0")
    yield running
    err = running.stop()
    assert running.proc.returncode == 130, err
    assert "every axis was stopped" in err


def user_client(endpoint: str, password: str = PASSWORD) -> Client:
    client = Client(endpoint)
    client.set_user(USER)
    client.set_password(password)
    return client


async def test_axes_are_browsed_with_their_units_and_limits(gateway: RunningGateway) -> None:
    async with Client(gateway.endpoint) as client:
        axes = await axes_of(client, MACHINE)
        assert sorted(axes) == ["c", "x", "y"]
        x_pos = await parameter(client, axes["x"], "ActualPosition")
        value = await x_pos.read_data_value()
        assert value.Value.VariantType == ua.VariantType.Double
        assert value.StatusCode.is_good() and math.isfinite(value.Value.Value)
        eu = await (await x_pos.get_child("0:EngineeringUnits")).read_value()
        assert eu.DisplayName.Text == "mm" and eu.UnitId == 5066068  # UNECE MMT
        eu_range = await (await x_pos.get_child("0:EURange")).read_value()
        assert (eu_range.Low, eu_range.High) == (-10.0, 300.0)
        c_pos = await parameter(client, axes["c"], "ActualPosition")
        assert (await (await c_pos.get_child("0:EngineeringUnits")).read_value()
                ).DisplayName.Text == "deg"
        speed = await parameter(client, axes["y"], "ActualSpeed")
        assert (await (await speed.get_child("0:EngineeringUnits")).read_value()
                ).DisplayName.Text == "mm/s"
        n = await names(client)
        model = await axes["c"].get_child([f"{n.di}:Identification", f"{n.di}:Model"])
        assert await model.read_value() == "yzaim"
        for name in ("Enabled", "Moving", "InPosition", "AlarmCode", "AlarmText"):
            assert (await (await parameter(client, axes["x"], name)).read_data_value()
                    ).StatusCode.is_good()
        methods = {(await m.read_browse_name()).Name for m in await axes["x"].get_methods()}
        assert methods == {"MoveAbsolute", "MoveRelative", "SetSpeed", "Stop", "Enable",
                           "Disable", "ResetAlarm", "Acknowledge"}


async def test_anonymous_is_read_only(gateway: RunningGateway) -> None:
    async with Client(gateway.endpoint) as client:
        n = await names(client)
        axes = await axes_of(client, MACHINE)
        # SetSpeed takes (Value, Ttl) since issue 27: a call must be well formed to be
        # refused for its user (one argument is BadArgumentsMissing before that)
        for method, args in (("MoveRelative", (1.0,)), ("MoveAbsolute", (1.0,)),
                             ("SetSpeed", (5.0, 0.5)), ("Stop", ()), ("Enable", ())):
            with pytest.raises(UaStatusCodeError) as refused:
                await axes["x"].call_method(f"{n.servobus}:{method}", *args)
            assert refused.value.code == ua.StatusCodes.BadUserAccessDenied, method
        with pytest.raises(UaStatusCodeError) as refused:
            await (await machine_node(client, MACHINE)).call_method(f"{n.servobus}:StopAll")
        assert refused.value.code == ua.StatusCodes.BadUserAccessDenied
        position = await parameter(client, axes["x"], "ActualPosition")
        with pytest.raises(UaStatusCodeError):
            await position.write_value(ua.DataValue(ua.Variant(5.0, ua.VariantType.Double)))


async def test_user_moves_an_axis_and_a_subscription_sees_it(gateway: RunningGateway) -> None:
    seen: list[float] = []

    class Handler:
        def datachange_notification(self, node: object, value: float, data: object) -> None:
            seen.append(value)

    async with user_client(gateway.endpoint) as client:
        n = await names(client)
        axes = await axes_of(client, MACHINE)
        position = await parameter(client, axes["y"], "ActualPosition")
        subscription = await client.create_subscription(20, Handler())
        await subscription.subscribe_data_change(position)
        await wait_until_async(lambda: _true(bool(seen)), timeout=10, what="first value")
        start = seen[-1]
        await axes["y"].call_method(f"{n.servobus}:MoveRelative", 2.0)
        await wait_until_async(lambda: _true(abs(seen[-1] - (start + 2.0)) < 0.01),
                               timeout=15, what=f"y at {start + 2.0} mm (seen {seen[-3:]})")
        await subscription.delete()


async def test_limits_and_arguments_are_named(gateway: RunningGateway) -> None:
    async with user_client(gateway.endpoint) as client:
        n = await names(client)
        axes = await axes_of(client, MACHINE)
        cases = [("MoveAbsolute", 1000.0, ua.StatusCodes.BadOutOfRange),
                 ("MoveAbsolute", -10.5, ua.StatusCodes.BadOutOfRange),
                 ("MoveRelative", -500.0, ua.StatusCodes.BadOutOfRange),
                 ("MoveAbsolute", math.nan, ua.StatusCodes.BadInvalidArgument)]
        for method, value, code in cases:
            with pytest.raises(UaStatusCodeError) as refused:
                await axes["x"].call_method(f"{n.servobus}:{method}", value)
            assert refused.value.code == code, (method, value)
        await axes["x"].call_method(f"{n.servobus}:Stop")  # a user may stop
        await (await machine_node(client, MACHINE)).call_method(f"{n.servobus}:StopAll")


async def test_a_method_on_another_object_is_refused_and_moves_nothing(
        gateway: RunningGateway) -> None:
    """Issue 30: x.MoveAbsolute called with axis c's ObjectId, or the Server object's,
    answered Good and moved x. Nothing moves: by the time a move of y (on x's link,
    commanded after the refused calls) is seen, x has not moved."""
    seen: dict[str, list[float]] = {"x": [], "y": []}
    async with user_client(gateway.endpoint) as client:
        n = await names(client)
        axes = await axes_of(client, MACHINE)
        nodes = {name: await parameter(client, axes[name], "ActualPosition")
                 for name in ("x", "y")}
        by_id = {node.nodeid: name for name, node in nodes.items()}

        class Handler:
            def datachange_notification(self, node: Node, value: float, data: object) -> None:
                seen[by_id[node.nodeid]].append(value)

        subscription = await client.create_subscription(20, Handler())
        await subscription.subscribe_data_change(list(nodes.values()))
        await wait_until_async(lambda: _true(bool(seen["x"] and seen["y"])), timeout=10,
                               what="first positions")
        x_before, y_before = seen["x"][-1], seen["y"][-1]
        move = await axes["x"].get_child(f"{n.servobus}:MoveAbsolute")
        target = x_before + 5.0 if x_before < 200.0 else x_before - 5.0
        for obj in (axes["c"], client.get_node(ua.NodeId(ua.ObjectIds.Server))):
            with pytest.raises(UaStatusCodeError) as refused:
                await obj.call_method(move.nodeid, target)
            assert refused.value.code == ua.StatusCodes.BadMethodInvalid
        await axes["y"].call_method(f"{n.servobus}:MoveRelative", 1.0)
        await wait_until_async(lambda: _true(abs(seen["y"][-1] - (y_before + 1.0)) < 0.01),
                               timeout=15, what="y moved by 1 mm")
        assert all(abs(x - x_before) < 0.01 for x in seen["x"]), seen["x"]
        await subscription.delete()


async def test_a_wrong_password_gets_no_session(gateway: RunningGateway) -> None:
    with pytest.raises(UaStatusCodeError) as refused:
        async with user_client(gateway.endpoint, "not the password"):
            pass
    assert refused.value.code == ua.StatusCodes.BadUserAccessDenied


async def _true(value: bool) -> bool:
    await asyncio.sleep(0)  # a coroutine predicate for wait_until_async: one yield, no wait
    return value


async def test_garbage_connections_do_not_stop_the_server(gateway: RunningGateway) -> None:
    host, port = gateway.endpoint.removeprefix("opc.tcp://").rsplit(":", 1)
    writers = []
    for i in range(100):
        reader, writer = await asyncio.open_connection(host, int(port))
        writer.write(b"HELF" + bytes([i]) * 60 if i % 2 else b"\xff" * 4096)
        writers.append((reader, writer))
    await asyncio.gather(*(w.drain() for _, w in writers))
    async with Client(gateway.endpoint) as client:  # served while they hang on
        axes = await axes_of(client, MACHINE)
        assert (await (await parameter(client, axes["x"], "ActualPosition")).read_data_value()
                ).StatusCode.is_good()
    for _, writer in writers:
        writer.close()


async def test_the_gui_is_served_from_the_same_process(gateway: RunningGateway) -> None:
    line = next(x for x in gateway.lines if x.startswith("servobus serve: gui "))
    url = line.split()[3]
    assert url.startswith("http://127.0.0.1:")
    loop = asyncio.get_running_loop()
    body = await loop.run_in_executor(
        None, lambda: urllib.request.urlopen(url + "api/axes", timeout=10).read())
    axes = json.loads(body)
    assert [a["identity"].get("name") for a in axes] == ["x", "y", "c"]
