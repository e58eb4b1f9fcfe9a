"""``servobus decode HEX...`` and ``servobus sniff``: DYN232M packets in human terms.

Both print one line per packet (raw bytes, then the meaning) and one line per checksum error
or run of garbage; direction is inferred as documented in :mod:`servobus.cli.line_decoder`.
``decode`` exits with status 1 when the bytes contained errors (like ``cmp``), 0 otherwise,
and says so in one stderr line.

``sniff`` decisions: Ctrl-C is the normal end of a live capture (exit 0 with the packet count,
like tcpdump and candump); a ``--from-file`` capture that is hex text is refused without
``--hex`` (a raw DYN232M capture always has bytes >= 0x80, hex text never has).
"""

from __future__ import annotations

import socket
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any, BinaryIO, Protocol

import click

from servobus.cli.command_class import ServobusCommand
from servobus.cli.context import CliContext, pass_cli
from servobus.cli.failures import EXIT_DIFFERENT, CliError, one_line
from servobus.cli.line_decoder import (
    CanEvent,
    ErrorEvent,
    LineDecoder,
    LineEvent,
    can_event,
    decode_stream,
    looks_like_hex_text,
    parse_can_frame,
    parse_hex,
)
from servobus.cli.open_axis import emit_json, note
from servobus.cli.open_failures import can_open_failure, check_can_reachable
from servobus.cli.param_types import Seconds

RAW_WIDTH = 21  # "xx " x 7 bytes


AnyEvent = LineEvent | CanEvent


def format_event(event: AnyEvent, prefix: str = "") -> list[str]:
    """Text lines for one event; an ambiguous packet gets a second line with the alternative."""
    if isinstance(event, CanEvent):
        return [f"{prefix}{event.raw_text:<{RAW_WIDTH}}{event.text}"]
    if isinstance(event, ErrorEvent):
        raw = event.raw_text or event.raw.hex(" ")
        return [f"{prefix}{raw:<{RAW_WIDTH}}{event.label}: {event.message}"]
    lines = [f"{prefix}{event.raw.hex(' '):<{RAW_WIDTH}}{event.text}"]
    if event.ambiguous:
        lines[0] += "   [direction ambiguous]"
        lines.append(f"{prefix}{'':<{RAW_WIDTH}}or {event.alternative}")
    return lines


@click.command("decode", cls=ServobusCommand)
@click.argument("hex_bytes", nargs=-1, required=True, metavar="HEX...")
@pass_cli
def decode_cmd(ctx: CliContext, hex_bytes: tuple[str, ...]) -> None:
    """Decode DYN232M packets from hex bytes in any spacing, or DYN CAN frames written ID#DATA.

    Examples: servobus decode 03 a3 ff 88 ad   (Go_Relative_Pos -120 to id 3);
    servobus decode 0ee#1b  (DYN CAN General_Read position from id 7)
    """
    events: list[AnyEvent]
    try:
        if any("#" in token for token in hex_bytes):
            events = [can_event(*parse_can_frame(t)) for arg in hex_bytes for t in arg.split()]
        else:
            events = list(decode_stream([parse_hex(hex_bytes)]))
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="HEX") from None
    if ctx.json:
        emit_json([e.as_dict() for e in events])
    else:
        for event in events:
            for line in format_event(event):
                click.echo(line)
    bad = sum(isinstance(e, ErrorEvent) for e in events)
    if bad:
        note(f"error: {bad} of {len(events)} item(s) are not valid packets or frames - "
             "see the lines marked above")
        sys.exit(EXIT_DIFFERENT)


class _Source(Protocol):
    def read(self) -> bytes | None:
        """Bytes received within a short poll interval; b"" if none yet; None at end."""

    def close(self) -> None: ...


POLL_S = 0.05


class _FileSource:
    def __init__(self, stream: BinaryIO, as_hex: bool, name: str) -> None:
        self._stream, self._hex, self._name = stream, as_hex, name
        self._first = True

    def read(self) -> bytes | None:
        if self._hex:
            text = self._stream.read().decode("ascii", "replace")
            self._hex = False  # read once; the next read() sees EOF
            try:
                data = parse_hex(text.split())
            except ValueError as exc:
                raise CliError(f"{self._name} is not hex text: {exc}",
                               "drop --hex for a raw binary capture") from None
            return data or None
        chunk = self._stream.read1(4096) if hasattr(self._stream, "read1") else \
            self._stream.read(4096)
        if self._first and looks_like_hex_text(chunk):
            raise CliError(f"{self._name} looks like hex text, not raw bytes",
                           "add --hex to decode it as hex")
        self._first = False
        return chunk or None

    def close(self) -> None:
        if self._stream is not sys.stdin.buffer:
            self._stream.close()


class _TcpSource:
    """A plain TCP client, e.g. for the simulator's tap ``tcp://127.0.0.1:PORT``."""

    def __init__(self, host: str, port: int) -> None:
        self._sock = socket.create_connection((host, port), timeout=5.0)
        self._sock.settimeout(POLL_S)

    def read(self) -> bytes | None:
        try:
            data = self._sock.recv(4096)
        except TimeoutError:
            return b""
        return data or None

    def close(self) -> None:
        self._sock.close()


class _SerialSource:
    def __init__(self, url: str, baud: int) -> None:
        import serial

        self._port: Any = serial.serial_for_url(url, baudrate=baud, timeout=POLL_S)

    def read(self) -> bytes | None:
        waiting = max(1, int(self._port.in_waiting or 0))
        return bytes(self._port.read(waiting))

    def close(self) -> None:
        self._port.close()


def _open_source(ctx: CliContext, tap: str | None, from_file: str | None,
                 as_hex: bool) -> tuple[_Source, bool]:
    """The byte source and whether it is live (timestamps make sense)."""
    if from_file is not None:
        if from_file == "-":
            return _FileSource(sys.stdin.buffer, as_hex, "stdin"), False
        try:
            stream = Path(from_file).open("rb")  # noqa: SIM115 - closed by _FileSource
        except OSError as exc:
            raise CliError(f"cannot read {from_file}: {exc.strerror or exc}",
                           "check the path ('-' reads stdin)") from None
        return _FileSource(stream, as_hex, from_file), False
    url = tap or ctx.port
    if url is None:
        raise click.UsageError("sniff needs --tap URL, --from-file FILE|- or the global --port URL")
    try:
        if url.startswith("tcp://"):
            host, _, port = url[len("tcp://"):].rpartition(":")
            return _TcpSource(host or "127.0.0.1", int(port)), True
        return _SerialSource(url, ctx.baud), True
    except (OSError, ValueError) as exc:
        raise CliError(f"cannot open {url}: {one_line(str(exc))}",
                       "start `servobus sim dyn2 --tap tcp://HOST:PORT` (or the line's bridge), "
                       "or fix the address") from None


def _chunks(source: _Source, deadline: float | None) -> Iterator[bytes]:
    while deadline is None or time.monotonic() < deadline:
        data = source.read()
        if data is None:
            return
        if data:
            yield data


@click.command("sniff", cls=ServobusCommand)
@click.option("--tap", metavar="URL", default=None,
              help="tap to read, e.g. tcp://127.0.0.1:PORT from `servobus sim dyn2 --tap`; "
                   "default: the global --port (a pyserial port/URL on the RS485 line) "
                   "or the global --can bus (DYN CAN frames)")
@click.option("--from-file", "from_file", metavar="FILE", default=None,
              help="decode raw bytes from FILE ('-' = stdin) instead of a live line")
@click.option("--hex", "as_hex", is_flag=True, help="with --from-file: the file holds hex text")
@click.option("--count", type=click.IntRange(min=1), default=None,
              help="stop after N packets")
@click.option("--duration", type=Seconds(allow_zero=True), default=None,
              help="stop after S seconds")
@pass_cli
def sniff_cmd(ctx: CliContext, tap: str | None, from_file: str | None, as_hex: bool,
              count: int | None, duration: float | None) -> None:
    """Print the packets on a live DYN232M line (or in a capture) as they pass.

    Direction is inferred (a reply follows the host's read with the expected Is_* code from
    the same id); when both readings fit, both are printed. Ctrl-C ends a live capture.
    """
    start = time.monotonic()
    deadline = None if duration is None else start + duration
    events: Iterator[AnyEvent]
    if ctx.can is not None and tap is None and from_file is None:
        source: _Source | None = None
        events, live = _can_events(ctx.can, deadline), True
    else:
        source, live = _open_source(ctx, tap, from_file, as_hex)
        events = _events(source, deadline)
    packets = errors = 0
    try:
        for event in events:
            if not isinstance(event, ErrorEvent):
                packets += 1
            else:
                errors += 1
            t = time.monotonic() - start
            if ctx.json:
                record = event.as_dict()
                if live:
                    record["t"] = round(t, 6)
                emit_json(record)
            else:
                for line in format_event(event, f"{t:9.4f}  " if live else ""):
                    click.echo(line)
            if count is not None and packets >= count:
                break
    except KeyboardInterrupt:
        pass  # the normal end of a live capture
    finally:
        if source is not None:
            source.close()
    if not ctx.json:
        note(f"{packets} packet(s), {errors} error(s)")


def _can_events(spec: str, deadline: float | None) -> Iterator[AnyEvent]:
    """Frames seen on a python-can bus (``--can INTERFACE:CHANNEL``), as DYN CAN events."""
    from servobus.transport.can_bus import open_bus

    check_can_reachable(spec)
    try:
        bus = open_bus(spec)
    except Exception as exc:  # whatever python-can or the vendor driver raises
        raise can_open_failure(spec, exc) from exc
    try:
        while deadline is None or time.monotonic() < deadline:
            msg = bus.recv(POLL_S)
            if msg is None:
                continue
            if msg.is_extended_id or msg.is_error_frame:
                yield ErrorEvent("frame", f"not a DYN CAN frame: id 0x{msg.arbitration_id:x}",
                                 bytes(msg.data), f"{msg.arbitration_id:x}#{msg.data.hex()}")
            else:
                yield can_event(msg.arbitration_id, bytes(msg.data))
    finally:
        bus.shutdown()


def _events(source: _Source, deadline: float | None) -> Iterator[LineEvent]:
    decoder = LineDecoder()
    for chunk in _chunks(source, deadline):
        yield from decoder.iter_feed(chunk)
    yield from decoder.finish()


def register(group: click.Group) -> None:
    group.add_command(decode_cmd)
    group.add_command(sniff_cmd)
