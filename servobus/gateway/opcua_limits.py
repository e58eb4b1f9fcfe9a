"""Fair limits per OPC UA client: sessions per address, subscriptions and monitored items per
session, published in the server's ServerCapabilities.

Decisions (docs/gateway.md "Limits per client", issue 30):

* at most :data:`MAX_SESSIONS` sessions in all and :data:`MAX_SESSIONS_PER_PEER` from one
  client address (created and not yet closed, activated or not; a session that is not
  activated within 10 s is dropped): one address, even anonymous, never takes every
  session. Beyond, CreateSession answers BadTooManySessions;
* per session at most :data:`MAX_SUBSCRIPTIONS_PER_SESSION` subscriptions (of 200 in all,
  servobus.gateway.opcua_server.MAX_SUBSCRIPTIONS: BadTooManySubscriptions) and
  :data:`MAX_ITEMS_PER_SESSION` monitored items, at most
  :data:`MAX_ITEMS_PER_SUBSCRIPTION` in one subscription (of :data:`MAX_ITEMS` in all).
  An item beyond a cap gets BadTooManyMonitoredItems in its own result; the items before
  it are created. So one address holds at most half of the subscriptions and monitored
  items of the server (10 sessions x 10 subscriptions of 200; 10 x 2,000 items of 40,000);
* a client that vanishes (a pulled cable, a killed process) leaves its session behind
  only until the session's timeout, at most :data:`MAX_SESSION_TIMEOUT_S`: asyncua keeps
  a session with subscriptions open after its connection is lost, for the client to come
  back, and closes it with its subscriptions at that timeout (asyncua's default cap was
  10 minutes; a vanished client's subscriptions then counted against the caps that long).

* TransferSubscriptions moves a subscription to the calling session only from a session
  of the same user (anonymous from anonymous; else BadUserAccessDenied: asyncua moved any
  subscription whose number a client named) and only within the caller's cap
  (BadTooManySubscriptions).

asyncua (2.1) enforces only a server-wide count of subscriptions; the per-session and item
caps are :class:`LimitedSession`'s, the session caps :class:`SessionRoom`'s. The
item counts read asyncua's per-subscription table of items (``_monitored_items``).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable
from typing import Any

from asyncua import Server, ua
from asyncua.common.utils import ServiceError
from asyncua.server.internal_session import InternalSession

log = logging.getLogger(__name__)

MAX_SESSIONS = 64
MAX_SESSIONS_PER_PEER = 10
MAX_SUBSCRIPTIONS_PER_SESSION = 10
MAX_ITEMS = 40_000
MAX_ITEMS_PER_SESSION = 2_000
MAX_ITEMS_PER_SUBSCRIPTION = 1_000
MAX_SESSION_TIMEOUT_S = 120.0

#: ServerCapabilities variable -> the limit it publishes (with MaxSubscriptions and
#: MaxMonitoredItemsQueueSize, which asyncua's own settings hold).
CAPABILITIES: dict[int, int] = {
    ua.ObjectIds.Server_ServerCapabilities_MaxSessions: MAX_SESSIONS,
    ua.ObjectIds.Server_ServerCapabilities_MaxSubscriptionsPerSession:
        MAX_SUBSCRIPTIONS_PER_SESSION,
    ua.ObjectIds.Server_ServerCapabilities_MaxMonitoredItems: MAX_ITEMS,
    ua.ObjectIds.Server_ServerCapabilities_MaxMonitoredItemsPerSubscription:
        MAX_ITEMS_PER_SUBSCRIPTION,
}

PeerOf = Callable[[object], str]


class SessionRoom:
    """MaxSessions, in all and per client address; one warning line per spell of
    refusals (a spell ends when a session is admitted)."""

    def __init__(self) -> None:
        self.refusing = False

    def check(self, sessions: Iterable[InternalSession], name: object,
              peer_of: PeerOf) -> None:
        """ServiceError(BadTooManySessions) when a new session from ``name``'s address
        (asyncua names a session after its connection's peer) would pass a cap."""
        peer = peer_of(name)
        count = from_peer = 0
        for session in sessions:
            count += 1
            from_peer += peer_of(session.name) == peer
        if count < MAX_SESSIONS and from_peer < MAX_SESSIONS_PER_PEER:
            self.refusing = False
            return
        if not self.refusing:
            self.refusing = True
            log.warning("OPC UA sessions refused from %s on: %s", peer or "an unknown address",
                        f"{MAX_SESSIONS} sessions in all" if count >= MAX_SESSIONS else
                        f"{MAX_SESSIONS_PER_PEER} sessions from this address")
        raise ServiceError(ua.StatusCodes.BadTooManySessions)


async def apply_limits(server: Server) -> None:
    """Cap the session timeout and write every limit into the standard ServerCapabilities
    variables (UInt32); after ``server.init()``, with asyncua's own limits set."""
    iserver = server.iserver
    iserver.max_session_timeout_ms = MAX_SESSION_TIMEOUT_S * 1000
    caps = ua.ObjectIds
    values = {**CAPABILITIES,
              caps.Server_ServerCapabilities_MaxSubscriptions: iserver.max_subscriptions,
              caps.Server_ServerCapabilities_MaxMonitoredItemsQueueSize:
                  iserver.max_monitored_item_queue_size}
    for ident, value in values.items():
        await server.write_attribute_value(
            ua.NodeId(ident), ua.DataValue(ua.Variant(value, ua.VariantType.UInt32)))


def _items(subscription: Any) -> int:
    return len(subscription.monitored_item_srv._monitored_items)


class LimitedSession(InternalSession):  # type: ignore[misc]
    """asyncua's session with the per-session caps on subscriptions and monitored items."""

    def _subscriptions(self) -> list[Any]:
        return [s for s in self.subscription_service.subscriptions.values()
                if s.session_id == self.session_id]

    async def create_subscription(self, params: ua.CreateSubscriptionParameters,
                                  callback: Callable[..., Any],
                                  request_callback: Callable[..., Any] | None = None
                                  ) -> ua.CreateSubscriptionResult:
        if len(self._subscriptions()) >= MAX_SUBSCRIPTIONS_PER_SESSION:
            raise ServiceError(ua.StatusCodes.BadTooManySubscriptions)
        result: ua.CreateSubscriptionResult = await super().create_subscription(
            params, callback, request_callback=request_callback)
        return result

    async def create_monitored_items(self, params: ua.CreateMonitoredItemsParameters
                                     ) -> list[ua.MonitoredItemCreateResult]:
        """The items that fit every cap, in order; BadTooManyMonitoredItems for the rest."""
        target = self.subscription_service.subscriptions.get(params.SubscriptionId)
        if target is None or target.session_id != self.session_id:
            raise ServiceError(ua.StatusCodes.BadSubscriptionIdInvalid)
        in_all = sum(_items(s) for s in self.subscription_service.subscriptions.values())
        room = min(MAX_ITEMS_PER_SUBSCRIPTION - _items(target),
                   MAX_ITEMS_PER_SESSION - sum(_items(s) for s in self._subscriptions()),
                   MAX_ITEMS - in_all)
        asked = list(params.ItemsToCreate)
        room = max(0, min(room, len(asked)))
        params.ItemsToCreate = asked[:room]
        results: list[ua.MonitoredItemCreateResult] = (
            await super().create_monitored_items(params) if room else [])
        for _ in asked[room:]:
            refused = ua.MonitoredItemCreateResult()
            refused.StatusCode = ua.StatusCode(ua.StatusCodes.BadTooManyMonitoredItems)
            results.append(refused)
        return results

    async def transfer_subscriptions(
            self, params: ua.TransferSubscriptionsParameters, callback: Callable[..., Any]
    ) -> list[ua.TransferResult]:
        """Only a subscription of the same user, and only within this session's cap."""
        held = len(self._subscriptions())
        refusals: dict[int, int] = {}  # position in the request -> status code
        allowed: list[int] = []
        for position, sub_id in enumerate(params.SubscriptionIds):
            sub = self.subscription_service.subscriptions.get(int(sub_id))
            if sub is None or sub.session_id == self.session_id:
                allowed.append(sub_id)  # asyncua answers these itself
            elif not self._same_user(sub.session_id):
                refusals[position] = ua.StatusCodes.BadUserAccessDenied
            elif held >= MAX_SUBSCRIPTIONS_PER_SESSION:
                refusals[position] = ua.StatusCodes.BadTooManySubscriptions
            else:
                allowed.append(sub_id)
                held += 1
        params.SubscriptionIds = allowed
        moved: list[ua.TransferResult] = (
            await super().transfer_subscriptions(params, callback) if allowed else [])
        results: list[ua.TransferResult] = []
        for position in range(len(allowed) + len(refusals)):
            if position in refusals:
                refused = ua.TransferResult()
                refused.StatusCode = ua.StatusCode(refusals[position])
                results.append(refused)
            else:
                results.append(moved.pop(0))
        return results

    def _same_user(self, session_id: ua.NodeId) -> bool:
        owner = next((s for s in self.iserver._external_sessions.values()
                      if s.session_id == session_id), None)
        return owner is not None and (owner.user.role, owner.user.name) == (
            self.user.role, self.user.name)
