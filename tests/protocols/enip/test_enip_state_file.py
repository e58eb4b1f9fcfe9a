"""``sim enip --state FILE`` starts again on the file it wrote (found with issue 17.4).

Before: the DYN5 records are keyed by the drive's IPv4 address, and the state-file check
wanted a power-on drive id: the second start refused the file the first one had written.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from servobus.protocols.enip.server import DYN5_STATE, make_drive
from servobus.sim.core.state_file import StateFileError, parse_state

pytestmark = pytest.mark.timeout(60)


def test_a_dyn5_record_is_written_and_read_back_by_address(tmp_path: Path) -> None:
    path = tmp_path / "dyn5.json"
    drive = make_drive("127.0.0.1", state=str(path))
    assert drive.set_param("main_gain", 50)
    records = parse_state(path.read_bytes(), str(path), DYN5_STATE)
    assert records["127.0.0.1"]["params"]["main_gain"] == 50
    with pytest.raises(StateFileError, match="IPv4 address"):
        parse_state(b'{"1": {"drive_id": 1}}', "x.json", DYN5_STATE)


def test_sim_enip_starts_again_on_its_own_state_file(tmp_path: Path) -> None:
    path = tmp_path / "dyn5.json"
    path.write_text(json.dumps({"127.0.0.1": {"drive_id": 1, "params": {"main_gain": 50}}}))
    proc = subprocess.run([sys.executable, "-m", "servobus", "sim", "enip", "--tcp-port", "0",
                           "--udp-port", "0", "--state", str(path), "--duration", "0.1"],
                          capture_output=True, text=True, timeout=30)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("listening on enip://")
