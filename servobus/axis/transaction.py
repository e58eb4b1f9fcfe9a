"""Moved to :mod:`servobus.link.transaction` (issue 19: ``axis/`` is the API only).

This alias keeps old imports working for one release; import from ``servobus.link``.
"""

from servobus.link.stats import TransactionStats
from servobus.link.transaction import DEFAULT_RETRIES, TransactionManager, check_call

__all__ = ["DEFAULT_RETRIES", "TransactionManager", "TransactionStats", "check_call"]
