"""The gateway process's heap after start-up: out of the garbage collector's scans.

Why (measured, docs/gateway.md "Garbage collection"): a started gateway holds about half
a million objects the cyclic garbage collector tracks, nearly all of them asyncua's
address space (the standard nodeset) built once at start and never freed. CPython's
full (generation 2) collection walks every one of them: 170-265 ms on the benchmark's
2-core machine, during which the event loop stands still - no sample, no OPC UA publish,
no command. One such collection in a 10 s run was the benchmark's single slow move
(a step seen after 190-285 ms instead of 35 ms) and set its p99.

Decision: when the gateway owns its process (``servobus serve``), it collects once after
start-up and then freezes everything that is left (:func:`gc.freeze`): those objects move
to the permanent generation, which no collection scans. Later collections see only what
was made after start-up (sessions, subscriptions, samples in flight): the longest full
collection falls to about 3 ms. Cost: a reference cycle made of start-up objects
that becomes garbage later is never collected (the address space is never torn down while
the gateway runs, so that is none in practice); objects freed by their reference count go
as before. The collector's thresholds stay CPython's: generation 0 and 1 collections take
about 1 ms after the freeze, and a higher threshold would trade them for fewer, longer
pauses.

Start-up (decision, issue 36, docs/gateway.md "Start-up time"): ``servobus serve`` starts
with the collector off (:func:`collector_off`). A start builds hundreds of thousands of
objects that live as long as the gateway (asyncua's address space, loaded from the cache
in one go): every generation-2 collection on the way walked all of them again, a quarter
of the start's CPU when the standard nodes are unpickled. The freeze then skips its own
full collection (another 0.5 s of CPU on the benchmark machine) and freezes the start-up's
garbage with the rest: about 2,900 unreachable objects of 655,000 when measured, kept for
the life of the process; the collector runs again from the freeze on.

A gateway inside someone else's process (tests, an application that embeds
:class:`servobus.gateway.serve.Gateway`) leaves the collector alone: its heap is not the
gateway's to freeze.
"""

from __future__ import annotations

import contextlib
import gc
from collections.abc import Iterator


@contextlib.contextmanager
def collector_off() -> Iterator[None]:
    """The collector off for the block (the start of the process's own gateway; the
    unpickling of a start-up cache), then as it was before; :func:`freeze_startup_heap`
    turns it on sooner."""
    was_on = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_on:
            gc.enable()


def freeze_startup_heap() -> int:
    """Freeze every object (collected first when the collector was on: with it off, the
    start-up's few garbage objects are frozen too), then turn the collector on; returns
    how many are frozen now."""
    if gc.isenabled():
        gc.collect()
    gc.freeze()
    gc.enable()
    return gc.get_freeze_count()
