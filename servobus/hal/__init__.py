"""``servobus hal``: a LinuxCNC userspace HAL component serving one machine file
(docs/linuxcnc.md). A front end: it knows no protocol or family, only the machine axes and
their typed capabilities."""
