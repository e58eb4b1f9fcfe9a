"""``servobus users add|list|remove`` and the users file (salted scrypt hashes)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from servobus.cli.failures import describe
from servobus.cli.main import cli
from servobus.gateway import users as users_module
from servobus.gateway.opcua_server import FileUsers
from servobus.gateway.users import LoginBudget, Users


def run(*args: str, stdin: str | None = None) -> tuple[int, str]:
    """The command in-process; a failure is described as servobus.cli.main reports it."""
    result = CliRunner().invoke(cli, list(args), input=stdin)
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        code, line = describe(result.exception)
        return code, result.output + line
    return result.exit_code, result.output


def test_users_add_stores_a_salted_hash_read_from_stdin(tmp_path: Path) -> None:
    path = tmp_path / "users.json"
    assert run("users", "add", "robot", "--file", str(path), stdin="same password\n")[0] == 0
    assert run("users", "add", "plc-7", "--file", str(path), stdin="same password\n")[0] == 0
    text = path.read_text()
    assert "same password" not in text
    stored = json.loads(text)["users"]
    assert stored["robot"]["scheme"] == "scrypt"
    assert stored["robot"]["salt"] != stored["plc-7"]["salt"]
    assert stored["robot"]["hash"] != stored["plc-7"]["hash"]  # salted: same password differs
    assert path.stat().st_mode & 0o077 == 0
    users = Users.load(path)
    assert users.verify("robot", "same password")
    assert not users.verify("robot", "same passwore")
    assert not users.verify("nobody", "same password")
    assert not users.verify(None, None)
    code, out = run("users", "list", "--file", str(path))
    assert (code, out.split()) == (0, ["plc-7", "robot"])
    code, out = run("users", "add", "robot", "--file", str(path), stdin="a new password\n")
    assert code == 0 and "replaced" in out
    assert Users.load(path).verify("robot", "a new password")
    assert run("users", "remove", "plc-7", "--file", str(path))[0] == 0
    assert list(Users.load(path).records) == ["robot"]


def test_bad_names_passwords_and_files_are_refused(tmp_path: Path) -> None:
    path = tmp_path / "users.json"
    code, out = run("users", "add", "robot", "--file", str(path), stdin="short\n")
    assert code == 2 and "password" in out and not path.exists()
    code, out = run("users", "add", "no/slash", "--file", str(path), stdin="long enough\n")
    assert code == 2 and "user name" in out
    path.write_text("{not json")
    code, out = run("users", "list", "--file", str(path))
    assert code == 2 and "not a servobus users file" in out
    code, _ = run("users", "remove", "ghost", "--file", str(tmp_path / "none.json"))
    assert code == 2


def test_logins_beyond_the_budget_are_refused_without_hashing(
        monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture) -> None:
    """A flood of OPC UA logins costs the gateway's loop at most the budget's scrypt hashes."""
    users = Users()
    users.add("op", "correct horse")
    hashes: list[str] = []
    real = users_module._hash
    monkeypatch.setattr(users_module, "_hash",
                        lambda *a: (hashes.append("h"), real(*a))[1])
    now = [100.0]
    manager = FileUsers(users, LoginBudget(per_second=2.0, burst=2, clock=lambda: now[0]))
    assert manager.get_user(None, "op", "correct horse") is not None
    assert manager.get_user(None, "op", "wrong password") is None
    assert len(hashes) == 2
    with caplog.at_level("WARNING", logger="servobus.gateway.opcua_server"):
        assert manager.get_user(None, "op", "correct horse") is None  # spent: not hashed
    assert len(hashes) == 2 and "password checks a second" in caplog.text
    assert manager.get_user(None) is not None  # anonymous (read-only) costs nothing
    now[0] += 0.5  # one check earned back
    assert manager.get_user(None, "op", "correct horse") is not None
    assert manager.get_user(None, "op", "correct horse") is None
    assert len(hashes) == 3
