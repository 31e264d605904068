"""The response database: one SQLite file (stdlib ``sqlite3``), written as each answer arrives.

Durability: WAL journal with ``synchronous=FULL`` and one transaction per answer, committed before
the server replies; so a killed server (even SIGKILL) or a crashed machine loses at most the trial
in progress, never a confirmed answer. Idempotence: the key of ``answers`` is (participant, trial)
and inserts are ``ON CONFLICT DO NOTHING``: a double submission stores nothing new; a second
submission with a *different* response keeps the first and is logged as an event for the
experimenter.

Versioning: ``meta`` holds ``schema_version`` and the ``test_id`` of the stimulus manifest the
database was made for (plus a copy of that manifest, so a report needs the database alone). Opening
a database of another schema version or another test is refused with a message saying what to do.

Privacy: participants are opaque ids (random, or chosen by the experimenter); the page's resume
token is stored only as its SHA-256. No name, address, user agent or IP is stored.
"""

from __future__ import annotations

import hashlib
import json
import re
import secrets
import sqlite3
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from perceptual.errors import AnswerError, StoreError

SCHEMA_VERSION = 1

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS participants (
    id TEXT PRIMARY KEY,
    ordinal INTEGER NOT NULL UNIQUE,
    token_sha256 TEXT NOT NULL,
    plan TEXT NOT NULL,
    created_utc TEXT NOT NULL,
    completed_utc TEXT
);
CREATE TABLE IF NOT EXISTS answers (
    participant TEXT NOT NULL REFERENCES participants(id),
    trial INTEGER NOT NULL,
    block TEXT NOT NULL,
    kind TEXT NOT NULL,
    practice INTEGER NOT NULL,
    stimulus TEXT NOT NULL,
    item TEXT NOT NULL,
    condition TEXT NOT NULL,
    snr_db REAL,
    truth TEXT NOT NULL,
    response TEXT NOT NULL,
    correct INTEGER NOT NULL,
    scored INTEGER NOT NULL,
    rt_ms REAL,
    latency_ms REAL,
    av_offset_ms REAL,
    plays INTEGER,
    answered_utc TEXT NOT NULL,
    PRIMARY KEY (participant, trial)
);
CREATE TABLE IF NOT EXISTS events (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    participant TEXT,
    trial INTEGER,
    kind TEXT NOT NULL,
    detail TEXT NOT NULL,
    at_utc TEXT NOT NULL
);
"""

ID_PATTERN = re.compile(r"^[A-Za-z0-9_-]{1,40}$")


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds")


def _sha(token: str) -> str:
    return hashlib.sha256(token.encode()).hexdigest()


@dataclass(frozen=True, kw_only=True)
class Participant:
    id: str
    ordinal: int
    plan: list[dict[str, Any]]
    created_utc: str
    completed_utc: str | None


class Store:
    """An open response database. Not thread-safe: the server uses it from its event loop only."""

    def __init__(self, conn: sqlite3.Connection, path: Path) -> None:
        self.conn = conn
        self.path = path

    # -- opening ----------------------------------------------------------------------------
    @classmethod
    def open(cls, path: str | Path, *, test_id: str, manifest: dict[str, Any]) -> Store:
        """Open (or create) the database for the test ``test_id``; StoreError if it belongs elsewhere."""
        path = Path(path)
        new = not path.exists() or path.stat().st_size == 0
        conn = cls._connect(path)
        store = cls(conn, path)
        if new:
            conn.executescript("BEGIN;" + _SCHEMA + "COMMIT;")
            with store._tx():
                conn.executemany(
                    "INSERT INTO meta(key, value) VALUES (?, ?)",
                    [
                        ("schema_version", str(SCHEMA_VERSION)),
                        ("test_id", test_id),
                        ("created_utc", _now()),
                        ("manifest", json.dumps(manifest)),
                    ],
                )
            return store
        store._check_version()
        have = store.meta("test_id")
        if have != test_id:
            conn.close()
            raise StoreError(
                f"{path}: this database holds answers to another test version (test id {have}); the stimuli "
                f"being served are test {test_id}. Use a new database file (--db) for this test, or serve the "
                f"stimuli it was made for"
            )
        return store

    @classmethod
    def open_existing(cls, path: str | Path) -> Store:
        """Open a filled database for reading (reports); StoreError if missing or of another schema."""
        path = Path(path)
        if not path.is_file():
            raise StoreError(f"{path}: response database not found")
        store = cls(cls._connect(path), path)
        store._check_version()
        return store

    @staticmethod
    def _connect(path: Path) -> sqlite3.Connection:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            conn = sqlite3.connect(str(path), isolation_level=None, timeout=10.0)
            conn.row_factory = sqlite3.Row
            conn.execute("PRAGMA journal_mode=WAL")
            conn.execute("PRAGMA synchronous=FULL")  # a confirmed answer survives even power loss
            conn.execute("PRAGMA foreign_keys=ON")
            return conn
        except sqlite3.DatabaseError as exc:
            raise StoreError(f"{path}: not a usable SQLite database: {exc}") from exc

    def _check_version(self) -> None:
        try:
            v = self.meta("schema_version")
        except sqlite3.DatabaseError as exc:
            self.conn.close()
            raise StoreError(f"{self.path}: not a facecast perceptual database: {exc}") from exc
        if v != str(SCHEMA_VERSION):
            self.conn.close()
            raise StoreError(
                f"{self.path}: database schema version {v}, this facecast reads version "
                f"{SCHEMA_VERSION}; use the facecast version that wrote it, or a new database"
            )

    @contextmanager
    def _tx(self) -> Iterator[None]:
        """One write transaction, committed (durably: synchronous=FULL) when the block ends."""
        self.conn.execute("BEGIN IMMEDIATE")
        try:
            yield
        except BaseException:
            self.conn.execute("ROLLBACK")
            raise
        self.conn.execute("COMMIT")

    def close(self) -> None:
        self.conn.close()

    def meta(self, key: str) -> str | None:
        row = self.conn.execute("SELECT value FROM meta WHERE key = ?", (key,)).fetchone()
        return None if row is None else row[0]

    def manifest(self) -> dict[str, Any]:
        return json.loads(self.meta("manifest") or "{}")

    # -- participants -----------------------------------------------------------------------
    def create_participant(self, requested_id: str | None, plan_for) -> tuple[Participant, str]:
        """A new participant (id ``requested_id`` or a random one) with ``plan_for(ordinal, id)``'s plan;
        returns it and its resume token. StoreError when the id is malformed or already used."""
        if requested_id is not None and not ID_PATTERN.match(requested_id):
            raise AnswerError(f"participant id {requested_id!r} must be 1-40 letters, digits, '-' or '_'")
        token = secrets.token_urlsafe(18)
        pid = requested_id or f"p-{secrets.token_hex(5)}"
        with self._tx():
            old = self.conn.execute(
                "SELECT created_utc, (SELECT count(*) FROM answers WHERE participant = ?) "
                "FROM participants WHERE id = ?",
                (pid, pid),
            ).fetchone()
            if old is None:
                ordinal = self.conn.execute("SELECT coalesce(max(ordinal) + 1, 0) FROM participants").fetchone()[0]
                plan = plan_for(ordinal, pid)
                created = _now()
                self.conn.execute(
                    "INSERT INTO participants(id, ordinal, token_sha256, plan, created_utc) VALUES (?, ?, ?, ?, ?)",
                    (pid, ordinal, _sha(token), json.dumps(plan), created),
                )
        if old is not None:
            # Logged in its own transaction: the refusal itself must reach the experimenter's page.
            self.log_event(
                pid,
                None,
                "id_reused",
                f"a new session asked for id {pid}, already used since {old[0]} ({old[1]} answers); refused",
            )
            raise StoreError(
                f"participant id {pid} is already used (since {old[0]}, {old[1]} answers): "
                f"choose another id, or continue in the browser that started it"
            )
        return Participant(id=pid, ordinal=ordinal, plan=plan, created_utc=created, completed_utc=None), token

    def participant(self, pid: str, token: str | None = None) -> Participant:
        """The participant ``pid``; with ``token``, AnswerError unless it is theirs."""
        row = self.conn.execute("SELECT * FROM participants WHERE id = ?", (pid,)).fetchone()
        if row is None:
            raise AnswerError(f"unknown participant {pid!r}")
        if token is not None and not secrets.compare_digest(_sha(token), row["token_sha256"]):
            raise AnswerError(f"participant {pid}: wrong session token (this id was started in another browser)")
        return Participant(
            id=row["id"],
            ordinal=row["ordinal"],
            plan=json.loads(row["plan"]),
            created_utc=row["created_utc"],
            completed_utc=row["completed_utc"],
        )

    def participants(self) -> list[Participant]:
        rows = self.conn.execute("SELECT id FROM participants ORDER BY ordinal").fetchall()
        return [self.participant(r[0]) for r in rows]

    def answered(self, pid: str) -> list[int]:
        return [
            r[0] for r in self.conn.execute("SELECT trial FROM answers WHERE participant = ? ORDER BY trial", (pid,))
        ]

    # -- answers ----------------------------------------------------------------------------
    def record_answer(self, pid: str, trial: int, row: dict[str, Any]) -> str:
        """Store one answer in its own committed transaction. Returns ``"stored"``, ``"duplicate"``
        (the same answer again: nothing changes) or ``"conflict"`` (another response for an answered
        trial: the first is kept, an event is logged)."""
        cols = (
            "block",
            "kind",
            "practice",
            "stimulus",
            "item",
            "condition",
            "snr_db",
            "truth",
            "response",
            "correct",
            "scored",
            "rt_ms",
            "latency_ms",
            "av_offset_ms",
            "plays",
        )
        values = [row[c] for c in cols]
        with self._tx():
            cur = self.conn.execute(
                f"INSERT INTO answers(participant, trial, {', '.join(cols)}, answered_utc) "
                f"VALUES (?, ?, {', '.join('?' * len(cols))}, ?) ON CONFLICT(participant, trial) DO NOTHING",
                (pid, trial, *values, _now()),
            )
            if cur.rowcount == 1:
                plan_len = len(
                    json.loads(self.conn.execute("SELECT plan FROM participants WHERE id = ?", (pid,)).fetchone()[0])
                )
                n = self.conn.execute("SELECT count(*) FROM answers WHERE participant = ?", (pid,)).fetchone()[0]
                if n == plan_len:
                    self.conn.execute("UPDATE participants SET completed_utc = ? WHERE id = ?", (_now(), pid))
                return "stored"
            first = self.conn.execute(
                "SELECT response FROM answers WHERE participant = ? AND trial = ?", (pid, trial)
            ).fetchone()[0]
            if first == row["response"]:
                self._event(pid, trial, "duplicate", "the same answer was submitted again; stored once")
                return "duplicate"
            self._event(
                pid,
                trial,
                "conflict",
                f"a different answer {row['response']} arrived for an answered trial; the first ({first}) is kept",
            )
            return "conflict"

    def log_event(self, pid: str | None, trial: int | None, kind: str, detail: str) -> None:
        with self._tx():
            self._event(pid, trial, kind, detail)

    def _event(self, pid: str | None, trial: int | None, kind: str, detail: str) -> None:
        self.conn.execute(
            "INSERT INTO events(participant, trial, kind, detail, at_utc) VALUES (?, ?, ?, ?, ?)",
            (pid, trial, kind, detail, _now()),
        )

    def answers(self) -> list[dict[str, Any]]:
        rows = self.conn.execute("SELECT * FROM answers ORDER BY participant, trial").fetchall()
        out = []
        for r in rows:
            d = dict(r)
            d["truth"] = json.loads(d["truth"])
            d["response"] = json.loads(d["response"])
            out.append(d)
        return out

    def events(self) -> list[dict[str, Any]]:
        return [dict(r) for r in self.conn.execute("SELECT * FROM events ORDER BY id").fetchall()]
