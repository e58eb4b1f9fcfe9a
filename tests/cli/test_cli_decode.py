"""``servobus decode`` / ``sniff`` and the direction inference behind them (no drive needed)."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest
from click.testing import CliRunner
from hypothesis import given
from hypothesis import strategies as st

from servobus.cli.main import cli
from servobus.families.dmm.vocabulary import DmmFunction as DF
from servobus.protocols.dyn232 import codec as c
from servobus.protocols.dyn232.sniff import (
    AMBIGUOUS,
    CODE,
    DECODER,
    REPLY,
    VALUE,
    LineDecoder,
    PacketEvent,
)
from servobus.sniff import decode_stream, parse_hex

SERVOBUS = [sys.executable, "-m", "servobus"]  # the interpreter running the tests
H, D = c.HostFunction, c.DriveFunction

# The manual's worked examples (7.6 examples 1-6, 7.2.6) and what decode must say about them.
GOLDEN = [
    ("03 80 80 83", "host -> id 3: SET_ORIGIN"),
    ("03 81 80 84", "host -> id 3: GO_ABSOLUTE_POS 0"),
    ("03 a3 80 f8 9e", "host -> id 3: GO_RELATIVE_POS 120"),
    ("03 a3 ff 88 ad", "host -> id 3: GO_RELATIVE_POS -120"),
    ("02 8a bc c8", "host -> id 2: TURN_CONST_SPEED 60"),
    ("02 8a c4 d0", "host -> id 2: TURN_CONST_SPEED -60"),
    ("08 8a b2 c4", "host -> id 8: TURN_CONST_SPEED 50"),
]


def run(*args: str, input: bytes | None = None) -> tuple[int, str]:
    result = CliRunner().invoke(cli, list(args), input=input)
    if result.exception and not isinstance(result.exception, SystemExit):
        raise result.exception
    return result.exit_code, result.stdout if result.exit_code != 2 else result.output


@pytest.mark.slow  # a real process
def test_decode_subprocess_example_4() -> None:
    proc = subprocess.run([*SERVOBUS, "decode", "03", "a3", "ff", "88", "ad"],
                          capture_output=True, text=True, timeout=30)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "03 a3 ff 88 ad       host -> id 3: GO_RELATIVE_POS -120"


@pytest.mark.parametrize(("hexbytes", "text"), GOLDEN)
def test_decode_golden(hexbytes: str, text: str) -> None:
    code, out = run("decode", hexbytes.replace(" ", ""))
    assert code == 0
    assert out.split(None, len(hexbytes.split()))[-1].strip() == text
    assert out.startswith(hexbytes)


def test_decode_any_spacing_and_several_packets() -> None:
    code, out = run("--json", "decode", "0x03,0x80", "8083", "03:81:80:84", "3", "a3ff88ad")
    assert code == 0
    records = json.loads(out)
    assert [(r["function"], r["value"], r["drive_id"]) for r in records] == [
        ("SET_ORIGIN", 0, 3), ("GO_ABSOLUTE_POS", 0, 3), ("GO_RELATIVE_POS", -120, 3)]


def test_decode_reports_checksum_error_and_garbage_with_status_1() -> None:
    code, out = run("decode", "03 a3 ff 88 ae", "ff ff", "03 81 80 84", "03 a3 ff")
    assert code == 1
    lines = out.splitlines()
    assert lines[0].startswith("03 a3 ff 88 ae") and "checksum error" in lines[0]
    assert "garbage: 2 stray byte(s)" in lines[1]
    assert lines[2].endswith("host -> id 3: GO_ABSOLUTE_POS 0")
    assert "truncated packet 03 a3 ff" in lines[3]
    assert len(lines) == 4


def test_decode_bad_hex_is_a_usage_error() -> None:
    code, out = run("decode", "03", "zz")
    assert code == 2 and "not hex" in out
    with pytest.raises(ValueError, match="odd number"):
        parse_hex(["03a"])


def classify(*packets: bytes) -> list[PacketEvent]:
    events = LineDecoder().feed(b"".join(packets))
    assert all(isinstance(e, PacketEvent) for e in events)
    return [e for e in events if isinstance(e, PacketEvent)]


def test_reply_follows_read_request() -> None:
    req, rep = classify(c.encode(3, DF.READ_DRIVE_STATUS), c.encode_reply(3, D.IS_STATUS, 0x21))
    assert (req.from_drive, req.basis) == (False, CODE)
    assert (rep.from_drive, rep.basis) == (True, REPLY)
    assert "IS_STATUS = 33" in rep.text and "motion busy" in rep.text


def test_reply_to_broadcast_read_carries_own_id() -> None:
    _, rep = classify(c.encode(127, DF.READ_DRIVE_ID), c.encode_reply(5, D.IS_DRIVE_ID, 5))
    assert rep.from_drive and rep.basis == REPLY and rep.packet.drive_id == 5


def test_overlapping_code_alone_is_ambiguous_then_resolved_by_reply() -> None:
    # 0x19 = Read_SpeedGain (host, dummy 0) or Is_Status 0 (drive): both fit.
    first, second = classify(c.encode(3, H.READ_SPEED_GAIN), c.encode_reply(3, D.IS_SPEED_GAIN, 40))
    assert first.basis == AMBIGUOUS and not first.from_drive
    assert first.alternative is not None and "IS_STATUS" in first.alternative
    assert second.basis == REPLY and second.text.endswith("IS_SPEED_GAIN = 40")


def test_reply_from_other_id_is_not_taken_for_the_answer() -> None:
    _, other = classify(c.encode(3, DF.READ_DRIVE_STATUS), c.encode_reply(4, D.IS_STATUS, 0))
    assert other.basis == AMBIGUOUS


@pytest.mark.parametrize(
    ("raw", "from_drive", "basis"),
    [
        (c.encode(1, H.SET_GEAR_NUMBER, 4096), False, VALUE),  # Is_Pos_OnRange can't be 4096
        (c.encode_reply(1, D.IS_GEAR_NUMBER, 4096), True, VALUE),  # Read_MainGain dummy is 0
        (c.encode(127, H.SET_MAIN_GAIN, 40), False, CODE),  # drives never send id 127
        (c.encode(1, H.READ_HIGH_SPEED), False, CODE),  # 0x1C has no Is_* meaning
    ],
)
def test_direction_by_code_and_value(raw: bytes, from_drive: bool, basis: str) -> None:
    (event,) = classify(raw)
    assert (event.from_drive, event.basis) == (from_drive, basis)


@given(st.lists(st.integers(1, 30), max_size=6))
def test_chunking_does_not_change_the_events(cuts: list[int]) -> None:
    data = b"".join([c.encode(3, DF.READ_DRIVE_STATUS), c.encode_reply(3, D.IS_STATUS, 1),
                     b"\xff\x90", c.encode(1, DF.GO_RELATIVE_POS, -5000),
                     c.encode(2, DF.GENERAL_READ, 0x1B), c.encode_reply(2, D.IS_ABS_POS32, -70000)])
    chunks, pos = [], 0
    for cut in cuts:
        chunks.append(data[pos:pos + cut])
        pos += cut
    chunks.append(data[pos:])
    assert list(decode_stream(DECODER, chunks)) == list(decode_stream(DECODER, [data]))


def conversation() -> bytes:
    return b"".join([
        c.encode(1, DF.GENERAL_READ, 0x1B), c.encode_reply(1, D.IS_ABS_POS32, 65536),
        c.encode(1, DF.GO_RELATIVE_POS, -120),
        c.encode(1, H.READ_MAIN_GAIN), c.encode_reply(1, D.IS_MAIN_GAIN, 100),
    ])


def test_sniff_from_file_and_stdin(tmp_path: Path) -> None:
    f = tmp_path / "capture.bin"
    f.write_bytes(conversation())
    code, out = run("sniff", "--from-file", str(f))
    assert code == 0
    assert [line.split(None, 1)[0] for line in out.splitlines()[:5]] == ["01"] * 5
    assert "drive id 1 -> host: IS_ABS_POS32 = 65536 counts" in out
    assert "drive id 1 -> host: IS_MAIN_GAIN = 100" in out
    code, out2 = run("sniff", "--from-file", "-", input=conversation())
    assert out2 == out


def test_sniff_hex_file_count_and_json(tmp_path: Path) -> None:
    f = tmp_path / "capture.txt"
    f.write_text(conversation().hex(" ") + "\n")
    code, out = run("--json", "sniff", "--from-file", str(f), "--hex", "--count", "2")
    records = [json.loads(line) for line in out.splitlines()]
    assert code == 0 and len(records) == 2
    assert records[1]["direction"] == "drive->host" and records[1]["value"] == 65536


@pytest.fixture
def tap_server() -> Iterator[tuple[int, threading.Event]]:
    """A TCP server that plays the conversation to one client, then stays open until told."""
    done = threading.Event()
    srv = socket.create_server(("127.0.0.1", 0))
    srv.settimeout(10)

    def serve() -> None:
        try:
            conn, _ = srv.accept()
        except OSError:
            return
        with conn:
            data = conversation()
            try:
                for i in range(0, len(data), 3):  # arbitrary chunking
                    conn.sendall(data[i:i + 3])
            except OSError:  # the sniffer may hang up once it has its --count
                return
            done.wait(10)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    yield srv.getsockname()[1], done
    done.set()
    srv.close()
    thread.join(10)


def test_sniff_tap_stops_after_count(tap_server: tuple[int, threading.Event]) -> None:
    port, _ = tap_server
    code, out = run("sniff", "--tap", f"tcp://127.0.0.1:{port}", "--count", "3")
    lines = out.splitlines()
    assert code == 0 and len(lines) == 3
    assert lines[2].endswith("host -> id 1: GO_RELATIVE_POS -120")
    assert float(lines[0].split()[0]) >= 0  # live capture: timestamp column


def test_sniff_tap_stops_after_duration(tap_server: tuple[int, threading.Event]) -> None:
    port, _ = tap_server
    code, out = run("sniff", "--tap", f"tcp://127.0.0.1:{port}", "--duration", "0.5")
    assert code == 0 and len(out.splitlines()) == 5


def test_sniff_without_source_is_a_usage_error() -> None:
    code, out = run("sniff")
    assert code == 2 and "--tap" in out


@pytest.mark.slow  # a real process
def test_sniff_live_tap_of_the_simulator() -> None:
    """End to end: `servobus sim dyn232 --tap`, a sniffer on the tap, a client on the line."""
    from servobus.axis import connect

    sim = subprocess.Popen([*SERVOBUS, "sim", "dyn232", "--fast", "--ids", "4", "--listen",
                            "tcp://127.0.0.1:0", "--tap", "tcp://127.0.0.1:0",
                            "--duration", "20"], stdout=subprocess.PIPE, text=True)
    sniff = None
    try:
        assert sim.stdout is not None
        ports: dict[str, str] = {}
        while len(ports) < 2:
            line = sim.stdout.readline()
            assert line, "simulator ended before announcing its ports"
            for key in ("listening on ", "tap on "):
                if line.startswith(key):
                    ports[key.split()[0]] = line.split()[-1]
        sniff = subprocess.Popen([*SERVOBUS, "--json", "sniff", "--tap", ports["tap"],
                                  "--count", "3", "--duration", "15"],
                                 stdout=subprocess.PIPE, text=True)
        line_url = ports["listening"].replace("tcp://", "socket://")
        with connect(line_url, drive_id=4) as axis:
            # Traffic until the sniffer (which may still be connecting) has seen 3 packets.
            while sniff.poll() is None:
                axis.position()
        out, _ = sniff.communicate(timeout=15)
    finally:
        for proc in (sniff, sim):
            if proc is not None and proc.poll() is None:
                proc.kill()
                proc.wait(5)
    records = [json.loads(line) for line in out.splitlines()]
    assert sniff.returncode == 0 and len(records) == 3
    # The tap may join between a request and its reply: the first full pair is what counts.
    start = 0 if records[0]["function"] == "GENERAL_READ" else 1
    request, reply = records[start:start + 2]
    assert (request["function"], request["drive_id"]) == ("GENERAL_READ", 4)
    assert (reply["function"], reply["basis"], reply["direction"]) == (
        "IS_ABS_POS32", "reply", "drive->host")


# ------------------------------------------------------------------ DYN CAN frames
def test_decode_can_frames_in_cansend_notation() -> None:
    from servobus.protocols.dyncan import codec as dyncan

    ident = dyncan.arbitration_id(7, DF.GENERAL_READ)
    code, out = run("decode", f"{ident:03x}#1b", f"{ident:03x}#00010000")
    lines = out.splitlines()
    assert code == 0 and len(lines) == 2
    assert lines[0].endswith("host -> id 7: GENERAL_READ 0x1b (POSITION)")
    assert lines[1].endswith("drive id 7 -> host: GENERAL_READ 65536")
    code, out = run("decode", "800#00")
    assert code == 2 and "11-bit" in out


def test_sniff_can_bus() -> None:
    import can

    from servobus.protocols.dyncan import codec as dyncan

    channel = "servobus-test-sniff"
    ident = dyncan.arbitration_id(2, DF.GENERAL_READ)
    stop = threading.Event()

    def send() -> None:
        with can.Bus(interface="virtual", channel=channel) as bus:
            while not stop.wait(0.02):  # until the sniffer has what it needs
                bus.send(can.Message(arbitration_id=ident, data=b"\x1b", is_extended_id=False))

    thread = threading.Thread(target=send, daemon=True)
    thread.start()
    try:
        code, out = run("--can", f"virtual:{channel}", "--json", "sniff", "--count", "2",
                        "--duration", "10")
    finally:
        stop.set()
        thread.join(5)
    records = [json.loads(line) for line in out.splitlines()]
    assert code == 0 and len(records) == 2
    assert records[0]["text"] == "host -> id 2: GENERAL_READ 0x1b (POSITION)"
