"""Transports move bytes or frames only; they know nothing about packets' meaning.

``base`` (ByteStream, Direction, TraceHook), ``serial_stream``, ``tcp_stream``, ``pair`` (the
in-process pair with fault injection), ``buffered``, ``can_bus`` (python-can and frame ports),
``trace``, ``address`` (is_loopback).
"""
