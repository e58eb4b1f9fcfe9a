"""OPC 40010-1 / OPC 10000-100 types, found by TypeDefinition, and drive alarms as OPC UA
conditions (issue 36): ``servobus serve`` on a machine file whose two axes are virtual
DYN232M drives in their own process; a fault goes in through the simulator's control
channel and comes out as an AlarmConditionType event on the Server object. An independent
asyncua client is the peer."""

from __future__ import annotations

import asyncio
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from asyncua import Client, ua
from gateway_rig import (
    RunningGateway,
    find_by_type,
    start_gateway,
    typedef,
    user_client,
    users_file,
)
from rig import free_port, wait_until_async
from subprocess_rig import read_line, stop_process

from servobus.sim.control_client import ControlClient

pytestmark = [pytest.mark.slow, pytest.mark.timeout(180)]
DI = "http://opcfoundation.org/UA/DI/"
ROBOTICS = "http://opcfoundation.org/UA/Robotics/"
#: Official NodeIds (DI, Robotics NodeSets).
DEVICE_SET, AXIS_TYPE, MOTION_DEVICE_TYPE = 5001, 16601, 1004
POWER_TRAIN_TYPE, MOTOR_TYPE, CONTROLLER_TYPE = 16794, 1019, 1003
ANALOG_UNIT_TYPE = ua.NodeId(ua.ObjectIds.AnalogUnitType)
#: Mandatory members (browse name in the Robotics or DI namespace) per type.
MANDATORY = {
    MOTION_DEVICE_TYPE: [("di", "Manufacturer"), ("di", "Model"), ("di", "ProductCode"),
                         ("di", "SerialNumber"), ("rob", "MotionDeviceCategory"),
                         ("rob", "Axes"), ("rob", "PowerTrains"), ("di", "ParameterSet")],
    AXIS_TYPE: [("rob", "MotionProfile"), ("di", "ParameterSet")],
    MOTOR_TYPE: [("di", "Manufacturer"), ("di", "Model"), ("di", "ProductCode"),
                 ("di", "SerialNumber"), ("di", "ParameterSet")],
    CONTROLLER_TYPE: [("di", "Manufacturer"), ("di", "Model"), ("di", "ProductCode"),
                      ("di", "SerialNumber"), ("rob", "CurrentUser"), ("rob", "Software"),
                      ("rob", "TaskControls")],
}


@pytest.fixture(scope="module")
def cell(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[RunningGateway, str]]:
    """Two virtual DYN232M drives with a control channel, served by ``servobus serve``."""
    folder: Path = tmp_path_factory.mktemp("typed")
    port = free_port()
    sim = subprocess.Popen([sys.executable, "-m", "servobus", "sim", "dyn232", "--listen",
                            f"tcp://127.0.0.1:{port}", "--ids", "1,2", "--fast", "--control",
                            "tcp://127.0.0.1:0", "--duration", "300"],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        control = ""
        listening = False
        while not (control and listening):
            line = read_line(sim, timeout=60)
            control = line.split()[-1] if line.startswith("control on") else control
            listening = listening or "listening on" in line
        url = f"dyn232+socket://127.0.0.1:{port}"
        machine = folder / "typed.toml"
        machine.write_text(f'name = "typed"\n[axes.x]\nurl = "{url}"\nid = 1\nunit = "mm"\n'
                           f'per_rev = 5.0\nlimits = [0.0, 100.0]\n'
                           f'[axes.spin]\nurl = "{url}"\nid = 2\nunit = "rev"\n'
                           f'continuous = true\n', encoding="utf-8")
        gateway = start_gateway("--machine", str(machine), "--users",
                                str(users_file(folder)), "--rate", "50")
        try:
            yield gateway, control
        finally:
            gateway.stop()
    finally:
        stop_process(sim)


async def test_every_axis_is_found_by_its_type_with_the_mandatory_members(
        cell: tuple[RunningGateway, str]) -> None:
    gateway, _ = cell
    async with Client(gateway.endpoint) as client:
        di = await client.get_namespace_index(DI)
        rob = await client.get_namespace_index(ROBOTICS)
        ns = {"di": di, "rob": rob}
        device_set = client.get_node(ua.NodeId(DEVICE_SET, di))
        assert (await device_set.read_browse_name()).Name == "DeviceSet"
        axes = await find_by_type(device_set, ua.NodeId(AXIS_TYPE, rob))
        names = sorted([(await a.read_browse_name()).Name for a in axes])
        assert names == ["spin", "x"]
        for type_id, members in MANDATORY.items():
            nodes = await find_by_type(device_set, ua.NodeId(type_id, rob))
            assert nodes, type_id
            for node in nodes:
                for space, name in members:
                    await node.get_child(f"{ns[space]}:{name}")  # raises when absent
        (device,) = await find_by_type(device_set, ua.NodeId(MOTION_DEVICE_TYPE, rob))
        assert await (await device.get_child(f"{di}:Manufacturer")).read_value() == \
            ua.LocalizedText("servobus")
        assert len(await find_by_type(device_set, ua.NodeId(POWER_TRAIN_TYPE, rob))) == 2
        by_name = {(await a.read_browse_name()).Name: a for a in axes}
        profiles = {name: await (await a.get_child(f"{rob}:MotionProfile")).read_value()
                    for name, a in by_name.items()}
        assert profiles == {"x": 3, "spin": 2}  # LINEAR, ROTARY_ENDLESS
        for name, axis in by_name.items():
            params = await axis.get_child(f"{di}:ParameterSet")
            for reading in ("ActualPosition", "ActualSpeed"):
                var = await params.get_child(f"{rob}:{reading}")
                assert await typedef(var) == ANALOG_UNIT_TYPE
                eu = await (await var.get_child("0:EngineeringUnits")).read_value()
                assert eu.UnitId != -1, (name, reading)
                assert isinstance(await (await var.get_child("0:EURange")).read_value(),
                                  ua.Range)
                rate = await var.read_attribute(ua.AttributeIds.MinimumSamplingInterval)
                assert rate.Value.Value == 20.0  # --rate 50: the sampler's period
        analog = await find_by_type(device_set, ANALOG_UNIT_TYPE, ua.NodeClass.Variable)
        assert len(analog) == 2 * 4  # per axis: position, speed, current, motor temperature
        for var in analog:  # every analog item: its unit and its range
            assert isinstance(await (await var.get_child("0:EngineeringUnits")).read_value(),
                              ua.EUInformation)
            assert isinstance(await (await var.get_child("0:EURange")).read_value(), ua.Range)
        spin = await (await by_name["spin"].get_child(
            [f"{di}:ParameterSet", f"{rob}:ActualPosition", "0:EngineeringUnits"])).read_value()
        assert spin.UnitId == 0x4D3434  # UNECE M44, revolution
        x_range = await (await by_name["x"].get_child(
            [f"{di}:ParameterSet", f"{rob}:ActualPosition", "0:EURange"])).read_value()
        assert (x_range.Low, x_range.High) == (0.0, 100.0)
        build = await client.get_node(ua.ObjectIds.Server_ServerStatus_BuildInfo).read_value()
        assert (build.ProductName, build.ManufacturerName) == ("servobus gateway", "servobus")


class Events:
    def __init__(self) -> None:
        self.events: list[Any] = []

    def event_notification(self, event: Any) -> None:
        self.events.append(event)


async def test_a_fault_on_the_control_channel_is_a_condition_on_the_server_object(
        cell: tuple[RunningGateway, str]) -> None:
    gateway, control = cell
    async with user_client(gateway.endpoint) as client:
        servobus = await client.get_namespace_index("urn:servobus:gateway")
        etype = await client.get_node(ua.ObjectIds.AlarmConditionType).get_child(
            f"{servobus}:AxisAlarmConditionType")  # its fields: AlarmCode, AlarmText too
        on_server, on_axis = Events(), Events()
        sub = await client.create_subscription(20, on_server)
        await sub.subscribe_events(client.nodes.server, etype)
        axes = await find_by_type(client.get_node(ua.NodeId(
            DEVICE_SET, await client.get_namespace_index(DI))), ua.NodeId(
            AXIS_TYPE, await client.get_namespace_index(ROBOTICS)))
        x = {(await a.read_browse_name()).Name: a for a in axes}["x"]
        axis_sub = await client.create_subscription(20, on_axis)
        await axis_sub.subscribe_events(x, etype)
        reply = await asyncio.to_thread(
            lambda: ControlClient(control).request({"cmd": "fault", "id": 1,
                                                    "fault": "over_current"}))
        assert reply["ok"], reply

        def alarm(events: Events) -> Any:
            return next((e for e in events.events if getattr(e, "AlarmCode", 0) == 2), None)

        await wait_until_async(lambda: _true(alarm(on_server) is not None), timeout=30,
                               what="the alarm event on the Server object")
        await wait_until_async(lambda: _true(alarm(on_axis) is not None), timeout=30,
                               what="the alarm event on the axis")
        event = alarm(on_server)
        assert event.EventType.NamespaceIndex != 0  # servobus's AxisAlarmConditionType
        assert (event.AxisName, event.SourceName) == ("x", "x")
        assert event.Retain is True and event.Severity == 800
        assert event.EventId == alarm(on_axis).EventId
        condition = client.get_node(event.NodeId)  # the ConditionId
        active = await condition.get_child(["0:ActiveState", "0:Id"])
        assert await active.read_value() is True
        # Acknowledge, by the condition's method, runs the gateway's ack path
        await condition.call_method("0:Acknowledge", ua.Variant(event.EventId,
                                    ua.VariantType.ByteString), ua.LocalizedText("seen"))
        await wait_until_async(lambda: _true(any(
            getattr(e, "AckedState/Id", False) and getattr(e, "AlarmCode", 0) == 2
            for e in on_server.events)), timeout=30, what="the acknowledged event")
        acked = await condition.get_child(["0:AckedState", "0:Id"])
        assert await acked.read_value() is True
        # still active (the drive's alarm is latched): ConditionRefresh replays it
        before = len(on_server.events)
        await client.get_node(ua.ObjectIds.ConditionType).call_method(
            ua.NodeId(ua.ObjectIds.ConditionType_ConditionRefresh),
            ua.Variant(sub.subscription_id, ua.VariantType.UInt32))
        await wait_until_async(lambda: _true(any(
            getattr(e, "AlarmCode", 0) == 2 for e in on_server.events[before:])),
            timeout=30, what="the retained alarm replayed by ConditionRefresh")


async def _true(value: bool) -> bool:
    return value
