"""Issue 30 on the gateway's OPC UA server (in this process, on a fake machine; one server for
the module): fair limits per client published in ServerCapabilities, a vanished client's
subscriptions freed at its session timeout, methods only on their own object, hostile calls
each answered while the server serves on, and the gateway's own namespace."""

from __future__ import annotations

import contextlib
import logging
from collections.abc import AsyncIterator
from dataclasses import dataclass
from typing import Any

import pytest
import pytest_asyncio
from asyncua import Client, Node, ua
from asyncua.ua.uaerrors import UaStatusCodeError
from fake_machine import FakeMachine
from gateway_rig import axes_of, machine_node, names
from rig import wait_until_async

from benchmarks.faults_hostile import login_flood, session_flood
from servobus.gateway import opcua_limits
from servobus.gateway.commands import Commander
from servobus.gateway.opcua_server import OpcUaGateway, OpcUaOptions
from servobus.gateway.users import Users

pytestmark = [pytest.mark.asyncio(loop_scope="module"), pytest.mark.timeout(120)]
USER, PASSWORD = "op", "correct horse"


@dataclass
class Served:
    gateway: OpcUaGateway
    machine: FakeMachine

    @property
    def endpoint(self) -> str:
        return self.gateway.endpoint

    def subscriptions(self) -> int:
        return len(self.gateway.server.iserver.subscription_service.subscriptions)


@pytest_asyncio.fixture(loop_scope="module", scope="module")
async def served() -> AsyncIterator[Served]:
    users = Users()
    users.add(USER, PASSWORD)
    machine = FakeMachine()
    gateway = OpcUaGateway(machine, Commander(machine),  # type: ignore[arg-type]
                           OpcUaOptions("opc.tcp://127.0.0.1:0", users=users))
    await gateway.start()
    gateway.server.iserver.min_session_timeout_ms = 100  # a vanished client, quickly
    try:
        yield Served(gateway, machine)
    finally:
        await gateway.stop()


def user_client(endpoint: str) -> Client:
    client = Client(endpoint, timeout=10)
    client.set_user(USER)
    client.set_password(PASSWORD)
    return client


class Quiet:
    def datachange_notification(self, node: object, value: object, data: object) -> None:
        pass


async def test_the_limits_are_published_in_server_capabilities(served: Served) -> None:
    async with Client(served.endpoint) as client:
        caps = client.get_node(ua.NodeId(ua.ObjectIds.Server_ServerCapabilities))
        got = {name: await (await caps.get_child(f"0:{name}")).read_value() for name in (
            "MaxSessions", "MaxSubscriptions", "MaxSubscriptionsPerSession",
            "MaxMonitoredItems", "MaxMonitoredItemsPerSubscription",
            "MaxMonitoredItemsQueueSize")}
    assert got == {"MaxSessions": 64, "MaxSubscriptions": 200,
                   "MaxSubscriptionsPerSession": 10, "MaxMonitoredItems": 40_000,
                   "MaxMonitoredItemsPerSubscription": 1_000,
                   "MaxMonitoredItemsQueueSize": 1_000}


async def test_one_session_takes_no_more_than_its_cap_of_subscriptions(served: Served) -> None:
    async with Client(served.endpoint) as greedy, Client(served.endpoint) as other:
        for _ in range(opcua_limits.MAX_SUBSCRIPTIONS_PER_SESSION):
            await greedy.create_subscription(500, Quiet())
        with pytest.raises(UaStatusCodeError) as refused:
            await greedy.create_subscription(500, Quiet())
        assert refused.value.code == ua.StatusCodes.BadTooManySubscriptions
        await other.create_subscription(500, Quiet())  # the next client still gets one
        assert served.subscriptions() == opcua_limits.MAX_SUBSCRIPTIONS_PER_SESSION + 1
    await wait_until_async(lambda: served.subscriptions() == 0, timeout=10,
                           what="subscriptions gone with their sessions")


async def test_monitored_items_beyond_a_cap_are_refused_one_by_one(
        served: Served, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(opcua_limits, "MAX_ITEMS_PER_SUBSCRIPTION", 5)
    monkeypatch.setattr(opcua_limits, "MAX_ITEMS_PER_SESSION", 8)
    async with Client(served.endpoint) as client:
        node = client.get_node(ua.NodeId(ua.ObjectIds.Server_ServerStatus_CurrentTime))
        first = await client.create_subscription(500, Quiet())
        handles = await first.subscribe_data_change([node] * 7)
        assert [isinstance(h, int) for h in handles] == [True] * 5 + [False] * 2
        refused = ua.StatusCodes.BadTooManyMonitoredItems
        assert all(h.value == refused for h in handles[5:])  # type: ignore[union-attr]
        second = await client.create_subscription(500, Quiet())
        handles = await second.subscribe_data_change([node] * 5)  # 3 left in the session
        assert [isinstance(h, int) for h in handles] == [True] * 3 + [False] * 2


async def test_sessions_from_one_address_are_capped_and_another_is_served(
        served: Served, monkeypatch: pytest.MonkeyPatch) -> None:
    """benchmarks.faults_hostile.session_flood with small counts: one address takes its
    share of sessions and subscriptions, no more; a client from another address is
    served."""
    monkeypatch.setattr(opcua_limits, "MAX_SESSIONS_PER_PEER", 3)
    lines = Lines()
    logger = logging.getLogger("servobus.gateway.opcua_limits")
    logger.addHandler(lines)
    try:
        result = await session_flood(served.endpoint, sessions=6, subscriptions=12,
                                     source="127.0.0.2", other="127.0.0.3")
    finally:
        logger.removeHandler(lines)
    assert result["opened"] == 3 and result["subscriptions"] == 30, result
    assert result["refused"] == {"BadTooManySessions": 3, "BadTooManySubscriptions": 6}
    assert result["serving"], result
    assert lines.lines == ["OPC UA sessions refused from 127.0.0.2 on: 3 sessions from this "
                           "address"]  # one line for the spell, not one per refusal
    await wait_until_async(lambda: served.subscriptions() == 0, timeout=10,
                           what="the flood's subscriptions gone with its sessions")


async def test_a_login_flood_from_one_address_leaves_another_its_login(
        served: Served) -> None:
    result = await login_flood(served.endpoint, USER, PASSWORD, wrong=12,
                               source="127.0.0.4", other="127.0.0.5")
    assert result["refused"] == {"BadUserAccessDenied": 12}, result
    assert result["right login"] == "Good" and result["serving"], result


async def vanish(client: Client) -> None:
    """The client's process is gone: no CloseSession, no reconnect, its socket closed."""
    client.uaclient.request_disconnect()
    for name in ("_stale_watchdog_task", "_supervisor_task", "_renew_channel_task"):
        task = getattr(client, name)
        if task is not None:
            task.cancel()
            with contextlib.suppress(BaseException):
                await task
    client.disconnect_socket()


async def test_a_vanished_clients_subscriptions_are_freed_at_its_session_timeout(
        served: Served) -> None:
    client = Client(served.endpoint, timeout=10)
    client.session_timeout = 2000  # ms, asked for; the server allows it (min 100 ms here)
    await client.connect()
    for _ in range(3):
        await client.create_subscription(100, Quiet())
    assert served.subscriptions() == 3
    await vanish(client)
    # asyncua keeps the session and its subscriptions for the client to come back, until
    # the session's timeout: then they are freed for others
    sessions = served.gateway.server.iserver._external_sessions
    await wait_until_async(lambda: served.subscriptions() == 0 and not sessions,
                           timeout=30, what="the vanished session and its subscriptions")


async def test_a_method_runs_only_on_its_own_object(served: Served) -> None:
    served.machine.log.clear()
    async with user_client(served.endpoint) as client:
        n = await names(client)
        axes = await axes_of(client, "bench")
        move = await axes["a0"].get_child(f"{n.servobus}:MoveAbsolute")
        stop_all = await (await machine_node(client, "bench")).get_child(f"{n.servobus}:StopAll")
        server_object = client.get_node(ua.NodeId(ua.ObjectIds.Server))
        for target, method in ((axes["a1"], move), (server_object, move),
                               (axes["a0"], stop_all)):
            with pytest.raises(UaStatusCodeError) as refused:
                await target.call_method(method.nodeid, *([12.5] if method is move else []))
            assert refused.value.code == ua.StatusCodes.BadMethodInvalid
        assert served.machine.log == []  # nothing moved, nothing stopped
        await axes["a0"].call_method(move.nodeid, 12.5)  # on its own axis it runs
        assert served.machine.log == ["a0 move_to 12.5"]
    served.machine.log.clear()


def variant(value: object, kind: ua.VariantType, array: bool = False) -> ua.Variant:
    return ua.Variant(value, kind, is_array=array)


async def test_hostile_calls_are_each_answered_and_the_server_serves_on(served: Served) -> None:
    double = ua.VariantType.Double
    cases: list[tuple[str, str, list[ua.Variant], int]] = [
        ("a0", "MoveAbsolute", [], ua.StatusCodes.BadArgumentsMissing),
        ("a0", "MoveAbsolute", [variant(1.0, double), variant(2.0, double)],
         ua.StatusCodes.BadTooManyArguments),
        ("a0", "MoveAbsolute", [variant("12.5", ua.VariantType.String)],
         ua.StatusCodes.BadInvalidArgument),
        ("a0", "MoveAbsolute", [variant(True, ua.VariantType.Boolean)],
         ua.StatusCodes.BadInvalidArgument),
        ("a0", "MoveAbsolute", [variant(None, ua.VariantType.Null)],
         ua.StatusCodes.BadInvalidArgument),
        ("a0", "MoveAbsolute", [variant([1.0, 2.0], double, array=True)],
         ua.StatusCodes.BadInvalidArgument),
        ("a0", "MoveAbsolute", [variant(b"\x00" * 100_000, ua.VariantType.ByteString)],
         ua.StatusCodes.BadInvalidArgument),
        ("a0", "MoveAbsolute", [variant(float("nan"), double)], ua.StatusCodes.BadInvalidArgument),
        ("a0", "MoveAbsolute", [variant(float("inf"), double)], ua.StatusCodes.BadInvalidArgument),
        ("a0", "MoveAbsolute", [variant(1.7e308, double)], ua.StatusCodes.BadOutOfRange),
        ("a0", "MoveAbsolute", [variant(2**63 - 1, ua.VariantType.Int64)],
         ua.StatusCodes.BadOutOfRange),
        ("a0", "MoveAbsolute", [variant(2**64 - 1, ua.VariantType.UInt64)],
         ua.StatusCodes.BadOutOfRange),
        ("a0", "MoveRelative", [variant(-1e300, double)], ua.StatusCodes.BadOutOfRange),
        ("a1", "SetSpeed", [variant(5.0, double)], ua.StatusCodes.BadArgumentsMissing),
        ("a1", "SetSpeed", [variant(5.0, double), variant(1e300, double)],
         ua.StatusCodes.BadOutOfRange),
        ("a1", "SetSpeed", [variant(5.0, double), variant(-0.0, double)],
         ua.StatusCodes.BadOutOfRange),
        ("a1", "Enable", [variant(1.0, double)], ua.StatusCodes.BadTooManyArguments),
    ]
    served.machine.log.clear()
    async with user_client(served.endpoint) as client:
        n = await names(client)
        axes = await axes_of(client, "bench")
        for axis, method, args, code in cases:
            node = await axes[axis].get_child(f"{n.servobus}:{method}")
            with pytest.raises(UaStatusCodeError) as refused:
                await axes[axis].call_method(node.nodeid, *args)
            assert refused.value.code == code, (axis, method, args[:1])
        # objects and methods that do not exist
        bogus = [(ua.NodeId("nowhere", 7), node.nodeid), (axes["a0"].nodeid, ua.NodeId(999999))]
        for object_id, method_id in bogus:
            with pytest.raises(UaStatusCodeError) as refused:
                await client.get_node(object_id).call_method(method_id)
            assert refused.value.code == ua.StatusCodes.BadNodeIdInvalid
        assert served.machine.log == []  # nothing reached an axis
        await served_still(client, axes["a0"])
    served.machine.log.clear()


async def served_still(client: Client, axis: Node) -> None:
    n = await names(client)
    await axis.call_method(f"{n.servobus}:Stop")
    position = await axis.get_child([f"{n.di}:ParameterSet", f"{n.robotics}:ActualPosition"])
    await position.read_data_value(raise_on_bad_status=False)


class Lines(logging.Handler):
    def __init__(self) -> None:
        super().__init__(logging.INFO)
        self.lines: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.lines.append(record.getMessage())


async def test_an_unexpected_error_in_a_call_is_bad_internal_error_and_one_line(
        served: Served, monkeypatch: pytest.MonkeyPatch) -> None:
    async def broken(*args: Any, **kwargs: Any) -> None:
        raise RuntimeError("a bug")

    monkeypatch.setattr(served.gateway.commander, "run", broken)
    lines = Lines()
    logger = logging.getLogger("servobus.gateway.opcua_server")
    async with user_client(served.endpoint) as client:
        n = await names(client)
        axes = await axes_of(client, "bench")
        logger.addHandler(lines)
        try:
            with pytest.raises(UaStatusCodeError) as refused:
                await axes["a0"].call_method(f"{n.servobus}:MoveAbsolute", 1.0)
        finally:
            logger.removeHandler(lines)
        assert refused.value.code == ua.StatusCodes.BadInternalError
        assert len(lines.lines) == 1 and "RuntimeError: a bug" in lines.lines[0], lines.lines
        monkeypatch.undo()
        await served_still(client, axes["a0"])
    served.machine.log.clear()


async def test_node_ids_live_in_the_gateways_own_namespace(served: Served) -> None:
    async with Client(served.endpoint) as client:
        uris = await client.get_namespace_array()
        assert uris[1] == "urn:servobus:gateway:bench"  # the ApplicationUri
        n = await names(client)
        assert uris[n.servobus] == "urn:servobus:gateway"  # browse names and types
        axes = await axes_of(client, "bench")
        assert axes["a0"].nodeid == ua.NodeId("bench.a0", 1)
        endpoints = await client.get_endpoints()
        assert {e.Server.ApplicationUri for e in endpoints} == {"urn:servobus:gateway:bench"}


async def transfer(client: Client, subscription_id: int) -> int:
    params = ua.TransferSubscriptionsParameters()
    params.SubscriptionIds = [subscription_id]
    params.SendInitialValues = False
    results = await client.uaclient.transfer_subscriptions(params)
    code: int = results[0].StatusCode.value
    return code


async def test_a_subscription_moves_only_to_its_own_user_within_the_cap(
        served: Served) -> None:
    """asyncua moved any subscription whose number a client named to that client."""
    async with user_client(served.endpoint) as owner, Client(served.endpoint) as stranger, \
            user_client(served.endpoint) as same_user:
        subscription = await owner.create_subscription(500, Quiet())
        sub_id = subscription.subscription_id
        assert await transfer(stranger, sub_id) == ua.StatusCodes.BadUserAccessDenied
        own = [await same_user.create_subscription(500, Quiet())
               for _ in range(opcua_limits.MAX_SUBSCRIPTIONS_PER_SESSION)]
        assert await transfer(same_user, sub_id) == ua.StatusCodes.BadTooManySubscriptions
        await own[0].delete()
        assert await transfer(same_user, sub_id) == ua.StatusCodes.Good
