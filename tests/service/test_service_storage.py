"""Storage: the same suite on SQLite and PostgreSQL (``storage`` fixture)."""

from __future__ import annotations

import json
import math
import threading
from datetime import UTC, datetime, timedelta, timezone
from typing import ClassVar

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from zonecast.service.storage import (
    Checkpoint,
    PutResult,
    SQLiteStorage,
    StorageURLError,
    open_storage,
)

T0 = datetime(2015, 4, 11, 17, 0, tzinfo=UTC)
PDT = timezone(timedelta(hours=-7))


def rows_at(n, point="T_NW", start=T0, value=20.0):
    return [(point, start + timedelta(minutes=15 * i), value + i) for i in range(n)]


def test_schema_created_and_versioned(storage, storage_url):
    assert storage.schema_version == 5
    storage.close()
    again = open_storage(storage_url)  # reopening does not re-apply migrations
    assert again.schema_version == 5
    again.close()


def test_version_1_database_is_migrated_and_keeps_its_readings(tmp_path):
    """A database written before the received_at index (schema 1) gets it on open."""
    import sqlite3

    class Version1(SQLiteStorage):
        _migrations: ClassVar[dict] = {1: SQLiteStorage._migrations[1]}

    url = f"sqlite:///{tmp_path / 'v1.db'}"
    old = Version1(url)
    assert old.schema_version == 1
    old.put_readings("office6", rows_at(3))
    old.close()
    store = open_storage(url)
    assert store.schema_version == 5
    assert store.readings("office6", T0, T0 + timedelta(hours=1))["T_NW"].tolist() == \
        [20.0, 21.0, 22.0]
    store.close()
    con = sqlite3.connect(tmp_path / "v1.db")
    plan = " ".join(str(r) for r in con.execute(
        "EXPLAIN QUERY PLAN SELECT MAX(received_at) FROM readings WHERE building = 'office6'"))
    con.close()
    assert "readings_by_received" in plan


def test_readings_matrix_equals_the_wide_frame(storage):
    rows = rows_at(4) + rows_at(2, point="VAV-NW-1 Flow", value=0.3) \
        + [("T_NE", T0 + timedelta(minutes=7), 19.0)]  # off the grid: a row of its own
    storage.put_readings("office6", rows)
    points = ["VAV-NW-1 Flow", "T_NW", "Nope"]
    end = T0 + timedelta(minutes=45)
    times, values = storage.readings_matrix("office6", T0, end, points)
    df = storage.readings("office6", T0, end, points=points).dropna(how="all")
    assert times.dtype == np.int64 and times.tolist() == df.index.as_unit("ns").asi8.tolist()
    np.testing.assert_array_equal(values, df.to_numpy())
    later = T0 + timedelta(hours=2)
    empty_t, empty_v = storage.readings_matrix("office6", later, later + timedelta(hours=1),
                                               points)
    assert empty_t.shape == (0,) and empty_v.shape == (0, 3)


def test_put_and_read_back_wide_utc_frame(storage):
    rows = rows_at(4) + rows_at(2, point="VAV-NW-1 Flow", value=0.3)
    assert storage.put_readings("office6", rows) == (6, 0)
    df = storage.readings("office6", T0, T0 + timedelta(hours=1))
    assert list(df.columns) == ["T_NW", "VAV-NW-1 Flow"]
    assert str(df.index.tz) == "UTC" and df.index.name == "time"
    assert df.index.is_monotonic_increasing and len(df) == 4
    assert df["T_NW"].tolist() == [20.0, 21.0, 22.0, 23.0]
    assert df["VAV-NW-1 Flow"].iloc[:2].tolist() == [0.3, 1.3]
    assert df["VAV-NW-1 Flow"].iloc[2:].isna().all()


def test_range_is_half_open_and_points_filter_keeps_order(storage):
    storage.put_readings("b", rows_at(8) + rows_at(8, point="OAT", value=10))
    df = storage.readings("b", T0 + timedelta(minutes=15), T0 + timedelta(minutes=60),
                          points=["OAT", "T_NW", "missing"])
    assert list(df.columns) == ["OAT", "T_NW", "missing"]
    assert df.index[0] == T0 + timedelta(minutes=15) and len(df) == 3
    assert df["missing"].isna().all()


def test_offsets_are_converted_to_utc(storage):
    local = datetime(2015, 4, 11, 10, 0, tzinfo=PDT)  # = 17:00 UTC
    storage.put_readings("b", [("T", local, 21.5), ("T", "2015-04-11T10:15:00-07:00", 21.6)])
    df = storage.readings("b", "2015-04-11T17:00:00Z", pd.Timestamp("2015-04-11 18:00", tz="UTC"))
    assert list(df.index) == [T0, T0 + timedelta(minutes=15)]


def test_empty_result_is_an_empty_utc_frame(storage):
    df = storage.readings("nobody", T0, T0 + timedelta(days=1))
    assert df.empty and str(df.index.tz) == "UTC"
    df = storage.readings("nobody", T0, T0 + timedelta(days=1), points=["a"])
    assert list(df.columns) == ["a"] and df.empty


def test_redelivery_is_idempotent(storage):
    rows = rows_at(5)
    assert storage.put_readings("b", rows) == (5, 0)
    again = storage.put_readings("b", rows)
    assert again == (0, 5) and again.conflicts == 0
    assert len(storage.readings("b", T0, T0 + timedelta(days=1))) == 5


def test_same_key_other_value_keeps_first_and_counts_conflict(storage):
    storage.put_readings("b", [("T", T0, 20.0)])
    result = storage.put_readings("b", [("T", T0, 25.0), ("T", T0 + timedelta(minutes=15), 1.0)])
    assert (result.inserted, result.duplicates, result.conflicts) == (1, 1, 1)
    assert storage.readings("b", T0, T0 + timedelta(minutes=1))["T"].tolist() == [20.0]


def test_repeats_within_one_batch(storage, caplog):
    result = storage.put_readings("b", [("T", T0, 1.0), ("T", T0, 1.0), ("T", T0, 2.0)])
    assert tuple(result) == (1, 2) and result.conflicts == 1
    assert "1 readings conflict" in caplog.text  # also when the batch went in as new
    assert storage.readings("b", T0, T0 + timedelta(minutes=1))["T"].tolist() == [1.0]


def test_supported_watermark_needs_min_points_and_ignores_excluded_ones(storage):
    """The watermark is the latest time with readings of at least min_points points;
    readings of excluded points (the meters) neither make such a time nor count."""
    step = timedelta(minutes=15)
    storage.put_readings("a", rows_at(4, "T1") + rows_at(4, "T2"))  # T0 .. T0 + 3 steps
    storage.put_readings("a", [("P1", T0 + 6 * step, 1.0), ("P2", T0 + 6 * step, 2.0),
                               ("T1", T0 + 5 * step, 1.0), ("P1", T0 + 5 * step, 1.0),
                               ("T1", T0 + 9 * step, 1.0)])  # a lone reading ahead
    until = T0 + timedelta(days=1)
    assert storage.supported_watermark("a", T0, until, 2) == T0 + 6 * step
    assert storage.supported_watermark("a", T0, until, 2, exclude=["P1", "P2"]) \
        == T0 + 3 * step
    assert storage.supported_watermark("a", T0, until, 1, exclude=["P2", "P1", "P1"]) \
        == T0 + 9 * step
    assert storage.supported_watermark("a", T0, T0 + 3 * step, 2, exclude=["P1"]) \
        == T0 + 2 * step
    assert storage.supported_watermark("a", T0, until, 3, exclude=["P1"]) is None
    with pytest.raises(ValueError, match="min_points must be >= 1"):
        storage.supported_watermark("a", T0, until, 0)


def test_buildings_are_separate(storage):
    storage.put_readings("a", [("T", T0, 1.0)])
    assert storage.put_readings("b", [("T", T0, 2.0)]) == (1, 0)
    assert storage.readings("b", T0, T0 + timedelta(minutes=1))["T"].tolist() == [2.0]


@pytest.mark.parametrize("bad, match", [
    (("T", datetime(2015, 1, 1), 1.0), "UTC offset"),
    (("T", T0, math.nan), "finite"),
    (("T", T0, "21"), "finite number"),
    (("", T0, 1.0), "point"),
    (("T\x00", T0, 1.0), "NUL"),
    (("T", T0), "triple"),
])
def test_invalid_rows_raise_and_store_nothing(storage, bad, match):
    with pytest.raises(ValueError, match=match):
        storage.put_readings("b", [("T", T0 + timedelta(hours=1), 1.0), bad])
    assert storage.readings("b", T0, T0 + timedelta(days=1)).empty


def test_put_many_is_one_transaction(storage):
    results = storage.put_many(
        [("a", rows_at(3)), ("b", rows_at(2))],
        dead_letters=[{"topic": "zonecast/a/telemetry", "payload": b"{", "reason": "x",
                       "building": "a"}])
    assert results == [(3, 0), (2, 0)]
    assert len(storage.dead_letters()) == 1
    with pytest.raises(ValueError):  # a bad batch rolls back the good one too
        storage.put_many([("c", rows_at(2)), ("d", [("T", T0, math.inf)])])
    assert storage.readings("c", T0, T0 + timedelta(days=1)).empty


def test_dead_letters_newest_first_and_excerpted(storage):
    storage.put_dead_letter("zonecast/x/telemetry", b"not json", "malformed_json: ...")
    storage.put_dead_letter("zonecast/b/telemetry", "x" * 5000, "payload_too_large: ...",
                            building="b")
    letters = storage.dead_letters(limit=10)
    assert [d.reason.split(":")[0] for d in letters] == ["payload_too_large", "malformed_json"]
    assert letters[0].building == "b" and letters[1].building is None
    assert len(letters[0].payload) == 1024
    assert letters[0].received_at.tzinfo is not None
    assert [d.topic for d in storage.dead_letters(limit=1)] == ["zonecast/b/telemetry"]
    assert len(storage.dead_letters(building="b")) == 1


def test_dead_letter_with_nul_bytes_is_storable(storage):
    storage.put_dead_letter("zonecast/b/telemetry", b"{\x00 bad", "malformed_json: x\x00")
    assert storage.dead_letters()[0].payload == "{\ufffd bad"


def test_checkpoints_roundtrip_latest_wins(storage):
    assert storage.load_checkpoint("b") is None
    state = json.dumps({"x": [1.0, 2.0]}).encode()
    storage.save_checkpoint("b", T0, state)
    storage.save_checkpoint("b", T0 + timedelta(minutes=15), b"\x00\x01binary")
    cp = storage.load_checkpoint("b")
    assert isinstance(cp, Checkpoint)
    assert cp.time == T0 + timedelta(minutes=15) and cp.state == b"\x00\x01binary"
    assert storage.load_checkpoint("other") is None
    with pytest.raises(TypeError, match="bytes"):
        storage.save_checkpoint("b", T0, {"x": 1})
    # without waiting for the disk (the runner's per-step checkpoint): same contents
    storage.save_checkpoint("b", T0 + timedelta(minutes=30), b"unsynced", sync=False)
    cp = storage.load_checkpoint("b")
    assert cp.time == T0 + timedelta(minutes=30) and cp.state == b"unsynced"
    assert storage.put_readings("b", rows_at(2)) == (2, 0)  # later writes still work


def test_unsynced_checkpoint_leaves_readings_synchronous(tmp_path):
    store = open_storage(f"sqlite:///{tmp_path}/d.db")
    seen = []
    store._conn.set_trace_callback(seen.append)
    store.save_checkpoint("b", T0, b"state", sync=False)
    store._conn.set_trace_callback(None)
    assert seen[0] == "PRAGMA synchronous=NORMAL" and seen[-1] == "PRAGMA synchronous=FULL"
    assert any(s.startswith("INSERT INTO checkpoints") for s in seen)
    assert store._conn.execute("PRAGMA synchronous").fetchone()[0] == 2  # FULL again
    store.save_checkpoint("b", T0, b"state")  # the default stays synchronous
    assert store._conn.execute("PRAGMA synchronous").fetchone()[0] == 2
    store.close()


def test_concurrent_writers_share_one_storage(storage):
    def write(k):
        storage.put_readings("b", rows_at(50, point=f"P{k}"))
        storage.put_readings("b", rows_at(50, point=f"P{k}"))  # redelivered

    threads = [threading.Thread(target=write, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    df = storage.readings("b", T0, T0 + timedelta(days=2))
    assert df.shape == (50, 4) and not df.isna().any().any()


@settings(max_examples=25, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(batches=st.lists(st.lists(st.tuples(st.sampled_from(["A", "B", "C"]),
                                           st.integers(0, 20),
                                           st.sampled_from([1.0, 2.5, -3.0])),
                                 max_size=15), min_size=1, max_size=4))
def test_stored_set_is_keep_first_union(storage, batches):
    building = f"h{abs(hash(repr(batches)))}"
    first: dict = {}
    for batch in batches:
        rows = [(p, T0 + timedelta(minutes=m), v) for p, m, v in batch]
        result = storage.put_readings(building, rows)
        new = 0
        for p, m, v in batch:
            if (p, m) not in first:
                first[(p, m)] = v
                new += 1
        assert result.inserted == new and result.inserted + result.duplicates == len(batch)
    df = storage.readings(building, T0, T0 + timedelta(hours=1))
    stored = {(p, int((t - T0).total_seconds() // 60)): v
              for p in df.columns for t, v in df[p].dropna().items()}
    assert stored == first


def test_sqlite_is_durable_wal_full(tmp_path):
    store = open_storage(f"sqlite:///{tmp_path}/d.db")
    assert isinstance(store, SQLiteStorage)
    conn = store._conn
    assert conn.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    assert conn.execute("PRAGMA synchronous").fetchone()[0] == 2  # FULL
    store.close()


def test_sqlite_relative_url(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with open_storage("sqlite:///sub/z.db") as store:
        store.put_readings("b", rows_at(1))
    assert (tmp_path / "sub" / "z.db").exists()


@pytest.mark.parametrize("url", ["mysql://x/y", "zonecast.db", "sqlite://", "sqlite:/x.db"])
def test_bad_urls_say_what_to_use(url):
    with pytest.raises(StorageURLError, match="sqlite:///"):
        open_storage(url)


def test_put_result_reads_like_a_tuple():
    r = PutResult(3, 2, 1)
    inserted, duplicates = r
    assert (inserted, duplicates, r.conflicts) == (3, 2, 1) and r == (3, 2)
    assert "conflicts=1" in repr(r)


def test_postgres_reconnects_after_connection_loss(postgres_url):
    import psycopg

    store = open_storage(postgres_url)
    store.put_readings("b", rows_at(1))
    pid = store._conn.info.backend_pid
    base = postgres_url.split("?")[0]
    with psycopg.connect(base, autocommit=True) as admin:
        admin.execute("SELECT pg_terminate_backend(%s)", (pid,))
    with pytest.raises(psycopg.OperationalError):  # the write in flight fails...
        store.put_readings("b", rows_at(2))
    assert store.put_readings("b", rows_at(2)) == (1, 1)  # ...the retry reconnects
    store.close()


def test_instance_value_is_stored_once_and_kept(storage, storage_url):
    """The first default stored under a key stays: later defaults and a reopened storage
    get it back (the MQTT client id's persistence, docs/security.md)."""
    assert storage.instance_value("mqtt_client_id", "zonecast-ingest-a") == "zonecast-ingest-a"
    assert storage.instance_value("mqtt_client_id", "zonecast-ingest-b") == "zonecast-ingest-a"
    assert storage.instance_value("other", "x") == "x"
    storage.close()
    again = open_storage(storage_url)
    assert again.instance_value("mqtt_client_id", "zonecast-ingest-c") == "zonecast-ingest-a"
    again.close()
    with open_storage(storage_url) as third, pytest.raises(ValueError, match="non-empty key"):
        third.instance_value("", "x")


def test_put_many_counts_each_batch_when_one_statement_cannot(storage):
    """Batches of one building go in as one statement; a redelivered batch or a key
    repeated across batches falls back to one statement per batch with exact counts."""
    storage.put_readings("office6", rows_at(2))  # T_NW at T0, T0+15 min stored
    fresh = rows_at(2, point="T_NE")
    results = storage.put_many([("office6", fresh),
                                ("office6", rows_at(3, value=20.0)),  # 2 dup + 1 new
                                ("office6", [("T_NE", T0, 99.0)]),  # same key as batch 0
                                ("office7", rows_at(1))])
    assert [tuple(r) for r in results] == [(2, 0), (1, 2), (0, 1), (1, 0)]
    assert [r.conflicts for r in results] == [0, 0, 1, 0]
    assert storage.readings("office6", T0, T0 + timedelta(hours=1))["T_NE"].tolist()[:2] == \
        [20.0, 21.0]
    # all new and distinct: one statement, the same counts as batch by batch
    results = storage.put_many([("office6", rows_at(2, start=T0 + timedelta(days=1))),
                                ("office6", rows_at(2, point="T_NE",
                                                    start=T0 + timedelta(days=1)))])
    assert [tuple(r) for r in results] == [(2, 0), (2, 0)]


def test_partly_stored_batch_falls_back_with_exact_counts_and_keeps_the_letter(storage):
    """A batch that is new except for one stored key (PostgreSQL: the plain INSERT raises
    unique_violation inside its savepoint) is stored by the keep-first insert instead: exact
    counts, the stored value kept, and the dead letter of the same transaction committed."""
    calls, plain = [], []
    unique, new = storage._insert_unique, storage._insert_new
    storage._insert_unique = lambda *a: calls.append(len(a[2])) or unique(*a)
    storage._insert_new = lambda *a: plain.append(len(a[2])) or new(*a)
    storage.put_readings("office6", [("T_NW", T0, 20.0)])
    postgres = not isinstance(storage, SQLiteStorage)
    assert calls == ([] if postgres else [1])  # PostgreSQL: new rows by the plain INSERT
    calls.clear()
    rows = [("T_NW", T0, 25.0), ("T_NE", T0, 21.0), ("T_SW", T0, 22.0)]
    letter = {"topic": "zonecast/office6/telemetry", "payload": b"{}", "reason": "x: y",
              "building": "office6"}
    plain.clear()
    [result] = storage.put_many([("office6", rows)], [letter])
    assert (tuple(result), result.conflicts) == ((2, 1), 1)
    assert calls == [3]
    # PostgreSQL: the plain INSERT is tried once; after its unique violation only the
    # keep-first insert (a second plain one would write rows again, and a transaction that
    # wrote nothing commits without a disk sync)
    assert plain == ([3] if postgres else [])
    got = storage.readings("office6", T0, T0 + timedelta(minutes=15))
    assert got.iloc[0][["T_NW", "T_NE", "T_SW"]].tolist() == [20.0, 21.0, 22.0]
    assert [d.reason for d in storage.dead_letters(building="office6")] == ["x: y"]


def _pg_key_columns(conn) -> list[str]:
    return [r[0] for r in conn.execute(
        "SELECT a.attname FROM pg_index i JOIN pg_class c ON c.oid = i.indrelid "
        "JOIN pg_namespace n ON n.oid = c.relnamespace "
        "JOIN LATERAL unnest(i.indkey) WITH ORDINALITY AS k(attnum, ord) ON true "
        "JOIN pg_attribute a ON a.attrelid = c.oid AND a.attnum = k.attnum "
        "WHERE c.relname = 'readings' AND n.nspname = current_schema() AND i.indisprimary "
        "ORDER BY k.ord").fetchall()]


def test_postgres_idempotency_is_the_primary_key_at_sql_level(postgres_url):
    """On PostgreSQL the rule lives in the database: the primary key refuses a second row
    of a key whatever writes it, and the conflict check probes that key per reading
    instead of reading the building's history (it hashed all of it before)."""
    import psycopg
    from zonecast.service.storage import _PG_CONFLICTS

    store = open_storage(postgres_url)
    conn = store._conn
    assert _pg_key_columns(conn) == ["building", "time", "point"]
    store.put_readings("office6", rows_at(3))
    with pytest.raises(psycopg.errors.UniqueViolation):
        conn.execute("INSERT INTO readings VALUES ('office6', 'T_NW', %s, 5.0, now())", (T0,))
    # history of 20,000 readings so that the planner has a choice to make
    conn.execute("INSERT INTO readings SELECT 'office6', 'P' || (s %% 20), "
                 "%s - s * interval '15 minutes', 1.0, now() "
                 "FROM generate_series(1, 20000) AS s", (T0,))
    conn.execute("ANALYZE readings")
    result = store.put_readings("office6", rows_at(3, value=20.5) + rows_at(1, point="T_SW"))
    assert tuple(result) == (1, 3) and result.conflicts == 3
    plan = "\n".join(r[0] for r in conn.execute(
        "EXPLAIN " + _PG_CONFLICTS, {"p": '{"T_NW"}', "t": "{" + T0.isoformat() + "}",
                                     "v": "{1.5}", "b": "office6"}).fetchall())
    assert "readings_pkey" in plan and "Seq Scan" not in plan and "Hash" not in plan, plan
    # the stored values are the first ones
    frame = store.readings("office6", T0, T0 + timedelta(hours=1))
    assert frame["T_NW"].tolist() == [20.0, 21.0, 22.0]
    store.close()


def test_postgres_schema_2_is_migrated_to_the_time_first_key(postgres_url):
    """A schema-2 PostgreSQL database (key (building, point, time) and an index on
    (building, time)) keeps its readings and idempotency after the migration."""
    from zonecast.service.storage import PostgresStorage

    class Version2(PostgresStorage):
        _migrations: ClassVar[dict] = {v: PostgresStorage._migrations[v] for v in (1, 2)}

    old = Version2(postgres_url)
    assert _pg_key_columns(old._conn) == ["building", "point", "time"]
    old.put_readings("office6", rows_at(3))
    old.close()
    store = open_storage(postgres_url)
    assert store.schema_version == 5
    assert _pg_key_columns(store._conn) == ["building", "time", "point"]
    indexes = {r[0] for r in store._conn.execute(
        "SELECT indexname FROM pg_indexes WHERE tablename = 'readings' "
        "AND schemaname = current_schema()").fetchall()}
    assert indexes == {"readings_pkey", "readings_by_received"}
    assert tuple(store.put_readings("office6", rows_at(4))) == (1, 3)
    assert store.readings("office6", T0, T0 + timedelta(hours=1))["T_NW"].tolist() == \
        [20.0, 21.0, 22.0, 23.0]
    store.close()
