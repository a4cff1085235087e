"""A flight-test campaign in one SQLite file: every flight (log file) and every test point.

Why SQLite (the standard library's :mod:`sqlite3`): the campaign is embedded (one file next to
the data, nothing to run or install), the queries are small relational filters (test points by
axis, swept input, verdict, flight, condition ranges), and SQLite gives atomic transactions (each
file is added all or nothing: a killed ``campaign add`` leaves every flight whole or absent) and
safe concurrent writers: the database runs in WAL mode (readers never block the writer) with a
``busy_timeout``, so two ``livesweep campaign add`` at once wait for each other's short write
transactions instead of failing.

Schema (``PRAGMA user_version`` is the schema version; :data:`MIGRATIONS` are applied in order,
each in its own transaction):

``flights``
    ``id, sha256 UNIQUE, path, format, vehicle, date, added_at`` (one row per distinct file
    content: the SHA-256 of the bytes is the identity, so the same file under another path is the
    same flight).
``test_points``
    ``id, flight_id -> flights(id) ON DELETE CASCADE, number, start_s, end_s, swept_input, axis,
    source ('recorded' | 'autopilot'), verdict ('GO' | 'NO-GO' | ... | NULL when not judged),
    label, conditions (JSON object name -> number), record (JSON: the whole record)``.
``results``
    ``id, test_point_ids (JSON list), selection (JSON: the query that chose them), kind, data
    (JSON), added_at``: identification results added later (:meth:`Campaign.add_result`).
"""

from __future__ import annotations

import json
import sqlite3
import time
from dataclasses import dataclass, field
from pathlib import Path

from livesweep.errors import LivesweepError

__all__ = ["open", "Campaign", "AddReport", "FlightRow", "TestPointRow", "MIGRATIONS", "SCHEMA_VERSION"]

_builtin_open = open

#: Schema migrations, applied in order: version k is reached by running ``MIGRATIONS[k - 1]``.
MIGRATIONS: tuple[tuple[str, ...], ...] = (
    (
        """CREATE TABLE flights (
            id INTEGER PRIMARY KEY,
            sha256 TEXT NOT NULL UNIQUE,
            path TEXT NOT NULL,
            format TEXT NOT NULL,
            vehicle TEXT,
            date TEXT,
            added_at TEXT NOT NULL)""",
        """CREATE TABLE test_points (
            id INTEGER PRIMARY KEY,
            flight_id INTEGER NOT NULL REFERENCES flights(id) ON DELETE CASCADE,
            number INTEGER NOT NULL,
            start_s REAL,
            end_s REAL,
            swept_input TEXT,
            axis INTEGER,
            source TEXT NOT NULL CHECK (source IN ('recorded', 'autopilot')),
            verdict TEXT,
            label TEXT,
            conditions TEXT NOT NULL DEFAULT '{}',
            record TEXT NOT NULL DEFAULT '{}',
            UNIQUE (flight_id, number))""",
        "CREATE INDEX test_points_flight ON test_points(flight_id)",
        "CREATE INDEX test_points_axis ON test_points(axis)",
        "CREATE INDEX test_points_verdict ON test_points(verdict)",
        "CREATE INDEX test_points_input ON test_points(swept_input)",
        """CREATE TABLE results (
            id INTEGER PRIMARY KEY,
            test_point_ids TEXT NOT NULL,
            selection TEXT,
            kind TEXT NOT NULL,
            data TEXT NOT NULL,
            added_at TEXT NOT NULL)""",
    ),
)
SCHEMA_VERSION = len(MIGRATIONS)
#: How long a writer waits for another's transaction before giving up [ms].
BUSY_TIMEOUT_MS = 30_000


@dataclass(frozen=True)
class AddReport:
    """What :meth:`Campaign.add` did, file by file.

    Attributes
    ----------
    added : tuple of (str, int)
        ``(path, test points)`` of each file added.
    unchanged : tuple of str
        Files whose content (SHA-256) was already in the campaign.
    skipped : tuple of (str, str)
        ``(path, one-line reason)`` of each file not added (damaged, unreadable, not a log).
    """

    added: tuple = ()
    unchanged: tuple = ()
    skipped: tuple = ()


@dataclass(frozen=True)
class FlightRow:
    id: int
    sha256: str
    path: str
    format: str
    vehicle: str | None
    date: str | None
    added_at: str
    test_points: int = 0


@dataclass(frozen=True)
class TestPointRow:
    """One test point. ``conditions`` is a tuple of ``(name, value)`` pairs (sorted); ``record``
    the JSON text of the whole record (:attr:`record_dict` parses it)."""

    __test__ = False                 # not a pytest class

    id: int
    flight_id: int
    flight_path: str
    number: int
    start_s: float | None
    end_s: float | None
    swept_input: str | None
    axis: int | None
    source: str
    verdict: str | None
    label: str | None
    conditions: tuple = field(default_factory=tuple)
    record: str = "{}"

    def condition(self, name: str, default=None):
        return dict(self.conditions).get(name, default)

    @property
    def record_dict(self) -> dict:
        return json.loads(self.record)


def open(path) -> Campaign:  # noqa: A001 - livesweep.campaign.open(path), as the issue asks
    """Open (or create) the campaign database at ``path`` and bring its schema up to date."""
    return Campaign(path)


def _now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())


class Campaign:
    """A campaign database (see the module docstring). Use as a context manager or call
    :meth:`close`."""

    def __init__(self, path):
        self.path = Path(path)
        self._con = sqlite3.connect(str(self.path), timeout=BUSY_TIMEOUT_MS / 1000, isolation_level=None)
        c = self._con
        c.execute(f"PRAGMA busy_timeout = {BUSY_TIMEOUT_MS}")
        try:
            mode = c.execute("PRAGMA journal_mode = WAL").fetchone()[0]
        except sqlite3.DatabaseError as e:
            c.close()
            raise LivesweepError(f"{self.path}: not a campaign database ({e})") from None
        if mode.lower() != "wal":
            c.close()
            raise LivesweepError(f"{self.path}: could not switch the database to WAL (journal mode {mode})")
        c.execute("PRAGMA foreign_keys = ON")
        c.execute("PRAGMA synchronous = NORMAL")       # WAL: durable at checkpoints, never corrupt
        self._migrate()

    # -- plumbing -----------------------------------------------------------------------------
    def _migrate(self) -> None:
        c = self._con
        if c.execute("PRAGMA user_version").fetchone()[0] >= SCHEMA_VERSION:
            return
        c.execute("BEGIN IMMEDIATE")
        try:
            v = c.execute("PRAGMA user_version").fetchone()[0]      # again, under the write lock
            if v > SCHEMA_VERSION:
                raise LivesweepError(f"{self.path}: campaign schema {v} is newer than this livesweep's "
                                     f"({SCHEMA_VERSION})")
            for k in range(v, SCHEMA_VERSION):
                for stmt in MIGRATIONS[k]:
                    c.execute(stmt)
            c.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
            c.execute("COMMIT")
        except BaseException:
            c.execute("ROLLBACK")
            raise

    @property
    def schema_version(self) -> int:
        return self._con.execute("PRAGMA user_version").fetchone()[0]

    @property
    def connection(self) -> sqlite3.Connection:
        """The SQLite connection (for queries this class does not offer)."""
        return self._con

    def close(self) -> None:
        self._con.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # -- writing ------------------------------------------------------------------------------
    def has(self, sha256: str) -> bool:
        return self._con.execute("SELECT 1 FROM flights WHERE sha256 = ?", (sha256,)).fetchone() is not None

    def insert(self, scanned) -> int | None:
        """Write one scanned file (:class:`~livesweep.campaign.scan.ScannedFile`, or anything with
        its attributes) and its test points in ONE transaction. Returns the new flight id, or None
        when its SHA-256 is already in (nothing written)."""
        c = self._con
        c.execute("BEGIN IMMEDIATE")
        try:
            if c.execute("SELECT 1 FROM flights WHERE sha256 = ?", (scanned.sha256,)).fetchone() is not None:
                c.execute("ROLLBACK")
                return None
            fid = c.execute("INSERT INTO flights (sha256, path, format, vehicle, date, added_at) "
                            "VALUES (?, ?, ?, ?, ?, ?)",
                            (scanned.sha256, str(scanned.path), scanned.format, scanned.vehicle, scanned.date,
                             _now())).lastrowid
            c.executemany(
                "INSERT INTO test_points (flight_id, number, start_s, end_s, swept_input, axis, source, verdict, "
                "label, conditions, record) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                [(fid, tp["number"], tp["start_s"], tp["end_s"], tp["swept_input"], tp["axis"], tp["source"],
                  tp["verdict"], tp["label"], json.dumps(tp.get("conditions") or {}, sort_keys=True),
                  json.dumps(tp.get("record") or {}, sort_keys=True, default=str))
                 for tp in scanned.test_points])
            c.execute("COMMIT")
            return fid
        except BaseException:
            if c.in_transaction:
                c.execute("ROLLBACK")
            raise

    def add(self, paths, *, progress=None) -> AddReport:
        """Add log files: each read (:func:`~livesweep.campaign.scan.scan_file`), then written with
        its test points in one transaction. A file whose content is already in is unchanged; a
        damaged or unreadable one is skipped with a one-line reason, nothing of it written.
        ``progress(path, outcome, detail)`` is called after each file."""
        from livesweep.campaign.scan import scan_file, sha256_of

        if isinstance(paths, (str, Path)):
            paths = [paths]
        added, unchanged, skipped = [], [], []
        for p in paths:
            p = str(p)
            try:
                if Path(p).is_file() and self.has(sha256_of(p)):     # cheap: no log reading
                    unchanged.append(p)
                    outcome, detail = "unchanged", None
                else:
                    scanned = scan_file(p)
                    if self.insert(scanned) is None:
                        unchanged.append(p)
                        outcome, detail = "unchanged", None
                    else:
                        added.append((p, len(scanned.test_points)))
                        outcome, detail = "added", len(scanned.test_points)
            except (LivesweepError, OSError) as e:
                reason = str(e).splitlines()[0] if str(e) else type(e).__name__
                for prefix in (str(Path(p).resolve()) + ": ", p + ": "):      # the path is said once
                    reason = reason.removeprefix(prefix)
                skipped.append((p, reason))
                outcome, detail = "skipped", reason
            if progress is not None:
                progress(p, outcome, detail)
        return AddReport(tuple(added), tuple(unchanged), tuple(skipped))

    def add_result(self, test_point_ids, kind: str, data, *, selection=None) -> int:
        """Store an identification result over some test points; returns its id."""
        c = self._con
        c.execute("BEGIN IMMEDIATE")
        try:
            rid = c.execute("INSERT INTO results (test_point_ids, selection, kind, data, added_at) "
                            "VALUES (?, ?, ?, ?, ?)",
                            (json.dumps([int(i) for i in test_point_ids]),
                             None if selection is None else json.dumps(selection, sort_keys=True), kind,
                             json.dumps(data, sort_keys=True, default=str), _now())).lastrowid
            c.execute("COMMIT")
            return rid
        except BaseException:
            if c.in_transaction:
                c.execute("ROLLBACK")
            raise

    # -- reading ------------------------------------------------------------------------------
    def flights(self) -> list[FlightRow]:
        rows = self._con.execute(
            "SELECT f.id, f.sha256, f.path, f.format, f.vehicle, f.date, f.added_at, "
            "(SELECT COUNT(*) FROM test_points t WHERE t.flight_id = f.id) FROM flights f ORDER BY f.id")
        return [FlightRow(*r) for r in rows]

    def test_points(self, *, axis=None, swept_input=None, verdict=None, flight=None, source=None,
                    conditions=None) -> list[TestPointRow]:
        """Test points matching every filter given, in flight then number order.

        ``flight`` is a flight id or a SHA-256 (a prefix of at least 8 hex digits works);
        ``verdict`` ``"GO"``, ``"NO-GO"`` ... or ``"none"`` for the unjudged; ``conditions`` maps a
        condition name to ``(lo, hi)`` inclusive (either None for open-ended): a test point
        without that condition does not match."""
        where, args = [], []
        if axis is not None:
            where.append("t.axis = ?"), args.append(int(axis))
        if swept_input is not None:
            where.append("t.swept_input = ?"), args.append(swept_input)
        if verdict is not None:
            if str(verdict).lower() in ("none", "null"):
                where.append("t.verdict IS NULL")
            else:
                where.append("t.verdict = ?"), args.append(str(verdict).upper())
        if source is not None:
            where.append("t.source = ?"), args.append(source)
        if flight is not None:
            if isinstance(flight, int) or str(flight).isdigit() and len(str(flight)) < 8:
                where.append("t.flight_id = ?"), args.append(int(flight))
            else:
                where.append("f.sha256 LIKE ?"), args.append(str(flight).lower() + "%")
        for name, (lo, hi) in (conditions or {}).items():
            expr = "json_extract(t.conditions, ?)"
            key = "$." + json.dumps(str(name))
            where.append(f"{expr} IS NOT NULL"), args.append(key)
            if lo is not None:
                where.append(f"{expr} >= ?"), args.extend((key, float(lo)))
            if hi is not None:
                where.append(f"{expr} <= ?"), args.extend((key, float(hi)))
        sql = ("SELECT t.id, t.flight_id, f.path, t.number, t.start_s, t.end_s, t.swept_input, t.axis, t.source, "
               "t.verdict, t.label, t.conditions, t.record FROM test_points t JOIN flights f ON f.id = t.flight_id"
               + (" WHERE " + " AND ".join(where) if where else "") + " ORDER BY t.flight_id, t.number")
        out = []
        for r in self._con.execute(sql, args):
            cond = tuple(sorted(json.loads(r[11]).items()))
            out.append(TestPointRow(*r[:11], conditions=cond, record=r[12]))
        return out

    def counts(self) -> dict:
        """Rows per table."""
        return {t: self._con.execute(f"SELECT COUNT(*) FROM {t}").fetchone()[0]
                for t in ("flights", "test_points", "results")}
