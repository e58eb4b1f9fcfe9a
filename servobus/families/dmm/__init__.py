"""DMM DYN2 / DC2 / DYN4 family: parameters, status and config registers, units, profiles,
the shared DYN232M/DYN CAN vocabulary, and the DMM Axis profile (axis.py, command_axis.py)."""
