"""Opening a port or CAN bus from the command line: check first, explain failures in one line.

* socketcand: a bounded TCP connect to HOST:PORT before python-can is asked to open it
  (python-can's socketcand client retries for 10 s and logs every attempt when nothing
  listens). The probe connection is closed at once; socketcand serves the next one.
* any exception while opening (python-can's CanInterfaceNotImplementedError /
  CanInitializationError, a missing vendor library's OSError, pyserial's SerialException,
  a refused TCP connection) becomes one :class:`CliError` naming the port and what to do,
  e.g. which vendor driver a CAN interface needs.
"""

from __future__ import annotations

import socket

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
    "socketcand": "start socketcand there (or `servobus sim dyncan --socketcand HOST:PORT`)",
}
CAN_FALLBACK = ("check the interface name and its driver (python-can's interface list: "
                "https://python-can.readthedocs.io/en/stable/interfaces.html)")

#: pyserial URL scheme -> what to check when it cannot be opened.
PORT_HINTS: dict[str, str] = {
    "sim": "check the sim:// options (README: ids, fast, state, model)",
    "socket": "start the serial-to-TCP bridge or `servobus sim dyn2 --listen tcp://HOST:PORT`, "
              "or fix HOST:PORT",
    "tcp": "start the serial-to-TCP bridge or `servobus sim dyn2 --listen tcp://HOST:PORT`, "
           "or fix HOST:PORT",
    "rfc2217": "start the RFC 2217 server, or fix HOST:PORT",
}
PORT_FALLBACK = ("check the port name (Linux /dev/ttyUSB0, Windows COM3), that the adapter is "
                 "plugged in and that you may use it (Linux: the dialout group)")


def can_interface(spec: str) -> str:
    return spec.partition(":")[0].lower()


def check_can_reachable(spec: str) -> None:
    """socketcand only: refuse at once (CliError) when nothing accepts TCP at HOST:PORT."""
    if can_interface(spec) != "socketcand":
        return
    from servobus.transport.can_bus import parse_can_spec

    try:
        kwargs = parse_can_spec(spec)
    except ValueError as exc:  # ArgumentRangeError: malformed HOST:PORT
        raise CliError(f"--can {spec}: {exc}", "write socketcand:HOST:PORT") from None
    host, port = kwargs["host"], kwargs["port"]
    try:
        with socket.create_connection((host, port), timeout=SOCKETCAND_PROBE_S):
            pass
    except OSError as exc:
        reason = exc.strerror or str(exc) or type(exc).__name__
        raise CliError(f"cannot reach socketcand at {host}:{port} ({reason})",
                       CAN_DRIVERS["socketcand"]) from None


def can_open_failure(spec: str, exc: BaseException) -> CliError:
    """The one-line explanation of a CAN bus that python-can could not open."""
    todo = CAN_DRIVERS.get(can_interface(spec), CAN_FALLBACK)
    return CliError(f"cannot open CAN bus {spec}: {_reason(exc)}", todo)


def port_open_failure(url: str, exc: BaseException) -> CliError:
    """The one-line explanation of a DYN232M port (or URL) that could not be opened."""
    scheme = url.split("://", 1)[0].lower() if "://" in url else ""
    return CliError(f"cannot open {url}: {_reason(exc)}", PORT_HINTS.get(scheme, PORT_FALLBACK))


def _reason(exc: BaseException) -> str:
    text = one_line(str(exc)) or type(exc).__name__
    return text.rstrip(".")
