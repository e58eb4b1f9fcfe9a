"""Gateways and brokers for the gateway tests: ``servobus serve`` in a child process on a
free port, a users file, a Mosquitto broker on a free loopback port, OPC UA browse helpers."""

from __future__ import annotations

import contextlib
import os
import shutil
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from asyncua import Client, Node, ua
from rig import free_port
from subprocess_rig import Process, read_line, stop_process

from servobus.gateway.opcua_model import DI_URI, ROBOTICS_URI, SERVOBUS_URI
from servobus.gateway.users import Users

USER, PASSWORD = "operator", "correct horse battery"


@dataclass
class RunningGateway:
    proc: Process
    endpoint: str
    lines: list[str]

    def stop(self) -> str:
        return stop_process(self.proc)


def users_file(folder: Path) -> Path:
    path = folder / "users.json"
    table = Users()
    table.add(USER, PASSWORD)
    table.save(path)
    return path


def start_gateway(*args: str, env: dict[str, str] | None = None) -> RunningGateway:
    """``servobus serve --opcua opc.tcp://127.0.0.1:0 ARGS`` until its ready line."""
    cmd = [sys.executable, "-m", "servobus", "serve", "--opcua", "opc.tcp://127.0.0.1:0",
           *args]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            env={**os.environ, **(env or {})})
    lines: list[str] = []
    try:
        while not lines or "ready" not in lines[-1]:
            lines.append(read_line(proc, "servobus serve:", timeout=60))
    except BaseException:
        stop_process(proc)
        raise
    endpoint = next(line.split()[3] for line in lines if line.startswith("servobus serve: opcua"))
    return RunningGateway(proc, endpoint, lines)


def user_client(endpoint: str) -> Client:
    """An asyncua client that logs in as the users file's USER."""
    client = Client(endpoint)
    client.set_user(USER)
    client.set_password(PASSWORD)
    return client


@dataclass
class Names:
    di: int
    robotics: int
    servobus: int


async def names(client: Client) -> Names:
    return Names(await client.get_namespace_index(DI_URI),
                 await client.get_namespace_index(ROBOTICS_URI),
                 await client.get_namespace_index(SERVOBUS_URI))


async def machine_node(client: Client, machine: str) -> Node:
    n = await names(client)
    return await client.nodes.objects.get_child(
        [f"{n.di}:DeviceSet", f"{n.robotics}:MotionDeviceSystem", f"{n.robotics}:MotionDevices",
         f"{n.servobus}:{machine}"])


async def axes_of(client: Client, machine: str) -> dict[str, Node]:
    """The objects under the machine's ``Axes``, by browse name."""
    n = await names(client)
    axes = await (await machine_node(client, machine)).get_child(f"{n.robotics}:Axes")
    out = {}
    for child in await axes.get_children():
        out[(await child.read_browse_name()).Name] = child
    return out


async def typedef(node: Node) -> ua.NodeId:
    return (await node.read_type_definition())  # type: ignore[no-any-return]


async def find_by_type(root: Node, wanted: ua.NodeId,
                       nodeclass: ua.NodeClass = ua.NodeClass.Object) -> list[Node]:
    """Every node of ``nodeclass`` below ``root`` (hierarchical references) whose
    TypeDefinition is ``wanted``: a client that knows the type and no browse name."""
    found, todo, seen = [], [root], {root.nodeid}
    while todo:
        node = todo.pop()
        for child in await node.get_children():
            if child.nodeid in seen:
                continue
            seen.add(child.nodeid)
            kind = await child.read_node_class()
            if kind == nodeclass and await typedef(child) == wanted:
                found.append(child)
            if kind in (ua.NodeClass.Object, ua.NodeClass.Variable):
                todo.append(child)
    return found


async def parameter(client: Client, axis: Node, name: str) -> Node:
    n = await names(client)
    ns = n.robotics if name in ("ActualPosition", "ActualSpeed") else n.servobus
    return await axis.get_child([f"{n.di}:ParameterSet", f"{ns}:{name}"])


# ---------------------------------------------------------------- Mosquitto
MOSQUITTO = shutil.which("mosquitto") or ("/usr/sbin/mosquitto"
                                          if Path("/usr/sbin/mosquitto").exists() else None)
PASSWD = shutil.which("mosquitto_passwd")
BROKER_USERS = {"gateway": "gateway-secret-1", "tester": "tester-secret-1"}


class Mosquitto:
    """One Mosquitto broker on a loopback port (users of BROKER_USERS); :meth:`restart`
    stops it and starts it again on the same port (its retained messages gone)."""

    def __init__(self, folder: Path) -> None:
        if MOSQUITTO is None or PASSWD is None:
            pytest.skip("mosquitto is not installed (Debian: apt-get install mosquitto)")
        self.folder = folder
        self.passwords = folder / "passwd"
        self.passwords.write_text("")
        for user, password in BROKER_USERS.items():
            subprocess.run([PASSWD, "-b", str(self.passwords), user, password], check=True,
                           capture_output=True)
        self.passwords.chmod(0o600)
        self.port = 0
        self.proc: Process | None = None

    def start(self, port: int) -> bool:
        conf = self.folder / "mosquitto.conf"
        # as root, mosquitto would drop to user mosquitto, who cannot read tmp_path
        stay = "user root\n" if os.geteuid() == 0 else ""
        conf.write_text(f"listener {port} 127.0.0.1\nallow_anonymous false\n"
                        f"password_file {self.passwords}\npersistence false\n{stay}")
        assert MOSQUITTO is not None
        self.proc = subprocess.Popen([MOSQUITTO, "-c", str(conf)], stdout=subprocess.DEVNULL,
                                     stderr=subprocess.PIPE)
        if _wait_listening(self.proc, port):
            self.port = port
            return True
        self.stop()
        return False

    def stop(self) -> None:
        if self.proc is not None:
            stop_process(self.proc)
            self.proc = None

    def restart(self) -> None:
        self.stop()
        if not self.start(self.port):
            pytest.fail(f"mosquitto did not start again on port {self.port}")


@contextlib.contextmanager
def mosquitto_broker(folder: Path) -> Iterator[Mosquitto]:
    """A :class:`Mosquitto` on a free loopback port, stopped at the end."""
    broker = Mosquitto(folder)
    for _attempt in range(5):  # the free port may be taken between the probe and the bind
        if broker.start(free_port()):
            break
    else:
        pytest.fail("mosquitto did not start on a free port")
    try:
        yield broker
    finally:
        broker.stop()


@contextlib.contextmanager
def mosquitto(folder: Path) -> Iterator[int]:
    """A Mosquitto broker on a free loopback port (users of BROKER_USERS); its port."""
    with mosquitto_broker(folder) as broker:
        yield broker.port


def _wait_listening(proc: Process, port: int, timeout: float = 20.0) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end and proc.poll() is None:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return True
        time.sleep(0.02)  # no event tells when the broker listens: poll the port
    return False
