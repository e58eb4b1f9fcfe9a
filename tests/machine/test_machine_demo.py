"""``servobus demo`` runs on the built-in virtual machine, with its output fixed (issue 20):
the header names the machine (not ``id default``), no empty alarm field, one status block."""

from __future__ import annotations

import json
import subprocess
import sys

SERVOBUS = [sys.executable, "-m", "servobus"]


def run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*SERVOBUS, *args], capture_output=True, text=True, timeout=60)


def test_demo_on_the_builtin_machine_tells_the_story() -> None:
    proc = run("--json", "demo")
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(proc.stdout)
    assert "virtual-cell" in doc["connection"] and "default" not in doc["connection"]
    steps = doc["steps"]
    assert [a["axis"] for a in steps[0]["axes"]] == ["x", "y", "c"]
    assert {a["protocol"] for a in steps[0]["axes"]} == {"dyn232", "easycan"}
    together = next(s for s in steps if s["step"].startswith("move together"))
    assert together["skew_s"] >= 0 and set(together["final"]) == {"x", "y", "c"}
    for name, target in together["targets"].items():
        assert abs(together["final"][name] - target) < 0.05, name
    final = steps[-1]
    assert final["step"] == "final status"
    assert all(line.endswith("no alarm") for line in final["axes"].values())
    assert "built-in virtual machine" in proc.stderr


def test_demo_text_has_one_status_block_and_no_empty_field() -> None:
    proc = run("demo")
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout
    assert out.splitlines()[0].startswith("servobus demo on machine virtual-cell")
    assert "id default" not in out
    assert out.count("machine virtual-cell\n") == 1  # the status table, once
    assert not [line for line in out.splitlines() if line.strip() == "alarm"]  # never empty
    assert "-      sim://easycan" in out  # the table's alarm column says "-" for none
    final = out.split("final status", 1)[1]
    assert "x: " in final and "c: " in final and "no alarm" in final


def test_demo_on_one_drive_names_its_id_and_the_alarm() -> None:
    proc = run("--url", "sim://dyn2?fast=1", "demo")
    assert proc.returncode == 0, proc.stderr
    first = proc.stdout.splitlines()[0]
    assert first == "servobus demo on sim://dyn2?fast=1, id 0"
    assert "  alarm          none" in proc.stdout
    assert proc.stdout.count("status of ") == 1
