"""Transports move bytes or frames only; they know nothing about packets' meaning."""

from servobus.transport.base import ByteStream, Direction, TraceHook

__all__ = ["ByteStream", "Direction", "TraceHook"]
