"""One identity per gateway: its id, MQTT client id, OPC UA URIs and topic prefix.

Decisions (docs/gateway.md "Identity", issue 30):

* ``--gateway-id ID`` names the gateway; by default it is the machine's name (a name with
  characters outside :data:`ID_CHARS` has each of them turned into ``-``). An id given
  by hand must be 1-64 of those characters: it is part of a URN and of a client id.
* The MQTT client id is ``servobus-<ID>``, the same at every connection and every start:
  a broker closes the older connection when a new one takes its client id, so a gateway
  that reconnects after a half-open blip replaces its own stale connection at once
  instead of leaving it to fire its last will later (servobus.gateway.mqtt_presence).
* The OPC UA ApplicationUri and the namespace of the gateway's node ids are
  ``urn:servobus:gateway:<ID>``: an aggregating server that merges many gateways keeps
  their nodes apart. Browse names and types stay in ``urn:servobus:gateway``, the same
  for every gateway, so a client written for one finds its way in all.
* Topics live under ``<prefix>/<machine>`` (``--mqtt-prefix``, default ``servobus``).
"""

from __future__ import annotations

import re

from servobus.errors import InvalidValue

#: The namespace of servobus's browse names and types, shared by every gateway.
TYPES_URI = "urn:servobus:gateway"
DEFAULT_PREFIX = "servobus"
MAX_ID = 64
ID_CHARS = "letters, digits, '.', '_' and '-'"
_ID = re.compile(r"^[A-Za-z0-9._-]{1,64}$")
_NOT_ID = re.compile(r"[^A-Za-z0-9._-]")
_PREFIX = re.compile(r"^[^+#\0]+$")


def gateway_id(machine_name: str, given: str | None = None) -> str:
    """The gateway's id: ``given`` (checked), else the machine's name made fit."""
    if given is not None:
        if not _ID.match(given):
            raise InvalidValue(f"--gateway-id {given!r}: 1-{MAX_ID} {ID_CHARS}")
        return given
    return _NOT_ID.sub("-", machine_name)[:MAX_ID] or "gateway"


def client_id(ident: str) -> str:
    """The gateway's MQTT client id."""
    return f"servobus-{ident}"


def application_uri(ident: str) -> str:
    """The gateway's OPC UA ApplicationUri, also the namespace of its node ids."""
    return f"{TYPES_URI}:{ident}"


def check_prefix(prefix: str) -> str:
    """``--mqtt-prefix``: one or more topic levels, no wildcard, no empty level."""
    if not _PREFIX.match(prefix) or "" in prefix.split("/"):
        raise InvalidValue(f"--mqtt-prefix {prefix!r}: topic levels without '+', '#' "
                                 "or an empty level (e.g. servobus or plant/line-3)")
    return prefix
