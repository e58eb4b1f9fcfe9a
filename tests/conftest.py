"""Fixtures and pytest hooks only; the helpers tests import live in rig.py and the *_rig.py
modules (never ``from conftest import``: docs/testing.md).

* ``async def test_...`` functions run on a fresh event loop each, by pytest-asyncio in auto
  mode (pyproject ``asyncio_mode = "auto"``): no marker, no decorator.
* Hypothesis runs the same examples every time, without its per-example deadline.
* Ctrl-C reaches the processes tests start, even from a run in the background.
* The processes tests start reuse compiled bytecode (``share_bytecode``).
* Tuning runs record their kept gains in a folder of the run's own (``own_state_folder``).
* The test process's garbage collector skips what collection built and runs less often
  (``collect_less``).
* At the end of a run (of each xdist worker) ``no_child_left_behind`` fails if a process
  started by a test is still running, naming it.
"""

from __future__ import annotations

import atexit
import contextlib
import gc
import os
import shutil
import signal
import sys
import tempfile
import time
from collections.abc import Iterator

import pytest
from hypothesis import settings

# Hypothesis's per-example deadline (200 ms) is a wall-clock assertion: a loaded machine
# failed a 0.03 ms codec example at 624 ms. Examples are still bounded by pytest's timeout.
# The examples are the same in every run (derandomize): a rare input drawn by chance once
# turned an unrelated change's run red (the eager Modbus framer's two-way frame, issue 22).
# SERVOBUS_HYPOTHESIS_EXPLORE=1 draws new ones, to search.
settings.register_profile("servobus", deadline=None,
                          derandomize=not os.environ.get("SERVOBUS_HYPOTHESIS_EXPLORE"))
settings.load_profile("servobus")


def share_bytecode() -> None:
    """The suite starts hundreds of Python processes (virtual drives, CLI runs, gateways);
    each compiled servobus's modules anew, about 0.2 s of CPU, where the environment sets
    PYTHONDONTWRITEBYTECODE (this one does) or the checkout is editable and read-only.

    They write and read bytecode under one folder in the temporary directory instead
    (PYTHONPYCACHEPREFIX), never in the checkout; Python checks each file against its
    source, and writes it atomically, so concurrent workers share it safely.
    """
    prefix = os.path.join(tempfile.gettempdir(), f"servobus-pycache-{os.getuid()}")
    os.environ.pop("PYTHONDONTWRITEBYTECODE", None)
    os.environ.setdefault("PYTHONPYCACHEPREFIX", prefix)
    sys.dont_write_bytecode = False
    sys.pycache_prefix = os.environ["PYTHONPYCACHEPREFIX"]


share_bytecode()


def own_state_folder() -> None:
    """Tuning runs record the kept gains in the user's state folder (servobus.tune.kept):
    the suite's runs, and the processes it starts, record in a folder of its own instead,
    so that a test killed mid-run never leaves a record in the user's home that refuses
    the user's next tuning run (or the next test run's)."""
    folder = tempfile.mkdtemp(prefix="servobus-state-")
    os.environ["XDG_STATE_HOME"] = folder
    atexit.register(shutil.rmtree, folder, ignore_errors=True)


own_state_folder()


# ------------------------------------------------------------ garbage collector
#: Allocations between two young collections in the test process (CPython: 700).
GC_YOUNG_THRESHOLD = 10_000


def collect_less() -> None:
    """The suite is CPU-bound on a 2-core machine, and a good part of its own process's CPU
    was the cyclic garbage collector: every full collection walks every live object, and the
    test process holds many - the imported modules, the collected tests, and asyncua's
    address spaces (about half a million objects each) that the gateway tests build in
    process. Measured on the OPC UA cache and user tests: 30-50 % of their CPU.

    So, in the test process only (the processes tests start keep CPython's settings): young
    collections run every ``GC_YOUNG_THRESHOLD`` allocations instead of 700, and what
    collection left alive is frozen out of later scans (``pytest_collection_finish``).
    Garbage is still collected, later; memory is still bounded (full collections still run
    once the heap grew by a quarter). A test that needs a collection calls ``gc.collect()``.
    Not higher: a middle-generation collection walks up to ten young generations, and
    in-process drives answer within 50 ms (10,000 kept most of the gain of 50,000).
    """
    _gen0, gen1, gen2 = gc.get_threshold()
    gc.set_threshold(GC_YOUNG_THRESHOLD, gen1, gen2)


collect_less()


def pytest_collection_finish(session: pytest.Session) -> None:
    """Freeze what collection built (modules, test items): alive for the whole run anyway,
    no collection needs to walk it again (``collect_less``)."""
    gc.collect()
    gc.freeze()


def pytest_configure(config: pytest.Config) -> None:
    """Ctrl-C reaches the processes the tests start.

    A run launched in the background of a non-interactive shell (``cmd &`` in a script, CI
    runners, nohup) has SIGINT ignored, and every child inherits that: the tests that press
    Ctrl-C on the CLI or the GUI would see a process that shrugs it off. Python's own handler
    (the interactive default) is put back; exec resets it to the default in each child.
    """
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


# ------------------------------------------------------------ no child left behind
LEFTOVER_GRACE_S = 10.0  # a child being stopped may take this long to go away on a loaded machine


def _children_of(pid: int) -> dict[int, int]:
    """Every process on the machine -> its parent, read from /proc (Linux; {} elsewhere)."""
    parents: dict[int, int] = {}
    try:
        entries = os.listdir("/proc")
    except OSError:
        return parents
    for entry in entries:
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat", encoding="utf-8", errors="replace") as f:
                stat = f.read()
        except OSError:  # gone meanwhile
            continue
        # "pid (comm) state ppid ...": comm may hold spaces and parentheses
        fields = stat[stat.rindex(")") + 2:].split()
        if fields[0] != "Z":  # a zombie has exited; only running leftovers matter
            parents[int(entry)] = int(fields[1])
    return parents


def leftover_processes() -> list[str]:
    """The live descendants of this process, as "pid: command line"."""
    parents = _children_of(os.getpid())
    found: list[int] = []
    todo = [os.getpid()]
    while todo:
        parent = todo.pop()
        kids = [p for p, pp in parents.items() if pp == parent]
        found += kids
        todo += kids
    out = []
    for pid in sorted(found):
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                cmd = f.read().replace(b"\0", b" ").decode(errors="replace").strip()
        except OSError:
            continue
        out.append(f"{pid}: {cmd}")
    return out


@pytest.fixture(scope="session", autouse=True)
def no_child_left_behind() -> Iterator[None]:
    """At the end of the session (of each xdist worker) no process started by a test is still
    running: a server, simulator or browser left behind is a bug of the test that started it.
    Fails the session's last teardown naming every leftover."""
    yield
    deadline = time.monotonic() + LEFTOVER_GRACE_S
    while (left := leftover_processes()) and time.monotonic() < deadline:
        time.sleep(0.1)  # polling /proc: a process ending has no event to wait on here
    if left:
        for line in left:  # named below; stopped so that they do not outlive the run
            with contextlib.suppress(OSError):
                os.kill(int(line.split(":", 1)[0]), signal.SIGKILL)
        pytest.fail("processes left behind by the tests:\n  " + "\n  ".join(left),
                    pytrace=False)
