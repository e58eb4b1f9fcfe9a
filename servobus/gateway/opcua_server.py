"""The gateway's OPC UA server (asyncua): security, users, values, alarm and link events.

Security (decision, docs/gateway.md "Security"):

* on a loopback address the endpoint offers security policy None (and the Sign&Encrypt
  policies as well when a certificate is given); anonymous sessions may browse, read
  and subscribe, nothing else;
* beyond loopback, policy None is refused: only Sign&Encrypt is served (Basic256Sha256,
  Aes128_Sha256_RsaOaep, Aes256_Sha256_RsaPss), with the given certificate or one generated
  on first start and kept next to the machine file (``<machine>.opcua-cert.der`` /
  ``.opcua-key.pem``; for the built-in machine in ``~/.config/servobus/``), its SAN naming
  the ApplicationUri, host names and addresses served (servobus.gateway.opcua_cert);
* every method (anything that moves, stops or powers an axis) needs a user of the users
  file (``--users``), on loopback too; without one it answers BadUserAccessDenied. The
  address space itself cannot be changed by any client (no writable node, no AddNodes).

Who calls (decision): asyncua tells a method callback nothing about the session. The
gateway's internal server (:class:`GatewayServer`, handed to asyncua's ``Server``) makes
every client session a :class:`GatewaySession`, which names itself to the method callbacks
of its Call requests (a context variable, set in the same task) and, when it closes, lets
go of the leases it holds. A session closes on CloseSession, on a lost connection (asyncua
keeps a session with subscriptions open for the client to come back, until the session
timeout) and on its timeout; a half-open connection closes nothing, so a SetSpeed's own
``Ttl`` (at most 1 s) is what ends the motion of a client that went silent.

Recovery (issue 29, decision, docs/gateway.md "Recovery"): while an axis cannot be read its
readings carry a Bad status and, as SourceTimestamp, the time they were last good (the
machine axis's ``last_good``), with no value (OPC UA: a Bad value is to be ignored, Part 4
7.7.1); they are Good again with the next good read, the server never restarts. Offline:
BadCommunicationError, or BadNoCommunication while the axis was never read. The link's
health variables stay Good. A link going down or back is one LinkEventType event emitted
by the machine object.
"""

from __future__ import annotations

import asyncio
import contextlib
import contextvars
import datetime
import logging
import math
from collections import deque
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import urlparse

from asyncua import Server, ua
from asyncua.common.connection import TransportLimits
from asyncua.crypto.permission_rules import User, UserRole
from asyncua.server.internal_server import InternalServer
from asyncua.server.internal_session import InternalSession, SessionState
from asyncua.server.user_managers import UserManager

from servobus import __version__
from servobus.errors import InvalidValue
from servobus.gateway.commands import Command, Commander, Refused
from servobus.gateway.identity import application_uri, gateway_id
from servobus.gateway.link_events import LinkEvent
from servobus.gateway.opcua_alarms import AxisAlarms
from servobus.gateway.opcua_cache import load_standard
from servobus.gateway.opcua_cert import ensure_certificate
from servobus.gateway.opcua_limits import LimitedSession, SessionRoom, apply_limits
from servobus.gateway.opcua_model import SERVOBUS_URI, AxisNodes, build_model
from servobus.gateway.sampler import Sample
from servobus.gateway.source import Machine
from servobus.gateway.users import Admission, LoginBudget, Users
from servobus.transport.address import is_loopback

log = logging.getLogger(__name__)

DEFAULT_ENDPOINT = "opc.tcp://127.0.0.1:4840"
PRODUCT_URI = "urn:servobus"
#: Sign&Encrypt only (decision, docs/gateway.md "Security"): Basic256Sha256 and the two Aes
#: policies of OPC UA 1.04 that current clients prefer.
SECURE_POLICIES = (ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt,
                   ua.SecurityPolicyType.Aes128Sha256RsaOaep_SignAndEncrypt,
                   ua.SecurityPolicyType.Aes256Sha256RsaPss_SignAndEncrypt)


def build_date() -> datetime.datetime:
    """BuildInfo's BuildDate: servobus records no build time, so the time its installed
    package was written (docs/gateway.md "Identity")."""
    import servobus

    return datetime.datetime.fromtimestamp(Path(servobus.__file__).stat().st_mtime,
                                           datetime.UTC)
#: Bounds (decision): no request to this model needs more than a few hundred kB; a session
#: that is not activated within 10 s is dropped; at most 200 subscriptions in all.
MAX_MESSAGE_BYTES = 4 * 1024 * 1024
BUFFER_BYTES = 65_535
PENDING_ACTIVATION_S = 10.0
MAX_SUBSCRIPTIONS = 200
MAX_ITEM_QUEUE = 1_000
#: Link events waiting for the update task (bounded: a link flapping faster than the
#: events go out loses its oldest ones, never the memory).
MAX_PENDING_LINK_EVENTS = 100
_caller: contextvars.ContextVar[GatewaySession | None] = contextvars.ContextVar(
    "opcua_caller", default=None)
#: The address of the client whose session asyncua is activating ("" when unknown).
_login_peer: contextvars.ContextVar[str] = contextvars.ContextVar("opcua_login_peer",
                                                                  default="")
ADMIN_REQUESTS = {ua.NodeId(i) for i in (
    ua.ObjectIds.AddNodesRequest_Encoding_DefaultBinary,
    ua.ObjectIds.DeleteNodesRequest_Encoding_DefaultBinary,
    ua.ObjectIds.AddReferencesRequest_Encoding_DefaultBinary,
    ua.ObjectIds.DeleteReferencesRequest_Encoding_DefaultBinary,
    ua.ObjectIds.RegisterServerRequest_Encoding_DefaultBinary,
    ua.ObjectIds.RegisterServer2Request_Encoding_DefaultBinary,
)}


class GatewayRules:
    """asyncua permission ruleset: no client changes the address space."""

    def check_validity(self, user: User, action_type_id: ua.NodeId, body: Any) -> bool:
        return action_type_id not in ADMIN_REQUESTS


SessionGone = Callable[[str], Awaitable[None]]


class GatewaySession(LimitedSession):
    """A client's session: the owner of the leases its SetSpeed calls hold, with the caps
    on its subscriptions and monitored items (servobus.gateway.opcua_limits)."""

    on_close: SessionGone | None = None
    _owner: str | None = None

    @property
    def owner(self) -> str:
        """Fixed at the first call: the session's number and its user."""
        if self._owner is None:
            who = self.user.name if self.user.role == UserRole.User else "anonymous"
            self._owner = f"opcua session {self.session_id.Identifier} ({who})"
        return self._owner

    async def call(self, params: list[ua.CallMethodRequest]) -> list[ua.CallMethodResult]:
        _caller.set(self)
        results: list[ua.CallMethodResult] = await super().call(params)
        return results

    def activate_session(self, params: ua.ActivateSessionParameters,
                         peer_certificate: bytes | None) -> ua.ActivateSessionResult:
        """asyncua's activation, which calls the user manager's ``get_user`` synchronously,
        with the client's address in :data:`_login_peer` (FileUsers reads it there).

        The address (decision): asyncua names an external session after its connection's
        peer (``transport.get_extra_info("peername")``); a client that re-activates its
        session over a new connection (OPC UA reconnect) counts against the address it
        created the session from, which needs that session's secret token.
        """
        token = _login_peer.set(peer_host(self.name))
        try:
            result: ua.ActivateSessionResult = super().activate_session(params,
                                                                         peer_certificate)
            return result
        finally:
            _login_peer.reset(token)

    async def close_session(self, delete_subs: bool = True) -> None:
        closed = self.state == SessionState.Closed
        await super().close_session(delete_subs)
        if not closed and self._owner is not None and self.on_close is not None:
            await self.on_close(self._owner)


class GatewayServer(InternalServer):  # type: ignore[misc]
    """asyncua's internal server whose client sessions are GatewaySessions."""

    def __init__(self, user_manager: UserManager, on_close: SessionGone) -> None:
        super().__init__(user_manager=user_manager)
        self.bind_condition_methods = True  # ConditionRefresh for the axes' alarms
        self.on_session_close = on_close
        self.session_room = SessionRoom()
        #: True when the last start loaded the standard nodes from the cache
        self.standard_from_cache = False

    async def load_standard_address_space(self, shelf_file: Path | None = None) -> None:
        """asyncua's standard nodes, from the user's cache when it holds them
        (servobus.gateway.opcua_cache); asyncua's shelf option is not used."""
        build = super().load_standard_address_space
        self.standard_from_cache = await load_standard(self, build)

    def create_session(self, name: str, user: User | None = None,
                       external: bool = False) -> InternalSession:
        if external:  # MaxSessions, in all and per client address
            self.session_room.check(self._external_sessions.values(), name, peer_host)
        session = GatewaySession(self, self.aspace, self.subscription_service, name,
                                 user=User(role=UserRole.Anonymous) if user is None else user,
                                 external=external)
        session.on_close = self.on_session_close
        return session


class FileUsers(UserManager):  # type: ignore[misc]
    """Anonymous sessions are read-only users; a name and password must be in the file.

    asyncua calls :meth:`get_user` on the event loop and waits for it, so each password check
    (a scrypt hash) stalls the loop: ``budget`` refuses logins beyond its rates unhashed, per
    peer address and in all (servobus.gateway.users.LoginBudget). asyncua passes get_user no
    session and no address: the peer is the one :class:`GatewaySession` sets around it."""

    def __init__(self, users: Users, budget: LoginBudget | None = None) -> None:
        self.users = users
        self.budget = LoginBudget() if budget is None else budget

    def get_user(self, iserver: Any, username: str | None = None, password: str | None = None,
                 certificate: Any = None) -> User | None:
        if username is None:  # certificate tokens are not offered: anonymous
            return User(role=UserRole.Anonymous)
        peer = _login_peer.get()
        admission = self.budget.take(peer)
        if admission is not Admission.CHECK:
            if self.budget.announce:  # one line per spell, not one per try
                log.warning("OPC UA logins from %s refused unchecked (user %r): %s",
                            peer or "an unknown address", username,
                            _SPENT[admission].format(b=self.budget))
            return None
        if self.users.verify(username, password):
            self.budget.refund(peer)
            return User(role=UserRole.User, name=username)
        log.warning("OPC UA login refused for user %r from %s: wrong name or password",
                    username, peer or "an unknown address")
        return None


_SPENT = {
    Admission.PEER_SPENT: "more than {b.peer_burst} wrong passwords from this address "
                          "(then one every {b.peer_interval_s:g} s)",
    Admission.ALL_SPENT: "more than {b.per_second:g} password checks a second in all",
}


def peer_host(name: object) -> str:
    """The host of asyncua's peer name (the socket's ``peername``: (host, port, ...)), or
    ""."""
    if isinstance(name, tuple | list) and name and isinstance(name[0], str):
        return name[0]
    return ""


def parse_endpoint(url: str) -> tuple[str, int]:
    parsed = urlparse(url)
    if parsed.scheme != "opc.tcp" or not parsed.hostname:
        raise InvalidValue(f"{url!r}: give the endpoint as opc.tcp://HOST:PORT")
    try:
        port = parsed.port if parsed.port is not None else 4840
    except ValueError:
        raise InvalidValue(f"{url!r}: the port must be 0..65535") from None
    return parsed.hostname, port


@dataclass(frozen=True)
class OpcUaOptions:
    endpoint: str = DEFAULT_ENDPOINT
    users: Users | None = None
    cert: Path | None = None  # DER certificate; generated next to ``cert_dir`` when missing
    key: Path | None = None
    cert_dir: Path | None = None
    cert_stem: str = "servobus"
    gateway_id: str | None = None  # None: the machine's name (servobus.gateway.identity)


def _status(code: str) -> ua.StatusCode:
    return ua.StatusCode(getattr(ua.StatusCodes, code, ua.StatusCodes.BadInternalError))


class OpcUaGateway:
    """Build, serve and update the address space of one machine."""

    def __init__(self, machine: Machine, commander: Commander, options: OpcUaOptions,
                 source: str = "", rate_hz: float | None = None) -> None:
        self.machine = machine
        self.commander = commander
        self.options = options
        self.source = source
        self.host, self.port = parse_endpoint(options.endpoint)
        self.gateway_id = gateway_id(machine.name, options.gateway_id)
        self.application_uri = application_uri(self.gateway_id)
        self.loopback = is_loopback(self.host)
        self.server = Server(iserver=GatewayServer(FileUsers(options.users or Users()),
                                                   self._session_closed))
        self.axes: dict[str, AxisNodes] = {}
        self.device: Any = None  # the machine's object: it emits the link events
        self._pending: dict[str, Sample] = {}
        self._links: deque[LinkEvent] = deque(maxlen=MAX_PENDING_LINK_EVENTS)
        self._wake = asyncio.Event()
        self._last: dict[tuple[str, str], tuple[object, ...]] = {}
        #: the readings' MinimumSamplingInterval: the sampler's period per link (a slow
        #: link's rounds take longer; none is sampled faster)
        self.sampling_ms = 1000.0 / rate_hz if rate_hz else 0.0
        self.alarms = AxisAlarms(self.server, self._acknowledge)
        self._health: dict[str, tuple[object, ...]] = {}
        self._link_event: Any = None
        self.notifications = 0  # value writes that changed something (for the benchmark)

    @property
    def endpoint(self) -> str:
        host = self.host if ":" not in self.host else f"[{self.host}]"
        return f"opc.tcp://{host}:{self.port}"

    async def start(self) -> None:
        s = self.server
        await s.init()
        s.limits = TransportLimits(max_recv_buffer=BUFFER_BYTES, max_send_buffer=BUFFER_BYTES,
                                   max_chunk_count=MAX_MESSAGE_BYTES // BUFFER_BYTES + 1,
                                   max_message_size=MAX_MESSAGE_BYTES)
        s.iserver.max_pending_activation_seconds = PENDING_ACTIVATION_S
        s.iserver.max_subscriptions = MAX_SUBSCRIPTIONS
        s.iserver.max_monitored_item_queue_size = MAX_ITEM_QUEUE
        await apply_limits(s)
        s.set_endpoint(f"opc.tcp://{self.host}:{self.port}")
        s.set_server_name(f"servobus gateway {self.machine.name}")
        await s.set_build_info(PRODUCT_URI, "servobus", "servobus gateway", __version__,
                               __version__, build_date())
        await s.set_application_uri(self.application_uri)
        s.set_identity_tokens([ua.AnonymousIdentityToken, ua.UserNameIdentityToken])
        policies = await self._security()
        s.set_security_policy(policies, permission_ruleset=GatewayRules())
        self.device, self.axes = await build_model(s, self.machine, self.source, self._call,
                                                   self.application_uri, self.sampling_ms)
        waiting = ua.DataValue(StatusCode=ua.StatusCode(ua.StatusCodes.BadWaitingForInitialData))
        for nodes in self.axes.values():  # until the first sample of the axis
            for node in (*nodes.variables.values(), *nodes.health.values()):
                await s.write_attribute_value(node.nodeid, waiting)
        await self.alarms.build(await s.get_namespace_index(SERVOBUS_URI),
                                await s.get_namespace_index(self.application_uri),
                                {name: nodes.node for name, nodes in self.axes.items()})
        await self._link_events()
        await s.start()
        if s.bserver is not None:
            self.port = s.bserver.port

    async def _security(self) -> list[ua.SecurityPolicyType]:
        o = self.options
        if self.loopback and o.cert is None:
            return [ua.SecurityPolicyType.NoSecurity]
        cert, key = o.cert, o.key
        if cert is None or key is None:
            folder = o.cert_dir or Path.home() / ".config" / "servobus"
            folder.mkdir(parents=True, exist_ok=True)
            cert = folder / f"{o.cert_stem}.opcua-cert.der"
            key = folder / f"{o.cert_stem}.opcua-key.pem"
            # both 0600 as docs/gateway.md says: the key is the secret; the certificate is
            # public, but nobody else on the PC needs it either (issue 32); its SAN names
            # what is served (servobus.gateway.opcua_cert)
            await asyncio.to_thread(ensure_certificate, key, cert, self.application_uri,
                                    self.host)
        await self.server.load_certificate(str(cert))
        await self.server.load_private_key(str(key))
        self.cert_path = cert
        if self.loopback:
            return [ua.SecurityPolicyType.NoSecurity, *SECURE_POLICIES]
        return list(SECURE_POLICIES)

    async def _link_events(self) -> None:
        s = self.server
        ns = await s.get_namespace_index(SERVOBUS_URI)
        etype = await s.create_custom_event_type(
            ns, "LinkEventType", ua.ObjectIds.BaseEventType,
            [("LinkUrl", ua.VariantType.String), ("AxisNames", ua.VariantType.String),
             ("Online", ua.VariantType.Boolean), ("Reason", ua.VariantType.String),
             ("PowerLost", ua.VariantType.String)])
        self._link_event = await s.get_event_generator(etype, self.device)

    async def stop(self) -> None:
        # asyncua's stop waits for its clock task's 1 s sleep; end that task first
        clock = getattr(self.server.iserver, "time_task", None)
        if clock is not None:
            clock.cancel()
            with contextlib.suppress(BaseException):
                await clock
            self.server.iserver.time_task = None
        await self.server.stop()

    # ---------------------------------------------------------------- methods
    async def _call(self, axis: str, command: str, arguments: tuple[float, ...]
                    ) -> ua.StatusCode:
        """A method call in its own error boundary: an unexpected error is BadInternalError
        and one log line; the server goes on."""
        try:
            return await self._run_call(axis, command, arguments)
        except Exception as exc:
            log.error("opcua: %s %s on axis %r failed unexpectedly: %s: %s", command,
                      arguments, axis, type(exc).__name__, exc)
            return ua.StatusCode(ua.StatusCodes.BadInternalError)

    async def _run_call(self, axis: str, command: str, arguments: tuple[float, ...]
                        ) -> ua.StatusCode:
        session = _caller.get()
        user = session.user if session is not None else None
        name = user.name if user is not None and user.role == UserRole.User else None
        value, ttl = (*arguments, None, None)[:2]
        owner = session.owner if session is not None else None
        try:
            await self.commander.run(name, Command(axis, command, value, ttl), "opcua", owner)
        except Refused as exc:
            return _status(exc.code)
        return ua.StatusCode(ua.StatusCodes.Good)

    async def _acknowledge(self, axis: str) -> ua.StatusCode:
        """A condition's Acknowledge: the axis's Acknowledge method's path."""
        return await self._call(axis, "ack", ())

    async def _session_closed(self, owner: str) -> None:
        await self.commander.release(owner, "opcua")

    # ---------------------------------------------------------------- values
    def on_sample(self, sample: Sample) -> None:
        """Sampler listener: the newest sample per axis waits for :meth:`run_updates`."""
        self._pending[sample.axis] = sample
        self._wake.set()

    def on_link(self, event: LinkEvent) -> None:
        """Sampler link listener: the event waits for :meth:`run_updates` (after the values
        of the same round)."""
        self._links.append(event)
        self._wake.set()

    async def run_updates(self) -> None:
        while True:
            await self._wake.wait()
            self._wake.clear()
            pending, self._pending = self._pending, {}
            for sample in pending.values():
                try:
                    await self._apply(sample)
                except Exception:  # one bad update must not end the updates
                    log.exception("OPC UA update of axis %s failed", sample.axis)
            while self._links:
                event = self._links.popleft()
                try:
                    await self._raise_link_event(event)
                except Exception:
                    log.exception("OPC UA event of link %s failed", event.url)

    async def _apply(self, sample: Sample) -> None:
        nodes = self.axes.get(sample.axis)
        if nodes is None:
            return
        st = sample.status
        values: dict[str, object] = {
            "ActualPosition": sample.position, "ActualSpeed": sample.speed,
            "ActualCurrent": math.nan if sample.current is None else sample.current,
        }
        if st is not None:
            values.update(Enabled=st.enabled, Moving=st.moving, InPosition=st.in_position,
                          AlarmCode=st.alarm_code, AlarmText=st.alarm_text)
        for name, node in nodes.variables.items():
            if name in values or not sample.ok:
                await self._write((sample.axis, name), node, values.get(name), sample)
        await self._apply_health(nodes, sample)
        if sample.ok and st is not None:
            message = await self.alarms.update(sample.axis, st.alarm_code, st.alarm_text)
            if message is not None:
                log.warning("%s", message)

    async def _write(self, key: tuple[str, str], node: Any, value: object, sample: Sample
                     ) -> None:
        """A reading, written when its value or its status changed; ``key`` (axis,
        variable) names the node cheaply (hashing asyncua's NodeId per value and sample cost
        more). Bad: no value, the status the sample names, and the time the axis was last
        good as SourceTimestamp (none while it never was)."""
        last_good = sample.health.last_good
        state = (True, value) if sample.ok else (False, sample.code, last_good)
        if self._last.get(key) == state:
            return
        self._last[key] = state
        if sample.ok:
            dv = WrittenValue(ua.Variant(value, _variant_type(value)),
                              SourceTimestamp=_utc(sample.time))
        else:
            dv = WrittenValue(StatusCode=_status(sample.code),
                              SourceTimestamp=None if last_good is None else _utc(last_good))
        self.notifications += 1
        await self.server.write_attribute_value(node.nodeid, dv)

    async def _apply_health(self, nodes: AxisNodes, sample: Sample) -> None:
        """The health variables: always Good, each written when it changed (most samples
        change none: one comparison). ``last_good`` changes with every good read and is
        not among them: a Bad reading's SourceTimestamp carries it."""
        h = sample.health
        error = "" if sample.ok else sample.error
        key = (h.online, h.power_lost, h.power_lost_reason, h.interrupted, error)
        if self._health.get(sample.axis) == key:
            return
        self._health[sample.axis] = key
        health: dict[str, object] = {
            "Online": h.online, "LastError": error, "PowerLost": h.power_lost,
            "PowerLostReason": h.power_lost_reason or "", "Interrupted": h.interrupted or "",
        }
        for name, node in nodes.health.items():
            value = health[name]
            if self._last.get((sample.axis, name)) == (value,):
                continue
            self._last[(sample.axis, name)] = (value,)
            self.notifications += 1
            await self.server.write_attribute_value(node.nodeid, WrittenValue(
                ua.Variant(value, _variant_type(value)), SourceTimestamp=_utc(sample.time)))

    async def _raise_link_event(self, event: LinkEvent) -> None:
        """One event per link change; the machine's own log line is its line."""
        gen = self._link_event
        gen.event.LinkUrl = event.url
        gen.event.AxisNames = ", ".join(event.axes)
        gen.event.Online = event.online
        gen.event.Reason = event.reason
        gen.event.PowerLost = ", ".join(event.power_lost)
        gen.event.Severity = 100 if event.online and not event.power_lost else \
            500 if event.online else 700
        gen.event.Message = ua.LocalizedText(event.message)
        await gen.trigger(time_attr=_utc(event.time))


class WrittenValue(ua.DataValue):  # type: ignore[misc]
    """A DataValue the gateway writes and never changes afterwards, so a deep copy of it is
    itself. asyncua deep-copies every value a monitored item is given (against later changes
    to the written object); for a sample's DataValue that copy cost many times building it
    (70 - 94 us against 5 us at load averages of 16 - 17, per subscribed variable and
    sample: benchmarks plant --profile; under 1 us as its own copy). Decision: the gateway
    builds a fresh value for every write (never one of asyncua's, never a shared Variant),
    which is what makes sharing it safe."""

    __slots__ = ()

    def __deepcopy__(self, memo: dict[int, object]) -> WrittenValue:
        return self


def _variant_type(value: object) -> ua.VariantType:
    if isinstance(value, bool):
        return ua.VariantType.Boolean
    if isinstance(value, int):
        return ua.VariantType.Int32
    if isinstance(value, str):
        return ua.VariantType.String
    return ua.VariantType.Double


def _utc(t: float) -> datetime.datetime:
    return datetime.datetime.fromtimestamp(t, datetime.UTC)
