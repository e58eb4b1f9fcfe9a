"""The gateway's users file: names with a salted scrypt hash of each password.

``servobus users add NAME --file FILE`` writes it; ``servobus serve --users FILE`` reads it.
Decisions: JSON (one object per user, readable and diffable), scrypt (hashlib, no extra
package) with n=2**14, r=8, p=1 and a 16-byte random salt per user; the file is written
atomically with mode 0600 (it is not a secret, but nobody else needs to read it).
Passwords are compared in constant time; an unknown name costs the same hash as a known one,
so a probe cannot tell the names apart by timing. A :class:`LoginBudget` bounds how many
password checks run per second where they run on an event loop (asyncua's logins do).
"""

from __future__ import annotations

import hashlib
import hmac
import json
import os
import re
import secrets
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from servobus.errors import ArgumentRangeError, ServobusError

SCHEME = "scrypt"
N, R, P = 2**14, 8, 1
SALT_BYTES = 16
KEY_BYTES = 32
MAX_FILE_BYTES = 1 << 20
NAME = re.compile(r"[A-Za-z0-9_.@-]{1,64}")
MIN_PASSWORD = 8
MAX_PASSWORD = 1024


#: Password checks per second, and in one burst, that a LoginBudget allows (decision; it was
#: a known limit of the gateway, issue 21): one check is a scrypt hash, 30-50 ms of CPU on the
#: project's machine, and asyncua runs it on the gateway's event loop. 4 a second keep a flood
#: of logins to a fifth of the loop's time; 8 at once cover a plant's clients reconnecting.
LOGINS_PER_S = 4.0
LOGIN_BURST = 8


class LoginBudget:
    """A token bucket of password checks: :meth:`take` is False when the budget is spent,
    and the login is then refused without hashing (``clock`` for tests)."""

    def __init__(self, per_second: float = LOGINS_PER_S, burst: int = LOGIN_BURST,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.per_second = per_second
        self._burst = float(burst)
        self._clock = clock
        self._tokens = self._burst
        self._at = clock()

    def take(self) -> bool:
        now = self._clock()
        self._tokens = min(self._burst, self._tokens + (now - self._at) * self.per_second)
        self._at = now
        if self._tokens < 1.0:
            return False
        self._tokens -= 1.0
        return True


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


def check_name(name: str) -> str:
    if not NAME.fullmatch(name):
        raise ArgumentRangeError(f"user name {name!r}: 1-64 letters, digits, '_', '.', '@', '-'")
    return name


def check_password(password: str) -> str:
    if not MIN_PASSWORD <= len(password) <= MAX_PASSWORD:
        raise ArgumentRangeError(f"a password has {MIN_PASSWORD}..{MAX_PASSWORD} characters")
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
            raise ArgumentRangeError(f"no user {name!r} in the file")
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
            data = json.loads(raw or b"{}")
            users = data.get("users", {}) if isinstance(data, dict) else None
            if not isinstance(users, dict):
                raise ValueError("no 'users' object")
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
