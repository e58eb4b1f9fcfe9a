"""Virtual drives: a protocol-free core (``core/``: engine, Motor, traces, state files), one
package per family (``dmm/``: VirtualDrive; ``yzaim/``: YzaimMotor) and the shared servers;
each protocol's front end and server live in its package."""

from servobus.sim.dmm.drive import VirtualDrive
from servobus.sim.dmm.eeprom import EepromStore

__all__ = ["EepromStore", "VirtualDrive"]
