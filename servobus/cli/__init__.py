"""The ``servobus`` command: one small module per command group (see main.COMMAND_MODULES)."""
