"""``origin = "set"`` zeroes an axis once, not at every command (issue 28).

A machine applies an origin rule once, when the axis's link first opens, never again on a
reopen; the one-shot CLI commands apply none and say so, so two ``move 90deg`` in two
commands end with ``position`` reading 90 deg (the motor is served by a simulator in its own
process, as a real drive outlives each command).
"""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from machine_rig import Run, write_machine
from machine_rig import run as run  # the fixture, for this module
from subprocess_rig import read_line, stop_process

from servobus.axis import connect
from servobus.machine import AsyncMachineAxis, open_machine_async

ORIGIN_SET = ('[axes.c]\nurl = "{url}"\nid = 1\nunit = "deg"\nlimits = [-360, 360]\n'
              'origin = "set"\n')


@pytest.fixture
def set_origin_calls(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    calls: list[str] = []
    real = AsyncMachineAxis.set_origin

    async def counted(self: AsyncMachineAxis) -> None:
        calls.append(self.name)
        await real(self)

    monkeypatch.setattr(AsyncMachineAxis, "set_origin", counted)
    return calls


async def test_the_rule_runs_once_per_machine_and_never_on_a_reopen(
        tmp_path: Path, set_origin_calls: list[str]) -> None:
    path = write_machine(tmp_path, ORIGIN_SET.format(url="sim://easycan?fast=1"))
    async with await open_machine_async(path) as machine:
        assert set_origin_calls == ["c"] and machine.origins_skipped == ()
        for link in machine.links:  # what a link coming back online runs
            await machine._apply_origins(link)
        assert set_origin_calls == ["c"]


async def test_origins_false_applies_none_and_names_them(
        tmp_path: Path, set_origin_calls: list[str]) -> None:
    path = write_machine(tmp_path, ORIGIN_SET.format(url="sim://easycan?fast=1"))
    async with await open_machine_async(path, origins=False) as machine:
        assert set_origin_calls == [] and machine.origins_skipped == ("c",)
        for link in machine.links:
            await machine._apply_origins(link)
        assert set_origin_calls == []


@pytest.fixture
def easycan_url() -> Iterator[str]:
    sim = subprocess.Popen([sys.executable, "-m", "servobus", "sim", "easycan", "--socketcand",
                            "127.0.0.1:0", "--ids", "1", "--duration", "90"],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        yield "easycan+socketcand://" + read_line(sim, "listening on ").split()[-1]
    finally:
        stop_process(sim)


@pytest.mark.slow  # a simulator process and wall-clock motion
@pytest.mark.timeout(90)
def test_two_cli_moves_to_90_deg_end_at_90_deg(tmp_path: Path, easycan_url: str,
                                              run: Run) -> None:
    with connect(easycan_url, drive_id=1, timeout=2.0) as motor:  # not at the origin
        motor.move_to(motor.degrees(45), wait=True, timeout=20)
    m = str(write_machine(tmp_path, ORIGIN_SET.format(url=easycan_url)))
    for _ in range(2):
        code, _, err = run("--machine", m, "--axis", "c", "move", "90deg", "--wait")
        assert code == 0, err
        assert 'c (origin = "set"): not applied by a one-shot command' in err
    code, out, err = run("--machine", m, "--axis", "c", "--json", "position")
    assert code == 0, err
    assert abs(json.loads(out)["position"] - 90.0) < 0.2  # +-10 counts = +-0.11 deg
    code, out, err = run("--machine", m, "--json", "status")
    assert code == 0, err
    assert abs(json.loads(out)["axes"][0]["position"] - 90.0) < 0.2
