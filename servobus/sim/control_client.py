"""A blocking client of the control channel (servobus.sim.control_server), for the CLI,
test rigs and scripts in another process: one request line out, one reply line back."""

from __future__ import annotations

import json
import socket
from typing import Any

from servobus.errors import ConnectionLost, DriveTimeout
from servobus.sim.core.control import ControlError, FaultTable, Reply
from servobus.sim.dmm import control as drive_control
from servobus.sim.line_server import parse_listen_url
from servobus.sim.yzaim import control as motor_control

DEFAULT_TIMEOUT_S = 5.0
#: The faults the channel's drives take, for clients that offer them by name (the CLI's
#: ``servobus sim control fault``): every family's, since the client does not know which
#: simulator it talks to (the DMM drives' and the YZ-AIM motors'; a name both have is the
#: DMM's entry here, and the server checks the arguments of its own).
FAULTS: FaultTable = {**motor_control.FAULTS, **drive_control.FAULTS}
MAX_REPLY = 1 << 20  # bytes of one reply line (a state reply is well under 2 KiB)


class ControlClient:
    """``ControlClient("tcp://127.0.0.1:4003").call("analog", 1, volts=2.5)``."""

    def __init__(self, url: str, *, timeout: float = DEFAULT_TIMEOUT_S) -> None:
        self.url = url
        host, port = parse_listen_url(url)
        try:
            self._sock = socket.create_connection((host, port), timeout=timeout)
        except TimeoutError:
            raise DriveTimeout(f"the control channel at {url} did not accept within "
                               f"{timeout:g} s - is the simulator running?") from None
        except OSError as exc:
            raise ConnectionLost(f"cannot reach the control channel at {url} - "
                                 f"{exc.strerror or exc}; start the simulator with "
                                 f"--control {url}") from None
        self._sock.settimeout(timeout)
        self._buf = b""

    def request(self, request: dict[str, Any]) -> Reply:
        """Send one request; return its reply (an ``{"ok": false, ...}`` reply included)."""
        try:
            self._sock.sendall(json.dumps(request).encode() + b"\n")
            while b"\n" not in self._buf:
                chunk = self._sock.recv(65_536)
                if not chunk:
                    raise ConnectionLost(f"the control channel at {self.url} closed")
                self._buf += chunk
                if len(self._buf) > MAX_REPLY:
                    raise ConnectionLost(f"the control channel at {self.url} sent a reply "
                                         f"longer than {MAX_REPLY} bytes")
        except TimeoutError:
            raise DriveTimeout(f"no reply from the control channel at {self.url}") from None
        except OSError as exc:
            raise ConnectionLost(f"the control channel at {self.url} failed: {exc}") from None
        line, _, self._buf = self._buf.partition(b"\n")
        try:
            reply = json.loads(line)
        except ValueError:
            reply = None
        if not isinstance(reply, dict):
            raise ConnectionLost(f"{self.url} does not speak the control protocol "
                                 f"(got {line[:60]!r})")
        return reply

    def call(self, cmd: str, drive_id: int | None = None, **args: Any) -> Reply:
        """As :meth:`request`; an error reply raises ControlError."""
        request: dict[str, Any] = {"cmd": cmd, **args}
        if drive_id is not None:
            request["id"] = drive_id
        reply = self.request(request)
        if not reply.get("ok"):
            raise ControlError(str(reply.get("kind", "?")), str(reply.get("error", reply)))
        return reply

    def close(self) -> None:
        self._sock.close()

    def __enter__(self) -> ControlClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
