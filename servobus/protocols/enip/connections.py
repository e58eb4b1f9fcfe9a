"""Class 1 connections of one DYN5 adapter: Forward_Open checks, Forward_Close matching,
O->T consumption, T->O sequence numbers, watchdog deadlines. No I/O: times are passed in.

The DYN5 has one I/O image (manual 5): an exclusive-owner connection consuming assembly 101
and producing assembly 100, point-to-point both ways, fixed sizes, cyclic, RPI >= 5 ms.
Checks, in order (each failure is general status 0x01 with this extended status):

1. the triad (connection serial, vendor, originator serial) of an open connection:
   0x0100 duplicate Forward_Open;
2. transport class 1 with the cyclic trigger, else 0x0103; timeout multiplier <= 7, else
   0x0133;
3. connection types: both null 0x0132 (null Forward_Open not supported), O->T not
   point-to-point 0x0123, T->O not point-to-point 0x0124; variable size 0x011F / 0x0120;
4. the connection path: an optional port segment to port 1 link 0 (the drive itself; other
   ports 0x0311, other links 0x0312), an optional electronic key (non-zero fields must match
   the Identity: 0x0114 vendor/product, 0x0115 device type, 0x0116 revision), network
   segments (ignored), class 0x04, optional configuration instance 0 (other instances
   0x0129; configuration data 0x0126), consumed point 101 (0x012A), produced point 100
   (0x012B); anything else 0x0315;
5. RPI: either direction below 5 ms: 0x0111 (RPI not supported);
6. sizes: O->T 10 bytes, T->O 18 (0x0127 / 0x0128 with the expected size as a second
   additional status word);
7. one exclusive owner at a time: 0x0106 ownership conflict.

Decisions: the O->T watchdog is O->T RPI x 4 x 2^multiplier; until the first O->T frame it
is at least 10 s (CIP's initial inactivity time). The T->O connection id is the one the
originator proposed (point-to-point: the consumer chooses), the O->T id is chosen here.
A Forward_Close matches on the triad and the originator's IP address (0x0107 otherwise);
a non-empty path must name the same connection points (0x0316 otherwise). O->T frames are
taken only from the originator's IP with a newer 32-bit sequence number; a frame with the
same 16-bit sequence count as the last one refreshes the watchdog but carries no new data.
Both T->O counters advance on every production (each frame is a fresh sample).
"""

from __future__ import annotations

import itertools
import random
from dataclasses import dataclass

from servobus.errors import FramingError
from servobus.families.dyn5 import params as dyn5
from servobus.families.dyn5.params import Identity
from servobus.protocols.enip.codec import io
from servobus.protocols.enip.codec.connection_manager import (
    ConnectionType,
    ExtendedStatus,
    ForwardCloseRequest,
    ForwardOpenReply,
    ForwardOpenRequest,
    NetworkParameters,
    TransportTrigger,
    Triad,
    watchdog_s,
)
from servobus.protocols.enip.codec.epath import (
    DataSegment,
    KeySegment,
    LogicalType,
    NetworkSegment,
    PortSegment,
    Segment,
)

INITIAL_WATCHDOG_S = 10.0
BACKPLANE_PORT = 1
OWN_LINK = b"\x00"
E = ExtendedStatus


@dataclass(frozen=True)
class ConnectionPoints:
    config: int | None
    consumed: int
    produced: int


class Refused(Exception):
    """A Forward_Open / Forward_Close check failed (internal control flow)."""

    def __init__(self, status: ExtendedStatus, *extra: int) -> None:
        super().__init__(f"{status.name} (0x{int(status):04X})")
        self.status = status
        self.extra = extra


@dataclass
class IoConnection:
    triad: Triad
    o_t_id: int
    t_o_id: int
    o_t_rpi_us: int
    t_o_rpi_us: int
    timeout_s: float
    originator_ip: str
    destination: tuple[str, int]  # where T->O frames go
    points: ConnectionPoints
    deadline: float
    produced_sequence: int = 0
    produced_count: int = 0
    consumed_sequence: int | None = None
    consumed_count: int | None = None
    last_command: int | None = None
    run: bool = False
    frames_in: int = 0
    frames_out: int = 0

    @property
    def t_o_rpi_s(self) -> float:
        return self.t_o_rpi_us / 1e6

    def next_production(self) -> tuple[int, int]:
        """Sequence number and sequence count of the next T->O frame."""
        self.produced_sequence = (self.produced_sequence + 1) & 0xFFFF_FFFF
        self.produced_count = (self.produced_count + 1) & 0xFFFF
        self.frames_out += 1
        return self.produced_sequence, self.produced_count


@dataclass(frozen=True)
class Consumed:
    connection: IoConnection
    image: io.OutputImage
    apply: bool  # a new, running frame whose command differs from the last one


def parse_points(path: tuple[Segment, ...], identity: Identity) -> ConnectionPoints:
    """Application path of a Forward_Open / Forward_Close (checks 4 in the docstring)."""
    config: int | None = None
    points: list[int] = []
    seen_class = False
    for seg in path:
        if isinstance(seg, PortSegment):
            if seen_class:
                raise Refused(E.INVALID_SEGMENT_IN_PATH)
            if seg.port != BACKPLANE_PORT:
                raise Refused(E.PORT_NOT_AVAILABLE)
            if seg.link != OWN_LINK:
                raise Refused(E.LINK_ADDRESS_NOT_VALID)
        elif isinstance(seg, KeySegment):
            _check_key(seg, identity)
        elif isinstance(seg, NetworkSegment):
            continue
        elif isinstance(seg, DataSegment):
            if seg.data:
                raise Refused(E.INVALID_CONFIGURATION_SIZE)
        elif seg.kind is LogicalType.CLASS and not seen_class:
            if seg.value != 0x04:
                raise Refused(E.INVALID_SEGMENT_IN_PATH)
            seen_class = True
        elif seg.kind is LogicalType.INSTANCE and seen_class and not points and config is None:
            config = seg.value
        elif seg.kind is LogicalType.CONNECTION_POINT and seen_class and len(points) < 2:
            points.append(seg.value)
        else:
            raise Refused(E.INVALID_SEGMENT_IN_PATH)
    if not seen_class or len(points) != 2:
        raise Refused(E.INVALID_SEGMENT_IN_PATH)
    if config not in (None, dyn5.CONFIG_ASSEMBLY):
        raise Refused(E.INVALID_CONFIGURATION_PATH)
    if points[0] != dyn5.OUTPUT_ASSEMBLY:
        raise Refused(E.INVALID_CONSUMING_PATH)
    if points[1] != dyn5.INPUT_ASSEMBLY:
        raise Refused(E.INVALID_PRODUCING_PATH)
    return ConnectionPoints(config, points[0], points[1])


def _check_key(key: KeySegment, identity: Identity) -> None:
    if ((key.vendor_id and key.vendor_id != identity.vendor_id)
            or (key.product_code and key.product_code != identity.product_code)):
        raise Refused(E.VENDOR_OR_PRODUCT_MISMATCH)
    if key.device_type and key.device_type != identity.device_type:
        raise Refused(E.DEVICE_TYPE_MISMATCH)
    major, minor = identity.revision
    if key.major_revision:
        if key.major_revision != major:
            raise Refused(E.REVISION_MISMATCH)
        if key.minor_revision and not (key.minor_revision <= minor if key.compatibility
                                       else key.minor_revision == minor):
            raise Refused(E.REVISION_MISMATCH)


def _application(points: ConnectionPoints) -> tuple[int, int]:
    return points.consumed, points.produced


class ConnectionTable:
    """The Class 1 connections of one adapter (at most one: the exclusive owner)."""

    def __init__(self, identity: Identity = dyn5.IDENTITY) -> None:
        self.identity = identity
        self.by_o_t_id: dict[int, IoConnection] = {}
        self._ids = itertools.count(random.getrandbits(30) + 1)

    def __len__(self) -> int:
        return len(self.by_o_t_id)

    def connections(self) -> list[IoConnection]:
        return list(self.by_o_t_id.values())

    def find(self, triad: Triad) -> IoConnection | None:
        return next((c for c in self.by_o_t_id.values() if c.triad == triad), None)

    # ---------------------------------------------------------------- Forward_Open
    def check_open(self, req: ForwardOpenRequest) -> ConnectionPoints:
        """Run checks 1-7; raises Refused."""
        if self.find(req.triad) is not None:
            raise Refused(E.DUPLICATE_FORWARD_OPEN)
        transport = TransportTrigger.from_byte(req.transport)
        if transport.transport_class != 1 or transport.trigger != 0:
            raise Refused(E.TRANSPORT_NOT_SUPPORTED)
        if req.timeout_multiplier > 7:
            raise Refused(E.TIMEOUT_MULTIPLIER_NOT_ACCEPTABLE)
        ot = NetworkParameters.from_word(req.o_t_params)
        to = NetworkParameters.from_word(req.t_o_params)
        p2p = ConnectionType.POINT_TO_POINT
        if ot.connection_type == ConnectionType.NULL and to.connection_type == ConnectionType.NULL:
            raise Refused(E.NULL_FORWARD_OPEN_NOT_SUPPORTED)
        if ot.connection_type != p2p:
            raise Refused(E.INVALID_O_T_CONNECTION_TYPE)
        if to.connection_type != p2p:
            raise Refused(E.INVALID_T_O_CONNECTION_TYPE)
        if ot.variable:
            raise Refused(E.INVALID_O_T_FIXED_VARIABLE)
        if to.variable:
            raise Refused(E.INVALID_T_O_FIXED_VARIABLE)
        points = parse_points(req.path, self.identity)
        if min(req.o_t_rpi_us, req.t_o_rpi_us) < dyn5.MIN_RPI_US:
            raise Refused(E.RPI_NOT_SUPPORTED)
        if ot.size != io.O_T_CONNECTION_SIZE:
            raise Refused(E.INVALID_O_T_SIZE, io.O_T_CONNECTION_SIZE)
        if to.size != io.T_O_CONNECTION_SIZE:
            raise Refused(E.INVALID_T_O_SIZE, io.T_O_CONNECTION_SIZE)
        if self.by_o_t_id:
            raise Refused(E.OWNERSHIP_CONFLICT)
        return points

    def open(self, req: ForwardOpenRequest, originator_ip: str,
             destination: tuple[str, int], now: float) -> tuple[IoConnection, ForwardOpenReply]:
        """Check and open; raises Refused."""
        points = self.check_open(req)
        o_t_id = next(self._ids) & 0xFFFF_FFFF
        timeout = watchdog_s(req.o_t_rpi_us, req.timeout_multiplier)
        conn = IoConnection(req.triad, o_t_id, req.t_o_connection_id, req.o_t_rpi_us,
                            req.t_o_rpi_us, timeout, originator_ip, destination, points,
                            deadline=now + max(timeout, INITIAL_WATCHDOG_S))
        self.by_o_t_id[o_t_id] = conn
        reply = ForwardOpenReply(o_t_id, conn.t_o_id, req.triad, req.o_t_rpi_us,
                                 req.t_o_rpi_us)
        return conn, reply

    # ---------------------------------------------------------------- Forward_Close
    def close(self, req: ForwardCloseRequest, originator_ip: str) -> IoConnection:
        """Find, check and remove; raises Refused."""
        conn = self.find(req.triad)
        if conn is None or conn.originator_ip != originator_ip:
            raise Refused(E.CONNECTION_NOT_FOUND)
        if req.path:
            try:
                points = parse_points(req.path, self.identity)
            except Refused:
                raise Refused(E.FORWARD_CLOSE_PATH_MISMATCH) from None
            if _application(points) != _application(conn.points):
                raise Refused(E.FORWARD_CLOSE_PATH_MISMATCH)
        return self.remove(conn)

    def remove(self, conn: IoConnection) -> IoConnection:
        self.by_o_t_id.pop(conn.o_t_id, None)
        return conn

    def drop_all(self) -> list[IoConnection]:
        dropped = list(self.by_o_t_id.values())
        self.by_o_t_id.clear()
        return dropped

    # ---------------------------------------------------------------- I/O
    def consume(self, frame: io.IoFrame, source_ip: str, now: float) -> Consumed | None:
        """An O->T frame; None when it is not for an open connection or not newer."""
        conn = self.by_o_t_id.get(frame.connection_id)
        if conn is None or conn.originator_ip != source_ip:
            return None
        if conn.consumed_sequence is not None and not io.seq32_newer(
                frame.sequence, conn.consumed_sequence):
            return None
        try:
            image = io.OutputImage.decode(frame.payload)
        except FramingError:
            return None
        conn.consumed_sequence = frame.sequence
        conn.deadline = now + conn.timeout_s
        conn.frames_in += 1
        fresh = conn.consumed_count is None or frame.count != conn.consumed_count
        conn.consumed_count = frame.count
        conn.run = image.run
        apply = False
        if fresh and image.run:
            apply = image.enable is not None and image.command != conn.last_command
            conn.last_command = image.command
        return Consumed(conn, image, apply)

    def expired(self, now: float) -> list[IoConnection]:
        """Remove and return every connection whose watchdog has run out."""
        gone = [c for c in self.by_o_t_id.values() if c.deadline <= now]
        for conn in gone:
            self.remove(conn)
        return gone
