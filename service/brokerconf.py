"""Mosquitto password file and ACL for zonecast: one user per building and the service user
(docs/security.md, ``zonecast mqtt-config``).

The ACL uses Mosquitto's ``pattern`` lines with ``%u`` (the user name): a building's
publisher logs in with the building id as its user name and may write only
``<prefix>/<id>/telemetry``, ``<prefix>/<id>/points/#`` and ``<prefix>/<id>/weather_forecast``
and read only its own ``state``, ``forecast`` and ``deadletter``. One ACL therefore serves
any number of buildings: adding a building is adding its password line, the ACL stays the
same. The service user has its own ``user`` block: it reads every building's telemetry and is
the only user that may write ``state``, ``forecast`` and ``deadletter``.

Password hashes are Mosquitto 2's ``$7$`` format: PBKDF2-HMAC-SHA512, 101 iterations, a
12-byte random salt, standard base64 for salt and hash (``mosquitto_passwd -H
sha512-pbkdf2``; Mosquitto 2.0 and later read it). They are computed here with the standard
library, so no password appears on a command line (``mosquitto_passwd -b`` would show it in
the process list) and the broker need not be installed where the files are made.
"""

from __future__ import annotations

import base64
import hashlib
import os
import re
import secrets
from dataclasses import dataclass, field
from pathlib import Path

from zonecast.service.settings import DEFAULT_PREFIX

__all__ = ["PBKDF2_ITERATIONS", "BrokerFiles", "acl_text", "hash_password", "read_passwd",
           "verify_password", "write_broker_files"]

#: iterations of Mosquitto's default sha512-pbkdf2 hash (mosquitto_passwd)
PBKDF2_ITERATIONS = 101
_SALT_BYTES = 12
_NAME = re.compile(r"[A-Za-z0-9_-]{1,64}")


def hash_password(password: str, *, salt: bytes | None = None,
                  iterations: int = PBKDF2_ITERATIONS) -> str:
    """``$7$<iterations>$<salt>$<hash>``: a Mosquitto 2 password-file hash of ``password``
    (PBKDF2-HMAC-SHA512, 64-byte hash, base64)."""
    if not password:
        raise ValueError("the password is empty")
    salt = os.urandom(_SALT_BYTES) if salt is None else salt
    digest = hashlib.pbkdf2_hmac("sha512", password.encode(), salt, iterations)
    return (f"$7${iterations}${base64.b64encode(salt).decode()}$"
            f"{base64.b64encode(digest).decode()}")


def verify_password(password: str, hashed: str) -> bool:
    """True if ``password`` matches a ``$7$`` hash (constant-time comparison)."""
    parts = hashed.split("$")
    if len(parts) != 5 or parts[1] != "7":
        raise ValueError(f"not a Mosquitto $7$ (sha512-pbkdf2) hash: {hashed[:12]!r}…")
    salt, digest = base64.b64decode(parts[3]), base64.b64decode(parts[4])
    again = hashlib.pbkdf2_hmac("sha512", password.encode(), salt, int(parts[2]))
    return secrets.compare_digest(again, digest)


def read_passwd(path: Path) -> dict[str, str]:
    """user -> hash of a Mosquitto password file (empty if it does not exist)."""
    if not path.is_file():
        return {}
    out = {}
    for n, line in enumerate(path.read_text().splitlines(), 1):
        if not line.strip() or line.startswith("#"):
            continue
        user, sep, hashed = line.partition(":")
        if not sep or not hashed:
            raise ValueError(f"{path}:{n}: expected 'user:hash'")
        out[user] = hashed
    return out


def acl_text(service_user: str, prefix: str = DEFAULT_PREFIX) -> str:
    """The ACL file (Mosquitto ``acl_file``): the service user's block and the pattern
    lines every building user gets through its user name."""
    p = prefix
    return f"""\
# zonecast ACL (zonecast mqtt-config; docs/security.md). Anything not granted is denied.
# Anonymous clients: nothing (and mosquitto.conf has allow_anonymous false).

# Building publishers: the user name is the building id (%u).
pattern write {p}/%u/telemetry
pattern write {p}/%u/points/#
pattern write {p}/%u/weather_forecast
pattern read {p}/%u/state
pattern read {p}/%u/forecast
pattern read {p}/%u/deadletter

# The zonecast service: reads all telemetry, the only writer of state, forecast, dead letters.
user {service_user}
topic read {p}/+/telemetry
topic read {p}/+/points/#
topic read {p}/+/weather_forecast
topic write {p}/+/state
topic write {p}/+/forecast
topic write {p}/+/deadletter
topic write {p}/deadletter
"""


@dataclass
class BrokerFiles:
    """What :func:`write_broker_files` wrote: the files and the new plain-text passwords
    (user -> password; only users whose password was created or rotated)."""

    passwd: Path
    acl: Path
    credentials: Path | None
    passwords: dict[str, str] = field(default_factory=dict)
    kept: list[str] = field(default_factory=list)


def _check_name(name: str, what: str) -> str:
    if not _NAME.fullmatch(name):
        raise ValueError(f"{what} {name!r} may only use letters, digits, '-' and '_' (1-64 "
                         "characters): it is a topic level and a Mosquitto user name")
    return name


def write_broker_files(buildings: list[str], out: str | Path, *,
                       service_user: str = "zonecast", prefix: str = DEFAULT_PREFIX,
                       rotate: list[str] | tuple[str, ...] = ()) -> BrokerFiles:
    """Write ``passwd`` and ``acl`` for Mosquitto into ``out``, and ``credentials.txt``
    with the new passwords.

    Users: ``service_user`` and one per building (user name = building id). A user already
    in ``out/passwd`` keeps its password unless named in ``rotate``; new users and rotated
    ones get a random password (32 bytes, URL-safe base64), listed in ``credentials.txt``
    (``user password`` lines, mode 0600: hand each line to its owner, then delete the file).
    Users in the old file that are no longer listed are removed. All files are written mode
    0600.

    Raises
    ------
    ValueError
        An invalid or duplicate name, a building named like the service user, an unknown
        user in ``rotate``, a malformed existing password file, or a ``credentials.txt``
        left from an earlier run when new passwords would be written (it would be
        overwritten: hand its passwords out and delete it first).
    """
    out = Path(out)
    _check_name(service_user, "service user")
    names = [_check_name(b, "building id") for b in buildings]
    if not names:
        raise ValueError("give at least one building id")
    if len(set(names)) != len(names):
        raise ValueError(f"building ids {names} contain duplicates")
    if service_user in names:
        raise ValueError(f"building {service_user!r} has the service user's name; choose "
                         "another --service-user")
    if not re.fullmatch(r"[A-Za-z0-9_-]+(/[A-Za-z0-9_-]+)*", prefix):
        raise ValueError(f"topic prefix {prefix!r} must be topic levels of letters, digits, "
                         "'-' and '_' (no wildcards)")
    users = [service_user, *names]
    unknown = sorted(set(rotate) - set(users))
    if unknown:
        raise ValueError(f"cannot rotate {unknown}: not among the users {users}")
    out.mkdir(parents=True, exist_ok=True)
    passwd = out / "passwd"
    old = read_passwd(passwd)
    if (out / "credentials.txt").exists() and (set(users) - set(old) or rotate):
        raise ValueError(f"{out / 'credentials.txt'} still holds passwords of an earlier run: "
                         "hand them out and delete the file first (nothing was changed)")
    hashes, new, kept = {}, {}, []
    for user in users:
        if user in old and user not in rotate:
            hashes[user] = old[user]
            kept.append(user)
        else:
            new[user] = secrets.token_urlsafe(32)
            hashes[user] = hash_password(new[user])
    _write_private(passwd, "".join(f"{u}:{h}\n" for u, h in hashes.items()))
    acl = out / "acl"
    _write_private(acl, acl_text(service_user, prefix))
    credentials = None
    if new:
        credentials = out / "credentials.txt"
        _write_private(credentials, "# user password (give each line to its owner, then "
                       "delete this file)\n" + "".join(f"{u} {p}\n" for u, p in new.items()))
    return BrokerFiles(passwd, acl, credentials, new, kept)


def _write_private(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` with mode 0600 (replacing it atomically)."""
    tmp = path.with_name(path.name + ".tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(text)
    os.replace(tmp, path)
