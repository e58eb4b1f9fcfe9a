"""The gateway's part of the fault run (issue 30): hostile MQTT payloads, an OPC UA session
flood and a login flood against a real ``servobus serve``, and what each did.

The run builds what a plant engineer would: a users file made with ``servobus users add``,
a Mosquitto broker on a free loopback port (with a password file: one user for the gateway,
one for the hostile client), and ``servobus serve`` in its own process on the built-in
virtual machine - OPC UA on a free port with ``--users``, MQTT with ``--mqtt-commands``.
Each selected kind of benchmarks/faults_hostile.py then runs against it, one after the
other, and gives one line: what it sent, what was answered or refused, whether the gateway
still served what a well-behaved client asks afterwards, its seconds, and the gateway's
log lines meanwhile. Last, the gateway must still serve - an OPC UA read of an axis's
position and an MQTT state message of that axis arrive - and it is stopped with SIGINT
(Ctrl-C), as an operator would.

Without Mosquitto (``mosquitto`` and ``mosquitto_passwd``) the gateway runs without MQTT,
the hostile payloads are skipped and the run says so in one line.

The gateway answers one MQTT command after the other, each after its reply's QoS 1 round
trip: 75-90 a second on the project's loaded 2-core machine, so the default 10,000
payloads take about 2 minutes (``--hostile-count N`` for fewer).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import os
import shutil
import signal
import socket
import sys
import time
from collections.abc import AsyncIterator, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from benchmarks.faults_hostile import hostile_mqtt, login_flood, session_flood
from benchmarks.verdict import mark, percent

#: The hostile kinds, by their name on the command line (``--only``), and in the report.
NAMES = {"mqtt": "hostile mqtt", "sessions": "session flood", "logins": "login flood"}
KINDS = tuple(NAMES)
HOSTILE_COUNT = 10_000
#: Commands the gateway answers a second on the loaded 2-core machine (measured; see the
#: module's docstring): what the run announces, and the base of its patience.
ANSWERED_PER_S = 90.0
USER, PASSWORD = "operator", "correct horse battery"
#: Broker users: the gateway's, and the hostile client's (any client the broker lets
#: publish on ``.../cmd``).
BROKER_USERS = {"gateway": "gateway-secret-1", "hostile": "hostile-secret-1"}
FLOOD_SOURCE, OTHER_SOURCE = "127.0.0.2", "127.0.0.3"
#: The session flood: this many anonymous sessions from FLOOD_SOURCE, each asking this many
#: subscriptions (past the gateway's caps: 10 sessions per address, 10 subscriptions each).
FLOOD_SESSIONS, FLOOD_SUBSCRIPTIONS = 40, 20
#: The login flood: wrong passwords from FLOOD_SOURCE before the right one from OTHER_SOURCE.
WRONG_LOGINS = 12
START_S = 60.0  # a loaded host starts the gateway (and its virtual drives) within this
MOSQUITTO = shutil.which("mosquitto") or ("/usr/sbin/mosquitto"
                                          if Path("/usr/sbin/mosquitto").exists() else None)
MOSQUITTO_PASSWD = shutil.which("mosquitto_passwd")


def mqtt_timeout(count: int) -> float:
    """How long the hostile payloads may take: four times the expected time, at least 60 s
    (a slower host shows as fewer answered, not as a hung run)."""
    return max(60.0, 4 * count / ANSWERED_PER_S)


def expected_time(count: int) -> str:
    """How long ``count`` hostile payloads should take here, for the run's first line."""
    seconds = count / ANSWERED_PER_S
    return f"about {seconds / 60:.1f} min" if seconds >= 90 else f"about {seconds:.0f} s"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


# ---------------------------------------------------------------- the broker
async def _listening(port: int, proc: asyncio.subprocess.Process, timeout: float) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end and proc.returncode is None:
        with contextlib.suppress(OSError):
            _, writer = await asyncio.open_connection("127.0.0.1", port)
            writer.close()
            return True
        await asyncio.sleep(0.05)  # no event tells when the broker listens: poll the port
    return False


@contextlib.asynccontextmanager
async def broker(folder: Path) -> AsyncIterator[int | None]:
    """A Mosquitto broker on a free loopback port with BROKER_USERS; its port, or None when
    Mosquitto is not installed."""
    if MOSQUITTO is None or MOSQUITTO_PASSWD is None:
        yield None
        return
    passwords = folder / "mosquitto.passwd"
    passwords.write_text("")
    for user, password in BROKER_USERS.items():
        made = await asyncio.create_subprocess_exec(
            MOSQUITTO_PASSWD, "-b", str(passwords), user, password,
            stdout=asyncio.subprocess.DEVNULL, stderr=asyncio.subprocess.DEVNULL)
        if await made.wait() != 0:
            raise RuntimeError(f"mosquitto_passwd could not add {user}")
    passwords.chmod(0o600)
    proc = None
    for _attempt in range(5):  # the free port may be taken between the probe and the bind
        port = free_port()
        conf = folder / "mosquitto.conf"
        # as root, mosquitto would drop to user mosquitto, who cannot read the folder
        stay = "user root\n" if os.geteuid() == 0 else ""
        conf.write_text(f"listener {port} 127.0.0.1\nallow_anonymous false\n"
                        f"password_file {passwords}\npersistence false\n{stay}")
        with (folder / "mosquitto.log").open("a") as err:
            proc = await asyncio.create_subprocess_exec(
                MOSQUITTO, "-c", str(conf), stdout=asyncio.subprocess.DEVNULL, stderr=err)
        if await _listening(port, proc, 20.0):
            break
        await _stop(proc, signal.SIGTERM)
    else:
        raise RuntimeError(f"mosquitto did not start on a free port; see {folder}")
    try:
        yield port
    finally:
        await _stop(proc, signal.SIGTERM)


async def _stop(proc: asyncio.subprocess.Process, sig: signal.Signals,
                timeout: float = 30.0) -> int:
    if proc.returncode is None:
        proc.send_signal(sig)
    try:
        return await asyncio.wait_for(proc.wait(), timeout)
    except TimeoutError:
        proc.kill()
        return await proc.wait()


# ---------------------------------------------------------------- the gateway
@dataclass
class Served:
    """A running ``servobus serve``: its process, what it said it serves, its log."""

    proc: asyncio.subprocess.Process
    endpoint: str
    machine: str
    axes: list[str]
    log: Path
    drain: asyncio.Task[None]
    mqtt_port: int | None

    @property
    def base(self) -> str:
        return f"servobus/{self.machine}"

    def log_lines(self) -> int:
        with self.log.open("rb") as f:
            return sum(1 for _ in f)


async def users_file(folder: Path) -> Path:
    """USER in a users file, made as an operator makes it: ``servobus users add``."""
    path = folder / "users.json"
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "servobus", "users", "add", USER, "--file", str(path),
        stdin=asyncio.subprocess.PIPE, stdout=asyncio.subprocess.DEVNULL,
        stderr=asyncio.subprocess.PIPE)
    _, err = await proc.communicate(PASSWORD.encode() + b"\n")
    if proc.returncode != 0:
        raise RuntimeError(f"servobus users add failed: {err.decode(errors='replace')}")
    return path


async def start_gateway(folder: Path, mqtt_port: int | None) -> Served:
    """``servobus serve`` on the built-in virtual machine until its ready line."""
    args = ["--opcua", "opc.tcp://127.0.0.1:0", "--users", str(await users_file(folder))]
    if mqtt_port is not None:
        secret = folder / "gateway.secret"
        secret.write_text(BROKER_USERS["gateway"] + "\n")
        args += ["--mqtt", f"mqtt://127.0.0.1:{mqtt_port}", "--mqtt-commands",
                 "--mqtt-user", "gateway", "--mqtt-password-file", str(secret)]
    env = {k: v for k, v in os.environ.items() if k != "SERVOBUS_MACHINE"}  # the built-in one
    log = folder / "gateway.log"
    with log.open("a") as err:
        proc = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "servobus", "serve", *args, env=env,
            stdout=asyncio.subprocess.PIPE, stderr=err)
    assert proc.stdout is not None
    lines: list[str] = []
    try:
        async with asyncio.timeout(START_S):
            while not lines or "ready" not in lines[-1]:
                line = (await proc.stdout.readline()).decode()
                if not line:
                    raise RuntimeError(f"servobus serve ended before it was ready; see {log}")
                lines.append(line.strip())
    except BaseException:
        await _stop(proc, signal.SIGTERM)
        raise
    said = {line.split()[2]: line.split(maxsplit=3)[3] for line in lines
            if line.startswith("servobus serve: ") and len(line.split()) > 3}
    machine = said["machine"].split()[0]
    axes = said["machine"].split("; axes ")[1].split(";")[0].split(", ")
    drain = asyncio.ensure_future(_drain(proc.stdout))
    return Served(proc, said["opcua"].split()[0], machine, axes, log, drain, mqtt_port)


async def _drain(stream: asyncio.StreamReader) -> None:
    while await stream.read(4096):
        pass


# ---------------------------------------------------------------- still serving
async def opcua_position(endpoint: str, machine: str, axis: str) -> tuple[bool, str]:
    """``<axis>.ActualPosition`` read by an anonymous client: (Good, the value), else
    (False, what failed)."""
    from asyncua import Client

    from servobus.gateway.opcua_model import DI_URI, ROBOTICS_URI, SERVOBUS_URI

    try:
        async with asyncio.timeout(30), Client(endpoint, timeout=10) as client:
            di = await client.get_namespace_index(DI_URI)
            ro = await client.get_namespace_index(ROBOTICS_URI)
            sb = await client.get_namespace_index(SERVOBUS_URI)
            node = await client.nodes.objects.get_child(
                [f"{di}:DeviceSet", f"{ro}:MotionDeviceSystem", f"{ro}:MotionDevices",
                 f"{sb}:{machine}", f"{ro}:Axes", f"{sb}:{axis}", f"{di}:ParameterSet",
                 f"{ro}:ActualPosition"])
            value = await node.read_data_value()
    except Exception as exc:  # reported as not serving, with what failed
        return False, f"{type(exc).__name__}: {exc}"
    if not value.StatusCode.is_good():
        return False, value.StatusCode.name
    return True, f"{value.Value.Value:g}"


async def mqtt_state(port: int, base: str, axis: str) -> bool:
    """A state message of ``axis`` arrives (published after this subscription: not an old
    one) with ``ok`` true."""
    import aiomqtt

    with contextlib.suppress(Exception):
        async with asyncio.timeout(30), aiomqtt.Client(
                "127.0.0.1", port, username="hostile", password=BROKER_USERS["hostile"],
                identifier=f"check-{os.getpid()}") as client:
            await client.subscribe(f"{base}/{axis}/state", qos=0)
            async for message in client.messages:
                payload = message.payload if isinstance(message.payload, bytes) else b""
                with contextlib.suppress(ValueError):
                    state = json.loads(payload)
                    if isinstance(state, dict) and state.get("ok") is True:
                        return True
    return False


# ---------------------------------------------------------------- the run
@dataclass
class HostileReport:
    results: list[dict[str, Any]] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    position: tuple[bool, str] = (False, "not read")  # the OPC UA read at the end
    axis: str = ""
    state_arrived: bool | None = None  # None: no broker
    exit_code: int | None = None
    ended_early: bool = False  # the gateway had ended before the run stopped it
    last_log_line: str = ""


@contextlib.contextmanager
def quiet_clients() -> Iterator[None]:
    """asyncua's client warnings (a plain-text password sent, each refused session or login:
    what the floods do on purpose) off this process's output while the kinds run."""
    logger = logging.getLogger("asyncua")
    level = logger.level
    logger.setLevel(logging.ERROR)
    try:
        yield
    finally:
        logger.setLevel(level)


async def run_hostile(kinds: list[str], count: int, seed: int, folder: Path) -> HostileReport:
    with quiet_clients():
        return await _run_hostile(kinds, count, seed, folder)


async def _run_hostile(kinds: list[str], count: int, seed: int, folder: Path) -> HostileReport:
    report = HostileReport()
    async with broker(folder) as mqtt_port:
        if mqtt_port is None and "mqtt" in kinds:
            report.skipped.append("hostile mqtt: skipped, mosquitto is not installed "
                                  "(Debian: apt-get install mosquitto); the gateway runs "
                                  "without MQTT")
        served = await start_gateway(folder, mqtt_port)
        axis = served.axes[0]
        report.axis = axis
        try:
            for kind in kinds:
                if kind == "mqtt" and mqtt_port is None:
                    continue
                before, start = served.log_lines(), time.monotonic()
                try:
                    result = await _one(kind, served, axis, count, seed)
                except Exception as exc:  # e.g. the gateway is gone: reported, the run goes on
                    result = {"kind": NAMES[kind], "error": f"{type(exc).__name__}: {exc}",
                              "serving": False,
                              "seconds": round(time.monotonic() - start, 2)}
                result["log lines"] = served.log_lines() - before
                result["process"] = served.proc.returncode is None
                report.results.append(result)
            report.position = await opcua_position(served.endpoint, served.machine, axis)
            if mqtt_port is not None:
                report.state_arrived = await mqtt_state(mqtt_port, served.base, axis)
        finally:
            report.ended_early = served.proc.returncode is not None
            report.exit_code = await _stop(served.proc, signal.SIGINT)
            with contextlib.suppress(BaseException):
                await served.drain
            lines = served.log.read_text(errors="replace").splitlines()
            report.last_log_line = lines[-1] if lines else ""
    return report


async def _one(kind: str, served: Served, axis: str, count: int, seed: int) -> dict[str, Any]:
    if kind == "mqtt":
        assert served.mqtt_port is not None
        return await hostile_mqtt("127.0.0.1", served.mqtt_port, "hostile",
                                  BROKER_USERS["hostile"], served.base, axis, count=count,
                                  seed=seed, timeout=mqtt_timeout(count))
    if kind == "sessions":
        return await session_flood(served.endpoint, sessions=FLOOD_SESSIONS,
                                   subscriptions=FLOOD_SUBSCRIPTIONS, source=FLOOD_SOURCE,
                                   other=OTHER_SOURCE)
    return await login_flood(served.endpoint, USER, PASSWORD, wrong=WRONG_LOGINS,
                             source=FLOOD_SOURCE, other=OTHER_SOURCE)


# ---------------------------------------------------------------- printing
def _counts(counts: dict[str, int]) -> str:
    return ", ".join(f"{code} {n}" for code, n in counts.items()) or "none"


def _yes(flag: bool) -> str:
    return "yes" if flag else "NO"


def describe(r: dict[str, Any]) -> str:
    """One line: what the kind sent, what was answered or refused, whether the gateway
    still served, its seconds and the gateway's log lines meanwhile."""
    serving = _yes(bool(r["serving"]) and r.get("process", True))
    tail = f"{r['seconds']:g} s; gateway log lines {r.get('log lines', '?')}"
    if "error" in r:
        return f"  {r['kind']:14s} FAILED: {r['error'][-300:]}; {tail}"
    if r["kind"] == "hostile mqtt":
        return (f"  hostile mqtt   sent {r['sent']}, answered {r['answered']} "
                f"({_counts(r['codes'])}); still serving {serving}; {tail}")
    if r["kind"] == "session flood":
        return (f"  session flood  {r['sessions']} anonymous sessions from {FLOOD_SOURCE} "
                f"asking {FLOOD_SUBSCRIPTIONS} subscriptions each: {r['opened']} opened, "
                f"{r['subscriptions']} subscriptions held; refused: {_counts(r['refused'])}; "
                f"still serving (a client from {OTHER_SOURCE}) {serving}; {tail}")
    return (f"  login flood    sent {r['sent']}: {r['sent'] - 1} wrong passwords from "
            f"{FLOOD_SOURCE} answered {_counts(r['refused'])}, the right one from "
            f"{OTHER_SOURCE} {r['right login']}; still serving {serving}; {tail}")


def print_hostile(r: HostileReport) -> None:
    for line in r.skipped:
        print(f"  {line}")
    for result in r.results:
        print(describe(result))
        if result["kind"] == "hostile mqtt" and "error" not in result:
            answered = result["answered"] / result["sent"] if result["sent"] else 0.0
            internal = result["codes"].get("BadInternalError", 0)
            print(f"    hostile payloads answered {result['answered']}/{result['sent']}   "
                  + mark("faults: hostile MQTT payloads answered", answered, at_least=1.0,
                         show=percent)
                  + f"; answered BadInternalError (an unexpected error) {internal}   "
                  + mark("faults: hostile MQTT payloads answered BadInternalError",
                         internal, at_most=0))
    mqtt = "no broker" if r.state_arrived is None else \
        f"MQTT state of {r.axis} arrived {_yes(r.state_arrived)}"
    print(f"  at the end: OPC UA read of {r.axis}.ActualPosition "
          + (f"{r.position[1]} (Good)" if r.position[0] else f"FAILED ({r.position[1]})")
          + f", {mqtt}; "
          + ("it had ENDED before the stop" if r.ended_early else "stopped with SIGINT")
          + f": exit {r.exit_code}, last log line {r.last_log_line!r}")
    checks = [bool(x["serving"]) and x.get("process", True) for x in r.results]
    checks += [r.position[0], *([] if r.state_arrived is None else [r.state_arrived])]
    print(f"  gateway serving after each kind and at the end: {sum(checks)}/{len(checks)}   "
          + mark("faults: gateway serving after each hostile kind and at the end",
                 sum(checks) / len(checks), at_least=1.0, show=percent))
