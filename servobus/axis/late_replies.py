"""Moved to :mod:`servobus.link.late_replies` (issue 19: ``axis/`` is the API only).

This alias keeps old imports working for one release; import from ``servobus.link``.
"""

from servobus.link.late_replies import DEFAULT_LATE_REPLY_S, LateReplies

__all__ = ["DEFAULT_LATE_REPLY_S", "LateReplies"]
