"""Character, frame and inter-frame times of an RTU line.

Decisions (Modbus over Serial Line v1.02 section 2.5.1.1; spec 004 section 1):

* A character is as many bits as the line really sends. The standard's RTU character is 11
  bits (8 data + parity + 1 stop, or 8 data + 2 stops), but the YZ-AIM serial port runs
  19200 8N1 (spec 004, "Serial ttl (19200, 8, n, 1)"): 10 bits. A receiver measures silence
  in its own character times, so t3.5 at 19200 8N1 is 3.5 x 10 / 19200 = 1.823 ms (11-bit
  characters would give 2.005 ms).
* Above 19200 baud the standard fixes t3.5 at 1.750 ms, whatever the character size.
"""

from __future__ import annotations

from servobus.errors import ArgumentRangeError

DEFAULT_BAUD = 19_200  # spec 004: the YZ-AIM TTL serial port
BITS_PER_CHAR = 10  # 8N1: start bit, 8 data bits, stop bit
GAP_CHARS = 3.5  # t3.5: silence that ends a frame
FIXED_GAP_ABOVE_BAUD = 19_200  # above this rate t3.5 is a fixed time ...
FIXED_GAP_S = 0.00175  # ... of 1.75 ms


def char_time_s(baud: int = DEFAULT_BAUD, bits_per_char: int = BITS_PER_CHAR) -> float:
    """Seconds one character occupies the line."""
    if baud <= 0 or bits_per_char <= 0:
        raise ArgumentRangeError(f"baud {baud} and bits per character {bits_per_char} "
                                 "must be positive")
    return bits_per_char / baud


def wire_time_s(n_bytes: int, baud: int = DEFAULT_BAUD,
                bits_per_char: int = BITS_PER_CHAR) -> float:
    """Seconds ``n_bytes`` back to back occupy the line (no gaps)."""
    return n_bytes * char_time_s(baud, bits_per_char)


def inter_frame_gap_s(baud: int = DEFAULT_BAUD, bits_per_char: int = BITS_PER_CHAR) -> float:
    """t3.5: the silence that ends a frame (and must precede the next one)."""
    if baud > FIXED_GAP_ABOVE_BAUD:
        char_time_s(baud, bits_per_char)  # validates the arguments
        return FIXED_GAP_S
    return GAP_CHARS * char_time_s(baud, bits_per_char)
