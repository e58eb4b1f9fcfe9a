"""The plant in miniature: three gateways with different machines on one MQTT broker, each a
Sparkplug B edge node of group "plant", read by one client over OPC UA and Sparkplug; the
second serves Basic256Sha256 Sign&Encrypt with its own certificate; the death of the third
leaves the others as they were (issue 36, item 6)."""

from __future__ import annotations

import asyncio
import dataclasses
import signal
import socket
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import pytest
from asyncua import Client, ua
from asyncua.crypto.cert_gen import setup_self_signed_certificate
from cryptography import x509
from cryptography.x509.oid import ExtendedKeyUsageOID
from gateway_rig import (
    BROKER_USERS,
    PASSWORD,
    USER,
    RunningGateway,
    axes_of,
    mosquitto,
    names,
    parameter,
    start_gateway,
    user_client,
    users_file,
)
from rig import free_port, wait_until_async

from servobus.gateway.opcua_server import OpcUaGateway, OpcUaOptions

GROUP = "plant"
MACHINES = {"press-line": ("clamp", "feed"), "packer": ("lift", "turntable"),
            "welder": ("torch", "wire")}

CELL_A = """name = "press-line"
[axes.feed]
url = "sim://dyn232?fast=1"
id = 1
unit = "mm"
per_rev = 10.0
limits = [0.0, 500.0]
[axes.clamp]
url = "dyn232+socket://127.0.0.1:{closed_port}"
id = 3
unit = "mm"
per_rev = 2.0
"""
CELL_C = """name = "welder"
[axes.torch]
url = "sim://easycan?fast=1"
id = 1
unit = "mm"
per_rev = 5.0
[axes.wire]
url = "sim://easycan?fast=1"
id = 2
unit = "mm"
per_rev = 1.0
"""
CELL_B = """name = "packer"
[axes.turntable]
url = "sim://easycan?fast=1"
id = 1
unit = "deg"
limits = [-360.0, 360.0]
[axes.lift]
url = "sim://easycan?fast=1"
id = 2
unit = "mm"
per_rev = 4.0
"""


async def certificate(folder: Path, name: str, use: object) -> tuple[Path, Path]:
    cert, key = folder / f"{name}.der", folder / f"{name}.pem"
    await setup_self_signed_certificate(key, cert, f"urn:test:{name}", socket.gethostname(),
                                        [use], {"commonName": name})
    return cert, key


@pytest.fixture(scope="module")
def broker(tmp_path_factory: pytest.TempPathFactory) -> Iterator[int]:
    with mosquitto(tmp_path_factory.mktemp("plant-broker")) as port:
        yield port


@pytest.fixture(scope="module")
def plant(tmp_path_factory: pytest.TempPathFactory,
          broker: int) -> Iterator[tuple[RunningGateway, ...]]:
    folder = tmp_path_factory.mktemp("plant")
    (folder / "a.toml").write_text(CELL_A.format(closed_port=free_port()))  # nobody listens
    (folder / "b.toml").write_text(CELL_B)
    (folder / "c.toml").write_text(CELL_C)
    cert, key = asyncio.run(certificate(folder, "server", ExtendedKeyUsageOID.SERVER_AUTH))
    users = users_file(folder)
    mqtt = ("--mqtt", f"mqtt://127.0.0.1:{broker}", "--mqtt-user", "gateway",
            "--sparkplug", GROUP)
    secret = {"SERVOBUS_MQTT_PASSWORD": BROKER_USERS["gateway"]}
    runs = [(mqtt, {"SERVOBUS_MACHINE": str(folder / "a.toml"), **secret}),  # from the env
            (("--machine", str(folder / "b.toml"), "--users", str(users), "--cert", str(cert),
              "--key", str(key), *mqtt), secret),
            (("--machine", str(folder / "c.toml"), *mqtt), secret)]
    with ThreadPoolExecutor(3) as pool:  # all start at once: a third of the waiting
        gateways = tuple(pool.map(lambda run: start_gateway(*run[0], env=run[1]), runs))
    yield gateways
    for gateway in gateways:  # all stop at once
        if gateway.proc.poll() is None:
            gateway.proc.send_signal(signal.SIGTERM)
    for gateway in gateways:
        gateway.stop()


async def test_one_client_reads_two_gateways(plant: tuple[RunningGateway, ...],
                                             tmp_path: Path) -> None:
    a, b, _ = plant
    client_cert, client_key = await certificate(tmp_path, "client",
                                                ExtendedKeyUsageOID.CLIENT_AUTH)
    secure = Client(b.endpoint)
    secure.application_uri = "urn:test:client"
    await secure.set_security_string(
        f"Basic256Sha256,SignAndEncrypt,{client_cert},{client_key}")
    secure.set_user(USER)
    secure.set_password(PASSWORD)
    async with Client(a.endpoint) as plain, secure:
        axes_a = await axes_of(plain, "press-line")
        assert sorted(axes_a) == ["clamp", "feed"]
        clamp = await parameter(plain, axes_a["clamp"], "ActualPosition")

        async def link_down() -> bool:  # never opened: no last known value (issue 29)
            value = await clamp.read_data_value(raise_on_bad_status=False)
            return bool(value.StatusCode.value == ua.StatusCodes.BadNoCommunication)

        await wait_until_async(link_down, timeout=10, what="the clamp's link reads Bad")
        axes_b = await axes_of(secure, "packer")
        assert sorted(axes_b) == ["lift", "turntable"]
        feed = await parameter(plain, (await axes_of(plain, "press-line"))["feed"],
                               "ActualPosition")
        table = await parameter(secure, axes_b["turntable"], "ActualPosition")
        for node in (feed, table):
            assert (await node.read_data_value()).StatusCode.is_good()
        units = [(await (await node.get_child("0:EngineeringUnits")).read_value()
                  ).DisplayName.Text for node in (feed, table)]
        assert units == ["mm", "deg"]
        n = await names(secure)
        await axes_b["lift"].call_method(f"{n.servobus}:MoveRelative", 1.0)  # a user, encrypted
    for policy in ("Aes128Sha256RsaOaep", "Aes256Sha256RsaPss"):  # offered and served too
        aes = Client(b.endpoint)
        aes.application_uri = "urn:test:client"
        await aes.set_security_string(f"{policy},SignAndEncrypt,{client_cert},{client_key}")
        async with aes:
            assert sorted(await axes_of(aes, "packer")) == ["lift", "turntable"], policy


async def test_beyond_loopback_only_sign_and_encrypt_with_a_kept_certificate(
        tmp_path: Path) -> None:
    # no server is started (tests bind loopback only): the policy choice and the certificate
    from fake_machine import FakeMachine

    from servobus.gateway.commands import Commander

    machine = FakeMachine()
    options = OpcUaOptions("opc.tcp://0.0.0.0:4840", cert_dir=tmp_path, cert_stem="cell")
    gateway = OpcUaGateway(machine, Commander(machine), options)  # type: ignore[arg-type]
    assert not gateway.loopback
    policies = await gateway._security()
    assert policies == [ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt,
                        ua.SecurityPolicyType.Aes128Sha256RsaOaep_SignAndEncrypt,
                        ua.SecurityPolicyType.Aes256Sha256RsaPss_SignAndEncrypt]
    cert = tmp_path / "cell.opcua-cert.der"
    first = cert.read_bytes()
    assert (tmp_path / "cell.opcua-key.pem").stat().st_mode & 0o077 == 0
    assert (tmp_path / "cell.opcua-cert.der").stat().st_mode & 0o077 == 0
    again = OpcUaGateway(machine, Commander(machine), options)  # type: ignore[arg-type]
    await again._security()
    assert cert.read_bytes() == first  # kept, not made anew on the next start
    san = x509.load_der_x509_certificate(first).extensions.get_extension_for_class(
        x509.SubjectAlternativeName).value
    assert san.get_values_for_type(x509.UniformResourceIdentifier) == [
        "urn:servobus:gateway:bench"]
    assert socket.gethostname() in san.get_values_for_type(x509.DNSName)
    addresses = {str(a) for a in san.get_values_for_type(x509.IPAddress)}
    resolved = {info[4][0] for info in socket.getaddrinfo(socket.gethostname(), None)}
    assert addresses == resolved  # 0.0.0.0: every address of the host name
    # another gateway id in the same files: a certificate for its own ApplicationUri
    other = OpcUaGateway(machine, Commander(machine), dataclasses.replace(  # type: ignore[arg-type]
        options, gateway_id="bench-2"))
    await other._security()
    san = x509.load_der_x509_certificate(cert.read_bytes()).extensions.get_extension_for_class(
        x509.SubjectAlternativeName).value
    assert san.get_values_for_type(x509.UniformResourceIdentifier) == [
        "urn:servobus:gateway:bench-2"]


async def opcua_view(endpoint: str, machine: str) -> tuple[str, dict[str, ua.DataValue]]:
    """A gateway's node namespace (index 1, its ApplicationUri) and every axis's position."""
    async with Client(endpoint) as client:
        uris = await client.get_namespace_array()
        endpoints = await client.get_endpoints()
        assert {e.Server.ApplicationUri for e in endpoints} == {uris[1]}
        positions = {}
        for name, axis in (await axes_of(client, machine)).items():
            node = await parameter(client, axis, "ActualPosition")
            positions[name] = await node.read_data_value(raise_on_bad_status=False)
        return uris[1], positions


def last_position(seen: Any, node: str, axis: str) -> float | None:
    """The axis's last Position over Sparkplug (its DBIRTH or a later DDATA)."""
    from tahu_rig import metrics, value

    for message in reversed(seen.of("DBIRTH", node, axis) + seen.of("DDATA", node, axis)):
        metric = metrics(message.payload).get("Position")
        if metric is not None:
            return float(value(metric)) if value(metric) is not None else None
    return None


async def same_positions(endpoint: str, machine: str, seen: Any) -> None:
    """Every good axis reads the same position over OPC UA and Sparkplug (once a motion of
    the test before has settled: both follow the same samples)."""
    async with Client(endpoint) as client:
        for axis, node in (await axes_of(client, machine)).items():
            position = await parameter(client, node, "ActualPosition")

            async def agree(position: Any = position, axis: str = axis) -> bool:
                dv = await position.read_data_value(raise_on_bad_status=False)
                spb = last_position(seen, machine, axis)
                if not dv.StatusCode.is_good():
                    return spb is None
                return spb is not None and abs(spb - dv.Value.Value) < 1e-6
            await wait_until_async(agree, timeout=30,
                                   what=f"{machine}/{axis}: one position both ways")


@pytest.mark.slow  # a third gateway process and a broker beside the two of the plant
async def test_an_observer_reads_every_axis_and_one_death_is_local(
        plant: tuple[RunningGateway, ...], broker: int) -> None:
    from sparkplug_rig import observing
    from tahu_rig import metrics, tahu, value

    a, b, c = plant
    views = {m: await opcua_view(g.endpoint, m) for m, g in zip(MACHINES, plant, strict=True)}
    assert {m: sorted(v[1]) for m, v in views.items()} == \
        {m: list(axes) for m, axes in MACHINES.items()}
    assert len({uri for uri, _ in views.values()}) == 3  # a namespace each
    assert {uri for uri, _ in views.values()} == {f"urn:servobus:gateway:{m}" for m in MACHINES}
    async with observing(broker, GROUP) as seen:
        for node in MACHINES:  # a host that comes late asks each node for its births
            ncmd = tahu().Payload(timestamp=1)
            ncmd.metrics.add(name="Node Control/Rebirth", datatype=tahu().Boolean,
                             boolean_value=True)
            await seen.publish(f"spBv1.0/{GROUP}/NCMD/{node}", ncmd.SerializeToString())
        await seen.until(lambda: {(m.node, m.device) for m in seen.of("DBIRTH")} == {
            (node, axis) for node, axes in MACHINES.items() for axis in axes},
            "every axis's DBIRTH")
        for (node, (_, positions)), gateway in zip(views.items(), plant, strict=True):
            for axis, dv in positions.items():
                born = metrics(seen.of("DBIRTH", node, axis)[-1].payload)
                good = bool(value(born["Good"]))
                assert good == dv.StatusCode.is_good(), (node, axis)
                if not good:
                    assert value(born["Position"]) is None and value(born["Error"])
            await same_positions(gateway.endpoint, node, seen)
        birth_of = {node: value(metrics(seen.of("NBIRTH", node)[-1].payload)["bdSeq"])
                    for node in MACHINES}
        before = len(seen.messages)
        c.proc.send_signal(signal.SIGKILL)  # the welder's gateway dies: its will speaks
        c.proc.wait(timeout=30)
        await seen.until(lambda: seen.of("NDEATH", "welder"), "the welder's NDEATH",
                         timeout=60)
        death = seen.of("NDEATH", "welder")[-1]
        assert value(metrics(death.payload)["bdSeq"]) == birth_of["welder"]
        async with user_client(b.endpoint) as operator:  # the packer serves on
            n = await names(operator)
            lift = (await axes_of(operator, "packer"))["lift"]
            start = (await (await parameter(operator, lift, "ActualPosition")).read_value())
            await lift.call_method(f"{n.servobus}:MoveRelative", 2.0)

        def lift_moved() -> bool:
            data = [metrics(m.payload).get("Position") for m in seen.of("DDATA", "packer",
                                                                        "lift")]
            return any(d is not None and abs(value(d) - (start + 2.0)) < 0.01 for d in data)
        await seen.until(lift_moved, "the packer's lift at +2 mm over Sparkplug")
        after = seen.messages[before:]
        assert not [m for m in after if m.node != "welder" and m.kind in ("NDEATH", "NBIRTH",
                                                                           "DBIRTH")]
    for machine, gateway in (("press-line", a), ("packer", b)):
        uri, positions = await opcua_view(gateway.endpoint, machine)
        assert uri == views[machine][0]
        assert [dv.StatusCode.is_good() for dv in positions.values()] == \
            [dv.StatusCode.is_good() for dv in views[machine][1].values()]
