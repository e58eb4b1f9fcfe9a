"""What every protocol client shares, below the Axis (docs/architecture.md).

``transaction`` the one transaction policy (deadlines, retries, lanes, pacing, dead links),
``late_replies`` the replies owed by timed-out attempts, ``eeprom_guard`` the EEPROM wear
guard, ``stats`` the counters, ``can`` and ``stream`` the bases of the CAN and the
byte-stream clients (the medium, the receive loop, closing), ``opening`` a client on an
open medium (closed again when
the client refuses its options). A link knows no protocol and no simulator; it moves nothing
itself (``servobus.transport`` does).
"""
