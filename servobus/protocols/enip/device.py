"""The virtual DYN5 adapter: CIP requests and Class 1 frames onto one VirtualDrive. No I/O.

The server (``server.py``) moves bytes and keeps time; everything a DYN5 decides lives here:
the Message Router, the Identity, Parameter and Connection Manager objects, the I/O images,
the fieldbus-loss action and Reset.

Message Router decisions (manual 4.1: "any unsupported class, service, instance or
attribute returns 05"): every well-formed request the drive does not implement answers
general status 0x05, including Set on Identity, class-level Parameter requests, Parameter
attributes other than 1, instances above 255, Large_Forward_Open and the Assembly, TCP/IP
and Ethernet Link objects (the manual lists only Identity and Parameter). A request whose
path cannot be parsed, or is not class / instance [/ attribute], answers 0x04 (path
segment error). Get requests ignore surplus request data. Unconnected_Send (0x52) to the
Connection Manager is unwrapped when its route is port 1 link 0 (the drive itself; what a
PLC with "Enable Routing, slot 0" sends); other routes answer 0x01 with 0x0311 / 0x0312.

Fieldbus loss (a Class 1 watchdog expiring; the manual is silent). Decision: what a drive
on a lost fieldbus should do without surprising anyone on reconnect: in position/speed mode
it brakes to standstill at High Accel (a speed-0 command, as 0x0E = 0) and then disables
the servo (motor free, status b1); in torque mode the torque command goes to 0 and the servo
is disabled at once. The servo stays disabled until an enable arrives (0x0D = 0xAAAA or the
output image); any drive command written meanwhile cancels the pending disable.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

from servobus.errors import FramingError
from servobus.families.dmm import units as U
from servobus.families.dyn5 import params as dyn5
from servobus.families.dyn5.params import Identity
from servobus.protocols.enip.codec import connection_manager as cm
from servobus.protocols.enip.codec import identity as ident
from servobus.protocols.enip.codec import io
from servobus.protocols.enip.codec.cip import (
    ClassCode,
    GeneralStatus,
    MessageRouterRequest,
    MessageRouterResponse,
    RequestTarget,
    Service,
    error_response,
    request_target,
)
from servobus.protocols.enip.codec.cpf import SockaddrInfo
from servobus.protocols.enip.codec.epath import PortSegment
from servobus.protocols.enip.connections import (
    BACKPLANE_PORT,
    OWN_LINK,
    ConnectionTable,
    Consumed,
    IoConnection,
    Refused,
)
from servobus.protocols.enip.parameter_object import (
    Effect,
    ParameterObject,
    status_word,
    torque_readout,
)
from servobus.sim.dmm.drive import VirtualDrive

log = logging.getLogger("servobus.enip")

STOPPED_RPM = 1.0  # below this the fieldbus-loss stop is complete
STOP_MARGIN_S = 0.5  # ... or this long after the braking time the speed implies
_ERR = dyn5.ERROR_STATUS


@dataclass(frozen=True)
class Origin:
    """Who sent a request: the TCP peer's IP and, for Forward_Open, its T->O sockaddr."""

    ip: str
    sockaddr_t_o: SockaddrInfo | None = None
    now: float = 0.0


@dataclass(frozen=True)
class Outcome:
    response: MessageRouterResponse
    opened: IoConnection | None = None
    closed: IoConnection | None = None
    reset: bool = False


class Dyn5Adapter:
    def __init__(self, drive: VirtualDrive, *, identity: Identity = dyn5.IDENTITY) -> None:
        self.drive = drive
        self.identity = identity
        self.params = ParameterObject(drive)
        self.connections = ConnectionTable(identity)
        self.stop_deadline: float | None = None  # fieldbus-loss stop in progress

    # ---------------------------------------------------------------- explicit messages
    def handle(self, raw: bytes, origin: Origin) -> Outcome:
        """One Message Router request (the unconnected data item); never raises."""
        try:
            req = MessageRouterRequest.decode(raw)
            target = request_target(req.path)
        except FramingError as exc:
            log.info("malformed CIP request from %s: %s", origin.ip, exc)
            service = raw[0] if raw else 0
            return Outcome(error_response(service, GeneralStatus.PATH_SEGMENT_ERROR))
        return self.request(req, target, origin)

    def request(self, req: MessageRouterRequest, target: RequestTarget,
                origin: Origin) -> Outcome:
        if target.class_id == ClassCode.IDENTITY:
            return Outcome(self._identity(req, target))
        if target.class_id == ClassCode.PARAMETER:
            return self._parameter(req, target)
        if target.class_id == ClassCode.CONNECTION_MANAGER and target.instance == 1:
            return self._connection_manager(req, target, origin)
        return Outcome(error_response(req.service, _ERR))

    def _identity(self, req: MessageRouterRequest, t: RequestTarget) -> MessageRouterResponse:
        data: bytes | None = None
        if t.instance == 0:
            if req.service == Service.GET_ATTRIBUTES_ALL and t.attribute is None:
                data = ident.class_all_attributes()
            elif req.service == Service.GET_ATTRIBUTE_SINGLE and t.attribute is not None:
                data = ident.class_attribute(t.attribute)
        elif t.instance == 1:
            if req.service == Service.GET_ATTRIBUTES_ALL and t.attribute is None:
                data = ident.all_attributes(self.identity)
            elif req.service == Service.GET_ATTRIBUTE_SINGLE and t.attribute is not None:
                data = ident.instance_attribute(self.identity, t.attribute)
        if data is None:
            return error_response(req.service, _ERR)
        return MessageRouterResponse(req.service, data=data)

    def _parameter(self, req: MessageRouterRequest, t: RequestTarget) -> Outcome:
        if (not 1 <= t.instance <= dyn5.INSTANCE_MAX
                or t.attribute != dyn5.PARAMETER_ATTRIBUTE):
            return Outcome(error_response(req.service, _ERR))
        if req.service == Service.GET_ATTRIBUTE_SINGLE:
            return Outcome(MessageRouterResponse(req.service,
                                                 data=self.params.read_bytes(t.instance)))
        if req.service != Service.SET_ATTRIBUTE_SINGLE:
            return Outcome(error_response(req.service, _ERR))
        result = self.params.write(t.instance, req.data)
        if not result.ok:
            return Outcome(error_response(req.service, _ERR))
        if result.effect is not Effect.NONE:
            self.stop_deadline = None
        return Outcome(MessageRouterResponse(req.service), reset=result.effect is Effect.RESET)

    # ---------------------------------------------------------------- Connection Manager
    def _connection_manager(self, req: MessageRouterRequest, t: RequestTarget,
                            origin: Origin) -> Outcome:
        if t.attribute is not None:
            return Outcome(error_response(req.service, _ERR))
        if req.service == Service.FORWARD_OPEN:
            return self._forward_open(req, origin)
        if req.service == Service.FORWARD_CLOSE:
            return self._forward_close(req, origin)
        if req.service == Service.UNCONNECTED_SEND:
            return self._unconnected_send(req, origin)
        return Outcome(error_response(req.service, _ERR))

    def _failure(self, service: int, refused: Refused, triad: cm.Triad | None
                 ) -> MessageRouterResponse:
        data = cm.ConnectionFailure(triad).encode() if triad is not None else b""
        return MessageRouterResponse(service, GeneralStatus.CONNECTION_FAILURE,
                                     (int(refused.status), *refused.extra), data)

    def _forward_open(self, req: MessageRouterRequest, origin: Origin) -> Outcome:
        try:
            fo = cm.ForwardOpenRequest.decode(req.data)
        except FramingError:
            return Outcome(self._bad_connection_request(req, cm.FORWARD_OPEN_LAYOUT))
        sock = origin.sockaddr_t_o
        dest_ip = sock.address if sock is not None and sock.address != "0.0.0.0" else origin.ip
        dest = (dest_ip, sock.port if sock is not None else io.UDP_PORT)
        try:
            conn, reply = self.connections.open(fo, origin.ip, dest, origin.now)
        except Refused as refused:
            log.info("Forward_Open from %s refused: %s", origin.ip, refused)
            return Outcome(self._failure(req.service, refused, fo.triad))
        log.info("Forward_Open from %s: O->T 0x%08X T->O 0x%08X, RPI %.1f/%.1f ms, "
                 "T->O to %s:%d", origin.ip, conn.o_t_id, conn.t_o_id,
                 conn.o_t_rpi_us / 1e3, conn.t_o_rpi_us / 1e3, *dest)
        return Outcome(MessageRouterResponse(req.service, data=reply.encode()), opened=conn)

    def _forward_close(self, req: MessageRouterRequest, origin: Origin) -> Outcome:
        try:
            fc = cm.ForwardCloseRequest.decode(req.data)
        except FramingError:
            return Outcome(self._bad_connection_request(req, cm.FORWARD_CLOSE_LAYOUT))
        try:
            conn = self.connections.close(fc, origin.ip)
        except Refused as refused:
            log.info("Forward_Close from %s refused: %s", origin.ip, refused)
            return Outcome(self._failure(req.service, refused, fc.triad))
        log.info("Forward_Close from %s: connection 0x%08X closed", origin.ip, conn.o_t_id)
        reply = cm.ForwardCloseReply(fc.triad).encode()
        return Outcome(MessageRouterResponse(req.service, data=reply), closed=conn)

    def _bad_connection_request(self, req: MessageRouterRequest, layout: cm.Layout
                                ) -> MessageRouterResponse:
        """Data shorter / longer than its path size says: 0x13 / 0x15; a path that does not
        parse: 0x01 with 0x0315 (invalid segment in path)."""
        data = req.data
        triad = cm.peek_triad(data, layout.triad_offset)
        if triad is None or len(data) <= layout.size_offset:
            return error_response(req.service, GeneralStatus.NOT_ENOUGH_DATA)
        end = layout.path_offset + 2 * data[layout.size_offset]
        if end > len(data):
            return error_response(req.service, GeneralStatus.NOT_ENOUGH_DATA)
        if end < len(data):
            return error_response(req.service, GeneralStatus.TOO_MUCH_DATA)
        return self._failure(req.service, Refused(cm.ExtendedStatus.INVALID_SEGMENT_IN_PATH),
                             triad)

    def _unconnected_send(self, req: MessageRouterRequest, origin: Origin) -> Outcome:
        try:
            us = cm.UnconnectedSendRequest.decode(req.data)
        except FramingError:
            return Outcome(error_response(req.service, GeneralStatus.PATH_SEGMENT_ERROR))
        route = us.route
        if len(route) != 1 or not isinstance(route[0], PortSegment):
            return Outcome(error_response(req.service, GeneralStatus.PATH_SEGMENT_ERROR))
        port = route[0]
        if port.port != BACKPLANE_PORT or port.link != OWN_LINK:
            status = (cm.ExtendedStatus.PORT_NOT_AVAILABLE if port.port != BACKPLANE_PORT
                      else cm.ExtendedStatus.LINK_ADDRESS_NOT_VALID)
            return Outcome(MessageRouterResponse(req.service, GeneralStatus.CONNECTION_FAILURE,
                                                 (int(status),), bytes((1, 0))))
        if not us.message or us.message[0] == Service.UNCONNECTED_SEND:
            return Outcome(error_response(req.service, _ERR))
        return self.handle(us.message, origin)

    # ---------------------------------------------------------------- implicit I/O
    def input_values(self) -> tuple[int, int, int, int]:
        """Assembly 100 now: position, speed, torque, status (section 5)."""
        d = self.drive
        return (dyn5.wrap_position(d.position), round(d.speed_rpm), torque_readout(d),
                status_word(d))

    def input_image(self) -> io.InputImage:
        return io.InputImage(*self.input_values())

    def consume(self, frame: io.IoFrame, source_ip: str, now: float) -> Consumed | None:
        """An O->T frame: applies a new enable/disable word; None if it was not taken."""
        got = self.connections.consume(frame, source_ip, now)
        if got is not None and got.apply:
            self.stop_deadline = None
            if got.image.enable:
                self.drive.enable()
            else:
                self.drive.disable()
        return got

    # ---------------------------------------------------------------- fieldbus loss, reset
    def connection_lost(self, now: float) -> None:
        """A Class 1 connection timed out: the fieldbus-loss action (module docstring)."""
        d = self.drive
        if d.servo_free:
            self.stop_deadline = None
            return
        if self.params.torque_mode:
            d.torque_command(0.0)
            d.disable()
            return
        d.turn_const_speed(0)
        accel = U.profile_accel_rpm_s(d.get_param("max_accel"), d.get_param("gear_num"))
        self.stop_deadline = now + abs(d.speed_rpm) / accel + STOP_MARGIN_S
        self.poll_stop(now)

    def poll_stop(self, now: float) -> bool:
        """Finish a fieldbus-loss stop once the motor stands; True when none is pending."""
        if self.stop_deadline is None:
            return True
        if abs(self.drive.speed_rpm) < STOPPED_RPM or now >= self.stop_deadline:
            self.drive.disable()
            self.stop_deadline = None
            log.info("fieldbus loss: motor stopped, servo disabled")
            return True
        return False

    def reset(self) -> list[IoConnection]:
        """Reset (0x21): drive power cycle, RAM values lost; returns the dropped connections."""
        self.params.reset_drive()
        self.stop_deadline = None
        return self.connections.drop_all()
