"""A long-running command's events on stderr: one line each (a link lost or back, a
possible power loss, an acknowledgement, an interrupted motion), never one per retry.

Library chatter stays with servobus.cli.main's rule (only with ``--debug``); the loggers
named here are the ones whose INFO and above are events a person at the server must see.
"""

from __future__ import annotations

import logging
import sys

FORMAT = "%(levelname)s %(name)s: %(message)s"


def log_events(*names: str) -> None:
    """Send the INFO-and-above records of ``names`` to stderr, one line each."""
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter(FORMAT))
    for name in names:
        logger = logging.getLogger(name)
        logger.setLevel(logging.INFO)
        logger.addHandler(handler)
        logger.propagate = False
