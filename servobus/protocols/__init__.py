"""One package per wire protocol: codec, commands, client, virtual-drive front end, server.

Each package's ``__init__`` is light: it declares the URL schemes it serves (``SCHEMES``,
scheme -> ``"module:opener"``, read by :mod:`servobus.axis.registry`), its in-process virtual
drive for ``sim://<name>`` (``SIM``), and its CLI additions (``CLI``, ``"module:register"``).
No package here imports another one.
"""
