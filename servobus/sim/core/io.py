"""JP3 pulse-train decoding (DYN2 manual 2.3, 4.1): Pulse/Dir, CW/CCW, A/B quadrature.

Levels are (pin 6, pin 4) samples: STEP/A/CW and DIR/B/CCW. Forward (+) = CW shaft rotation.
Decisions: Pulse/Dir counts rising STEP edges, DIR high = forward; CW/CCW counts rising edges
on either line; A/B counts one pulse per quadrature cycle (rising A edge; A leading B =
forward), so every format gives 4 x GEAR_NUM pulses per revolution.
"""

from __future__ import annotations

from collections.abc import Iterable
from enum import Enum


class PulseFormat(Enum):
    PULSE_DIR = "pulse_dir"
    CW_CCW = "cw_ccw"
    AB = "ab"


class PulseDecoder:
    def __init__(self, fmt: PulseFormat = PulseFormat.PULSE_DIR) -> None:
        self.format = fmt
        self._last = (False, False)

    def feed(self, levels: Iterable[tuple[bool, bool]]) -> int:
        """Decode level samples; returns the signed pulse count."""
        count = 0
        a0, b0 = self._last
        fmt = self.format
        for a, b in levels:
            if fmt is PulseFormat.PULSE_DIR:
                if a and not a0:
                    count += 1 if b else -1
            elif fmt is PulseFormat.CW_CCW:
                if a and not a0:
                    count += 1
                if b and not b0:
                    count -= 1
            elif a and not a0:  # A/B: on A's rising edge, B low means A leads B
                count += -1 if b else 1
            a0, b0 = a, b
        self._last = (a0, b0)
        return count


#: One pulse of a train (4.1 "Reference Pulse Format"), as (pin 6, pin 4) level samples,
#: forward and reverse. Pulse/Dir: one STEP pulse with DIR high (forward) or low; CW/CCW: a
#: pulse on CW (pin 6) or CCW (pin 4); A/B: one quadrature cycle, A leading B forward.
_PERIODS: dict[tuple[PulseFormat, bool], tuple[tuple[bool, bool], ...]] = {
    (PulseFormat.PULSE_DIR, True): ((False, True), (True, True)),
    (PulseFormat.PULSE_DIR, False): ((False, False), (True, False)),
    (PulseFormat.CW_CCW, True): ((False, False), (True, False)),
    (PulseFormat.CW_CCW, False): ((False, False), (False, True)),
    (PulseFormat.AB, True): ((False, False), (True, False), (True, True), (False, True)),
    (PulseFormat.AB, False): ((False, False), (False, True), (True, True), (True, False)),
}


def pulse_period(fmt: PulseFormat, forward: bool) -> tuple[tuple[bool, bool], ...]:
    """Level samples of one pulse of a ``fmt`` train, forward (CW) or reverse."""
    return _PERIODS[(fmt, forward)]
