"""DMM DYN2 / DC2 / DYN4 family: parameters, status and config registers, units, profiles."""
