"""The gateway's DataValues (servobus.gateway.opcua_server.WrittenValue): their deep copy is
themselves, and on the wire and in asyncua's monitored items they are plain DataValues."""

from __future__ import annotations

import copy
import dataclasses
import datetime

from asyncua import ua
from asyncua.server.monitored_item_service import MonitoredItemService, MonitoredItemValues
from asyncua.ua.ua_binary import struct_to_binary

from servobus.gateway.opcua_server import WrittenValue

WHEN = datetime.datetime(2026, 11, 27, 12, 0, tzinfo=datetime.UTC)


def test_a_deep_copy_is_the_value_itself() -> None:
    value = WrittenValue(ua.Variant(1.5, ua.VariantType.Double), SourceTimestamp=WHEN)
    assert copy.deepcopy(value) is value
    plain = ua.DataValue(ua.Variant(1.5, ua.VariantType.Double), SourceTimestamp=WHEN)
    assert copy.deepcopy(plain) is not plain  # what asyncua's monitored items would pay for


def test_it_encodes_as_a_plain_data_value_alone_and_in_a_notification() -> None:
    def both(**fields: object) -> tuple[bytes, bytes]:
        return (struct_to_binary(WrittenValue(**fields)),
                struct_to_binary(ua.DataValue(**fields)))

    good, good_plain = both(Value=ua.Variant(-2.25, ua.VariantType.Double),
                            SourceTimestamp=WHEN)
    assert good == good_plain
    bad, bad_plain = both(StatusCode=ua.StatusCode(ua.StatusCodes.BadCommunicationError),
                          SourceTimestamp=WHEN)
    assert bad == bad_plain and bad != good
    note = ua.MonitoredItemNotification(ClientHandle=7, Value=WrittenValue(
        ua.Variant(True, ua.VariantType.Boolean), SourceTimestamp=WHEN))
    plain = ua.MonitoredItemNotification(ClientHandle=7, Value=ua.DataValue(
        ua.Variant(True, ua.VariantType.Boolean), SourceTimestamp=WHEN))
    assert struct_to_binary(note) == struct_to_binary(plain)


def test_a_monitored_item_still_sees_each_change() -> None:
    values = MonitoredItemValues()
    trigger = ua.DataChangeTrigger.StatusValue
    for position in (1.0, 2.0):
        values.set_current_datavalue(WrittenValue(
            ua.Variant(position, ua.VariantType.Double), SourceTimestamp=WHEN))
        assert MonitoredItemService._is_data_changed(values, trigger)
    values.set_current_datavalue(WrittenValue(ua.Variant(2.0, ua.VariantType.Double),
                                              SourceTimestamp=WHEN))
    assert not MonitoredItemService._is_data_changed(values, trigger)
    # asyncua nulls the value of a Bad write with dataclasses.replace: still ours, still Bad
    bad = dataclasses.replace(
        WrittenValue(StatusCode=ua.StatusCode(ua.StatusCodes.BadTimeout)),
        Value=ua.Variant(None, ua.VariantType.Null))
    assert isinstance(bad, WrittenValue) and bad.StatusCode is not None
    assert bad.StatusCode.is_bad()
