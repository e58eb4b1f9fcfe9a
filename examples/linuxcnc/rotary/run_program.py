#!/usr/bin/python3
"""A headless LinuxCNC display (``DISPLAY = ./run_program.py``): leave E-stop, machine on,
home every joint, run the INI's [DISPLAY] OPEN_FILE, wait until the feedback stands on the
command, exit (LinuxCNC then shuts down, and servobus hal stops its axes).

LinuxCNC's own tests drive it the same way; docs/linuxcnc.md. Debian's python3 finds the
``linuxcnc`` module of linuxcnc-uspace by itself.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable

import linuxcnc  # type: ignore[import-not-found]

POLL_S = 0.05
#: How near its command a joint's feedback must stand before the display exits (LinuxCNC
#: then shuts down and servobus hal stops the axes): two counts of a YZ-AIM motor, in degrees.
SETTLED = 0.022

command = linuxcnc.command()
status = linuxcnc.stat()
errors = linuxcnc.error_channel()
seen: list[str] = []  # LinuxCNC's error messages (a following error, an amplifier fault)


def until(done: Callable[[], bool], what: str, timeout: float = 60.0) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        status.poll()
        error = errors.poll()
        if error:
            print(f"linuxcnc: {error[1]}", flush=True)
            seen.append(str(error[1]))
        if done():
            return
        time.sleep(POLL_S)
    print(f"run_program: {what}: not within {timeout:g} s", flush=True)
    sys.exit(1)


def leave_estop() -> None:
    """E-stop reset, retried: the E-stop chain closes once servobus sees the reset."""
    end = time.monotonic() + 60.0
    while True:
        command.state(linuxcnc.STATE_ESTOP_RESET)
        command.wait_complete()
        time.sleep(0.2)
        status.poll()
        if status.task_state == linuxcnc.STATE_ESTOP_RESET or time.monotonic() > end:
            return


def main() -> None:
    ini = linuxcnc.ini(sys.argv[sys.argv.index("-ini") + 1])
    program = ini.find("DISPLAY", "OPEN_FILE")
    leave_estop()
    until(lambda: status.task_state == linuxcnc.STATE_ESTOP_RESET, "E-stop reset")
    command.state(linuxcnc.STATE_ON)
    until(lambda: status.task_state == linuxcnc.STATE_ON, "machine on")
    command.mode(linuxcnc.MODE_MANUAL)
    command.wait_complete()
    command.home(-1)
    until(lambda: all(status.homed[j] for j in range(status.joints)), "homed")
    command.mode(linuxcnc.MODE_AUTO)
    command.wait_complete()
    command.program_open(program)
    command.auto(linuxcnc.AUTO_RUN, 0)
    until(lambda: status.interp_state != linuxcnc.INTERP_IDLE, "program started", 10.0)
    until(lambda: status.interp_state == linuxcnc.INTERP_IDLE, "program ended", 120.0)
    until(lambda: all(abs(status.joint[j]["output"] - status.joint[j]["input"]) < SETTLED
                      for j in range(status.joints)), "feedback on the command")
    if seen:
        print(f"run_program: failed: {seen[0]}", flush=True)
        sys.exit(1)
    print("run_program: done at " + " ".join(
        f"joint {j} {status.joint[j]['input']:.3f}" for j in range(status.joints)), flush=True)


if __name__ == "__main__":
    main()
