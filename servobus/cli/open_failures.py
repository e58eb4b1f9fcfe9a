"""Opening a port or CAN bus from the command line: check first, explain failures in one line.

Protocol-free: what to say depends on the transport the URL names, never on the protocol.

* socketcand: a bounded TCP connect to HOST:PORT before python-can is asked to open it
  (python-can's socketcand client retries for 10 s and logs every attempt when nothing
  listens). The probe connection is closed at once; socketcand serves the next one.
* a transport nobody serves (``dyn232+sockte://``) is named with the one it resembles (difflib
  over pyserial's URL schemes and python-can's interfaces); ``socketcan`` given HOST:PORT
  points to ``socketcand`` (socketcan takes a Linux interface such as can0);
* any exception while opening (python-can's CanInterfaceNotImplementedError /
  CanInitializationError, a missing vendor library's OSError, pyserial's SerialException,
  a refused TCP connection) becomes one :class:`CliError` naming the port and what to do,
  e.g. which vendor driver a CAN interface needs.
"""

from __future__ import annotations

import difflib
import pkgutil
import re
import socket

from servobus.axis.url import DriveUrl
from servobus.cli.failures import CliError, one_line

#: Seconds the socketcand probe may take (a remote host that drops packets).
SOCKETCAND_PROBE_S = 2.0

#: python-can interface -> what it needs on this machine.
CAN_DRIVERS: dict[str, str] = {
    "pcan": "install PEAK's PCAN-Basic library (Linux: libpcanbasic from peak-system.com, "
            "with the peak driver or the kernel's peak_usb module; Windows: the PEAK driver "
            "package with PCANBasic.dll)",
    "kvaser": "install Kvaser CANlib (Linux: linuxcan; Windows: the Kvaser drivers) from "
              "kvaser.com",
    "vector": "install the Vector driver setup with the XL Driver Library (vxlapi) from "
              "vector.com and assign the channel in Vector Hardware Config",
    "ixxat": "install the IXXAT VCI driver (Windows) or ECI (Linux) from hms-networks.com",
    "socketcan": "bring the Linux interface up: sudo ip link set can0 up type can bitrate "
                 "1000000",
    "slcan": "check the SLCAN adapter's serial device (e.g. slcan:/dev/ttyACM0) and its "
             "permissions",
    "gs_usb": "install pyusb and libusb (pip install pyusb) and check the USB permissions",
    "socketcand": "start socketcand there (or a virtual bus: `servobus sim <protocol> "
                  "--socketcand HOST:PORT`)",
}
CAN_FALLBACK = ("check the interface name and its driver (python-can's interface list: "
                "https://python-can.readthedocs.io/en/stable/interfaces.html)")

#: pyserial URL scheme -> what to check when it cannot be opened.
PORT_HINTS: dict[str, str] = {
    "sim": "check the sim:// options (docs/axis.md: ids, fast, state, model)",
    "socket": "start the serial-to-TCP bridge or a virtual line (`servobus sim <protocol> "
              "--listen tcp://HOST:PORT`), or fix HOST:PORT",
    "tcp": "start the serial-to-TCP bridge or a virtual line (`servobus sim <protocol> "
           "--listen tcp://HOST:PORT`), or fix HOST:PORT",
    "rfc2217": "start the RFC 2217 server, or fix HOST:PORT",
}
NETWORK_HINT = ("check that the drive is on and reachable at that address (ping it), the port, "
                "or start its virtual drive (`servobus sim <protocol>`)")
PORT_FALLBACK = ("check the port name (Linux /dev/ttyUSB0, Windows COM3), that the adapter is "
                 "plugged in and that you may use it (Linux: the dialout group)")


def check_reachable(url: DriveUrl) -> None:
    """A socketcand transport: refuse at once (CliError) when nothing accepts TCP there."""
    if url.transport != "socketcand":
        return
    address = url.target.partition("/")[0]
    host, sep, port_text = address.rpartition(":")
    if not sep or not host or not port_text.isdigit():
        raise CliError(f"{url.raw}: socketcand address {address!r} is not HOST:PORT",
                       "write <protocol>+socketcand://HOST:PORT[/can0]")
    host, port = host, int(port_text)
    try:
        with socket.create_connection((host, port), timeout=SOCKETCAND_PROBE_S):
            pass
    except OSError as exc:
        reason = exc.strerror or str(exc) or type(exc).__name__
        raise CliError(f"cannot reach socketcand at {host}:{port} ({reason})",
                       CAN_DRIVERS["socketcand"]) from None


_HOST_PORT = re.compile(r"[^/:]+:\d+(/.*)?")


def known_transports() -> set[str]:
    """What may follow ``+``: pyserial's URL schemes, python-can's interfaces, ours."""
    import can.interfaces  # lazy: only on a failure
    import serial.urlhandler

    serial_schemes = {m.name.removeprefix("protocol_")
                      for m in pkgutil.iter_modules(serial.urlhandler.__path__)}
    return serial_schemes | set(can.interfaces.VALID_INTERFACES) | set(PORT_HINTS) \
        | set(CAN_DRIVERS)


def transport_failure(url: DriveUrl) -> CliError | None:
    """A transport that cannot be right, with what was probably meant (module docstring)."""
    if url.transport == "socketcan" and _HOST_PORT.fullmatch(url.target):
        return CliError(f"cannot open CAN bus {url.raw}: socketcan takes a Linux CAN "
                        f"interface (can0), not the network address {url.target}",
                        f"for a socketcand server write {url.scheme}+socketcand://{url.target}")
    if not url.transport or url.transport in known_transports():
        return None
    close = difflib.get_close_matches(url.transport, sorted(known_transports()), n=1)
    if not close:  # nothing resembles it: the CAN interface list says what exists
        return None
    return CliError(f"unknown transport {url.transport!r} in {url.raw}",
                    f"did you mean {url.scheme}+{close[0]}://{url.target}?")


def open_failure(url: DriveUrl, exc: BaseException) -> CliError:
    """The one-line explanation of a port, bus or connection that could not be opened."""
    wrong = transport_failure(url)
    if wrong is not None:
        return wrong
    if url.transport in CAN_DRIVERS:
        return CliError(f"cannot open CAN bus {url.raw}: {_reason(exc)}",
                        CAN_DRIVERS[url.transport])
    if url.transport and url.transport not in PORT_HINTS and "://" not in url.target:
        return CliError(f"cannot open CAN bus {url.raw}: {_reason(exc)}", CAN_FALLBACK)
    scheme = url.transport or url.scheme
    if scheme not in PORT_HINTS and scheme and _looks_like_host(url.target):
        return CliError(f"cannot reach {url.raw}: {_reason(exc)}", NETWORK_HINT)
    return CliError(f"cannot open {url.raw}: {_reason(exc)}",
                    PORT_HINTS.get(scheme, PORT_FALLBACK))


def _looks_like_host(target: str) -> bool:
    """``192.168.1.10``, ``drive.local:44818``: a network address, not a serial device."""
    return bool(target) and not target.startswith("/") and not target.upper().startswith("COM")


def _reason(exc: BaseException) -> str:
    text = one_line(str(exc)) or type(exc).__name__
    return text.rstrip(".")
