"""Real-time thread priority (SCHED_FIFO) for the threads whose timing is the product: Class 1.

Decision (issue 22), measured with benchmarks/bench_enip.py on a 2-core machine at load
9-12: 16 virtual adapters x RPI 5 ms, p99 interval error at the scanner's socket 7.3 ms
(max 47 ms) under the default scheduler, 0.11 ms (max 0.45 ms) with the adapters' loop
thread at SCHED_FIFO. A CPU-bound process beside a normal thread takes its core for
whole scheduler slices (several ms); a SCHED_FIFO thread preempts it as soon as its timer
expires. Linux applies ``sched_setscheduler(0, ...)`` to the calling thread only, so
servobus asks for it on threads it owns - the ``servobus sim enip`` loop, and the Class 1
clock thread when ``SERVOBUS_CLOCK_REALTIME=1`` (opt-in: ``enip/clock.py`` says why) -
never on a user's thread. It needs root or CAP_SYS_NICE (or an RLIMIT_RTPRIO
above 0, e.g. ``@realtime - rtprio 20`` in /etc/security/limits.conf); without it the
thread runs as before and one log line says so. Safety: the threads that ask for it sleep
between frames and spin at most :data:`servobus.protocols.enip.clock.SPIN_NS`, and the
kernel keeps 5 % of each core for other work (``sched_rt_runtime_us``).
``SERVOBUS_REALTIME=0`` turns it off everywhere.
"""

from __future__ import annotations

import logging
import os

log = logging.getLogger("servobus.thread_priority")

#: SCHED_FIFO priority servobus asks for (1-99; above the default 0 of normal threads,
#: below the kernel's own threads at 50 and the usual audio/IRQ threads).
DEFAULT_PRIORITY = 10
#: Environment variable: ``0`` (or ``off``) never asks for real-time scheduling.
ENV = "SERVOBUS_REALTIME"


def enabled_by_env() -> bool:
    return os.environ.get(ENV, "").strip().lower() not in ("0", "off", "no", "false")


def request_realtime(what: str, priority: int = DEFAULT_PRIORITY) -> bool:
    """SCHED_FIFO at ``priority`` for the calling thread; True if granted. Not permitted
    or not on Linux: False and one log line naming ``what`` and what to configure."""
    if not enabled_by_env():
        return False
    setter = getattr(os, "sched_setscheduler", None)
    fifo = getattr(os, "SCHED_FIFO", None)
    if setter is None or fifo is None:
        log.info("%s: real-time scheduling is not available on this platform; it keeps the "
                 "default scheduler", what)
        return False
    try:
        setter(0, fifo, os.sched_param(priority))
    except OSError as exc:
        log.info("%s: SCHED_FIFO not permitted (%s); it keeps the default scheduler and may "
                 "run late beside CPU-bound work (docs/enip.md: run as root, grant "
                 "CAP_SYS_NICE, or set RLIMIT_RTPRIO)", what, exc.strerror or exc)
        return False
    return True


def is_realtime() -> bool:
    """The calling thread runs under SCHED_FIFO or SCHED_RR."""
    getter = getattr(os, "sched_getscheduler", None)
    if getter is None:
        return False
    policy = getter(0)
    return policy in (getattr(os, "SCHED_FIFO", -1), getattr(os, "SCHED_RR", -1))
