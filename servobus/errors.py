"""Typed errors. Every failure a caller can act on has its own class."""

from __future__ import annotations


class ServobusError(Exception):
    """Base class of every servobus error."""


class ProtocolError(ServobusError):
    """Bytes or frames that do not follow the protocol."""


class FramingError(ProtocolError):
    """A packet is malformed (wrong start byte, length, or truncated)."""


class ChecksumError(ProtocolError):
    """A packet failed its checksum; its value is never used."""

    def __init__(self, message: str, raw: bytes = b"") -> None:
        super().__init__(message)
        self.raw = raw


class DriveTimeout(ServobusError, TimeoutError):
    """No valid reply arrived before the deadline (after the bounded retries)."""


class DriveAlarm(ServobusError):
    """The drive reports an alarm; it ignores commands until reset or power cycle."""

    def __init__(self, message: str, code: int = 0, drive_id: int | None = None) -> None:
        super().__init__(message)
        self.code = code
        self.drive_id = drive_id


class ArgumentRangeError(ServobusError, ValueError):
    """An argument is outside the range the manual allows; nothing was sent."""


class InvalidValue(ArgumentRangeError):
    """A value of the wrong kind or form rather than out of range: a unit the axis does not
    take, a name that does not exist, a malformed URL. The message says what is accepted;
    ``todo`` is what the terminal adds (nothing was sent, or the file is unchanged)."""

    def __init__(self, message: str, todo: str = "nothing was sent") -> None:
        super().__init__(message)
        self.todo = todo


class LimitError(ArgumentRangeError):
    """A motion would cross a machine axis's soft limit; nothing was sent."""


class OwnerError(ServobusError):
    """Another owner (a page, a session, a program) holds this axis's open-ended motion;
    ``owner`` names it. Nothing was sent. Stop and STOP ALL always win (docs/safety.md)."""

    def __init__(self, message: str, owner: str = "") -> None:
        super().__init__(message)
        self.owner = owner


class MotionRefused(ArgumentRangeError):
    """A motion, or a register write that would start one, refused before it was written:
    it would never end (open-ended motion on an axis that is not ``continuous``) or never
    run (a YZ-AIM cruise speed of 0). Nothing was written."""


class MachineFileError(ArgumentRangeError):
    """A mistake in a machine file (servobus.machine): one line naming file, axis and key."""


class UnknownScheme(ArgumentRangeError):
    """A drive URL names no scheme servobus serves; ``suggestion`` is the resembling URL."""

    def __init__(self, message: str, suggestion: str | None = None) -> None:
        super().__init__(message)
        self.suggestion = suggestion


class EepromGuardError(ServobusError):
    """Parameter writes exceed the configured EEPROM write rate; nothing was sent."""


class DriveError(ServobusError):
    """The drive answered with an explicit error (e.g. DYN CAN Drive Error 0xFF)."""

    def __init__(self, message: str, code: int = 0, drive_id: int | None = None) -> None:
        super().__init__(message)
        self.code = code
        self.drive_id = drive_id


class MoveFailed(ServobusError):
    """A move did not end where it was asked: the drive is disabled, or it stopped off its
    target beyond its in-position window. ``position`` and ``target`` in counts when known."""

    def __init__(self, message: str, drive_id: int | None = None,
                 position: int | None = None, target: int | None = None) -> None:
        super().__init__(message)
        self.drive_id = drive_id
        self.position = position
        self.target = target


class ConnectionLost(ServobusError, ConnectionError):
    """The transport went away (closed, reset, broken pipe); also a ``ConnectionError``."""


class MachineLinkError(ConnectionLost):
    """A machine axis's link cannot be opened (or is offline): names the axis and its URL."""


class PowerLostError(ServobusError):
    """A machine axis whose drive may have lost power (position or origin may be gone)
    refuses motion until acknowledged (``acknowledge()``, ``servobus ack``); nothing was
    sent."""


class TuningInterrupted(ServobusError):
    """An earlier tuning run of this drive ended without writing its kept gains back (its
    process was killed): the drive may still hold gains under test. ``path`` is the record
    that keeps them; ``servobus tune --restore`` writes them back (servobus.tune.kept).
    Nothing was moved or written."""

    def __init__(self, message: str, path: object = None) -> None:
        super().__init__(message)
        self.path = path


class ClosedError(ServobusError, RuntimeError):
    """A call on an Axis or a machine after its ``close()`` (or from the wrong thread):
    nothing was sent. Also a ``RuntimeError``, as before it had a type of its own."""


class NotSupported(ServobusError):
    """The connected drive family or protocol does not have this feature; nothing was sent."""

    def __init__(self, message: str, family: str = "") -> None:
        super().__init__(message)
        self.family = family


class JsonRefused(ServobusError, ValueError):
    """Text from outside (a GUI request or message, an MQTT command) that is not JSON the
    server accepts: not UTF-8, not JSON, too large, nested too deep, or a number that is no
    finite double (``1e400``, a 400-digit integer, ``NaN``). Nothing of it was used; the
    message says what is wrong (servobus.bounded_json). Also a ``ValueError``."""


class GatewayConflict(ServobusError):
    """Another live gateway already serves these MQTT topics (the same ``--mqtt-prefix`` and
    machine name on the same broker): this one did not take them over and the other goes
    on serving. The message names the other and what to do."""
