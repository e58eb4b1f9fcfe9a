"""EtherNet/IP (CIP) for the DMM DYN5: encapsulation, CPF, Message Router, Connection
Manager and Class 1 codecs (pure), the virtual DYN5 adapter and its asyncio server, the
explicit-messaging client, the Axis and the Class 1 scanner, docs/enip.md.

URLs: ``enip://192.168.50.18[:44818]``; ``sim://enip`` (in-process adapters on loopback).
Spec: DMM "DYN5 EtherNet/IP Specification" 1.1A; the device model (Parameter instances,
Identity values, quirks) is ``servobus.families.dyn5.params``.
"""

from servobus.protocols import ProtocolSpec

SPEC = ProtocolSpec(
    name="enip",
    family="dmm-dyn5",
    opener="servobus.protocols.enip.opener:open_axis",
    schemes=("enip",),
    sim="servobus.protocols.enip.inprocess:open_sim_axis",
    cli="servobus.protocols.enip.cli:register",
    decoder="servobus.protocols.enip.sniff:DECODER",
    params="servobus.families.dyn5.family:PARAM_NAMES",
)
