"""DMM DYN5 family: the Parameter object instance table (params.py), the Axis view
(family.py) and the DYN5 profile over instance reads and writes (axis.py)."""
