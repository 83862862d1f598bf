"""The gateway's OPC UA users: a TOML file of names and scrypt password hashes.

Format (docs/opcua.md, "Security")::

    [users]
    alice = "scrypt$16384$8$1$<salt hex>$<hash hex>"   # plugcell opcua hash-password
    bob   = "scrypt$16384$8$1$…"

A user's name is the *sender* of every process the gateway creates for that user,
so it must be a valid participant name (``[A-Za-z0-9][A-Za-z0-9_.-]{0,63}``): the
services' access policy (``PLUGCELL_ACL``) decides on it and the journal records it.
Passwords are never stored: ``hash`` is scrypt (RFC 7914) of the password with a
random 16-byte salt; checking compares in constant time.
"""

from __future__ import annotations

import hashlib
import hmac
import os
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from asyncua.crypto.permission_rules import User, UserRole

from plugcell.framework.keys import check_name

#: scrypt cost parameters (N, r, p) of new hashes: ~50 ms and 16 MiB on a small VM.
SCRYPT_N, SCRYPT_R, SCRYPT_P = 16384, 8, 1


class UsersFileError(ValueError):
    """A users file that cannot be used; the message names the file and the entry."""


def hash_password(password: str, *, salt: bytes | None = None) -> str:
    """``scrypt$N$r$p$<salt hex>$<hash hex>`` of ``password`` (a new random salt)."""
    salt = salt if salt is not None else os.urandom(16)
    digest = hashlib.scrypt(
        password.encode(), salt=salt, n=SCRYPT_N, r=SCRYPT_R, p=SCRYPT_P, dklen=32
    )
    return f"scrypt${SCRYPT_N}${SCRYPT_R}${SCRYPT_P}${salt.hex()}${digest.hex()}"


def _parse_hash(text: str, where: str) -> tuple[int, int, int, bytes, bytes]:
    parts = text.split("$")
    if len(parts) != 6 or parts[0] != "scrypt":
        raise UsersFileError(f"{where}: not a password hash of `plugcell opcua hash-password`")
    try:
        n, r, p = (int(v) for v in parts[1:4])
        salt, digest = bytes.fromhex(parts[4]), bytes.fromhex(parts[5])
    except ValueError as exc:
        raise UsersFileError(f"{where}: malformed password hash ({exc})") from None
    if n < 2 or n & (n - 1) or not 1 <= r <= 64 or not 1 <= p <= 16 or not salt or not digest:
        raise UsersFileError(f"{where}: password hash parameters out of range")
    return n, r, p, salt, digest


@dataclass(frozen=True)
class UserBook:
    """Users and their password hashes; :meth:`check` verifies a login."""

    hashes: dict[str, str]
    source: str = "<memory>"

    @classmethod
    def load(cls, path: str | Path) -> UserBook:
        """Read a users file (UsersFileError naming the file and the user if it is bad)."""
        path = Path(path)
        try:
            doc: dict[str, Any] = tomllib.loads(path.read_text(encoding="utf-8"))
        except OSError as exc:
            raise UsersFileError(f"{path}: cannot read: {exc.strerror or exc}") from None
        except tomllib.TOMLDecodeError as exc:
            raise UsersFileError(f"{path}: not TOML: {exc}") from None
        unknown = set(doc) - {"users"}
        if unknown:
            raise UsersFileError(f"{path}: unknown keys {sorted(unknown)} (only [users])")
        users = doc.get("users", {})
        if not isinstance(users, dict) or not users:
            raise UsersFileError(f"{path}: no [users] table with at least one user")
        for name, value in users.items():
            where = f"{path}: user {name!r}"
            try:
                check_name(name, "OPC UA user name")
            except ValueError as exc:
                raise UsersFileError(f"{where}: {exc}") from None
            if not isinstance(value, str):
                raise UsersFileError(f"{where}: the value must be a password hash string")
            _parse_hash(value, where)
        return cls(dict(users), str(path))

    def check(self, name: str | None, password: str | None) -> bool:
        """Whether ``password`` is ``name``'s (constant-time compare)."""
        stored = self.hashes.get(name or "")
        if stored is None or password is None:
            return False
        n, r, p, salt, digest = _parse_hash(stored, self.source)
        got = hashlib.scrypt(
            password.encode(), salt=salt, n=n, r=r, p=p, dklen=len(digest), maxmem=2**28
        )
        return hmac.compare_digest(got, digest)


class GatewayUsers:
    """asyncua's user manager: users of a :class:`UserBook`, anonymous if allowed.

    An authenticated user keeps its name (the processes' sender); an anonymous one
    has none (the gateway's own name is the sender).
    """

    def __init__(self, book: UserBook | None, allow_anonymous: bool) -> None:
        self.book = book
        self.allow_anonymous = allow_anonymous

    def get_user(
        self, iserver: Any, username: str | None = None, password: str | None = None,
        certificate: Any = None,
    ) -> User | None:
        if username is None:
            return User(role=UserRole.User) if self.allow_anonymous else None
        if self.book is not None and self.book.check(username, password):
            return User(role=UserRole.User, name=username)
        return None
