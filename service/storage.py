"""Durable, idempotent storage of readings, dead letters and runner checkpoints.

One interface, :class:`Storage`, two backends selected by URL with
:func:`open_storage`:

- ``sqlite:///relative/path.db``, ``sqlite:////absolute/path.db`` (default
  :data:`DEFAULT_URL`): WAL journal with ``synchronous=FULL``, so a committed
  transaction survives a power cut; times are stored as integer microseconds
  since the Unix epoch (UTC).
- ``postgresql://user@host:port/db`` (psycopg 3): times are ``timestamptz``.
  The extra query parameter ``schema=NAME`` keeps all tables in that schema
  (created if missing), e.g. one schema per test run or per deployment.

Idempotency rule: a reading is identified by ``(building, point, time)``. The
first value stored for a key is kept; a later reading with the same key is a
*duplicate* (not stored again). A duplicate whose value differs from the stored
one is also counted as a *conflict* (:attr:`PutResult.conflicts`) and logged,
but never overwrites: stored history is immutable, so a forecast can always be
reproduced from what was stored. Correct a wrong value by deleting it first.

All methods are thread-safe (one connection guarded by a lock).
"""

from __future__ import annotations

import logging
import math
import sqlite3
import threading
import time
from abc import ABC, abstractmethod
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any, ClassVar, NamedTuple, Self
from urllib.parse import parse_qsl, urlencode, urlsplit, urlunsplit

import numpy as np
import pandas as pd
from zonecast.service.ingest import CheckedReadings, parse_time
from zonecast.service.settings import DEFAULT_URL

__all__ = [
    "DEFAULT_URL",
    "Checkpoint",
    "DeadLetter",
    "Gap",
    "PostgresStorage",
    "PutResult",
    "SQLiteStorage",
    "Storage",
    "StorageURLError",
    "open_storage",
]

log = logging.getLogger(__name__)

_EPOCH = datetime(1970, 1, 1, tzinfo=UTC)
#: Longest payload excerpt kept in a dead letter [characters].
EXCERPT_CHARS = 1024


#: gaps in the telemetry a building's site declares (schema 4): one row per point and run
#: of consecutive steps without a reading, [gap_start, gap_end); an open gap's end is where
#: the runner was when the row was last written
_GAPS_DDL = ("CREATE TABLE gaps (building TEXT NOT NULL, point TEXT NOT NULL, "
             "gap_start {time} NOT NULL, gap_end {time} NOT NULL, is_open {flag} NOT NULL, "
             "PRIMARY KEY (building, gap_start, point))")


class StorageURLError(ValueError):
    """The storage URL names no supported backend or is incomplete."""


class PutResult(tuple):
    """``(inserted, duplicates)`` of one write, plus ``conflicts``.

    Unpacks as a 2-tuple. ``duplicates`` counts every row not inserted because
    its key was already stored (or repeated within the same call);
    ``conflicts`` is the part of ``duplicates`` whose value differed.
    """

    def __new__(cls, inserted: int, duplicates: int, conflicts: int = 0) -> Self:
        self = super().__new__(cls, (inserted, duplicates))
        self.conflicts = conflicts
        return self

    @property
    def inserted(self) -> int:
        return self[0]

    @property
    def duplicates(self) -> int:
        return self[1]

    def __repr__(self) -> str:
        return (f"PutResult(inserted={self[0]}, duplicates={self[1]}, "
                f"conflicts={self.conflicts})")


@dataclass(frozen=True)
class DeadLetter:
    """A rejected message as stored (``payload`` is an excerpt)."""

    id: int
    building: str | None
    topic: str
    payload: str
    reason: str
    received_at: datetime


@dataclass(frozen=True)
class Gap:
    """A run of consecutive steps without a reading of one point, ``[start, end)``; an
    open gap has not ended yet (``end``: how far it was known to reach)."""

    point: str
    start: datetime
    end: datetime
    open: bool


class Checkpoint(NamedTuple):
    """Latest saved state of a building's online runner."""

    time: datetime
    state: bytes
    saved_at: datetime


def _utc(value: Any, what: str) -> datetime:
    """A tz-aware UTC datetime from a datetime, pandas Timestamp or ISO string."""
    if hasattr(value, "to_pydatetime"):
        value = value.to_pydatetime()
    try:
        return parse_time(value)
    except ValueError as exc:
        raise ValueError(f"{what}: {exc}") from None


def _excerpt(payload: bytes | str) -> str:
    if isinstance(payload, bytes | bytearray | memoryview):
        payload = bytes(payload[: EXCERPT_CHARS * 4]).decode("utf-8", errors="replace")
    # PostgreSQL text cannot hold NUL: keep the excerpt storable on every backend.
    return payload[:EXCERPT_CHARS].replace("\x00", "\ufffd")


def _check_name(value: Any, what: str) -> str:
    if not isinstance(value, str) or not value or "\x00" in value:
        raise ValueError(f"{what} must be a non-empty string without NUL characters, "
                         f"got {value!r}")
    return value


def _unique_rows(rows: Iterable[Sequence[Any]]
                 ) -> tuple[list[tuple[str, datetime, float]], int, int, set[datetime]]:
    """Validate rows; drop repeats of a key inside the batch (first kept).

    Returns the unique rows, the number of repeats, how many of those repeats carried a
    different value, and the distinct times.
    """
    if type(rows) is CheckedReadings:  # validated by ingest with distinct keys
        return list(rows), 0, 0, {row[1] for row in rows}
    seen: dict[tuple[str, datetime], float] = {}
    times: set[datetime] = set()
    repeats = conflicts = 0
    for row in rows:
        try:
            point, when, value = row
        except (TypeError, ValueError):
            raise ValueError(f"reading {row!r} must be a (point, time, value) triple") from None
        if type(point) is not str or not point or "\x00" in point:  # message built on error only
            _check_name(point, f"reading {row!r}: point")
        if isinstance(value, bool) or not isinstance(value, int | float) \
                or not math.isfinite(value):
            raise ValueError(f"reading {row!r}: value must be a finite number; omit missing "
                             "readings instead of storing NaN")
        # ingest hands over UTC datetimes: no parsing for those (the hot path)
        key = (point, when if type(when) is datetime and when.tzinfo is UTC
               else _utc(when, f"reading {point!r}"))
        if key in seen:
            repeats += 1
            conflicts += seen[key] != float(value)
        else:
            seen[key] = float(value)
            times.add(key[1])
    return [(p, t, v) for (p, t), v in seen.items()], repeats, conflicts, times


def _distinct_keys(prepared: list[tuple]) -> bool:
    """True if no key (point, time) repeats across these prepared batches of one building
    (each batch's keys are distinct already)."""
    if len(prepared) == 1:
        return True
    # batches with disjoint times (one message, one time) cannot share a key; else compare
    # the keys themselves
    times = [b[4] for b in prepared]
    if sum(map(len, times)) == len(set().union(*times)):
        return True
    keys = [(p, t) for b in prepared for p, t, _ in b[1]]
    return len(set(keys)) == len(keys)


class _KeyStored(Exception):
    """Internal: a reading's key is stored already (rolls back the fast path of put_many)."""


class Storage(ABC):
    """Readings, dead letters and checkpoints of any number of buildings.

    Use :func:`open_storage` rather than the subclasses. The schema is created
    or migrated on open (table ``schema_version`` records applied versions).
    """

    #: Placeholder style of the driver ("?" for sqlite3, "%s" for psycopg).
    _param = "?"
    #: Versioned migrations: version -> DDL statements of this backend.
    _migrations: ClassVar[dict[int, tuple[str, ...]]] = {}

    def __init__(self, url: str):
        self.url = url
        self._lock = threading.RLock()
        self._conn: Any = None
        self._connect()
        self._migrate()

    # --- backend hooks -------------------------------------------------
    @abstractmethod
    def _connect(self) -> None:
        """Open ``self._conn``."""

    @abstractmethod
    def _transaction(self) -> Any:
        """Context manager: one transaction, yields a cursor."""

    @abstractmethod
    def _insert_unique(self, cur: Any, building: str, rows: list[tuple[str, datetime, float]],
                       received_at: datetime) -> tuple[int, int]:
        """Insert key-unique rows, keep existing; return (inserted, conflicts)."""

    @abstractmethod
    def _lock_schema(self, cur: Any) -> None:
        """Serialise concurrent migrations."""

    def _to_db(self, when: datetime) -> Any:
        return when

    def _from_db(self, value: Any) -> datetime:
        return value.astimezone(UTC)

    def _sql(self, text: str) -> str:
        return text if self._param == "?" else text.replace("?", self._param)

    def _unsynced(self) -> Any:
        """Context (entered with the lock held, outside a transaction) in which commits
        do not wait for the disk; default: nothing to do."""
        return nullcontext()

    def _unsynced_transaction(self, cur: Any) -> None:
        """Make the current transaction's commit not wait for the disk (if per
        transaction)."""

    # --- schema ----------------------------------------------------------
    @property
    def schema_version(self) -> int:
        """Highest applied migration."""
        with self._transaction() as cur:
            cur.execute("SELECT max(version) FROM schema_version")
            return int(cur.fetchone()[0] or 0)

    def _migrate(self) -> None:
        with self._transaction() as cur:
            self._lock_schema(cur)
            cur.execute("CREATE TABLE IF NOT EXISTS schema_version ("
                        "version INTEGER PRIMARY KEY, applied_at TEXT NOT NULL)")
            cur.execute("SELECT max(version) FROM schema_version")
            current = int(cur.fetchone()[0] or 0)
            for version in sorted(v for v in self._migrations if v > current):
                for statement in self._migrations[version]:
                    cur.execute(statement)
                cur.execute(self._sql("INSERT INTO schema_version VALUES (?, ?)"),
                            (version, datetime.now(UTC).isoformat()))
                log.info("storage %s: applied schema version %d", self._safe_url(), version)

    def _safe_url(self) -> str:
        parts = urlsplit(self.url)
        netloc = parts.netloc.rsplit("@", 1)[-1]
        return urlunsplit((parts.scheme, netloc, parts.path, "", ""))

    # --- readings --------------------------------------------------------
    def put_readings(self, building: str, rows: Iterable[Sequence[Any]], *,
                     received_at: datetime | None = None) -> PutResult:
        """Store readings of one building in one transaction, idempotently.

        Parameters
        ----------
        building : str
            Building identifier.
        rows : iterable of (point, time, value)
            ``time`` tz-aware (datetime, pandas Timestamp or ISO string with
            offset); ``value`` a finite number in the point's unit.
        received_at : datetime, optional
            When the readings arrived; default now (UTC).

        Returns
        -------
        PutResult
            ``(inserted, duplicates)`` with ``.conflicts``; see the module
            docstring for the keep-first rule.
        """
        return self.put_many([(building, rows)], received_at=received_at)[0]

    def put_many(self, batches: Sequence[tuple[str, Iterable[Sequence[Any]]]],
                 dead_letters: Sequence[dict[str, Any]] = (), *,
                 received_at: datetime | None = None) -> list[PutResult]:
        """Store readings of several buildings and dead letters in ONE transaction.

        The ingester uses this to commit a group of messages with one disk
        sync before acknowledging them.

        Parameters
        ----------
        batches : sequence of (building, rows)
            As for :meth:`put_readings`.
        dead_letters : sequence of dict
            Keyword arguments of :meth:`put_dead_letter`.
        received_at : datetime, optional
            Arrival time of the readings; default now (UTC).

        Returns
        -------
        list of PutResult
            One per batch, in order.
        """
        received = _utc(received_at or datetime.now(UTC), "received_at")
        prepared = []
        for building, rows in batches:
            _check_name(building, "building")
            prepared.append((building, *_unique_rows(rows)))
        letters = [self._dead_letter_row(**kw) for kw in dead_letters]
        groups = self._by_building(prepared)
        if self._new_rows_cheaper and all(_distinct_keys([prepared[i] for i in members])
                                          for members in groups.values()):
            # the normal case first, without savepoints (two round trips less per commit):
            # every reading new, one plain INSERT per building
            try:
                with self._transaction() as cur:
                    for building, members in groups.items():
                        rows = [row for i in members for row in prepared[i][1]]
                        if not self._insert_new(cur, building, rows, received):
                            raise _KeyStored
                    self._insert_dead_letters(cur, letters)
            except _KeyStored:
                # rolled back: some key is stored already (a redelivery). Below, by the
                # keep-first insert only: a second plain INSERT would write (and undo) rows
                # again, and a transaction that wrote nothing commits without a disk sync
                plain = False
            else:
                results = [PutResult(len(unique), repeats, repeat_conflicts)
                           for _, unique, repeats, repeat_conflicts, _ in prepared]
                plain = None
        else:
            plain = True
        if plain is not None:
            results = [PutResult(0, 0)] * len(prepared)
            with self._transaction() as cur:
                for building, members in groups.items():
                    self._insert_group(cur, building, [(i, prepared[i]) for i in members],
                                       received, results, plain)
                self._insert_dead_letters(cur, letters)
        for (building, *_), result in zip(prepared, results, strict=True):
            if result.conflicts:
                log.warning("building %s: %d readings conflict with stored values (kept the "
                            "stored ones)", building, result.conflicts)
        return results

    @staticmethod
    def _by_building(prepared: list[tuple]) -> dict[str, list[int]]:
        groups: dict[str, list[int]] = {}
        for i, (building, unique, *_) in enumerate(prepared):
            if unique:
                groups.setdefault(building, []).append(i)
        return groups

    def _insert_group(self, cur: Any, building: str, members: list[tuple[int, tuple]],
                      received: datetime, results: list[PutResult], plain: bool = True) -> None:
        """Store the batches of one building (``members``: index, prepared batch) and set
        their results. One statement for all of them when their keys are distinct and all
        new (the normal case: one statement per building and commit, not per message);
        otherwise (a redelivery or a key repeated across messages) the statement is undone
        and each batch is stored by itself, so every batch's counts stay exact. ``plain``
        False: the one statement is the keep-first insert even where a plain INSERT would be
        cheaper (a key is known to be stored)."""
        if len(members) > 1 or (plain and self._new_rows_cheaper):
            combined = [row for _, (_, unique, *_) in members for row in unique]
            if _distinct_keys([b for _, b in members]):
                insert_new = self._insert_new if plain else Storage._insert_new.__get__(self)
                cur.execute("SAVEPOINT zonecast_group")
                if insert_new(cur, building, combined, received):
                    cur.execute("RELEASE SAVEPOINT zonecast_group")
                    for i, (_, unique, repeats, repeat_conflicts, _) in members:
                        results[i] = PutResult(len(unique), repeats, repeat_conflicts)
                    return
                cur.execute("ROLLBACK TO SAVEPOINT zonecast_group")
                cur.execute("RELEASE SAVEPOINT zonecast_group")
        for i, (_, unique, repeats, repeat_conflicts, _) in members:
            inserted, conflicts = self._insert_unique(cur, building, unique, received)
            results[i] = PutResult(inserted, len(unique) - inserted + repeats,
                                   conflicts + repeat_conflicts)

    #: True if :meth:`_insert_new` is cheaper than :meth:`_insert_unique` (PostgreSQL: a
    #: plain INSERT instead of ON CONFLICT's speculative insertion), so that even a single
    #: batch tries it first
    _new_rows_cheaper = False

    def _insert_new(self, cur: Any, building: str, rows: list[tuple[str, datetime, float]],
                    received_at: datetime) -> bool:
        """Insert key-unique rows expected to be new, inside a savepoint the caller rolls
        back on False: True if every row went in, False if some key was already stored (the
        transaction may then be in error until the rollback)."""
        inserted, _ = self._insert_unique(cur, building, rows, received_at)
        return inserted == len(rows)

    def reading_bounds(self, building: str, since: Any = None, until: Any = None
                       ) -> tuple[datetime | None, datetime | None, datetime | None]:
        """First reading time at or after ``since`` (any time if None), latest reading
        time (before ``until`` if given), and latest arrival (``received_at``) of
        ``building``; None where no row.

        The online runner uses these to find its first step, to skip gaps and as the
        watermark of the stream; ``until`` keeps implausible future times out of both
        reading times.
        """
        where, params = "building = ?", [building]
        received_where, received_params = where, list(params)
        if until is not None:
            where += " AND time < ?"
            params.append(self._to_db(_utc(until, "until")))
        first_where, first_params = where, list(params)
        if since is not None:
            first_where += " AND time >= ?"
            first_params.append(self._to_db(_utc(since, "since")))
        # one aggregate per statement: each is then a single look-up in an index
        # ((building, time), (building, received_at)) instead of a scan of the building
        with self._transaction() as cur:
            cur.execute(self._sql(f"SELECT MIN(time) FROM readings WHERE {first_where}"),
                        first_params)
            first = cur.fetchone()[0]
            cur.execute(self._sql(f"SELECT MAX(time) FROM readings WHERE {where}"), params)
            last = cur.fetchone()[0]
            cur.execute(self._sql(f"SELECT MAX(received_at) FROM readings WHERE "
                                  f"{received_where}"), received_params)
            received = cur.fetchone()[0]
        return tuple(None if v is None else self._from_db(v)  # type: ignore[return-value]
                     for v in (first, last, received))

    def supported_watermark(self, building: str, since: Any, until: Any,
                            min_points: int = 2, exclude: Sequence[str] = ()
                            ) -> datetime | None:
        """The latest time in ``[since, until)`` at which readings of at least
        ``min_points`` points of ``building`` are stored; None if there is none. Readings
        of the ``exclude`` points neither make such a time nor count toward it.

        The runner's watermark: a lone reading far ahead of the stream (a publisher with a
        wrong clock) is not one, so it cannot close the rows before it; nor can a feed of
        points the rows do not wait for (the runner excludes the lights and plug-load
        meters, which may come from another system ahead of the temperatures). One
        backwards walk of the ``(building, time)`` index from ``until``, with a count per
        candidate time; it stops at the first time that qualifies.
        """
        if min_points < 1:
            raise ValueError(f"min_points must be >= 1, got {min_points}")
        lo, hi = self._to_db(_utc(since, "since")), self._to_db(_utc(until, "until"))
        exclude = sorted(set(exclude))
        marks = ", ".join("?" * len(exclude))
        outer = f" AND r.point NOT IN ({marks})" if exclude else ""
        inner = f" AND s.point NOT IN ({marks})" if exclude else ""
        with self._transaction() as cur:
            cur.execute(self._sql(
                "SELECT r.time FROM readings r WHERE r.building = ? AND r.time >= ? "
                f"AND r.time < ?{outer} AND (SELECT COUNT(*) FROM readings s WHERE "
                f"s.building = r.building AND s.time = r.time{inner}) >= ? "
                "ORDER BY r.time DESC LIMIT 1"),
                (building, lo, hi, *exclude, *exclude, int(min_points)))
            row = cur.fetchone()
        return None if row is None else self._from_db(row[0])

    def late_readings(self, building: str, received_after: Any, received_until: Any,
                      before: Any) -> tuple[int, datetime | None, datetime | None]:
        """Readings of ``building`` that arrived in ``(received_after, received_until]`` with
        a time before ``before``: (count, earliest time, latest time).

        The runner counts with this the readings that came for rows it had already
        processed (a scan of the arrivals since its last poll, by the
        ``(building, received_at)`` index).
        """
        with self._transaction() as cur:
            cur.execute(self._sql(
                "SELECT COUNT(*), MIN(time), MAX(time) FROM readings WHERE building = ? "
                "AND received_at > ? AND received_at <= ? AND time < ?"),
                (building, self._to_db(_utc(received_after, "received_after")),
                 self._to_db(_utc(received_until, "received_until")),
                 self._to_db(_utc(before, "before"))))
            n, lo, hi = cur.fetchone()
        return (int(n), None if lo is None else self._from_db(lo),
                None if hi is None else self._from_db(hi))

    def readings(self, building: str, start: Any, end: Any,
                 points: Sequence[str] | None = None) -> pd.DataFrame:
        """Readings of one building in ``[start, end)`` as a wide table.

        Parameters
        ----------
        building : str
            Building identifier.
        start, end : datetime, pandas Timestamp or ISO string
            tz-aware bounds; ``start`` inclusive, ``end`` exclusive.
        points : sequence of str, optional
            Only these points, as columns in this order (all-NaN when a point
            has no data). Default: every stored point, sorted by name.

        Returns
        -------
        pandas.DataFrame
            Index ``time`` (tz-aware UTC, ascending), one float column per
            point, NaN where a point has no reading at that time.
        """
        lo, hi = _utc(start, "start"), _utc(end, "end")
        sql = "SELECT point, time, value FROM readings WHERE building = ? AND time >= ? AND time < ?"
        params: list[Any] = [building, self._to_db(lo), self._to_db(hi)]
        if points is not None:
            points = list(points)
            if not points:
                raise ValueError("points is empty: pass None for all points")
            sql += f" AND point IN ({', '.join('?' * len(points))})"
            params += points
        with self._transaction() as cur:
            cur.execute(self._sql(sql + " ORDER BY time, point"), params)
            rows = cur.fetchall()
        long = pd.DataFrame(rows, columns=["point", "time", "value"])
        long["time"] = pd.DatetimeIndex([self._from_db(t) for t in long["time"]], tz=UTC) \
            if len(long) else pd.DatetimeIndex([], tz=UTC)
        long["value"] = long["value"].astype(float)
        wide = long.pivot(index="time", columns="point", values="value")
        wide.columns.name = None
        wide = wide.reindex(columns=points if points is not None else sorted(wide.columns))
        wide.index = pd.DatetimeIndex(wide.index, tz=UTC, name="time")
        return wide.astype(float)

    def _ns(self, value: Any) -> int:
        """Stored time -> UTC nanoseconds since the epoch."""
        delta = self._from_db(value) - _EPOCH
        return ((delta.days * 86_400 + delta.seconds) * 1_000_000 + delta.microseconds) * 1000

    def readings_matrix(self, building: str, start: Any, end: Any,
                        points: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
        """Readings of ``points`` in ``[start, end)`` as plain arrays (no pandas): the
        online runner's read.

        Returns
        -------
        times : numpy.ndarray of int64, shape (N,)
            Distinct reading times, ascending, as UTC nanoseconds since the epoch.
        values : numpy.ndarray, shape (N, len(points))
            One column per point in the order given; NaN where a point has no reading.
        """
        points = list(points)
        if not points:
            raise ValueError("points is empty")
        lo, hi = _utc(start, "start"), _utc(end, "end")
        sql = (f"SELECT point, time, value FROM readings WHERE building = ? AND time >= ? "
               f"AND time < ? AND point IN ({', '.join('?' * len(points))}) ORDER BY time")
        with self._transaction() as cur:
            cur.execute(self._sql(sql), [building, self._to_db(lo), self._to_db(hi), *points])
            rows = cur.fetchall()
        col = {p: j for j, p in enumerate(points)}
        row_of: dict[Any, int] = {}
        for _, when, _ in rows:
            if when not in row_of:
                row_of[when] = len(row_of)
        values = np.full((len(row_of), len(points)), np.nan)
        for point, when, value in rows:
            values[row_of[when], col[point]] = value
        times = np.fromiter((self._ns(t) for t in row_of), dtype=np.int64, count=len(row_of))
        return times, values

    # --- dead letters ---------------------------------------------------------
    def _dead_letter_row(self, topic: str, payload: bytes | str, reason: str, *,
                         building: str | None = None,
                         received_at: datetime | None = None) -> tuple[Any, ...]:
        received = _utc(received_at or datetime.now(UTC), "received_at")
        return (building, _excerpt(topic), _excerpt(payload), _excerpt(str(reason)),
                self._to_db(received))

    def _insert_dead_letters(self, cur: Any, rows: list[tuple[Any, ...]]) -> None:
        if rows:
            cur.executemany(self._sql("INSERT INTO dead_letters (building, topic, payload, reason, "
                                      "received_at) VALUES (?, ?, ?, ?, ?)"), rows)

    def put_dead_letter(self, topic: str, payload: bytes | str, reason: str, *,
                        building: str | None = None,
                        received_at: datetime | None = None) -> None:
        """Record a rejected message.

        Parameters
        ----------
        topic : str
            Topic the message arrived on.
        payload : bytes or str
            The message body; the first :data:`EXCERPT_CHARS` characters are kept.
        reason : str
            Why it was rejected (``"<code>: <detail>"``).
        building : str, optional
            Building named by the topic, if it could be read.
        received_at : datetime, optional
            Arrival time; default now (UTC).
        """
        row = self._dead_letter_row(topic, payload, reason, building=building,
                                    received_at=received_at)
        with self._transaction() as cur:
            self._insert_dead_letters(cur, [row])

    def dead_letters(self, limit: int = 100, building: str | None = None) -> list[DeadLetter]:
        """Most recent dead letters first, optionally of one building only."""
        if limit < 1:
            raise ValueError(f"limit must be >= 1, got {limit}")
        where = " WHERE building = ?" if building is not None else ""
        params = ([building] if building is not None else []) + [int(limit)]
        with self._transaction() as cur:
            cur.execute(self._sql("SELECT id, building, topic, payload, reason, received_at "
                                  f"FROM dead_letters{where} ORDER BY id DESC LIMIT ?"), params)
            rows = cur.fetchall()
        return [DeadLetter(i, b, t, p, r, self._from_db(at)) for i, b, t, p, r, at in rows]

    # --- gaps -----------------------------------------------------------------------
    def record_gaps(self, building: str, gaps: Iterable[Gap], *, sync: bool = True) -> None:
        """Insert or update gaps of ``building`` (keyed by point and start), one
        transaction. The runner writes a gap when it opens and when it closes; ``sync``
        as for :meth:`save_checkpoint`."""
        rows = [(building, _check_name(g.point, "gap point"),
                 self._to_db(_utc(g.start, "gap start")), self._to_db(_utc(g.end, "gap end")),
                 bool(g.open)) for g in gaps]
        if not rows:
            return
        with self._lock, (nullcontext() if sync else self._unsynced()), \
                self._transaction() as cur:
            if not sync:
                self._unsynced_transaction(cur)
            cur.executemany(self._sql(
                "INSERT INTO gaps (building, point, gap_start, gap_end, is_open) "
                "VALUES (?, ?, ?, ?, ?) ON CONFLICT (building, gap_start, point) DO UPDATE "
                "SET gap_end = excluded.gap_end, is_open = excluded.is_open"), rows)

    def gaps(self, building: str, start: Any = None, end: Any = None, *,
             point: str | None = None, open_only: bool = False, limit: int = 100,
             offset: int = 0) -> tuple[int, list[Gap]]:
        """Gaps of ``building`` overlapping ``[start, end)`` (open gaps reach any later
        ``start``), ordered by start and point.

        Returns
        -------
        total : int
            How many gaps match (for paging).
        page : list of Gap
            At most ``limit`` of them from ``offset`` on.
        """
        if limit < 1 or offset < 0:
            raise ValueError(f"limit must be >= 1 and offset >= 0, got {limit}, {offset}")
        where, params = ["building = ?"], [building]
        if end is not None:
            where.append("gap_start < ?")
            params.append(self._to_db(_utc(end, "end")))
        if start is not None:
            where.append("(gap_end > ? OR is_open)")
            params.append(self._to_db(_utc(start, "start")))
        if point is not None:
            where.append("point = ?")
            params.append(_check_name(point, "point"))
        if open_only:
            where.append("is_open")
        cond = " AND ".join(where)
        with self._transaction() as cur:
            cur.execute(self._sql(f"SELECT count(*) FROM gaps WHERE {cond}"), params)
            total = int(cur.fetchone()[0])
            cur.execute(self._sql(f"SELECT point, gap_start, gap_end, is_open FROM gaps "
                                  f"WHERE {cond} ORDER BY gap_start, point LIMIT ? OFFSET ?"),
                        [*params, int(limit), int(offset)])
            rows = cur.fetchall()
        return total, [Gap(p, self._from_db(a), self._from_db(b), bool(o))
                       for p, a, b, o in rows]

    # --- checkpoints ----------------------------------------------------------
    def save_checkpoint(self, building: str, time: Any, state: bytes, *,
                        sync: bool = True) -> None:
        """Save the online runner's state for ``building`` after step ``time``.

        Only the latest saved checkpoint per building is kept (last write wins,
        whatever its ``time``).

        Parameters
        ----------
        building : str
            Building identifier.
        time : datetime
            tz-aware time of the last step the state includes.
        state : bytes
            Opaque serialised state (e.g. UTF-8 JSON).
        sync : bool, default True
            False: commit without waiting for the disk (SQLite ``synchronous=NORMAL``
            for this transaction, PostgreSQL ``synchronous_commit = off``). The write
            is safe against a crash of the process and the database stays consistent;
            after a power cut or OS crash it may be lost until the next synchronous
            commit (any readings write) has flushed the log. The online runner uses
            this: a checkpoint it loses that way is one whose rows it can recompute
            from the stored readings, which were committed synchronously before it.
        """
        if not isinstance(state, bytes | bytearray | memoryview):
            raise TypeError(f"state must be bytes, got {type(state).__name__}: "
                            "serialise it (e.g. json.dumps(...).encode())")
        step = self._to_db(_utc(time, "checkpoint time"))
        saved = self._to_db(datetime.now(UTC))
        with self._lock, (nullcontext() if sync else self._unsynced()), \
                self._transaction() as cur:
            if not sync:
                self._unsynced_transaction(cur)
            cur.execute(self._sql(
                "INSERT INTO checkpoints (building, time, state, saved_at) VALUES (?, ?, ?, ?) "
                "ON CONFLICT (building) DO UPDATE SET time = excluded.time, "
                "state = excluded.state, saved_at = excluded.saved_at"),
                (building, step, bytes(state), saved))

    def load_checkpoint(self, building: str) -> Checkpoint | None:
        """The latest checkpoint of ``building``, or None if none was saved."""
        with self._transaction() as cur:
            cur.execute(self._sql("SELECT time, state, saved_at FROM checkpoints "
                                  "WHERE building = ?"), (building,))
            row = cur.fetchone()
        if row is None:
            return None
        return Checkpoint(self._from_db(row[0]), bytes(row[1]), self._from_db(row[2]))

    # --- identity of the service instance ------------------------------------
    def instance_value(self, key: str, default: str) -> str:
        """The value stored under ``key`` in table ``instance``; if there is none, store
        ``default`` and return it. Atomic: of two processes opening the same storage at once
        both get the value the first one stored. Used for values that must outlive restarts
        of the service, e.g. the MQTT ingester's client id (``mqtt_client_id``)."""
        if not key or not isinstance(default, str) or not default:
            raise ValueError("instance_value needs a non-empty key and default string")
        with self._lock, self._transaction() as cur:
            cur.execute(self._sql("INSERT INTO instance (key, value) VALUES (?, ?) "
                                  "ON CONFLICT (key) DO NOTHING"), (key, default))
            cur.execute(self._sql("SELECT value FROM instance WHERE key = ?"), (key,))
            return str(cur.fetchone()[0])

    # --- lifecycle ------------------------------------------------------------
    def close(self) -> None:
        """Close the connection (idempotent)."""
        with self._lock:
            if self._conn is not None:
                self._conn.close()
                self._conn = None

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self._safe_url()!r})"


class SQLiteStorage(Storage):
    """SQLite backend (WAL, ``synchronous=FULL``); see :func:`open_storage`."""

    _migrations: ClassVar[dict[int, tuple[str, ...]]] = {
        1: (
            ("CREATE TABLE readings (building TEXT NOT NULL, point TEXT NOT NULL, "
             "time INTEGER NOT NULL, value REAL NOT NULL, received_at INTEGER NOT NULL, "
             "PRIMARY KEY (building, point, time)) WITHOUT ROWID"),
            "CREATE INDEX readings_by_time ON readings (building, time)",
            ("CREATE TABLE dead_letters (id INTEGER PRIMARY KEY AUTOINCREMENT, building TEXT, "
             "topic TEXT NOT NULL, payload TEXT NOT NULL, reason TEXT NOT NULL, "
             "received_at INTEGER NOT NULL)"),
            ("CREATE TABLE checkpoints (building TEXT PRIMARY KEY, time INTEGER NOT NULL, "
             "state BLOB NOT NULL, saved_at INTEGER NOT NULL)"),
        ),
        # the runner's watermark query: latest arrival per building without a scan
        2: ("CREATE INDEX readings_by_received ON readings (building, received_at)",),
        # PostgreSQL's key order changed in 3; SQLite's readings stay as they are (rebuilding
        # a WITHOUT ROWID table would copy the whole history; SQLite was not the bottleneck)
        3: (),
        4: (_GAPS_DDL.format(time="INTEGER", flag="INTEGER"),),
        # values that outlive restarts of the service (the MQTT client id)
        5: ("CREATE TABLE instance (key TEXT PRIMARY KEY, value TEXT NOT NULL)",),
    }

    def __init__(self, url: str):
        path = url[len("sqlite://"):] if url.lower().startswith("sqlite:///") else ""
        if path in ("", "/"):
            raise StorageURLError(f"bad SQLite URL {url!r}: use sqlite:///relative.db or "
                                  "sqlite:////absolute/path.db")
        self.path = path[1:]
        super().__init__(url)

    def _connect(self) -> None:
        if self.path != ":memory:":
            Path(self.path).parent.mkdir(parents=True, exist_ok=True)
        conn = sqlite3.connect(self.path, isolation_level=None, check_same_thread=False,
                               timeout=30.0)
        # switching to WAL needs the file to itself and SQLite does not wait for that: a
        # second process (an ingest worker) opening the file while another one migrates it
        # gets "database is locked" at once, so wait here as long as the busy timeout would
        deadline = time.monotonic() + 30.0
        while True:
            try:
                conn.execute("PRAGMA journal_mode=WAL")
                break
            except sqlite3.OperationalError as exc:
                if "locked" not in str(exc) or time.monotonic() > deadline:
                    conn.close()
                    raise
                time.sleep(0.05)
        conn.execute("PRAGMA synchronous=FULL")
        conn.execute("PRAGMA foreign_keys=ON")
        self._conn = conn

    @contextmanager
    def _transaction(self) -> Iterator[sqlite3.Cursor]:
        with self._lock:
            if self._conn is None:
                raise ValueError(f"{self!r} is closed: open a new storage")
            cur = self._conn.cursor()
            cur.execute("BEGIN IMMEDIATE")
            try:
                yield cur
            except BaseException:
                cur.execute("ROLLBACK")
                raise
            cur.execute("COMMIT")

    def _lock_schema(self, cur: sqlite3.Cursor) -> None:
        pass  # BEGIN IMMEDIATE already holds the write lock

    @contextmanager
    def _unsynced(self) -> Iterator[None]:
        # per connection, set outside a transaction; in WAL mode NORMAL skips the sync at
        # commit, and the next FULL commit syncs the log with this transaction in it
        if self._conn is None:
            raise ValueError(f"{self!r} is closed: open a new storage")
        self._conn.execute("PRAGMA synchronous=NORMAL")
        try:
            yield
        finally:
            self._conn.execute("PRAGMA synchronous=FULL")

    def _to_db(self, when: datetime) -> int:
        delta = when - _EPOCH
        return (delta.days * 86_400 + delta.seconds) * 1_000_000 + delta.microseconds

    def _from_db(self, value: int) -> datetime:
        return _EPOCH + timedelta(microseconds=int(value))

    def _ns(self, value: int) -> int:
        return int(value) * 1000

    def _insert_unique(self, cur: sqlite3.Cursor, building: str,
                       rows: list[tuple[str, datetime, float]],
                       received_at: datetime) -> tuple[int, int]:
        received = self._to_db(received_at)
        params = [(building, p, self._to_db(t), v, received) for p, t, v in rows]
        cur.executemany("INSERT INTO readings (building, point, time, value, received_at) "
                        "VALUES (?, ?, ?, ?, ?) ON CONFLICT DO NOTHING", params)
        inserted = cur.rowcount
        conflicts = 0
        if inserted < len(rows):  # rare: redelivery; compare with what is stored
            for _, point, when, value, _ in params:
                cur.execute("SELECT value FROM readings WHERE building = ? AND point = ? "
                            "AND time = ?", (building, point, when))
                conflicts += cur.fetchone()[0] != value
        return inserted, conflicts


#: one statement per building and commit: the readings as three arrays, stored unless their
#: key is (ON CONFLICT on the primary key: no read of the history)
_PG_INSERT = (
    "INSERT INTO readings (building, point, time, value, received_at) "
    "SELECT %(b)s, i.point, i.time, i.value, %(r)s FROM unnest(%(p)s::text[], "
    "%(t)s::timestamptz[], %(v)s::float8[]) AS i(point, time, value) "
    "ON CONFLICT (building, point, time) DO NOTHING")
#: the same for rows expected to be new (a stored key raises unique_violation)
_PG_INSERT_NEW = _PG_INSERT.removesuffix(" ON CONFLICT (building, point, time) DO NOTHING")
#: how many of the readings differ from the stored value of their key. Runs after the
#: insert in the same transaction: a key inserted just now holds its own value, so only
#: keys stored before count. LATERAL ... LIMIT 1 makes it one primary-key look-up per
#: reading; a plain join let the planner hash the building's whole history (94 ms at
#: 258,000 readings, growing with it).
_PG_CONFLICTS = (
    "SELECT count(*) FROM unnest(%(p)s::text[], %(t)s::timestamptz[], %(v)s::float8[]) "
    "AS i(point, time, value) CROSS JOIN LATERAL (SELECT r.value FROM readings r "
    "WHERE r.building = %(b)s AND r.point = i.point AND r.time = i.time LIMIT 1) AS s "
    "WHERE s.value <> i.value")


def _pg_quote(text: str) -> str:
    """One element of a PostgreSQL array literal, double-quoted and escaped."""
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


class PostgresStorage(Storage):
    """PostgreSQL backend (psycopg 3); see :func:`open_storage`."""

    _param = "%s"
    _migrations: ClassVar[dict[int, tuple[str, ...]]] = {
        1: (
            ("CREATE TABLE readings (building TEXT NOT NULL, point TEXT NOT NULL, "
             "time TIMESTAMPTZ NOT NULL, value DOUBLE PRECISION NOT NULL, "
             "received_at TIMESTAMPTZ NOT NULL, PRIMARY KEY (building, point, time))"),
            "CREATE INDEX readings_by_time ON readings (building, time)",
            ("CREATE TABLE dead_letters (id BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY, "
             "building TEXT, topic TEXT NOT NULL, payload TEXT NOT NULL, reason TEXT NOT NULL, "
             "received_at TIMESTAMPTZ NOT NULL)"),
            ("CREATE TABLE checkpoints (building TEXT PRIMARY KEY, time TIMESTAMPTZ NOT NULL, "
             "state BYTEA NOT NULL, saved_at TIMESTAMPTZ NOT NULL)"),
        ),
        2: ("CREATE INDEX readings_by_received ON readings (building, received_at)",),
        # the key in the order readings arrive (one time, all points): inserts append at
        # the index's right edge instead of one leaf per point, and the key also serves the
        # time-range reads, so the (building, time) index goes (one index less per row)
        3: (("ALTER TABLE readings DROP CONSTRAINT readings_pkey, "
             "ADD CONSTRAINT readings_pkey PRIMARY KEY (building, time, point)"),
            "DROP INDEX readings_by_time"),
        4: (_GAPS_DDL.format(time="TIMESTAMPTZ", flag="BOOLEAN"),),
        # values that outlive restarts of the service (the MQTT client id)
        5: ("CREATE TABLE instance (key TEXT PRIMARY KEY, value TEXT NOT NULL)",),
    }

    def __init__(self, url: str):
        parts = urlsplit(url)
        query = dict(parse_qsl(parts.query))
        self.schema = query.pop("schema", None)
        if self.schema is not None and not self.schema.replace("_", "").isalnum():
            raise StorageURLError(f"schema {self.schema!r} must be letters, digits and _ only")
        query.setdefault("connect_timeout", "10")
        self._quoted: dict[str, str] = {}  # point -> its array-literal element
        self._conninfo = urlunsplit(("postgresql", parts.netloc, parts.path,
                                     urlencode(query), ""))
        super().__init__(url)

    def _connect(self) -> None:
        # imported here, not at the top: psycopg loads libpq, which only postgresql:// URLs
        # need; a SQLite deployment neither pays for it nor needs a working libpq
        import psycopg

        conn = psycopg.connect(self._conninfo, autocommit=True)
        conn.execute("SET TIME ZONE 'UTC'")
        if self.schema:
            conn.execute(f'CREATE SCHEMA IF NOT EXISTS "{self.schema}"')
            conn.execute(f'SET search_path TO "{self.schema}"')
        self._conn = conn

    @contextmanager
    def _transaction(self) -> Iterator[Any]:
        with self._lock:
            if self._conn is None:
                raise ValueError(f"{self!r} is closed: open a new storage")
            if self._conn.broken or self._conn.closed:
                log.warning("storage %s: connection lost, reconnecting", self._safe_url())
                self._connect()
            with self._conn.transaction(), self._conn.cursor() as cur:
                yield cur

    def _lock_schema(self, cur: Any) -> None:
        cur.execute("SELECT pg_advisory_xact_lock(hashtext(current_schema() || '.zonecast'))")

    def _unsynced_transaction(self, cur: Any) -> None:
        cur.execute("SET LOCAL synchronous_commit TO OFF")

    _new_rows_cheaper = True

    def _array_params(self, building: str, rows: list[tuple[str, datetime, float]],
                      received_at: datetime) -> dict[str, Any]:
        # the three columns as array literals built with str.join: psycopg adapts a
        # Python list item by item (about 4 us per reading, the largest CPU cost of ingest)
        quoted = self._quoted
        points, times, values = zip(*rows) if rows else ((), (), ())
        missing = set(points).difference(quoted)
        if missing:
            if len(quoted) + len(missing) > 100_000:  # bounded: names come from catalogues
                quoted.clear()
                missing = set(points)
            quoted.update((p, _pg_quote(p)) for p in missing)
        # ISO form of each distinct time: no character that needs quoting in an array
        stamps = {when: when.isoformat() for when in set(times)}
        # all of it in C-level joins and maps: ~1 us per reading less than a Python loop
        return {"p": "{" + ",".join(map(quoted.__getitem__, points)) + "}",
                "t": "{" + ",".join(map(stamps.__getitem__, times)) + "}",
                # shortest repr of each float: read back exactly
                "v": "{" + ",".join(map(float.__repr__, map(float, values))) + "}",
                "b": building, "r": received_at}

    def _insert_new(self, cur: Any, building: str, rows: list[tuple[str, datetime, float]],
                    received_at: datetime) -> bool:
        # A plain INSERT: ON CONFLICT's speculative insertion costs PostgreSQL ~2 us more
        # per row (~100 us of its CPU per 47-reading message, docs/benchmarks.md); a stored
        # key raises unique_violation and the caller falls back to _insert_unique.
        try:
            cur.execute(_PG_INSERT_NEW, self._array_params(building, rows, received_at))
        except Exception as exc:
            if getattr(exc, "sqlstate", None) == "23505":  # unique_violation
                return False
            raise
        return True

    def _insert_unique(self, cur: Any, building: str, rows: list[tuple[str, datetime, float]],
                       received_at: datetime) -> tuple[int, int]:
        params = self._array_params(building, rows, received_at)
        # The primary key (building, point, time) is the idempotency rule: each row is one
        # probe of its index, whatever the size of the history.
        cur.execute(_PG_INSERT, params)
        inserted = cur.rowcount
        conflicts = 0
        if inserted < len(rows):  # redelivery (rare): compare with what is stored
            cur.execute(_PG_CONFLICTS, params)
            conflicts = int(cur.fetchone()[0])
        return int(inserted), conflicts


def open_storage(url: str = DEFAULT_URL) -> Storage:
    """Open (and create or migrate) the storage named by ``url``.

    Parameters
    ----------
    url : str
        ``sqlite:///path.db`` (relative), ``sqlite:////abs/path.db``,
        ``sqlite:///:memory:`` (tests only: not durable) or
        ``postgresql://user@host:port/db[?schema=NAME]``.

    Returns
    -------
    Storage

    Raises
    ------
    StorageURLError
        When the URL names no supported backend.
    """
    scheme = url.split(":", 1)[0].lower() if ":" in url else ""
    if scheme == "sqlite":
        return SQLiteStorage(url)
    if scheme in ("postgresql", "postgres"):
        return PostgresStorage(url)
    raise StorageURLError(f"unsupported storage URL {url!r}: use sqlite:///path.db or "
                          "postgresql://user@host/db")
