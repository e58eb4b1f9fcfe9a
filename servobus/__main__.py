"""``python -m servobus``: the same command as the installed ``servobus`` script."""

from servobus.cli.main import main

if __name__ == "__main__":
    main()
