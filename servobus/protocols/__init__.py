"""One package per wire protocol: codec, commands, client, virtual-drive front end, server.

A protocol package never imports another protocol package; what two protocols share (device
families, the drive core, transports) lives in ``servobus.families``, ``servobus.sim`` and
``servobus.transport``.
"""
