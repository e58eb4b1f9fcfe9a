"""OK/MISS against each figure's target, and the summary line ``python -m benchmarks`` ends with.

Benchmarks are not tests: a MISS is reported, never raised, and the exit status stays 0.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

OK, MISS = "OK", "MISS"


@dataclass(frozen=True)
class Figure:
    name: str
    value: float
    target: str  # e.g. ">= 97 %"
    ok: bool


FIGURES: list[Figure] = []
ERRORS: list[str] = []


def percent(x: float) -> str:
    return f"{x * 100:g} %"


def mark(name: str, value: float, *, at_least: float | None = None,
         at_most: float | None = None, show: Callable[[float], str] = "{:g}".format) -> str:
    """``(target >= 97 %) OK`` for a figure line; records the figure for :func:`summary`.

    ``show`` formats the target bound in the figure's unit (e.g. :func:`percent`).
    """
    if (at_least is None) == (at_most is None):
        raise ValueError("give exactly one of at_least, at_most")
    if at_least is not None:
        ok, target = value >= at_least, f">= {show(at_least)}"
    else:
        assert at_most is not None
        ok, target = value <= at_most, f"<= {show(at_most)}"
    FIGURES.append(Figure(name, value, target, ok))
    return f"(target {target}) {OK if ok else MISS}"


def error(module: str, exc: BaseException) -> str:
    """A benchmark that could not run: reported in the summary, not raised."""
    ERRORS.append(module)
    return f"{module}: ERROR {type(exc).__name__}: {exc}"


def summary() -> str:
    missed = [f.name for f in FIGURES if not f.ok]
    text = (f"summary: {len(FIGURES)} figure(s) with a target, "
            f"{len(FIGURES) - len(missed)} {OK}, {len(missed)} {MISS}")
    if missed:
        text += f" ({'; '.join(missed)})"
    if ERRORS:
        text += f"; {len(ERRORS)} benchmark(s) could not run ({', '.join(ERRORS)})"
    return text
