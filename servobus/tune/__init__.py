"""``servobus tune``: the manuals' trial-and-error tuning, done by the tool (docs/tuning.md).

:mod:`~servobus.tune.tuner` runs the procedure against a :class:`~servobus.tune.plant.Plant`
(the drive as the tuner sees it: gains by role from ``Capability.TUNING``, a leased test move
that returns a :class:`~servobus.tune.record.Record`). The plant of a real or ``sim://``
axis is :mod:`servobus.tune.axis_plant`; the simulated-time plant of the tests and the
benchmark is :mod:`servobus.sim.tune_plant`.
"""
