"""Global CLI options shared by every command group: which drive, how to talk to it."""

from __future__ import annotations

import os
from dataclasses import dataclass

import click

#: The built-in virtual drive: used when no drive is named (the simulator picks the protocol).
EMBEDDED_SIM_URL = "sim://"
URL_ENV = "SERVOBUS_URL"
ID_ENV = "SERVOBUS_ID"
MACHINE_ENV = "SERVOBUS_MACHINE"


@dataclass
class CliContext:
    url_option: str | None  # --url
    port: str | None  # --port: a serial port or pyserial URL (a shortcut)
    can: str | None  # --can INTERFACE:CHANNEL (a shortcut for the CAN protocol's URL)
    drive_id_option: int | None  # --id
    baud: int | None
    json: bool
    timeout: float | None
    machine_option: str | None = None  # --machine FILE
    axis_option: str | None = None  # --axis NAME

    @property
    def machine_path(self) -> str | None:
        """The machine file named: --machine, else SERVOBUS_MACHINE unless --url/--port/--can
        names a drive (an option beats the environment; docs/machine.md)."""
        if self.machine_option:
            return self.machine_option
        if self.url_option or self.port or self.can:
            return None
        return os.environ.get(MACHINE_ENV) or None

    @property
    def machine_mode(self) -> bool:
        """Commands act on a machine's axis: a file is named, or ``--axis`` without any drive
        URL (then the built-in virtual machine)."""
        if self.machine_option and (self.url_option or self.port or self.can):
            raise click.UsageError("give --machine FILE or a drive (--url/--port/--can), "
                                   "not both")
        if self.machine_path is not None or self.axis_option is not None:
            self._refuse_drive_options()
        if self.machine_path is not None:
            return True
        if self.axis_option is not None:
            if self.url_given:
                raise click.UsageError(f"--axis {self.axis_option} names an axis of a machine "
                                       "file; add --machine FILE (or drop --axis)")
            return True
        return False

    def _refuse_drive_options(self) -> None:
        """--id, --baud and --timeout name a drive's link: a machine axis takes its own from
        the file, so with --machine/--axis they would be ignored (a usage error instead)."""
        given = [name for name, value in (("--id", self.drive_id_option), ("--baud", self.baud),
                                          ("--timeout", self.timeout)) if value is not None]
        if given and not (self.url_option or self.port or self.can):
            raise click.UsageError(f"{', '.join(given)} would be ignored: a machine axis "
                                   "takes its id and link from the machine file (drop "
                                   f"{' and '.join(given)}, or name a drive with --url "
                                   "instead of --machine/--axis)")

    @property
    def named_url(self) -> str | None:
        """The URL the user named (options first, then SERVOBUS_URL), or None."""
        if self.url_option:
            return self.url_option
        if self.port:
            return self.port
        if self.can:
            return can_shortcut(self.can)
        return os.environ.get(URL_ENV) or None

    @property
    def url_given(self) -> bool:
        return self.named_url is not None

    @property
    def url(self) -> str:
        return self.named_url or EMBEDDED_SIM_URL

    @property
    def drive_id(self) -> int | None:
        """``--id``, else SERVOBUS_ID, else None (the protocol's default id)."""
        if self.drive_id_option is not None:
            return self.drive_id_option
        text = os.environ.get(ID_ENV, "").strip()
        if not text:
            return None
        try:
            return int(text)
        except ValueError:
            raise click.BadParameter(f"{ID_ENV}={text!r} is not a drive id") from None


def can_shortcut(spec: str) -> str:
    """``--can INTERFACE:CHANNEL`` -> the drive URL of the protocol that claims the shortcut."""
    from servobus.axis import registry

    template = registry.provided("SHORTCUTS").get("can")
    if template is None:
        raise click.UsageError("no installed protocol serves --can; use --url")
    interface, sep, channel = spec.partition(":")
    if not sep or not interface:
        raise click.BadParameter(f"{spec!r}: write INTERFACE:CHANNEL, e.g. pcan:PCAN_USBBUS1 or "
                                 "socketcand:127.0.0.1:29536", param_hint="--can")
    return template.format(interface=interface, channel=channel)


pass_cli = click.make_pass_decorator(CliContext)
