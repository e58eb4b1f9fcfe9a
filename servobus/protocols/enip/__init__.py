"""EtherNet/IP (CIP) for the DMM DYN5: encapsulation, CPF, Message Router, Connection
Manager and Class 1 codecs (pure), the virtual DYN5 adapter and its asyncio server.

Spec: DMM "DYN5 EtherNet/IP Specification" 1.1A (docs/enip.md); the device model (Parameter
instances, Identity values, quirks) is ``servobus.families.dyn5``.
"""
