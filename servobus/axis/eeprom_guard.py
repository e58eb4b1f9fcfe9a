"""Moved to :mod:`servobus.link.eeprom_guard` (issue 19: ``axis/`` is the API only).

This alias keeps old imports working for one release; import from ``servobus.link``.
"""

from servobus.link.eeprom_guard import EEPROM_CYCLE_LIMIT, EepromGuard, EepromWearWarning

__all__ = ["EEPROM_CYCLE_LIMIT", "EepromGuard", "EepromWearWarning"]
