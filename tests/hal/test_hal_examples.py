"""The LinuxCNC examples hold together (examples/linuxcnc): each machine file parses, every
servobus pin the HAL file names exists, each position axis gets its command and feeds
back, and the E-stop chain and the watchdog are wired. (The rotary example also runs in the
full LinuxCNC: test_hal_halrun.py.)"""

from __future__ import annotations

import configparser
import re
from pathlib import Path

import pytest

from servobus.hal.pins import AXIS_PINS, COMPONENT_PINS
from servobus.machine.config import load_machine_file

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "linuxcnc"
PIN = re.compile(r"\bservobus\.([A-Za-z0-9_.-]+)")


def ini_of(folder: Path) -> configparser.ConfigParser:
    ini = configparser.ConfigParser(strict=False, interpolation=None)
    ini.read(next(folder.glob("*.ini")))
    return ini


@pytest.mark.parametrize("example", ["mill", "rotary"])
def test_the_example_holds_together(example: str) -> None:
    folder = EXAMPLES / example
    ini = ini_of(folder)
    hal_text = (folder / ini["HAL"]["HALFILE"]).read_text()
    assert (folder / ini["DISPLAY"]["OPEN_FILE"]).is_file()
    loadusr = next(line for line in hal_text.splitlines() if line.startswith("loadusr"))
    machine_name = re.search(r"--machine (\S+)", loadusr)
    assert machine_name is not None
    spec = load_machine_file(folder / machine_name.group(1))
    known = {p.name for p in COMPONENT_PINS} | {
        f"{axis.name}.{p.name}" for axis in spec.axes for p in AXIS_PINS}
    named = set(PIN.findall(hal_text.replace("servobus-", "")))
    assert named <= known, named - known
    assert {"fault", "watchdog"} <= named  # the E-stop chain and the watchdog
    assert "iocontrol.0.emc-enable-in" in hal_text
    for axis in spec.axes:
        assert f"{axis.name}.fault-reset" in named
        if axis.hal == "position":
            assert {f"{axis.name}.position-cmd", f"{axis.name}.position-fb"} <= named


def test_the_examples_are_one_position_and_one_monitor_machine() -> None:
    modes = {folder.name: {a.hal for a in load_machine_file(next(folder.glob("*.toml"))).axes}
             for folder in EXAMPLES.iterdir() if folder.is_dir()}
    assert modes == {"mill": {"monitor"}, "rotary": {"position"}}
