"""Pure EtherNet/IP explicit-messaging commands for the host: the Message Router request a
service on a class/instance/attribute becomes, and the retry rule. No I/O.

Retry rule (servobus decision, docs/enip.md): Get_Attribute_Single and Get_Attributes_All
are reads, re-sent after a timeout; every other service (Set_Attribute_Single, Forward_Open,
...) is sent once.
"""

from __future__ import annotations

from servobus.protocols.enip.codec import epath
from servobus.protocols.enip.codec.cip import MessageRouterRequest, Service

READ_SERVICES = frozenset({Service.GET_ATTRIBUTES_ALL, Service.GET_ATTRIBUTE_SINGLE})


def make_message(service: int, class_id: int, instance: int,
                 attribute: int | None = None) -> bytes:
    """The encoded Message Router request without data (a Set appends its data)."""
    path = epath.request_path(class_id, instance, attribute)
    return MessageRouterRequest(service, path).encode()


def is_read(service: int) -> bool:
    """A read service: retried after a timeout."""
    return service in READ_SERVICES
