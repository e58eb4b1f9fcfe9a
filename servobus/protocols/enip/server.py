"""asyncio EtherNet/IP server for the virtual DYN5: moves bytes, keeps time; the adapter decides.

Per drive (one IP address each, like drives on a daisy chain): TCP explicit messaging on
the encapsulation port (44818) with several sessions at once, UDP ListIdentity /
ListServices / ListInterfaces on the same port number, Class 1 I/O on UDP (2222). Binds
127.0.0.1 by default; port 0 picks a free port (the bound ports are in ``tcp_port``,
``list_port`` and ``udp_port``).

Encapsulation decisions (CIP Vol. 2 ch. 2): a packet with non-zero options is discarded;
NOP gets no reply; an unknown or TCP-only-on-UDP command answers 0x0001; a length above
the bound 0x0065 (its data skipped); RegisterSession with another version or options
0x0069, a second registration on one TCP connection 0x0001, more than ``max_sessions``
0x0002; a session handle that is not this connection's 0x0064; a SendRRData whose data or
CPF items do not parse 0x0003. The connection stays open after each of these. The sender
context is echoed in every reply. SendUnitData is dropped: the DYN5 has no Class 3
connections (manual 1: explicit messaging is unconnected).

Class 1: T->O frames go every T->O RPI (on absolute times, a late tick does not shift the
grid; every connection of every server on the loop shares one timer, ``production.py``) to
the originator's Sockaddr Info 0x8001 when it sent one, else to port 2222 of its IP. A
Forward_Open reply carries a 0x8000 item naming the O->T port when it is not 2222.
Reset (0x21 = 0xABCD): the reply is sent, then every connection and session is dropped,
the drive power-cycles and the adapter ignores traffic for ``reset_downtime_s``
(3 s like the drive; tests shorten it).

Fair service (issue 17.5): every TCP client is served at most ``PACKETS_PER_TURN`` packets
per event-loop turn, so a client that floods requests delays another by a few packets, not
by its whole backlog; a client that does not read its replies is not read either (asyncio
flow control past ``WRITE_HIGH_WATER``, as on the serial and CAN servers). Memory per client
is bounded: one received chunk of packets and the replies of one turn (``MAX_OUTPUT`` is the
last bound: a client past it is cut off).
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import ipaddress
import itertools
import logging
import random
import threading
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, cast

from servobus.errors import ArgumentRangeError, FramingError
from servobus.families.dyn5 import params as dyn5
from servobus.families.dyn5.params import Identity
from servobus.protocols.enip.codec import discovery, io
from servobus.protocols.enip.codec.cpf import (
    RRData,
    SockaddrInfo,
    UnconnectedMessage,
    plain_rr_data,
    unconnected_message,
)
from servobus.protocols.enip.codec.encap import (
    MAX_DATA,
    TCP_PORT,
    UDP_COMMANDS,
    Command,
    EncapFramer,
    EncapPacket,
    EncapReject,
    EncapStatus,
    RegisterSessionData,
)
from servobus.protocols.enip.connections import IoConnection
from servobus.protocols.enip.device import Dyn5Adapter, Origin, Outcome
from servobus.protocols.enip.production import Producer, ProductionWheel
from servobus.sim.core.state_file import StateKind
from servobus.sim.dmm.drive import VirtualDrive
from servobus.sim.dmm.eeprom import EepromStore, check_drive_record
from servobus.sim.server_limits import MAX_OUTPUT_BYTES, WRITE_HIGH_WATER
from servobus.sim.wall_clock import RealtimeClock

log = logging.getLogger("servobus.enip")

MAX_OUTPUT = MAX_OUTPUT_BYTES  # past asyncio's flow control: the last bound, then cut off
PACKETS_PER_TURN = 8  # packets of one client handled per loop turn (fair service)
QUANTUM = 1024  # bytes of one client framed at a time (a 256 KiB read is not parsed at once)
MAX_SESSIONS = 32
MAX_CLIENTS = 64
STOP_POLL_S = 0.005


@dataclass
class _Producer:
    conn: IoConnection
    packer: io.FramePacker
    wheel: ProductionWheel
    tick: Producer | None = None
    watchdog: asyncio.TimerHandle | None = None

    def cancel(self) -> None:
        if self.tick is not None:
            self.wheel.remove(self.tick)
        if self.watchdog is not None:
            self.watchdog.cancel()


@dataclass
class ServerStats:
    sessions_opened: int = 0
    requests: int = 0
    malformed: int = 0
    frames_out: int = 0
    frames_in: int = 0
    frames_dropped: int = 0
    watchdog_expiries: int = 0
    resets: int = 0


class EnipServer:
    """One virtual DYN5 on one IP address."""

    def __init__(self, drive: VirtualDrive, host: str = "127.0.0.1", *,
                 tcp_port: int = TCP_PORT, udp_port: int = io.UDP_PORT,
                 clock: RealtimeClock | None = None, identity: Identity = dyn5.IDENTITY,
                 reset_downtime_s: float = dyn5.RESET_DOWNTIME_S,
                 max_sessions: int = MAX_SESSIONS, max_data: int = MAX_DATA) -> None:
        self.drive = drive
        self.host = host
        self.tcp_port = tcp_port
        self.list_port = tcp_port
        self.udp_port = udp_port
        self.adapter = Dyn5Adapter(drive, identity=identity)
        self.identity = identity
        self.reset_downtime_s = reset_downtime_s
        self.max_sessions = max_sessions
        self.max_data = max_data
        self.stats = ServerStats()
        self._own_clock = clock is None
        self.clock = clock if clock is not None else RealtimeClock([drive])
        self._tcp: asyncio.Server | None = None
        self._list: asyncio.DatagramTransport | None = None
        self._io: asyncio.DatagramTransport | None = None
        self._clients: set[_TcpClient] = set()
        self._sessions: dict[int, _TcpClient] = {}
        self._session_ids = itertools.count(random.getrandbits(24) + 1)
        self._producers: dict[int, _Producer] = {}
        self._down_until = 0.0
        self._stop_poll: asyncio.TimerHandle | None = None
        self._loop: asyncio.AbstractEventLoop | None = None

    # ---------------------------------------------------------------- lifecycle
    async def start(self) -> EnipServer:
        loop = self._loop = asyncio.get_running_loop()
        self._tcp = await loop.create_server(lambda: _TcpClient(self), self.host,
                                             self.tcp_port)
        self.tcp_port = self._tcp.sockets[0].getsockname()[1]
        try:
            self._list, _ = await loop.create_datagram_endpoint(
                lambda: _ListProtocol(self), local_addr=(self.host, self.tcp_port))
        except OSError:  # the TCP port number is taken on UDP: any free port
            self._list, _ = await loop.create_datagram_endpoint(
                lambda: _ListProtocol(self), local_addr=(self.host, 0))
        self.list_port = self._list.get_extra_info("sockname")[1]
        self._io, _ = await loop.create_datagram_endpoint(
            lambda: _IoProtocol(self), local_addr=(self.host, self.udp_port))
        self.udp_port = self._io.get_extra_info("sockname")[1]
        if self._own_clock:
            self.clock.start()
        log.info("virtual DYN5 on %s: TCP %d, UDP list %d, UDP I/O %d", self.host,
                 self.tcp_port, self.list_port, self.udp_port)
        return self

    async def stop(self) -> None:
        for prod in self._producers.values():
            prod.cancel()
        self._producers.clear()
        if self._stop_poll is not None:
            self._stop_poll.cancel()
        for client in list(self._clients):
            client.close()
        for transport in (self._list, self._io):
            if transport is not None:
                transport.close()
        if self._tcp is not None:
            self._tcp.close()
            with contextlib.suppress(asyncio.TimeoutError):
                await asyncio.wait_for(self._tcp.wait_closed(), 1.0)
        if self._own_clock:
            await self.clock.stop()

    async def __aenter__(self) -> EnipServer:
        return await self.start()

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()

    @property
    def session_count(self) -> int:
        return len(self._sessions)

    @property
    def down(self) -> bool:
        return self._now() < self._down_until

    def _now(self) -> float:
        return self._loop.time() if self._loop is not None else 0.0

    def _sync(self) -> None:
        t = self.clock.sim_time()
        if t > self.drive.time:
            self.drive.advance_to(t)

    # ---------------------------------------------------------------- encapsulation
    def handle_packet(self, item: EncapPacket | EncapReject, client: _TcpClient | None
                      ) -> EncapPacket | None:
        """One packet from TCP (``client``) or UDP (None); the reply, or None for none."""
        if isinstance(item, EncapReject):
            self.stats.malformed += 1
            log.info("encapsulation length %d above %d: rejected", item.header.length,
                     self.max_data)
            h = item.header
            return EncapPacket(h.command, b"", h.session, item.status, h.context)
        pkt = item
        if pkt.options:
            self.stats.malformed += 1
            log.info("encapsulation packet with options 0x%X discarded", pkt.options)
            return None
        cmd = pkt.command
        if client is None and cmd not in UDP_COMMANDS:
            return pkt.reply(status=EncapStatus.INVALID_COMMAND)
        if cmd == Command.NOP:
            return None
        if cmd == Command.LIST_IDENTITY:
            return pkt.reply(discovery.list_identity_reply(self.identity_item()))
        if cmd == Command.LIST_SERVICES:
            return pkt.reply(discovery.list_services_reply())
        if cmd == Command.LIST_INTERFACES:
            return pkt.reply(discovery.list_interfaces_reply())
        assert client is not None
        if cmd == Command.REGISTER_SESSION:
            return self._register(pkt, client)
        if cmd == Command.UNREGISTER_SESSION:
            if pkt.session and pkt.session == client.session:
                log.info("session 0x%08X unregistered", pkt.session)
                client.close()
                return None
            return pkt.reply(status=EncapStatus.INVALID_SESSION)
        if cmd in (Command.SEND_RR_DATA, Command.SEND_UNIT_DATA):
            if not pkt.session or pkt.session != client.session:
                return pkt.reply(status=EncapStatus.INVALID_SESSION)
            if cmd == Command.SEND_UNIT_DATA:
                log.debug("SendUnitData dropped: no Class 3 connections")
                return None
            return self._send_rr_data(pkt, client)
        self.stats.malformed += 1
        log.info("unsupported encapsulation command 0x%04X", cmd)
        return pkt.reply(status=EncapStatus.INVALID_COMMAND)

    def identity_item(self) -> discovery.IdentityItem:
        i = self.identity
        return discovery.IdentityItem(SockaddrInfo(self.tcp_port, self.host), i.vendor_id,
                                      i.device_type, i.product_code, i.revision, i.status,
                                      i.serial_number, i.product_name, i.state)

    def _register(self, pkt: EncapPacket, client: _TcpClient) -> EncapPacket:
        answer = RegisterSessionData().encode()
        try:
            data = RegisterSessionData.decode(pkt.data)
        except FramingError:
            return pkt.reply(answer, status=EncapStatus.INVALID_LENGTH)
        if data.version != RegisterSessionData().version or data.options:
            return pkt.reply(answer, status=EncapStatus.UNSUPPORTED_PROTOCOL)
        if client.session:
            return pkt.reply(answer, status=EncapStatus.INVALID_COMMAND)
        if len(self._sessions) >= self.max_sessions:
            return pkt.reply(answer, status=EncapStatus.INSUFFICIENT_MEMORY)
        session = next(self._session_ids) & 0xFFFF_FFFF
        client.session = session
        self._sessions[session] = client
        self.stats.sessions_opened += 1
        log.info("session 0x%08X registered by %s", session, client.peer_ip)
        return pkt.reply(answer, session=session)

    def _send_rr_data(self, pkt: EncapPacket, client: _TcpClient) -> EncapPacket | None:
        try:
            msg, handle = unconnected_message(pkt.data)
            if handle or not msg.message:
                raise FramingError("interface handle must be 0 and the message not empty")
        except FramingError as exc:
            self.stats.malformed += 1
            log.info("SendRRData from %s: %s", client.peer_ip, exc)
            return pkt.reply(status=EncapStatus.INCORRECT_DATA)
        self.stats.requests += 1
        self._sync()
        now = self._now()
        outcome = self.adapter.handle(msg.message, Origin(client.peer_ip, msg.sockaddr_t_o, now))
        response = outcome.response.encode()
        if outcome.opened is not None and self.udp_port != io.UDP_PORT:
            reply = UnconnectedMessage(response, SockaddrInfo(self.udp_port, self.host))
            data = RRData(reply.items()).encode()
        else:
            data = plain_rr_data(response)
        self._after(outcome, now)
        return pkt.reply(data)

    def _after(self, outcome: Outcome, now: float) -> None:
        if outcome.opened is not None:
            self._start_producer(outcome.opened, now)
        if outcome.closed is not None:
            self._stop_producer(outcome.closed)
        if outcome.reset:
            assert self._loop is not None
            self._loop.call_soon(self.reset)

    # ---------------------------------------------------------------- Class 1
    def _start_producer(self, conn: IoConnection, now: float) -> None:
        assert self._loop is not None
        prod = _Producer(conn, io.input_packer(conn.t_o_id),
                         ProductionWheel.for_loop(self._loop))
        self._producers[conn.o_t_id] = prod
        prod.tick = prod.wheel.add(Producer(conn.t_o_rpi_s, now,
                                            functools.partial(self._produce, prod)))
        prod.watchdog = self._loop.call_at(conn.deadline, self._watch, prod)

    def _stop_producer(self, conn: IoConnection) -> None:
        prod = self._producers.pop(conn.o_t_id, None)
        if prod is not None:
            prod.cancel()

    def _produce(self, prod: _Producer) -> None:
        """One T->O frame (called by the production wheel on the connection's grid)."""
        assert self._io is not None
        conn = prod.conn
        self._sync()
        seq, count = conn.next_production()
        frame = prod.packer.pack(seq, count, *self.adapter.input_values())
        with contextlib.suppress(OSError):
            self._io.sendto(frame, conn.destination)
        self.stats.frames_out += 1

    def _watch(self, prod: _Producer) -> None:
        assert self._loop is not None
        now = self._loop.time()
        conn = prod.conn
        if conn.deadline > now:
            prod.watchdog = self._loop.call_at(conn.deadline, self._watch, prod)
            return
        self.adapter.connections.remove(conn)
        self._stop_producer(conn)
        self.stats.watchdog_expiries += 1
        log.warning("Class 1 connection 0x%08X from %s timed out (%.0f ms without O->T data)",
                    conn.o_t_id, conn.originator_ip, conn.timeout_s * 1e3)
        self._sync()
        self.adapter.connection_lost(now)
        self._poll_stop()

    def _poll_stop(self) -> None:
        assert self._loop is not None
        self._stop_poll = None
        self._sync()
        if not self.adapter.poll_stop(self._loop.time()):
            self._stop_poll = self._loop.call_later(STOP_POLL_S, self._poll_stop)

    def consume_datagram(self, data: bytes, addr: tuple[str, int]) -> None:
        if self.down:
            return
        try:
            frame = io.decode_frame(data)
        except FramingError as exc:
            self.stats.frames_dropped += 1
            log.debug("malformed Class 1 datagram from %s: %s", addr[0], exc)
            return
        self._sync()
        got = self.adapter.consume(frame, addr[0], self._now())
        if got is None:
            self.stats.frames_dropped += 1
            return
        self.stats.frames_in += 1
        prod = self._producers.get(got.connection.o_t_id)
        if prod is not None and prod.watchdog is not None and (
                prod.watchdog.when() > got.connection.deadline):  # the first frame: 10 s -> RPI
            assert self._loop is not None
            prod.watchdog.cancel()
            prod.watchdog = self._loop.call_at(got.connection.deadline, self._watch, prod)
        if got.apply:
            log.info("O->T from %s: %s", addr[0], "enable" if got.image.enable else "disable")

    # ---------------------------------------------------------------- reset
    def reset(self) -> None:
        """0x21 = 0xABCD: drop everything, power-cycle the drive, go quiet for a while."""
        self.stats.resets += 1
        self._sync()
        for conn in self.adapter.reset():
            self._stop_producer(conn)
        if self._stop_poll is not None:
            self._stop_poll.cancel()
            self._stop_poll = None
        for client in list(self._clients):
            client.close()
        self._down_until = self._now() + self.reset_downtime_s
        log.warning("virtual DYN5 %s reset: connections dropped, RAM settings lost, "
                    "EtherNet/IP down for %.1f s", self.host, self.reset_downtime_s)

    # ---------------------------------------------------------------- clients
    def client_opened(self, client: _TcpClient) -> bool:
        if self.down or len(self._clients) >= MAX_CLIENTS:
            return False
        self._clients.add(client)
        return True

    def client_closed(self, client: _TcpClient) -> None:
        self._clients.discard(client)
        if client.session:
            self._sessions.pop(client.session, None)


class _TcpClient(asyncio.Protocol):
    """One TCP client: served fairly, a bounded number of packets per loop turn.

    A received chunk is kept as bytes and framed ``QUANTUM`` bytes at a time; at most
    ``PACKETS_PER_TURN`` packets are handled per turn and the rest wait behind every other
    ready callback (the other clients' requests). While a client has input queued, or its
    replies are not being drained (asyncio's write flow control, ``WRITE_HIGH_WATER``), its
    input is not read: the back-pressure reaches the client through TCP. Memory per client:
    one received chunk, the packets of one quantum and the replies of one turn.
    """

    def __init__(self, server: EnipServer) -> None:
        self.server = server
        self.framer = EncapFramer(server.max_data)
        self.session = 0
        self.peer_ip = ""
        self.transport: asyncio.Transport | None = None
        self._pending: deque[EncapPacket | EncapReject] = deque()
        self._backlog = bytearray()  # received, not yet framed (QUANTUM bytes per turn)
        self._scheduled = False
        self._reading_paused = False
        self._writing_paused = False

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = cast(asyncio.Transport, transport)
        peer = transport.get_extra_info("peername")
        self.peer_ip = peer[0] if peer else ""
        if not self.server.client_opened(self):
            self.transport = None
            cast(asyncio.Transport, transport).abort()
            return
        self.transport.set_write_buffer_limits(high=WRITE_HIGH_WATER)

    def data_received(self, data: bytes) -> None:
        if self.transport is None:
            return
        self._backlog += data
        if not self._scheduled and not self._writing_paused:
            self._serve()  # nothing of this client waits: its turn is now
        else:
            self._pause_reading()

    def pause_writing(self) -> None:
        self._writing_paused = True
        self._pause_reading()  # no more requests until the client reads its replies

    def resume_writing(self) -> None:
        self._writing_paused = False
        if self._pending or self._backlog:
            self._schedule()
        else:
            self._resume_reading()

    def _schedule(self) -> None:
        if not self._scheduled and self.server._loop is not None:
            self._scheduled = True
            self.server._loop.call_soon(self._serve)  # behind every other ready callback

    def _serve(self) -> None:
        """One turn: up to PACKETS_PER_TURN packets; their SendRRData replies in one write."""
        self._scheduled = False
        transport = self.transport
        if transport is None:
            self._drop_queued()
            return
        if self._writing_paused:
            return  # resume_writing() continues
        while len(self._pending) < PACKETS_PER_TURN and self._backlog:
            self._pending.extend(self.framer.feed(bytes(self._backlog[:QUANTUM])))
            del self._backlog[:QUANTUM]
        out: list[bytes] = []
        for _ in range(PACKETS_PER_TURN):
            if not self._pending:
                break
            item = self._pending.popleft()
            if out and (isinstance(item, EncapReject) or item.command != Command.SEND_RR_DATA):
                transport.write(b"".join(out))  # before a packet that may end the session
                out.clear()
            try:
                reply = self.server.handle_packet(item, self)
            except Exception:  # a bug must not take the adapter down: log it, drop the client
                log.exception("internal error on a packet from %s", self.peer_ip)
                self.close(abort=True)
                return
            if self.transport is None:
                self._drop_queued()
                return
            if reply is not None:
                out.append(reply.encode())
        if out:
            transport.write(b"".join(out))
        if transport.get_write_buffer_size() > MAX_OUTPUT:  # flow control failed: a bound
            log.info("client %s does not read its replies: disconnected", self.peer_ip)
            self.close(abort=True)
            return
        if self._pending or self._backlog:
            self._pause_reading()
            if not self._writing_paused:
                self._schedule()
        else:
            self._resume_reading()

    def _drop_queued(self) -> None:
        self._pending.clear()
        self._backlog.clear()

    def _pause_reading(self) -> None:
        if not self._reading_paused and self.transport is not None \
                and not self.transport.is_closing():
            self._reading_paused = True
            self.transport.pause_reading()

    def _resume_reading(self) -> None:
        if self._reading_paused and not self._writing_paused and not self._pending \
                and not self._backlog:
            self._reading_paused = False
            if self.transport is not None and not self.transport.is_closing():
                self.transport.resume_reading()

    def connection_lost(self, exc: Exception | None) -> None:
        if self.transport is not None:
            self.server.client_closed(self)
        self.transport = None
        self._drop_queued()

    def close(self, *, abort: bool = False) -> None:
        transport, self.transport = self.transport, None
        self._drop_queued()
        self.server.client_closed(self)
        if transport is None:
            return
        if abort:
            transport.abort()
        else:
            transport.close()


class _ListProtocol(asyncio.DatagramProtocol):
    def __init__(self, server: EnipServer) -> None:
        self.server = server
        self.transport: asyncio.DatagramTransport | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = cast(asyncio.DatagramTransport, transport)

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        if self.server.down or self.transport is None:
            return
        try:
            pkt = EncapPacket.decode(data)
        except FramingError as exc:
            log.debug("malformed UDP encapsulation from %s: %s", addr[0], exc)
            return
        reply = self.server.handle_packet(pkt, None)
        if reply is not None:
            self.transport.sendto(reply.encode(), addr)


class _IoProtocol(asyncio.DatagramProtocol):
    def __init__(self, server: EnipServer) -> None:
        self.server = server

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        self.server.consume_datagram(data, addr)


# ---------------------------------------------------------------- the CLI's entry point
def parse_hosts(text: str) -> list[str]:
    """``"127.0.0.1,127.0.0.2"`` -> addresses (IPv4, no duplicates)."""
    hosts = [h.strip() for h in text.split(",") if h.strip()]
    if not hosts:
        raise ArgumentRangeError("at least one listen address is needed")
    for h in hosts:
        try:
            ipaddress.IPv4Address(h)
        except ValueError:
            raise ArgumentRangeError(f"{h!r} is not an IPv4 address") from None
    if len(set(hosts)) != len(hosts):
        raise ArgumentRangeError(f"duplicate listen addresses in {text!r}")
    return hosts


def _check_dyn5_record(key: str, rec: object) -> dict[str, Any]:
    try:
        ipaddress.IPv4Address(key)
    except ValueError:
        raise ValueError("the key must be the drive's IPv4 address") from None
    return check_drive_record(rec)


#: ``sim enip --state``: DMM drive records keyed by the drive's IPv4 address (decision; the
#: DYN2/DYN4 files key by power-on drive id, which a DYN5 on EtherNet/IP does not have).
DYN5_STATE = StateKind("drive records keyed by IPv4 address", _check_dyn5_record)


def make_drive(host: str, *, state: str | None = None, model: str | None = None
               ) -> VirtualDrive:
    """One drive per address; with ``state`` its EEPROM is kept under the address."""
    drive_id = int(host.rsplit(".", 1)[1]) % 64
    kwargs: dict[str, Any] = {} if model is None else {"model": model}
    eeprom = EepromStore(state, key=host, kind=DYN5_STATE) if state else None
    return VirtualDrive(drive_id, eeprom=eeprom, **kwargs)


@dataclass
class EnipFleet:
    """Started virtual DYN5s sharing one realtime clock (stop them with :meth:`stop`)."""

    servers: list[EnipServer]
    clock: RealtimeClock

    async def stop(self) -> None:
        for server in self.servers:
            await server.stop()
        await self.clock.stop()


async def start_fleet(hosts: str | Sequence[str] = "127.0.0.1", tcp_port: int = TCP_PORT,
                      udp_port: int = io.UDP_PORT, state: str | None = None, *,
                      model: str | None = None,
                      reset_downtime_s: float = dyn5.RESET_DOWNTIME_S) -> EnipFleet:
    """One started virtual DYN5 per address. With port 0 the first server picks a free port
    and every other address uses the same number (real drives all listen on 44818); the
    UDP I/O port is picked per address when ``udp_port`` is 0."""
    host_list = parse_hosts(hosts) if isinstance(hosts, str) else list(hosts)
    drives = [make_drive(h, state=state, model=model) for h in host_list]
    clock = RealtimeClock(drives)
    fleet = EnipFleet([], clock)
    try:
        for drive, host in zip(drives, host_list, strict=True):
            server = EnipServer(drive, host, tcp_port=tcp_port, udp_port=udp_port,
                                clock=clock, reset_downtime_s=reset_downtime_s)
            fleet.servers.append(await server.start())
            tcp_port = server.tcp_port
    except BaseException:
        await fleet.stop()
        raise
    clock.start()
    return fleet


async def serve(hosts: str | Sequence[str] = "127.0.0.1", tcp_port: int = TCP_PORT,
                     udp_port: int = io.UDP_PORT, state: str | None = None, *,
                     model: str | None = None, stop: asyncio.Event | None = None,
                     duration: float | None = None,
                     reset_downtime_s: float = dyn5.RESET_DOWNTIME_S,
                     on_ready: Callable[[list[EnipServer]], None] | None = None
                     ) -> list[EnipServer]:
    """Serve one virtual DYN5 per address until ``stop`` is set or ``duration`` passes.

    What ``servobus sim enip --listen HOSTS --tcp-port N --udp-port M --state FILE`` runs.
    ``on_ready`` gets the started servers (their bound ports) before serving begins."""
    fleet = await start_fleet(hosts, tcp_port, udp_port, state, model=model,
                              reset_downtime_s=reset_downtime_s)
    stop = stop or asyncio.Event()
    try:
        if on_ready is not None:
            on_ready(fleet.servers)
        if duration is not None:
            asyncio.get_running_loop().call_later(duration, stop.set)
        await stop.wait()
    finally:
        await fleet.stop()
    return fleet.servers


class BackgroundEnip:
    """Virtual DYN5 adapters on their own event loop thread: ``start()`` / ``stop()`` for
    blocking clients (pycomm3, raw sockets) and tests."""

    def __init__(self, hosts: str | Sequence[str] = "127.0.0.1", tcp_port: int = 0,
                 udp_port: int = 0, state: str | None = None, *,
                 reset_downtime_s: float = dyn5.RESET_DOWNTIME_S) -> None:
        self._args = (hosts, tcp_port, udp_port, state)
        self._downtime = reset_downtime_s
        self.servers: list[EnipServer] = []
        self._loop = asyncio.new_event_loop()
        self._stop: asyncio.Event | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None

    def start(self, timeout: float = 5.0) -> BackgroundEnip:
        self._thread = threading.Thread(target=self._run, name="enip-sim", daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout):
            raise TimeoutError("virtual DYN5 did not start")
        if self._error is not None:
            raise self._error
        return self

    def _run(self) -> None:
        asyncio.set_event_loop(self._loop)

        def ready(servers: list[EnipServer]) -> None:
            self.servers = servers
            self._ready.set()

        async def main() -> None:
            self._stop = asyncio.Event()
            await serve(*self._args, stop=self._stop, on_ready=ready,
                             reset_downtime_s=self._downtime)

        try:
            self._loop.run_until_complete(main())
        except BaseException as exc:  # reported to start()
            self._error = exc
            self._ready.set()
        finally:
            self._loop.close()

    def call(self, fn: Callable[[], Any], timeout: float = 5.0) -> Any:
        """Run ``fn`` on the server loop (e.g. to read drive state) and return its result."""
        async def wrapped() -> Any:
            return fn()

        return asyncio.run_coroutine_threadsafe(wrapped(), self._loop).result(timeout)

    def stop(self, timeout: float = 5.0) -> None:
        if self._stop is not None and not self._loop.is_closed():
            self._loop.call_soon_threadsafe(self._stop.set)
        if self._thread is not None:
            self._thread.join(timeout)

    def __enter__(self) -> BackgroundEnip:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
