"""``servobus users add|list|remove``, the users file (salted scrypt hashes) and the login
budget (per peer address and in all, on a real OPC UA server too)."""

from __future__ import annotations

import json
from collections.abc import AsyncIterator
from pathlib import Path

import pytest
from asyncua import ua
from asyncua.ua.uaerrors import UaStatusCodeError
from click.testing import CliRunner
from fake_machine import FakeMachine

from benchmarks.faults_hostile import bound_client
from servobus.cli.failures import describe
from servobus.cli.main import cli
from servobus.gateway import users as users_module
from servobus.gateway.commands import Commander
from servobus.gateway.opcua_server import FileUsers, OpcUaGateway, OpcUaOptions, _login_peer
from servobus.gateway.users import (
    LOGIN_BURST,
    PEER_BURST,
    Admission,
    LoginBudget,
    Users,
    peer_key,
)


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


# ------------------------------------------------------------------ login budget (issue 30)
class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_a_peer_budget_counts_wrong_passwords_beside_the_cap_in_all() -> None:
    clock = Clock()
    budget = LoginBudget(clock=clock)
    wrong = [budget.take("10.0.0.1") for _ in range(12)]
    assert wrong == [Admission.CHECK] * PEER_BURST + [Admission.PEER_SPENT] * (12 - PEER_BURST)
    assert budget.take("10.0.0.2") is Admission.CHECK  # another peer still has its checks
    budget.refund("10.0.0.2")  # a right password costs its peer nothing ...
    for _ in range(LOGIN_BURST - PEER_BURST - 1):
        assert budget.take("10.0.0.2") is Admission.CHECK
        budget.refund("10.0.0.2")
    # ... but every check counts in all: the cap holds for every peer, new ones too
    assert budget.take("10.0.0.2") is Admission.ALL_SPENT
    assert budget.take("10.0.0.3") is Admission.ALL_SPENT
    clock.now += 1.0 / budget.per_second  # one check earned back in all
    assert budget.take("10.0.0.3") is Admission.CHECK
    assert budget.take("10.0.0.1") is Admission.PEER_SPENT  # still spent: 2 s a try
    clock.now += budget.peer_interval_s
    assert budget.take("10.0.0.1") is Admission.CHECK


def test_many_peers_together_are_held_to_the_cap_in_all() -> None:
    """A loopback client has 2**24 addresses: each has its own budget, the cap in all holds."""
    clock = Clock()
    budget = LoginBudget(clock=clock)
    checks = sum(budget.take(f"127.0.{i // 250}.{i % 250 + 1}") is Admission.CHECK
                 for i in range(1000))
    assert checks == LOGIN_BURST
    clock.now += 10.0
    checks = sum(budget.take(f"127.1.{i // 250}.{i % 250 + 1}") is Admission.CHECK
                 for i in range(1000))
    assert checks == LOGIN_BURST  # the burst again, never more, whatever the addresses


def test_the_peer_table_is_bounded_and_forgets_idle_peers() -> None:
    clock = Clock()
    budget = LoginBudget(per_second=1e9, burst=1_000_000, clock=clock, max_peers=50)
    for i in range(500):
        budget.take(f"10.1.{i // 200}.{i % 200}")
        assert len(budget) <= 50
    budget.take("10.9.9.9")
    budget.take("10.9.9.9")
    clock.now += PEER_BURST * budget.peer_interval_s  # every budget refilled: all idle
    budget.take("10.9.9.8")
    assert len(budget) == 1  # only the peer just seen


def test_peers_are_counted_by_address_and_ipv6_by_its_64() -> None:
    assert peer_key("127.0.0.2") == "127.0.0.2"
    assert peer_key("2001:db8::1") == peer_key("2001:db8::ffff:1") == "2001:db8::/64"
    assert peer_key("2001:db8:0:1::1") != peer_key("2001:db8::1")
    assert peer_key("::ffff:10.0.0.1") == "10.0.0.1"
    assert peer_key("fe80::1%eth0") == "fe80::/64"
    assert peer_key("") == ""


def test_a_flood_is_one_log_line_per_spell(caplog: pytest.LogCaptureFixture,
                                           monkeypatch: pytest.MonkeyPatch) -> None:
    users = Users()
    users.add("op", "correct horse")
    monkeypatch.setattr(users_module, "_hash", lambda *a: b"x" * 32)  # no scrypt needed here
    clock = Clock()
    manager = FileUsers(users, LoginBudget(clock=clock))
    with caplog.at_level("WARNING", logger="servobus.gateway.opcua_server"):
        for _ in range(100):
            assert manager.get_user(None, "op", "wrong password") is None
    spent = [r for r in caplog.records if "refused unchecked" in r.getMessage()]
    wrong = [r for r in caplog.records if "wrong name or password" in r.getMessage()]
    assert len(spent) == 1 and len(wrong) == PEER_BURST
    assert "wrong passwords from this address" in spent[0].getMessage()


# ------------------------------------------------------------------ on a real OPC UA server
USER, PASSWORD = "op", "correct horse"


async def login(endpoint: str, source: str, password: str) -> bool:
    """A user login from ``source``: True when the session was activated."""
    client = bound_client(endpoint, source)  # asyncua cannot choose its address
    client.set_user(USER)
    client.set_password(password)
    try:
        await client.connect()
    except UaStatusCodeError as exc:
        assert exc.code == ua.StatusCodes.BadUserAccessDenied
        return False
    await client.disconnect()
    return True


@pytest.fixture
async def server(monkeypatch: pytest.MonkeyPatch) -> AsyncIterator[tuple[str, Clock, list[str]]]:
    """The gateway's OPC UA server in this process; its budget's clock stands still unless
    the test moves it; the peers whose passwords were hashed, in order."""
    users = Users()
    users.add(USER, PASSWORD)
    machine = FakeMachine()
    gateway = OpcUaGateway(machine, Commander(machine),  # type: ignore[arg-type]
                           OpcUaOptions("opc.tcp://127.0.0.1:0", users=users))
    clock = Clock()
    manager: FileUsers = gateway.server.iserver.user_manager
    manager.budget = LoginBudget(clock=clock)
    hashed: list[str] = []
    verify = users.verify

    def counted(name: str | None, password: str | None) -> bool:
        hashed.append(_login_peer.get())  # the peer FileUsers was told of
        return verify(name, password)

    monkeypatch.setattr(users, "verify", counted)
    await gateway.start()
    try:
        yield gateway.endpoint, clock, hashed
    finally:
        await gateway.stop()


@pytest.mark.timeout(120)
async def test_wrong_logins_from_one_peer_leave_another_peer_its_login(
        server: tuple[str, Clock, list[str]]) -> None:
    endpoint, clock, hashed = server
    for _ in range(12):
        assert not await login(endpoint, "127.0.0.2", "wrong password")
    assert hashed == ["127.0.0.2"] * PEER_BURST  # the others were refused unhashed
    assert await login(endpoint, "127.0.0.3", PASSWORD)
    assert not await login(endpoint, "127.0.0.2", PASSWORD)  # its own budget is spent
    clock.now += 2.0  # one wrong password more earned back
    assert await login(endpoint, "127.0.0.2", PASSWORD)
    # the cap in all: peer after peer, no more hashes than the burst, the right password too
    hashed.clear()
    clock.now += 100.0
    results = [await login(endpoint, f"127.0.1.{i}", "wrong password") for i in range(1, 11)]
    assert not any(results) and len(hashed) == LOGIN_BURST
    assert not await login(endpoint, "127.0.2.1", PASSWORD)
    assert len(hashed) == LOGIN_BURST
    clock.now += 1.0
    assert await login(endpoint, "127.0.2.1", PASSWORD)
