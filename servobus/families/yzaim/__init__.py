"""YZ-AIM family: the register map, models and alarms (registers.py), the Axis view
(family.py) and the YZ-AIM profile over register reads and writes (axis.py)."""
