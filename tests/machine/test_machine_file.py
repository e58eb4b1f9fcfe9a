"""The machine file: every key, and every mistake one line naming file, axis and key."""

from __future__ import annotations

from pathlib import Path

import pytest
from machine_rig import MIXED, write_machine

from servobus.errors import ArgumentRangeError, MachineFileError
from servobus.machine import load_machine_file, parse_machine


def test_the_mixed_file_parses_with_defaults(tmp_path: Path) -> None:
    spec = load_machine_file(write_machine(tmp_path))
    assert spec.name == "test-cell"
    assert [a.name for a in spec.axes] == ["x", "y", "c"]
    x, y, c = spec.axes
    assert (x.url, x.drive_id, x.unit, x.per_rev, x.limits, x.speed) == (
        "sim://dyn232?fast=1", 1, "mm", 5.0, (-10.0, 300.0), 50.0)
    assert y.direction == -1 and y.limits is None and y.origin == "none"
    assert c.per_rev == 360.0 and c.gear == 1.0


def test_name_defaults_to_the_file_stem(tmp_path: Path) -> None:
    text = MIXED.replace('name = "test-cell"\n', "")
    assert load_machine_file(write_machine(tmp_path, text, "cell-7.toml")).name == "cell-7"


AXIS = '[axes.x]\nurl = "sim://dyn232"\nunit = "mm"\nper_rev = 5.0\n'

MISTAKES = [
    ("", None, "axes", "names no axis"),
    ("bogus = 1\n" + AXIS, None, "bogus", "unknown key"),
    ("[axes.x]\nunit = \"mm\"\nper_rev = 1.0\n", "x", "url", "missing"),
    (AXIS + "id = 300\n", "x", "id", "0..255"),
    (AXIS + "id = true\n", "x", "id", "integer"),
    (AXIS.replace('"mm"', '"inch"'), "x", "unit", "one of mm, deg, rev, counts"),
    ('[axes.x]\nurl = "sim://"\nunit = "mm"\n', "x", "per_rev", "missing"),
    (AXIS.replace("5.0", "0"), "x", "per_rev", "> 0"),
    ('[axes.x]\nurl = "sim://"\nper_rev = 2.0\n', "x", "per_rev", "counts axis"),
    (AXIS + "gear = -2\n", "x", "gear", "> 0"),
    (AXIS + "direction = 2\n", "x", "direction", "1 or -1"),
    (AXIS + "limits = [300.0, -10.0]\n", "x", "limits", "low must be below high"),
    (AXIS + "limits = [1.0]\n", "x", "limits", "[low, high]"),
    (AXIS + "limits = [0, \"a\"]\n", "x", "limits", "finite number"),
    (AXIS + "speed = nan\n", "x", "speed", "finite number"),
    (AXIS + "accel = 0\n", "x", "accel", "> 0"),
    (AXIS + "origin = \"later\"\n", "x", "origin", "none, set, home"),
    (AXIS + "limit = [0, 1]\n", "x", "limit", "unknown key"),
    (AXIS.replace("axes.x", 'axes."x y"'), "x y", None, "letters, digits"),
    (AXIS.replace("axes.x", 'axes."ü"'), "ü", None, "letters, digits"),
    (AXIS + AXIS.replace("axes.x", "axes.z"), "z", "id", "already axis x"),
    ("[axes.x\n", None, None, "not valid TOML"),
]


@pytest.mark.parametrize(("text", "axis", "key", "words"), MISTAKES)
def test_every_mistake_is_one_line_naming_file_axis_and_key(
        tmp_path: Path, text: str, axis: str | None, key: str | None, words: str) -> None:
    path = write_machine(tmp_path, text)
    with pytest.raises(MachineFileError) as info:
        load_machine_file(path)
    message = str(info.value)
    assert "\n" not in message
    expected = str(path) + (f": axis {axis}" if axis else "") + (f": {key}" if key else "")
    assert message.startswith(expected + ":"), message
    assert words in message
    assert isinstance(info.value, ArgumentRangeError)  # the argument/range family: exit 2


def test_a_missing_file_is_one_line(tmp_path: Path) -> None:
    with pytest.raises(MachineFileError, match=r"^.*nope\.toml: cannot read"):
        load_machine_file(tmp_path / "nope.toml")


def test_axis_names_may_have_digits_dash_and_underscore() -> None:
    spec = parse_machine(AXIS.replace("axes.x", "axes.x_2-b"))
    assert spec.axes[0].name == "x_2-b"


def test_continuous_is_a_bool_only_without_limits_and_the_url_may_say_it() -> None:
    """Issue 27: only an axis that may turn for ever (no limits) runs open-ended speed."""
    axis = '[axes.s]\nurl = "sim://dyn232"\n'
    assert not parse_machine(axis).axes[0].continuous
    assert parse_machine(axis + "continuous = true\n").axes[0].continuous
    assert parse_machine(axis.replace("dyn232", "dyn232?continuous=1")).axes[0].continuous
    with pytest.raises(MachineFileError, match=r"axis s: continuous: must be true or false"):
        parse_machine(axis + 'continuous = "yes"\n')
    with pytest.raises(MachineFileError, match=r"axis s: continuous: .*no soft limits"):
        parse_machine(axis + "continuous = true\nlimits = [0.0, 1.0]\n")
    with pytest.raises(MachineFileError, match=r"continuous: .*no soft limits"):
        parse_machine(axis.replace("dyn232", "dyn232?continuous=1") + "limits = [0.0, 1.0]\n")


async def test_a_url_says_continuous_to_its_axis() -> None:
    from servobus.axis.connect import connect_async

    for url, want in (("sim://dyn232?fast=1&continuous=1", True), ("sim://dyn232?fast=1", False),
                      ("sim://dyn232?fast=1&continuous=no", False)):
        axis = await connect_async(url)
        try:
            assert axis.continuous is want, url
        finally:
            await axis.close()
    with pytest.raises(ArgumentRangeError, match="continuous must be 1 or 0"):
        await connect_async("sim://dyn232?continuous=maybe")
