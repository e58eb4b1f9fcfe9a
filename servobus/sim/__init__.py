"""Virtual drives: one protocol-free core (``VirtualDrive``) and one server per protocol."""

from servobus.sim.dmm.drive import VirtualDrive
from servobus.sim.dmm.eeprom import EepromStore

__all__ = ["EepromStore", "VirtualDrive"]
