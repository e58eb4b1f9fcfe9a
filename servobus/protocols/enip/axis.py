"""EnipAxis: the vendor-neutral Axis of one DYN5 over EtherNet/IP explicit messaging.

Units (docs/axis.md): positions in encoder counts (65,536 per revolution), speed in rpm,
current in amperes. Every call is a Get/Set_Attribute_Single on the Parameter object
(class 0x0F, attribute 1) through :class:`AsyncEnipClient`; the instance table is
``servobus.families.dyn5.params`` and the Axis view of it ``servobus.families.dyn5.family``.

* Moves: counts -> command units through GEAR_NUM (read once, then tracked through this
  axis's own writes; forgotten at Reset and origin, which reload RAM), written to 0x15 /
  0x17. A Set reply only says the module took the value (manual 4.1, 7: effective within
  300 us); motion is seen in the status word. Never re-sent.
* Current: 0x1F counts 2000 = 100 % of the drive's peak current, positive = CCW (4.4); the
  Axis gives amperes positive towards increasing position (CW), so the sign flips. The
  peak current is not readable over EtherNet/IP: ``peak_current_a`` (default 20 A, the
  DYN5-H01 of the manual's 4.4 example) scales it.
* Ids: a DYN5 has no drive id; it is addressed by its IP address, and the drives of one
  daisy chain share B3.B2.B1 (manual 2). Decision: the Axis's ``drive_id`` is B0, the last
  octet; ``sibling(n)`` opens its own session to B3.B2.B1.n on the same TCP port;
  ``drive_ids`` is 1..253 (the manual asks to avoid 0, 254 and 255); ``assign_id`` is
  NotSupported (the address is set in DMMDRV5, 3.1). A sibling connects on first use; a
  drive that does not accept the connection is a DriveTimeout (an absent drive).
* Reset (0x21 = 0xABCD): the adapter answers, then drops every session and is down for
  about 3 s (4.4). ``reset()`` reconnects until the adapter answers a status read again,
  within ``reset_timeout`` (default 15 s). The manual asks for 10 s before new commands
  after a Reset; a real drive may need that wait (``await asyncio.sleep``) before motion.
* Torque mode (0x25/0x26/0x27) and cyclic I/O (``io()``, section 5) are DYN5 extras.
"""

from __future__ import annotations

import asyncio
import ipaddress
import logging
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

from servobus.axis import checks
from servobus.axis.base import DEFAULT_WAIT_TIMEOUT_S, AsyncAxis, AxisTraceHook, check_int
from servobus.errors import (
    ArgumentRangeError,
    ConnectionLost,
    DriveError,
    DriveTimeout,
    FramingError,
    NotSupported,
    ProtocolError,
)
from servobus.families.base import AxisStatus, Family, ParamInfo, StreamProfile
from servobus.families.dmm import units as U
from servobus.families.dmm.family import command_to_counts, counts_to_command
from servobus.families.dyn5 import params as dyn5
from servobus.families.dyn5.family import DYN5, PARAM_INSTANCES, Dyn5Status, axis_status
from servobus.families.dyn5.params import Instance
from servobus.link.transaction import DEFAULT_RETRIES
from servobus.protocols.enip.client import CONNECT_TIMEOUT_S, DEFAULT_TIMEOUT_S, AsyncEnipClient
from servobus.protocols.enip.codec.cip import ClassCode
from servobus.protocols.enip.codec.encap import TCP_PORT
from servobus.protocols.enip.codec.identity import IdentityReply

if TYPE_CHECKING:
    from servobus.protocols.enip.scanner import CyclicIo, InputFrame

log = logging.getLogger("servobus.enip")

PROTOCOL = "enip"
#: DYN5-H01 peak output current (manual 4.4, 0x1F and 0x20 examples).
DEFAULT_PEAK_CURRENT_A = 20.0
DEFAULT_RESET_TIMEOUT_S = 15.0
RESET_RETRY_S = 0.2
#: B0 of a daisy chain's addresses (manual 2: avoid 0, 254 and 255).
DRIVE_IDS = range(1, 254)
_I = dyn5.BY_NAME


@dataclass(frozen=True)
class EnipOptions:
    """How an EnipAxis (and each sibling) talks to its adapter."""

    port: int = TCP_PORT
    timeout: float = DEFAULT_TIMEOUT_S
    retries: int = DEFAULT_RETRIES
    connect_timeout: float = CONNECT_TIMEOUT_S
    peak_current_a: float = DEFAULT_PEAK_CURRENT_A
    reset_timeout: float = DEFAULT_RESET_TIMEOUT_S
    max_in_flight: int = 1

    def checked(self) -> EnipOptions:
        """Every field checked (ArgumentRangeError) before anything is opened."""
        if isinstance(self.port, bool) or not isinstance(self.port, int) or not (
                0 < self.port <= 0xFFFF):
            raise ArgumentRangeError(f"port must be 1..65535, got {self.port!r}")
        checks.seconds("timeout", self.timeout)
        checks.count("retries", self.retries)
        checks.seconds("connect_timeout", self.connect_timeout)
        checks.seconds("reset_timeout", self.reset_timeout)
        checks.positive_int("max_in_flight", self.max_in_flight)
        peak = checks.positive("peak_current_a", self.peak_current_a, "A")
        return replace(self, peak_current_a=peak)


def check_ip(host: str) -> str:
    """A dotted IPv4 address (DYN5: static IPv4 only, manual 1)."""
    try:
        return str(ipaddress.IPv4Address(host))
    except ValueError:
        raise ArgumentRangeError(f"{host!r} is not an IPv4 address") from None


def with_last_octet(ip: str, b0: int) -> str:
    """B3.B2.B1 of ``ip`` with B0 = ``b0`` (a drive of the same daisy chain)."""
    if isinstance(b0, bool) or not isinstance(b0, int) or not 0 <= b0 <= 255:
        raise ArgumentRangeError(f"a DYN5 drive id is the last address byte 0..255, got {b0!r}")
    return f"{ip.rsplit('.', 1)[0]}.{b0}"


class EnipAxis(AsyncAxis):
    """One DYN5 on one EtherNet/IP session (module docstring)."""

    def __init__(self, client: AsyncEnipClient | None, ip: str,
                 options: EnipOptions = EnipOptions()) -> None:
        self._client = client
        self.ip = check_ip(ip)
        self.options = options
        self._gear_num: int | None = None
        self._hooks: list[AxisTraceHook] = []
        self._closers: list[Callable[[], Awaitable[None]]] = []
        self._closed = False

    def on_close(self, closer: Callable[[], Awaitable[None]]) -> None:
        """Run ``closer`` after the session closes (e.g. an in-process adapter's servers)."""
        self._closers.append(closer)

    # ------------------------------------------------------------- connection
    @property
    def address(self) -> tuple[str, int]:
        return self.ip, self.options.port

    async def _connect(self, connect_timeout: float | None = None) -> AsyncEnipClient:
        o = self.options
        client = await AsyncEnipClient.connect(
            self.ip, o.port, timeout=o.timeout, retries=o.retries,
            connect_timeout=o.connect_timeout if connect_timeout is None else connect_timeout,
            max_in_flight=o.max_in_flight)
        for hook in self._hooks:
            client.add_trace(hook)
        return client

    async def client(self, connect_timeout: float | None = None) -> AsyncEnipClient:
        """The session; a sibling (or an axis after ``reset``) connects on first use."""
        if self._closed:
            raise ConnectionLost(f"the axis of {self.ip} is closed")
        if self._client is None:
            self._client = await self._connect(connect_timeout)
        return self._client

    async def reconnect(self) -> None:
        """Close the session (if any) and register a new one (e.g. after ConnectionLost)."""
        old, self._client = self._client, None
        if old is not None:
            await old.close()
        await self.client()

    # ------------------------------------------------------------- identity
    @property
    def drive_id(self) -> int:
        return int(self.ip.rsplit(".", 1)[1])

    @property
    def protocol(self) -> str:
        return PROTOCOL

    @property
    def family(self) -> Family:
        return DYN5

    @property
    def drive_ids(self) -> range:
        return DRIVE_IDS

    # ------------------------------------------------------------- Parameter object
    async def read_instance(self, key: int | str, *, timeout: float | None = None,
                            retries: int | None = None) -> int:
        """Attribute 1 of a Parameter instance (number or table name), signed where the
        instance's range is. Write-only and missing instances read 0x12345 (4.1)."""
        inst = dyn5.instance(key) if isinstance(key, str) else dyn5.BY_NUMBER.get(key)
        number = inst.number if inst is not None else _instance_number(key)
        client = await self.client()
        data = await client.get_attribute_single(ClassCode.PARAMETER, number,
                                                 dyn5.PARAMETER_ATTRIBUTE, timeout=timeout,
                                                 retries=retries)
        if len(data) != 4:
            raise FramingError(f"instance 0x{number:02X} answered {len(data)} bytes, not a UDINT")
        return inst.decode(data) if inst is not None else dyn5.decode_udint(data)

    async def write_instance(self, key: int | str, value: int) -> None:
        """Set attribute 1 of a known instance; the value is checked against the table first."""
        inst = dyn5.instance(key)
        await self._write(inst, value)

    async def _write(self, inst: Instance, value: int) -> None:
        data = inst.encode(inst.check(value))
        client = await self.client()
        await client.set_attribute_single(ClassCode.PARAMETER, inst.number,
                                          dyn5.PARAMETER_ATTRIBUTE, data)

    @property
    def id_address(self) -> str:
        """B3.B2.B1.id: the drive id picks the drive of the URL's daisy chain (docs/enip.md)."""
        return self.ip

    # ------------------------------------------------------------- units
    async def gear_num(self) -> int:
        """GEAR_NUM as this axis knows it (read from the drive the first time)."""
        if self._gear_num is None:
            self._gear_num = await self.read_instance(_I["gear_num"].number)
        return self._gear_num

    async def to_command(self, counts: int) -> int:
        return counts_to_command(counts, await self.gear_num())

    def _check_move(self, value: object, *, relative: bool) -> int:
        """Type, then the command range at the GEAR_NUM known so far (the widest before the
        first read): a value no GEAR_NUM can reach is refused before even the gear read."""
        counts = super()._check_move(value, relative=relative)
        gear = self._gear_num or DYN5.param("gear_num").minimum
        _I["go_relative_pos" if relative else "go_absolute_pos"].check(
            counts_to_command(counts, gear))
        return counts

    async def position_window(self) -> int:
        """On Position Range (1/16384 rev) in counts: the drive's own in-position window."""
        return max(1, round(U.onrange_to_counts(await self.read_param("on_range"))))

    # ------------------------------------------------------------- motion
    async def _send_move_to(self, position: int) -> None:
        command = await self.to_command(position)
        self._check_limits(position, False)  # now at the drive's GEAR_NUM
        await self._write(_I["go_absolute_pos"], command)

    async def _send_move_by(self, distance: int) -> None:
        command = await self.to_command(distance)
        self._check_limits(distance, True)
        await self._write(_I["go_relative_pos"], command)

    def _move_limits(self, relative: bool) -> tuple[int, int] | None:
        """0x15/0x16's command range in counts at the GEAR_NUM known so far (the widest,
        GEAR_NUM's minimum, before it is read)."""
        inst = _I["go_relative_pos" if relative else "go_absolute_pos"]
        if inst.minimum is None or inst.maximum is None:
            return None
        gear = self._gear_num or DYN5.param("gear_num").minimum
        return command_to_counts(inst.minimum, gear), command_to_counts(inst.maximum, gear)

    def _limits_note(self) -> str:
        return f" at GEAR_NUM {self._gear_num}" if self._gear_num else ""

    async def move_range(self, *, relative: bool = False) -> tuple[int, int] | None:
        await self.gear_num()
        return self._move_limits(relative)

    async def stream_profile(self) -> StreamProfile:
        """High Speed and High Accel at GEAR_NUM: Go_Absolute_Pos over explicit messaging
        retargets the running profile (DTPU); never written per motion (EEPROM)."""
        return StreamProfile(*U.stream_profile(await self.read_param("max_speed"),
                                               await self.read_param("max_accel"),
                                               await self.gear_num()))

    async def move_to_command(self, command: int, *, wait: bool = False,
                              timeout: float | None = None) -> None:
        """Absolute move in raw command units (x 4096/GEAR_NUM x 4 counts), no conversion."""
        await self._write(_I["go_absolute_pos"], check_int("command", command))
        if wait:
            await self.wait_idle(DEFAULT_WAIT_TIMEOUT_S if timeout is None else timeout)

    async def move_by_command(self, command: int, *, wait: bool = False,
                              timeout: float | None = None) -> None:
        """Relative move in raw command units, no conversion."""
        await self._write(_I["go_relative_pos"], check_int("command", command))
        if wait:
            await self.wait_idle(DEFAULT_WAIT_TIMEOUT_S if timeout is None else timeout)

    async def turn(self, rpm: int) -> None:
        await self._write(_I["turn_const_speed"], check_int("rpm", rpm))

    async def square_wave(self, amplitude: int) -> None:
        """Square-wave motion, 4096 = 180 deg (send ``wave_frequency`` first, 4.4)."""
        await self._write(_I["square_wave_amplitude"], amplitude)

    async def sine_wave(self, amplitude: int) -> None:
        await self._write(_I["sine_wave_amplitude"], amplitude)

    async def wave_frequency(self, hz: int) -> None:
        await self._write(_I["ss_frequency"], hz)

    async def set_origin(self) -> None:
        """0x03 = 0xFFFF: the current position becomes absolute zero (multi-turn), then the
        drive resets its servo control (4.4): RAM values, GEAR_NUM included, are reloaded."""
        await self._write(_I["set_abs_origin"], dyn5.ORIGIN_KEY)
        self._gear_num = None

    async def home(self) -> None:
        """The DYN5 runs no homing of its own: after power-up or Reset it reports its
        absolute position without moving (DYN5 manual 4.4, 0x21 and "Motor Absolute
        Position"); nothing is sent."""
        raise NotSupported(f"a {self.family.title} runs no homing of its own: after a "
                           "power-up or Reset it reports its absolute position without "
                           "moving: set the zero where the axis stands "
                           "(origin: Set ABS Origin), then move to 0", family=self.family.name)

    async def _move_profile_values(self, rpm: float | None,
                                   accel_rpm_s: float | None) -> dict[str, int]:
        """High Speed and High Accel (EEPROM; the DMM formulas, Appendix B) at GEAR_NUM."""
        return U.profile_params(rpm, accel_rpm_s, await self.gear_num())

    async def enable(self) -> None:
        await self._write(_I["sw_enable"], dyn5.ENABLE)

    async def disable(self) -> None:
        await self._write(_I["sw_enable"], dyn5.DISABLE)

    async def reset(self) -> None:
        """0x21 = 0xABCD, then reconnect once the adapter is back (module docstring)."""
        await self._write(_I["drive_reset"], dyn5.RESET_KEY)
        self._gear_num = None
        old, self._client = self._client, None
        if old is not None:
            await old.close()
        deadline = time.monotonic() + self.options.reset_timeout
        last: Exception | None = None
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise DriveTimeout(f"{self.ip} did not come back within "
                                   f"{self.options.reset_timeout:g} s after Reset ({last})")
            await asyncio.sleep(min(RESET_RETRY_S, remaining))
            try:
                client = await self.client(min(self.options.connect_timeout,
                                               max(remaining, 0.05)))
                await self.status()
                log.info("%s answers again after Reset (session 0x%08X)", self.ip,
                         client.session)
                return
            except (DriveTimeout, ConnectionLost, ProtocolError) as exc:
                last = exc
                broken, self._client = self._client, None
                if broken is not None:
                    await broken.close()

    def on_link_lost(self, callback: Callable[[ConnectionLost], object]) -> bool:
        """The session open now (a sibling's, opened on first use, is not watched: its
        failed calls show the loss)."""
        if self._client is None:
            return False
        self._client.transactions.on_lost(callback)
        return True

    async def power_marker(self, token: int | None = None) -> int | None:
        """Instance 0x01, the memory test object (4.4): RAM that "will be lost after power
        cycle or Reset", 0 after power-up. The machine leaves a non-zero token there and
        reads it after its link came back: 0 means the drive lost power (or was reset)."""
        if token is not None:
            await self._write(_I["memory_test"], token)
        return await self.read_instance("memory_test")

    # ------------------------------------------------------------- torque mode
    async def set_torque_mode(self, torque: bool) -> None:
        """0x25: torque mode (True) or position/speed mode (False); the torque command
        restarts at 0."""
        await self._write(_I["command_mode"],
                          dyn5.TORQUE_MODE if torque else dyn5.POSITION_SPEED_MODE)

    async def torque_mode(self) -> bool:
        return await self.read_instance(_I["command_mode"].number) == dyn5.TORQUE_MODE

    async def torque(self, amps: float) -> None:
        """Torque-mode current command in amperes, positive towards increasing position
        (0x26: 2000 = peak current, positive = CW); clamped to +-peak.

        The drive delivers it only below the torque-mode speed limit (parameter
        ``torque_speed_limit``, 0x27): there its speed loop clamps the torque and holds the
        limit, so the current read back falls to what the load takes (docs/enip.md)."""
        if isinstance(amps, bool) or not isinstance(amps, int | float) or amps != amps:
            raise ArgumentRangeError(f"amps must be a number, got {amps!r}")
        await self._write(_I["torque_command"],
                          dyn5.amps_to_torque(float(amps), self.options.peak_current_a))

    # ------------------------------------------------------------- readouts
    async def status_word(self) -> int:
        return await self.read_instance(_I["drive_status"].number)

    async def status(self) -> AxisStatus:
        """The status word, and the speed when no profile runs (moving = the motor turns,
        dyn5_family.axis_status): a constant speed leaves the busy bit clear."""
        word = await self.status_word()
        busy = Dyn5Status.from_word(word).motion_busy
        return axis_status(word, None if busy else await self.speed())

    async def readings(self) -> tuple[int, float, AxisStatus]:
        """One speed read serves both the speed and :meth:`status` (3 requests, not 4)."""
        word, position, speed = await asyncio.gather(
            self.status_word(), self.position(), self.speed())
        busy = Dyn5Status.from_word(word).motion_busy
        return position, speed, axis_status(word, None if busy else speed)

    async def position(self) -> int:
        return await self.read_instance(_I["motor_position"].number)

    async def speed(self) -> float:
        return float(await self.read_instance(_I["motor_speed"].number))

    async def torque_raw(self) -> int:
        """0x1F as read: 2000 = peak current, positive = CCW."""
        return await self.read_instance(_I["motor_torque"].number)

    async def current(self) -> float:
        return 0.0 - dyn5.torque_to_amps(await self.torque_raw(), self.options.peak_current_a)

    async def identity(self) -> IdentityReply:
        """Identity object instance 1, Get_Attributes_All (4.2)."""
        client = await self.client()
        return IdentityReply.decode(await client.get_attributes_all(ClassCode.IDENTITY, 1))

    # ------------------------------------------------------------- parameters and ids
    def parameters(self) -> tuple[ParamInfo, ...]:
        return DYN5.params

    def _param_instance(self, name: str) -> Instance:
        self.param_info(checks.param_name(name))
        return PARAM_INSTANCES[name]

    async def read_param(self, name: str) -> int:
        return await self.read_instance(self._param_instance(name).number)

    def _check_param(self, name: str, value: object) -> int:
        checked = super()._check_param(name, value)
        return self._param_instance(name).check(checked)

    async def write_param(self, name: str, value: int) -> None:
        self._check_param(name, value)
        await self._write(self._param_instance(name), value)
        if name == "gear_num":
            self._gear_num = value

    async def read_id(self) -> int:
        """B0 of the address, once the drive has answered a status read."""
        await self.status()
        return self.drive_id

    async def assign_id(self, new_id: int) -> None:
        raise self.unsupported("drive_id")

    async def ping(self, timeout: float = 0.05) -> bool:
        """One status read without retry (connecting first if needed). A refused request
        still proves that something answered."""
        checks.seconds("timeout", timeout)
        try:
            client = await self.client(connect_timeout=timeout)
            await client.get_attribute_single(ClassCode.PARAMETER, _I["drive_status"].number,
                                              dyn5.PARAMETER_ATTRIBUTE, timeout=timeout,
                                              retries=0)
        except (DriveTimeout, ConnectionLost):
            return False
        except (ProtocolError, DriveError):
            return True
        return True

    async def sibling(self, drive_id: int) -> EnipAxis:
        """The drive at B3.B2.B1.``drive_id`` on the same port (its own session, opened on
        first use; closing it never closes this one)."""
        return EnipAxis(None, with_last_octet(self.ip, drive_id), self.options)

    # ------------------------------------------------------------- cyclic I/O
    def io(self, rpi_ms: float = 10.0, **options: object) -> CyclicIo:
        """Class 1 implicit I/O (``async with axis.io(rpi_ms=10) as io``), see
        :class:`servobus.protocols.enip.scanner.CyclicIo`."""
        from servobus.protocols.enip.scanner import CyclicIo

        return CyclicIo(self, rpi_ms=rpi_ms, **options)  # type: ignore[arg-type]

    async def monitor_io(self, on_frame: Callable[[InputFrame], None], *,
                         rpi_ms: float = 10.0, frames: int | None = None,
                         duration: float | None = None) -> dict[str, int]:
        """Open cyclic I/O and call ``on_frame`` for each input frame until ``frames`` have
        arrived or ``duration`` passed (or the call is cancelled); the I/O statistics."""
        if frames is not None:
            checks.positive_int("frames", frames)
        limit = checks.optional_seconds("duration", duration)
        cyclic = self.io(rpi_ms=rpi_ms)
        stream = cyclic.frames()  # before the open: from the very first frame
        async with cyclic:
            seen = 0
            deadline = asyncio.timeout(limit)
            try:
                async with deadline:
                    async for frame in stream:
                        on_frame(frame)
                        seen += 1
                        if frames is not None and seen >= frames:
                            break
            except TimeoutError:
                if not deadline.expired():
                    raise
            return cyclic.stats.as_dict()

    # ------------------------------------------------------------- housekeeping
    async def add_trace(self, hook: AxisTraceHook) -> None:
        self._hooks.append(hook)
        if self._client is not None:
            self._client.add_trace(hook)

    async def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        client, self._client = self._client, None
        try:
            if client is not None:
                await client.close()
        finally:
            closers, self._closers = self._closers, []
            for closer in closers:
                await closer()

    def __repr__(self) -> str:
        return f"<EnipAxis {self.ip}:{self.options.port}>"


def _instance_number(key: object) -> int:
    if isinstance(key, bool) or not isinstance(key, int) or not 1 <= key <= dyn5.INSTANCE_MAX:
        raise ArgumentRangeError(f"a Parameter instance is 1..{dyn5.INSTANCE_MAX}, got {key!r}")
    return key
