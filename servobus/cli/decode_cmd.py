"""``servobus decode HEX...`` and ``servobus sniff``: wire traffic in human terms.

Both print one line per packet or frame (raw bytes, then the meaning) and one line per
checksum error or run of garbage. The decoding is the protocol's (each protocol package
declares a decoder, :mod:`servobus.sniff`): ``--protocol`` names it; otherwise the protocol
of the drive URL the global options name, else the first protocol that reads the medium
(hex bytes: a serial line; ``ID#DATA``: a CAN bus).
``decode`` exits with status 1 when the bytes contained errors (like ``cmp``), 0 otherwise,
and says so in one stderr line.

``sniff`` decisions: Ctrl-C is the normal end of a live capture (exit 0 with the packet count,
like tcpdump and candump); a ``--from-file`` capture that is hex text is refused without
``--hex`` (a raw capture of a binary protocol has bytes hex text never has).
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
from servobus.cli.open_failures import check_reachable, open_failure
from servobus.cli.output import emit_json, note
from servobus.cli.param_types import Seconds
from servobus.sniff import (
    BYTES,
    CAN,
    Decoder,
    ErrorEvent,
    Event,
    decode_stream,
    decoder_for,
    decoders,
    looks_like_hex_text,
    parse_can_frame,
    parse_hex,
)


def pick_decoder(ctx: CliContext, medium: str, name: str | None) -> Decoder:
    """``--protocol``, else the protocol of the global drive URL, else the medium's first."""
    if name is None and ctx.url_given:
        from servobus.axis import registry
        from servobus.axis.url import parse_url

        own = registry.protocol_of(parse_url(ctx.url))
        if own is not None and own in decoders() and decoders()[own].medium == medium:
            name = own
    try:
        return decoder_for(medium, name)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--protocol") from None


PROTOCOL_OPTION = click.option(
    "--protocol", "protocol", metavar="NAME", default=None,
    help="decode as this protocol (dyn232, dyncan, ...) [default: the drive URL's protocol, "
         "else the first that reads hex bytes or ID#DATA frames]")


@click.command("decode", cls=ServobusCommand)
@click.argument("hex_bytes", nargs=-1, required=True, metavar="HEX...")
@PROTOCOL_OPTION
@pass_cli
def decode_cmd(ctx: CliContext, hex_bytes: tuple[str, ...], protocol: str | None) -> None:
    """Decode packets from hex bytes in any spacing, or CAN frames written ID#DATA.

    Examples: servobus decode 03 a3 ff 88 ad   (DYN232M Go_Relative_Pos -120 to id 3);
    servobus decode 0ee#1b  (DYN CAN General_Read position from id 7)
    """
    events: list[Event]
    can = any("#" in token for token in hex_bytes)
    decoder = pick_decoder(ctx, CAN if can else BYTES, protocol)
    try:
        if can:
            events = [decoder.frame(*parse_can_frame(t)) for arg in hex_bytes
                      for t in arg.split()]
        else:
            events = list(decode_stream(decoder, [parse_hex(hex_bytes)]))
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="HEX") from None
    if ctx.json:
        emit_json([e.as_dict() for e in events])
    else:
        for event in events:
            for line in event.lines():
                click.echo(line)
    bad = sum(e.is_error for e in events)
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
        return _SerialSource(url, ctx.baud or 38_400), True
    except (OSError, ValueError) as exc:
        raise CliError(f"cannot open {url}: {one_line(str(exc))}",
                       "start the virtual drive's tap (`servobus sim ... --tap tcp://HOST:PORT`) "
                       "or the line's bridge, or fix the address") from None


def _chunks(source: _Source, deadline: float | None) -> Iterator[bytes]:
    while deadline is None or time.monotonic() < deadline:
        data = source.read()
        if data is None:
            return
        if data:
            yield data


@click.command("sniff", cls=ServobusCommand)
@click.option("--tap", metavar="URL", default=None,
              help="tap to read, e.g. tcp://127.0.0.1:PORT from `servobus sim dyn232 --tap`; "
                   "default: the global --port (a pyserial port/URL on the RS485 line) "
                   "or the global --can bus (DYN CAN frames)")
@click.option("--from-file", "from_file", metavar="FILE", default=None,
              help="decode raw bytes from FILE ('-' = stdin) instead of a live line")
@click.option("--hex", "as_hex", is_flag=True, help="with --from-file: the file holds hex text")
@click.option("--count", type=click.IntRange(min=1), default=None,
              help="stop after N packets")
@click.option("--duration", type=Seconds(allow_zero=True), default=None,
              help="stop after S seconds")
@PROTOCOL_OPTION
@pass_cli
def sniff_cmd(ctx: CliContext, tap: str | None, from_file: str | None, as_hex: bool,
              count: int | None, duration: float | None, protocol: str | None) -> None:
    """Print the packets on a live line or CAN bus (or in a capture) as they pass.

    On a serial line the direction is inferred by the protocol's decoder (DYN232M: a reply
    follows the host's read with the expected Is_* code from the same id; when both readings
    fit, both are printed). Ctrl-C ends a live capture.
    """
    start = time.monotonic()
    deadline = None if duration is None else start + duration
    events: Iterator[Event]
    if ctx.can is not None and tap is None and from_file is None:
        source: _Source | None = None
        events, live = _can_events(ctx.can, pick_decoder(ctx, CAN, protocol), deadline), True
    else:
        source, live = _open_source(ctx, tap, from_file, as_hex)
        events = _events(source, pick_decoder(ctx, BYTES, protocol), deadline)
    packets = errors = 0
    try:
        for event in events:
            if not event.is_error:
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
                for line in event.lines(f"{t:9.4f}  " if live else ""):
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


def _can_events(spec: str, decoder: Decoder, deadline: float | None) -> Iterator[Event]:
    """Frames seen on a python-can bus (``--can INTERFACE:CHANNEL``), decoded."""
    from servobus.axis.url import parse_url
    from servobus.transport.can_bus import open_bus

    interface, _, channel = spec.partition(":")
    url = parse_url(f"can+{interface}://{channel}")
    check_reachable(url)
    try:
        bus = open_bus(spec)
    except Exception as exc:  # whatever python-can or the vendor driver raises
        raise open_failure(url, exc) from exc
    try:
        while deadline is None or time.monotonic() < deadline:
            msg = bus.recv(POLL_S)
            if msg is None:
                continue
            if msg.is_extended_id or msg.is_error_frame:
                yield ErrorEvent("frame", f"not a CAN 2.0A frame: id 0x{msg.arbitration_id:x}",
                                 bytes(msg.data), f"{msg.arbitration_id:x}#{msg.data.hex()}")
            else:
                yield decoder.frame(msg.arbitration_id, bytes(msg.data))
    finally:
        bus.shutdown()


def _events(source: _Source, decoder: Decoder, deadline: float | None) -> Iterator[Event]:
    return decode_stream(decoder, _chunks(source, deadline))


def register(group: click.Group) -> None:
    group.add_command(decode_cmd)
    group.add_command(sniff_cmd)
