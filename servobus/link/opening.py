"""Opening a client on a medium that is already open: one rule for every opener."""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol, TypeVar

C = TypeVar("C")


class Closable(Protocol):
    async def close(self) -> None: ...


M = TypeVar("M", bound=Closable)


async def client_on(medium: M, make: Callable[[M], C]) -> C:
    """``make(medium)``; when that raises (a bad option: ArgumentRangeError, nothing was
    sent) the medium is closed again before the error goes on."""
    try:
        return make(medium)
    except BaseException:
        await medium.close()
        raise
