"""The explorer's secret: a word every line must carry (``"secret": S``) when the explorer is
started with ``--secret FILE``, and that no reply ever holds.

Replies go to every subscriber of ``reply``, so anything a reply says (a session's name, the
step ``k``, the next cell) is known to whoever listens; a probe that copies them is taken as the
holder's. The secret is what a listener to replies cannot copy: it travels only from the driver
to the explorer, in the lines it sends, and is read from a file that only its owner may read.
It does not hide the lines themselves: a process that listens on ``probe`` reads it (DDS
Security, ``--secure``, encrypts and authenticates; see docs/robot.md).

>>> import tempfile, pathlib
>>> where = pathlib.Path(tempfile.mkdtemp()) / "explorer.secret"
>>> secret = explorer_secret(where)            # a new one, written for the driver
>>> driver_secret(where) == secret, len(secret) >= MIN_LENGTH
(True, True)
>>> line = {"cell": [5, 7], "secret": secret}
>>> take_secret(line, secret), line           # checked and taken off the line
(None, {'cell': [5, 7]})
>>> take_secret({"cell": [5, 7]}, secret)
'the line carries no "secret": this explorer takes only lines with its secret (--secret)'
"""

from __future__ import annotations

import hmac
import os
import secrets
import stat
from pathlib import Path

from bayesprog import BayesprogError

#: the key of a line that carries the secret
KEY = "secret"
#: the shortest secret taken from a file (one the explorer writes has 43 characters)
MIN_LENGTH = 16
#: what a reply refused for its secret says besides its error (``"refused": "secret"``), so that
#: a driver tells a stranger's refused line from a refusal of its own
REFUSED = "secret"


def take_secret(line: dict, secret: str | None) -> str | None:
    """Remove ``"secret"`` from ``line`` and check it against the explorer's ``secret``; None
    when the line may be answered, else why it is refused (the message never quotes what the
    line carried)."""
    given = line.pop(KEY, None)
    if secret is None:
        if given is None:
            return None
        return ('the line carries a "secret", but this explorer was started without one: '
                "start it with --secret FILE (the driver's file), or send lines without it")
    if given is None:
        return (f'the line carries no "{KEY}": this explorer takes only lines with its secret '
                "(--secret)")
    if not isinstance(given, str) or not hmac.compare_digest(given.encode(), secret.encode()):
        return ("the line's secret is not this explorer's: send the one in the file the "
                "explorer was started with (--secret FILE)")
    return None


def explorer_secret(path: Path) -> str:
    """The secret in ``path``, or a new one written there (readable by its owner only) when the
    file does not exist, for the driver to read."""
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except FileExistsError:
        return driver_secret(path)
    except OSError as exc:
        raise BayesprogError(f"--secret: cannot write {path}: {exc.strerror or exc}") from None
    secret = secrets.token_urlsafe(32)
    with os.fdopen(fd, "w") as out:
        out.write(secret + "\n")
    return secret


def driver_secret(path: Path) -> str:
    """The secret in ``path``: a file that only its owner may read, holding one word of at
    least :data:`MIN_LENGTH` printable characters."""
    try:
        mode = path.stat().st_mode
        text = path.read_text(encoding="ascii")
    except FileNotFoundError:
        raise BayesprogError(f"--secret: no file {path}: start the explorer with --secret "
                             f"{path} first (it writes a new secret there), or write one "
                             "yourself (chmod 600)") from None
    except UnicodeDecodeError:
        raise BayesprogError(f"--secret: {path} is not a secret: expected one word of printable "
                             "ASCII characters") from None
    except OSError as exc:
        raise BayesprogError(f"--secret: cannot read {path}: {exc.strerror or exc}") from None
    if not stat.S_ISREG(mode):
        raise BayesprogError(f"--secret: {path} is not a file")
    if mode & (stat.S_IRWXG | stat.S_IRWXO):
        raise BayesprogError(f"--secret: {path} may be read or written by others (mode "
                             f"{stat.S_IMODE(mode):04o}): expected a file only its owner reads "
                             f"(chmod 600 {path})")
    secret = text.strip()
    if len(secret) < MIN_LENGTH or not secret.isprintable() or any(c.isspace() for c in secret):
        raise BayesprogError(f"--secret: {path} holds no secret: expected one word of at least "
                             f"{MIN_LENGTH} printable characters, found {len(secret)} "
                             "character(s)" + (" with spaces" if " " in secret else ""))
    return secret
