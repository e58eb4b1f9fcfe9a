"""The virtual YZ-AIM integrated motors: the register file (``motor.YzaimMotor``) on the
protocol-free :class:`servobus.sim.core.motor.Motor`, their sizing, EEPROM and fleets."""
