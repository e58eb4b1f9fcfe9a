"""Modbus RTU (the YZ-AIM TTL serial port, 19200 8N1): generic frames, no device registers.

``crc`` CRC-16/MODBUS; ``codec`` frames <-> frozen dataclasses for both sides; ``timing``
character and inter-frame times; ``framer`` cutting a byte stream into frames (by silence
and content for a line or sniffer, by predicted length for a host awaiting a reply).
"""
