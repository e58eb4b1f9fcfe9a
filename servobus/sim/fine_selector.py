"""An epoll selector with microsecond timeouts, for the paced simulator's event loop.

``select()`` has microsecond timeouts but fails beyond file descriptor 1023 (``ValueError:
filedescriptor out of range in select()``: a server holding ~1,020 connections died of it);
epoll scales to any number of descriptors but rounds timeouts up to the millisecond, which
would make paced replies up to 1 ms late. :class:`FineEpollSelector` keeps every descriptor
in epoll and waits on the epoll descriptor itself with ``select()``: an epoll descriptor is
readable exactly when one of its descriptors has an event, and it is created with the loop,
so its number is small. Only when it is not (>= 1024) does the wait fall back to epoll's own
millisecond timeout.
"""

from __future__ import annotations

import asyncio
import contextlib
import select
import selectors

FD_SETSIZE = 1024  # select()'s limit on descriptor numbers (glibc)


if hasattr(selectors, "EpollSelector"):  # Linux

    class FineEpollSelector(selectors.EpollSelector):
        """``selectors.EpollSelector`` whose finite timeouts have microsecond resolution."""

        def select(self, timeout: float | None = None
                   ) -> list[tuple[selectors.SelectorKey, int]]:
            if timeout is not None and timeout > 0:
                fd = self.fileno()
                if fd < FD_SETSIZE:
                    with contextlib.suppress(InterruptedError):
                        select.select([fd], [], [], timeout)
                    timeout = 0  # then collect whatever is ready without waiting again
            return super().select(timeout)


def fine_event_loop() -> asyncio.AbstractEventLoop:
    """An asyncio loop for the simulator servers (``asyncio.Runner(loop_factory=...)``):
    :class:`FineEpollSelector` on Linux, the platform's default selector elsewhere (kqueue
    already has sub-millisecond timeouts)."""
    if hasattr(selectors, "EpollSelector"):
        return asyncio.SelectorEventLoop(FineEpollSelector())
    return asyncio.SelectorEventLoop(selectors.DefaultSelector())
