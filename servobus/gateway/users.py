"""The gateway's users file: names with a salted scrypt hash of each password.

``servobus users add NAME --file FILE`` writes it; ``servobus serve --users FILE`` reads it.
Decisions: JSON (one object per user, readable and diffable), scrypt (hashlib, no extra
package) with n=2**14, r=8, p=1 and a 16-byte random salt per user; the file is written
atomically with mode 0600 (it is not a secret, but nobody else needs to read it).
Passwords are compared in constant time; an unknown name costs the same hash as a known one,
so a probe cannot tell the names apart by timing. A :class:`LoginBudget` bounds how many
password checks run per second where they run on an event loop (asyncua's logins do): per
peer address, so one peer's wrong passwords do not lock out the others, and in all.
"""

from __future__ import annotations

import enum
import hashlib
import hmac
import ipaddress
import json
import os
import re
import secrets
import tempfile
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from servobus.errors import InvalidValue, ServobusError

SCHEME = "scrypt"
N, R, P = 2**14, 8, 1
SALT_BYTES = 16
KEY_BYTES = 32
MAX_FILE_BYTES = 1 << 20
NAME = re.compile(r"[A-Za-z0-9_.@-]{1,64}")
MIN_PASSWORD = 8
MAX_PASSWORD = 1024


#: Password checks per second, and in one burst, that a LoginBudget allows in all (decision;
#: issue 21): one check is a scrypt hash, 30-50 ms of CPU on the project's machine, and
#: asyncua runs it on the gateway's event loop. 4 a second keep a flood of logins to a fifth
#: of the loop's time; 8 at once cover a plant's clients reconnecting.
LOGINS_PER_S = 4.0
LOGIN_BURST = 8
#: Wrong passwords one peer may try (decision; issue 30): 4 at once, then one every 2 s. A
#: right password costs its peer nothing (its check is given back), so a client that knows
#: its password is never slowed by its own peer's budget. Fewer than LOGIN_BURST, so one peer
#: alone can never spend the checks of every other peer: 12 wrong passwords from one address
#: leave the right one from another address its check.
PEER_LOGINS_PER_S = 0.5
PEER_BURST = 4
#: Peers remembered at most (bounded memory): a peer whose budget has refilled is forgotten
#: (it is as good as new); beyond this many, the least recently seen is forgotten first.
MAX_PEERS = 1024


class _Bucket:
    """A token bucket: ``tokens`` at ``at``, refilled at ``rate`` up to ``burst``."""

    def __init__(self, burst: float, rate: float, now: float) -> None:
        self.burst, self.rate = burst, rate
        self.tokens, self.at = burst, now
        self.refusing = False  # its refusal was logged: not again until it admits one

    def refill(self, now: float) -> None:
        self.tokens = min(self.burst, self.tokens + (now - self.at) * self.rate)
        self.at = now

    def full(self, now: float) -> bool:
        return self.tokens + (now - self.at) * self.rate >= self.burst


class Admission(enum.Enum):
    """What :meth:`LoginBudget.take` decided."""

    CHECK = "check"  # hash the password
    PEER_SPENT = "peer"  # this peer tried too many wrong passwords: refused, not hashed
    ALL_SPENT = "all"  # every peer together spent the checks a second: refused, not hashed


def peer_key(address: str) -> str:
    """The budget a client address counts against: an IPv4 address itself, an IPv6 address
    by its /64 (one host usually holds a whole /64; an IPv4-mapped address is its IPv4);
    anything else (a name, "" when asyncua gave none) as it is."""
    try:
        ip = ipaddress.ip_address(address.split("%", 1)[0])
    except ValueError:
        return address
    if isinstance(ip, ipaddress.IPv6Address):
        if ip.ipv4_mapped is not None:
            return str(ip.ipv4_mapped)
        return str(ipaddress.ip_network(f"{ip}/64", strict=False))
    return str(ip)


class LoginBudget:
    """Password checks per peer address beside a cap in all (decisions above).

    :meth:`take` before a check (a login refused by it is not hashed); :meth:`refund` after
    a right password. ``announce`` is True for the first refusal of a spell (per peer, and
    for the cap in all), so a flood is one log line, not one per try. ``clock`` for tests.
    """

    def __init__(self, per_second: float = LOGINS_PER_S, burst: int = LOGIN_BURST,
                 clock: Callable[[], float] = time.monotonic, *,
                 peer_per_second: float = PEER_LOGINS_PER_S, peer_burst: int = PEER_BURST,
                 max_peers: int = MAX_PEERS) -> None:
        self.per_second = per_second
        self.peer_per_second, self.peer_burst = peer_per_second, peer_burst
        self.max_peers = max_peers
        self._clock = clock
        self._all = _Bucket(float(burst), per_second, clock())
        self._peers: OrderedDict[str, _Bucket] = OrderedDict()  # least recently seen first
        self.announce = False

    @property
    def peer_interval_s(self) -> float:
        """Seconds between wrong passwords a spent peer may try."""
        return 1.0 / self.peer_per_second

    def __len__(self) -> int:
        """Peers remembered now."""
        return len(self._peers)

    def take(self, peer: str = "") -> Admission:
        now = self._clock()
        self._forget_idle(now)
        key = peer_key(peer)
        bucket = self._peers.pop(key, None) or _Bucket(float(self.peer_burst),
                                                       self.peer_per_second, now)
        self._peers[key] = bucket  # now the most recently seen
        bucket.refill(now)
        self._all.refill(now)
        if bucket.tokens < 1.0:
            return self._refuse(bucket, Admission.PEER_SPENT)
        if self._all.tokens < 1.0:
            return self._refuse(self._all, Admission.ALL_SPENT)
        bucket.tokens -= 1.0
        self._all.tokens -= 1.0
        bucket.refusing = self._all.refusing = False
        self.announce = False
        return Admission.CHECK

    def refund(self, peer: str = "") -> None:
        """A right password: its peer gets its check back (the cap in all does not)."""
        bucket = self._peers.get(peer_key(peer))
        if bucket is not None:
            bucket.tokens = min(bucket.burst, bucket.tokens + 1.0)

    def _refuse(self, bucket: _Bucket, why: Admission) -> Admission:
        self.announce = not bucket.refusing
        bucket.refusing = True
        return why

    def _forget_idle(self, now: float) -> None:
        peers = self._peers
        while peers:
            oldest = next(iter(peers.values()))
            if len(peers) < self.max_peers and not oldest.full(now):
                break
            peers.popitem(last=False)


class UsersFileError(ServobusError):
    """The users file cannot be read or is not a servobus users file."""


@dataclass(frozen=True)
class UserRecord:
    name: str
    salt: bytes
    digest: bytes
    n: int = N
    r: int = R
    p: int = P

    def as_json(self) -> dict[str, object]:
        return {"scheme": SCHEME, "salt": self.salt.hex(), "hash": self.digest.hex(),
                "n": self.n, "r": self.r, "p": self.p}


def _hash(password: str, salt: bytes, n: int, r: int, p: int) -> bytes:
    return hashlib.scrypt(password.encode(), salt=salt, n=n, r=r, p=p, dklen=KEY_BYTES,
                          maxmem=256 * 1024 * 1024)


#: What the terminal adds to a refused user name or password (servobus.cli.failures).
UNCHANGED = "the users file is unchanged"


def check_name(name: str) -> str:
    if not NAME.fullmatch(name):
        raise InvalidValue(f"user name {name!r}: 1-64 letters, digits, '_', '.', '@', '-'",
                           UNCHANGED)
    return name


def check_password(password: str) -> str:
    if not MIN_PASSWORD <= len(password) <= MAX_PASSWORD:
        raise InvalidValue(f"a password has {MIN_PASSWORD}..{MAX_PASSWORD} characters", UNCHANGED)
    return password


def make_record(name: str, password: str) -> UserRecord:
    salt = secrets.token_bytes(SALT_BYTES)
    return UserRecord(check_name(name), salt, _hash(check_password(password), salt, N, R, P))


class Users:
    """The users of one file; :meth:`verify` answers whether a name/password pair is valid."""

    def __init__(self, records: dict[str, UserRecord] | None = None) -> None:
        self.records: dict[str, UserRecord] = dict(records or {})
        self._dummy = make_record("dummy", secrets.token_hex(16))

    def __len__(self) -> int:
        return len(self.records)

    def verify(self, name: str | None, password: str | None) -> bool:
        if not name or password is None or len(password) > MAX_PASSWORD:
            return False
        record = self.records.get(name)
        probe = record or self._dummy
        digest = _hash(password, probe.salt, probe.n, probe.r, probe.p)
        return hmac.compare_digest(digest, probe.digest) and record is not None

    def add(self, name: str, password: str) -> bool:
        """Add or replace ``name``; True when it replaced an existing user."""
        replaced = name in self.records
        self.records[name] = make_record(name, password)
        return replaced

    def remove(self, name: str) -> None:
        if name not in self.records:
            raise InvalidValue(f"no user {name!r} in the file",
                               "`servobus users list --file FILE` lists the names")
        del self.records[name]

    @classmethod
    def load(cls, path: Path) -> Users:
        try:
            with path.open("rb") as f:
                raw = f.read(MAX_FILE_BYTES + 1)
        except OSError as exc:
            raise UsersFileError(f"cannot read users file {path}: {exc.strerror or exc}") \
                from None
        if len(raw) > MAX_FILE_BYTES:
            raise UsersFileError(f"users file {path} is larger than {MAX_FILE_BYTES} bytes")
        try:
            data = json.loads(raw or b'{"users": {}}')
            if not isinstance(data, dict) or not isinstance(data.get("users"), dict):
                raise ValueError("no 'users' object")
            if set(data) != {"users"}:  # {"robot": "x"}: not this file (issue 32)
                raise ValueError(f"unknown keys {sorted(set(data) - {'users'})}")
            users = data["users"]
            records = {}
            for name, entry in users.items():
                if entry.get("scheme") != SCHEME:
                    raise ValueError(f"user {name!r}: unknown scheme {entry.get('scheme')!r}")
                records[check_name(name)] = UserRecord(
                    name, bytes.fromhex(entry["salt"]), bytes.fromhex(entry["hash"]),
                    int(entry["n"]), int(entry["r"]), int(entry["p"]))
        except (ValueError, TypeError, KeyError, AttributeError) as exc:
            raise UsersFileError(f"{path} is not a servobus users file: {exc}") from None
        return cls(records)

    @classmethod
    def load_or_empty(cls, path: Path) -> Users:
        return cls.load(path) if path.exists() else cls()

    def save(self, path: Path) -> None:
        text = json.dumps({"users": {n: r.as_json() for n, r in sorted(self.records.items())}},
                          indent=1) + "\n"
        folder = path.parent if str(path.parent) else Path(".")
        fd, tmp = tempfile.mkstemp(prefix=".users-", dir=folder)
        try:
            with os.fdopen(fd, "w") as f:
                f.write(text)
            os.chmod(tmp, 0o600)
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
