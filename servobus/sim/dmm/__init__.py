"""The virtual DMM drives (DYN2/DC2/DYN4, and the DYN5 core): parameters, registers, JP3
I/O and DMM alarms on the engine (``drive.VirtualDrive``), General_Read actions, their
EEPROM (``eeprom``), fleets, trace view (``trace``) and control channel (``control``)."""
