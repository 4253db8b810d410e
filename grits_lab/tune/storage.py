"""Open a study's storage: a crash-safe journal file by default, an RDB or shared journal by URL.

Journal files (Optuna's JournalStorage with a file backend) append one record per operation under
a file lock, and several processes (or machines on a shared disk) can append to one file. A
process killed mid-append, or a full disk, leaves a half-written last record: it is cut back to
the last complete record, with a warning, before the journal is opened, so the next record is not
glued onto it and the study keeps its history. An RDB URL
(postgresql://, mysql://, sqlite:///) goes through SQLAlchemy; PostgreSQL and MySQL serve many
machines, SQLite suits one writer only. Unreachable storage fails with one line, passwords hidden.
"""

from __future__ import annotations

import json
import os
import re
import sys
import time
from pathlib import Path
from typing import Callable
from urllib.parse import unquote

from optuna.storages import BaseStorage, JournalStorage, RDBStorage
from optuna.storages.journal import JournalFileBackend, JournalFileSymlinkLock

from grits_lab.errors import StorageError
from grits_lab.io import ensure_writable_dir

RDB_SCHEMES = ("postgresql", "postgres", "mysql", "sqlite")
_DRIVER_HINT = {"postgresql": "psycopg2-binary", "mysql": "PyMySQL"}


def redact(spec: str) -> str:
    """The storage spec with its password (and any `password=` query value) replaced by ***.

    Found by parsing, not by a pattern of what a password may hold: the user information runs
    from `://` to the last `@`, and the password from its first `:`, so a password holding `/`,
    `:`, `@`, `?` or percent-escapes is hidden whole.
    """
    password = _password(spec)
    shown = spec
    if password:
        scheme, rest = spec.split("://", 1)
        user = rest.split(":", 1)[0]
        shown = f"{scheme}://{user}:***@{rest[len(user) + 1 + len(password) + 1:]}"
    return re.sub(r"([?&](?:password|passwd|pwd)=)[^&#]*", r"\1***", shown, flags=re.IGNORECASE)


def _password(spec: str) -> str:
    """The password as written in the URL `spec` ('' if none)."""
    if "://" not in spec:
        return ""
    rest = spec.split("://", 1)[1]
    if "@" not in rest:
        return ""
    userinfo = rest.rsplit("@", 1)[0]
    return userinfo.split(":", 1)[1] if ":" in userinfo else ""


def _scrubbed(text: str, spec: str) -> str:
    """`text` (a driver's message) with the URL's password, as written and decoded, replaced by ***."""
    password = _password(spec)
    for form in sorted({password, unquote(password)} - {""}, key=len, reverse=True):
        text = text.replace(form, "***")
    return text


def open_storage(spec: str | None, default_journal: Path) -> tuple[BaseStorage, str]:
    """(storage, printable description). `spec` None means the journal file `default_journal`."""
    if spec is None:
        return _open_journal(Path(default_journal)), str(default_journal)
    if "://" not in spec:
        return _open_journal(Path(spec)), spec
    scheme = spec.split("://", 1)[0].split("+", 1)[0].lower()
    if scheme not in RDB_SCHEMES:
        raise StorageError(
            f"unsupported storage URL {redact(spec)}: use postgresql://, mysql://, sqlite:/// or a journal file path"
        )
    if "@" in _password(spec):  # SQLAlchemy ends the password at its first `@` and would take the rest for the host
        raise StorageError(f"the password in storage URL {redact(spec)} holds a raw `@`: write it as %40")
    if scheme == "postgres":  # SQLAlchemy dropped this alias
        spec, scheme = "postgresql" + spec[len("postgres"):], "postgresql"
    return _open_rdb(_with_available_driver(spec), scheme, redact(spec), lambda text: _scrubbed(text, spec)), redact(spec)


def _with_available_driver(url: str) -> str:
    """postgresql:// means psycopg 3 to SQLAlchemy 2.1; use psycopg2 when only that is installed."""
    if not url.startswith("postgresql://"):
        return url
    import importlib.util

    if importlib.util.find_spec("psycopg") is None and importlib.util.find_spec("psycopg2") is not None:
        return "postgresql+psycopg2://" + url[len("postgresql://"):]
    return url


def _open_journal(path: Path) -> JournalStorage:
    if path.is_dir():
        raise StorageError(f"journal storage path {path} is a directory; give a file path such as {path}/journal.log")
    ensure_writable_dir(path.parent if str(path.parent) else Path("."))
    try:
        repair_journal(path)
        return JournalStorage(JournalFileBackend(str(path)))
    except OSError as exc:
        raise StorageError(f"cannot open journal storage {path}: {exc.strerror or exc}") from None
    except (ValueError, KeyError) as exc:
        raise StorageError(f"journal storage {path} is not a readable Optuna journal: {exc}") from None


def repair_journal(path: Path) -> int:
    """Cut a torn tail off the journal at `path`; return the number of bytes cut (0: it was whole).

    Runs under the journal's own lock, so no worker appends meanwhile. A torn tail is the bytes
    after the last newline, or a last line that is not a JSON record. A bad record followed by good
    ones is not a crash's trace but damage this cannot undo, and it is reported with its line.
    """
    if not path.is_file() or path.stat().st_size == 0:
        return 0
    lock = JournalFileSymlinkLock(str(path))
    lock.acquire()
    try:
        data = path.read_bytes()
        good = 0  # bytes of complete, readable records from the start
        lines = data.split(b"\n")
        complete, tail = lines[:-1], lines[-1]
        for number, line in enumerate(complete, start=1):
            if not _is_record(line):
                if number < len(complete):
                    raise StorageError(
                        f"journal storage {path} has an unreadable record on line {number} of {len(complete)}, "
                        f"followed by others; restore it from a copy or choose another storage"
                    )
                tail = line + b"\n" + tail
                break
            good += len(line) + 1
        cut = len(data) - good
        if cut:
            os.truncate(path, good)
            print(f"warning: journal storage {path} ended in a half-written record ({cut} bytes, left by a "
                  f"killed process or a full disk); cut back to the last complete record", file=sys.stderr)
        return cut
    finally:
        lock.release()


def _is_record(line: bytes) -> bool:
    try:
        return isinstance(json.loads(line), dict)
    except ValueError:
        return False


def _open_rdb(url: str, scheme: str, shown: str, scrub: Callable[[str], str]) -> RDBStorage:
    import sqlalchemy.exc

    engine_kwargs: dict = {"pool_pre_ping": True}
    if scheme in ("postgresql", "mysql"):
        engine_kwargs["connect_args"] = {"connect_timeout": 10}
    # Two workers starting at once on an empty database may race on creating Optuna's tables:
    # the loser sees an integrity or programming error and simply retries.
    for attempt in range(5):
        try:
            return RDBStorage(url, engine_kwargs=engine_kwargs)
        except ImportError:  # Optuna re-raises the driver's ModuleNotFoundError as ImportError
            driver = _DRIVER_HINT.get(scheme, "its database driver")
            raise StorageError(f"storage {shown} needs a database driver (pip install {driver})") from None
        except sqlalchemy.exc.OperationalError as exc:
            raise StorageError(f"cannot reach storage {shown}: {scrub(_first_line(exc.orig or exc))}") from None
        except (sqlalchemy.exc.IntegrityError, sqlalchemy.exc.ProgrammingError) as exc:
            if attempt == 4:
                raise StorageError(f"cannot initialize storage {shown}: {scrub(_first_line(exc.orig or exc))}") from None
            time.sleep(0.2 * (attempt + 1))
        except (sqlalchemy.exc.ArgumentError, ValueError) as exc:  # ValueError: a port that is not a number
            raise StorageError(f"invalid storage URL {shown}: {scrub(_first_line(exc))}") from None
        except sqlalchemy.exc.SQLAlchemyError as exc:
            raise StorageError(f"cannot open storage {shown}: {scrub(_first_line(exc))}") from None
    raise AssertionError("unreachable")


def _first_line(exc: object) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def dashboard_command(storage_description: str) -> str:
    """The shell command that opens this storage in optuna-dashboard (extra `dashboard`), the
    storage quoted for a POSIX shell; it serves on 127.0.0.1 (docs/sweeps.md: reaching it from
    another machine)."""
    import shlex

    return f"optuna-dashboard {shlex.quote(storage_description)}"

