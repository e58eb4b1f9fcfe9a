"""EtherNet/IP (CIP) for the DMM DYN5: encapsulation, CPF, Message Router, Connection
Manager and Class 1 codecs (pure), the virtual DYN5 adapter and its asyncio server, the
explicit-messaging client, the Axis and the Class 1 scanner, docs/enip.md.

URLs: ``enip://192.168.50.18[:44818]``; ``sim://enip`` (in-process adapters on loopback).
Spec: DMM "DYN5 EtherNet/IP Specification" 1.1A; the device model (Parameter instances,
Identity values, quirks) is ``servobus.families.dyn5.params``.
"""

from servobus.protocols import ProtocolSpec

#: Explicit messaging speaks only when asked (Class 1 I/O runs inside ``monitor_io``'s call,
#: or on an AsyncAxis): the sync facade runs ``enip://`` calls on the caller's thread.
SPEC = ProtocolSpec.conventional("enip", "dmm-dyn5",
                                  params="servobus.families.dyn5.family:PARAM_NAMES",
                                  inline_schemes=("enip",), link="network")
