"""Global CLI options shared by every command group."""

from __future__ import annotations

from dataclasses import dataclass

import click

EMBEDDED_SIM_URL = "sim://dyn232"


@dataclass
class CliContext:
    port: str | None  # pyserial URL; None -> the embedded virtual drive
    drive_id: int
    baud: int | None
    json: bool
    can: str | None  # "INTERFACE:CHANNEL" for DYN CAN, None for DYN232M
    timeout: float | None

    @property
    def url(self) -> str:
        """The drive URL the global options name (``--can`` is a shortcut for dyncan+...)."""
        if self.can:
            interface, _, channel = self.can.partition(":")
            return f"dyncan+{interface}://{channel}"
        return self.port or EMBEDDED_SIM_URL


pass_cli = click.make_pass_decorator(CliContext)
