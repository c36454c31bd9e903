"""PostgreSQL ingest at rate: sustained MQTT messages/s with zero loss, and the per-message
storage cost as the stored history grows.

Three measurements for each history size (``--history 0 1000000 10000000``):

1. **History**: a fresh schema whose ``readings`` table is filled server-side
   (``generate_series``) with that many readings of the benchmark building, on the same
   47 points, at times before the benchmark's (secondary indexes dropped during the load
   and rebuilt, then ``VACUUM (ANALYZE)``; the load time is printed, not part of any
   figure).
2. **Storage alone**: ``put_readings`` of one 47-reading message per transaction,
   ``--single`` messages, then the same messages again (a redelivery: every reading a
   duplicate, conflict detection included); median and p90 per message [ms]; and 20
   groups of 100 messages in one ``put_many`` each (as the ingester commits), median
   per message [ms].
3. **MQTT at rate**: a publisher process sends ``--rate`` messages/s (QoS 1, map form,
   47 readings, one 15-min step each) for ``--seconds``; the zonecast ingester in this
   process stores them. Reported: the rate achieved, the ingester's backlog (published but
   not stored) once per second, how long it took to drain after the last publish, the
   storage time per message (time inside ``put_many`` / messages) and the readings counted
   in the table afterwards: lost = expected - stored (the broker drops what exceeds its
   queue, so a falling-behind ingester shows up as loss).

With ``--workers N`` the ingesting side is this process and N-1 more (as ``zonecast ingest
--worker``), members of one MQTT shared subscription (``mqtt.share_group``). CPU per stored
message is reported for each component over publish + drain: the ingesting processes, their
PostgreSQL backends, the broker (``--private-broker``: a mosquitto of our own, configured as
the machine's) and the publisher; unlike wall throughput, these hardly depend on what else
runs on the machine.

The broker is the one at ``--host:--port`` as configured there (the project machine's
Mosquitto runs with defaults: ``max_queued_messages`` 1000), else a private ``mosquitto``
on a free port with the defaults. Run the same script against other code with
``PYTHONPATH`` pointing at its ``zonecast`` package to get the reference.

Usage::

    python benchmarks/bench_pg_ingest.py --url postgresql://postgres@127.0.0.1/test \
        [--history 0 1000000 10000000] [--rate 1500 --seconds 60] [--json out.json] \
        [--workers 2] [--private-broker]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import platform
import statistics
import sys
import tempfile
import time
import uuid
from datetime import UTC, datetime, timedelta
from pathlib import Path

# first benchmark message; the history lies before it. 90,000 messages (60 s at 1,500/s) of
# one 15-min step each reach mid-2024: every time stays in the past, as ingest requires
T0 = datetime(2022, 1, 3, 0, 0, tzinfo=UTC)
POINTS = [f"P{i:02d}" for i in range(47)]


def _payload(i: int) -> str:
    when = T0 + timedelta(minutes=15 * i)
    return json.dumps({"time": when.isoformat(),
                       "readings": {p: round(20 + (i % 97) / 10 + k / 1000, 3)
                                    for k, p in enumerate(POINTS)}})


def load_history(conn, building: str, n: int) -> float:
    """``n`` readings of ``building`` before :data:`T0`, loaded server-side; seconds taken."""
    start = time.perf_counter()
    if n <= 0:
        return 0.0
    steps = -(-n // len(POINTS))
    rows = conn.execute("SELECT indexname, indexdef FROM pg_indexes WHERE tablename = "
                        "'readings' AND schemaname = current_schema()").fetchall()
    pkey = [name for name, _ in rows if name.endswith("_pkey")]
    secondary = [(name, ddl) for name, ddl in rows if not name.endswith("_pkey")]
    for name, _ in secondary:
        conn.execute(f'DROP INDEX "{name}"')
    # the primary key stays: it is the table's identity and may carry the idempotency rule
    conn.execute(
        "INSERT INTO readings (building, point, time, value, received_at) "
        "SELECT %s, 'P' || lpad(p::text, 2, '0'), %s - s * interval '15 minutes', "
        "20 + (s %% 97) / 10.0, %s - s * interval '15 minutes' "
        "FROM generate_series(1, %s) AS s, generate_series(0, %s) AS p "
        "WHERE (s - 1) * %s + p < %s",
        (building, T0, T0, steps, len(POINTS) - 1, len(POINTS), n))
    for _, ddl in secondary:
        conn.execute(ddl)
    # as a table in steady state: vacuumed and analysed, so that autovacuum does not start
    # on the fresh rows in the middle of the measurement
    conn.execute("VACUUM (ANALYZE) readings")
    assert pkey, "readings has no primary key"
    return time.perf_counter() - start


def single_message_cost(store, building: str, messages: int) -> dict[str, float]:
    """Median/p90 [ms] of one message (47 readings) per transaction, fresh then redelivered."""
    out = {}
    base = 10_000_000  # message numbers far after the MQTT run's
    bodies = [json.loads(_payload(base + i)) for i in range(messages)]
    for label in ("fresh", "redelivered"):
        times = []
        for body in bodies:
            rows = [(p, body["time"], v) for p, v in body["readings"].items()]
            t = time.perf_counter()
            res = store.put_readings(building, rows)
            times.append((time.perf_counter() - t) * 1e3)
            expect = (len(rows), 0) if label == "fresh" else (0, len(rows))
            if tuple(res) != expect:
                raise AssertionError(f"{label}: put_readings returned {res}, expected {expect}")
        times.sort()
        out[f"{label}_median_ms"] = statistics.median(times)
        out[f"{label}_p90_ms"] = times[int(0.9 * (len(times) - 1))]
    # groups of 100 messages in one put_many, as the ingester commits them: the index work
    # per reading shows here, not hidden behind the commit's disk sync
    per_message = []
    for g in range(20):
        group = [json.loads(_payload(base + messages + 100 * g + j)) for j in range(100)]
        batches = [(building, [(p, b["time"], v) for p, v in b["readings"].items()])
                   for b in group]
        t = time.perf_counter()
        store.put_many(batches)
        per_message.append((time.perf_counter() - t) * 1e3 / 100)
    out["group100_median_ms_per_message"] = statistics.median(per_message)
    return out


def publisher(host: str, port: int, topic: str, rate: float, seconds: float,
              counter, done) -> None:
    """Child process: publish ``rate`` messages/s for ``seconds`` (QoS 1)."""
    import paho.mqtt.client as mqtt
    from paho.mqtt.enums import CallbackAPIVersion

    client = mqtt.Client(callback_api_version=CallbackAPIVersion.VERSION2,
                         client_id=f"bench-pg-bms-{uuid.uuid4().hex[:6]}",
                         protocol=mqtt.MQTTv5)
    client.max_inflight_messages_set(1000)
    client.max_queued_messages_set(0)
    client.connect(host, port)
    client.loop_start()
    total = int(rate * seconds)
    payloads = [_payload(i) for i in range(total)]
    start = time.perf_counter()
    for i, body in enumerate(payloads):
        due = start + i / rate
        delay = due - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
        client.publish(topic, body, qos=1)
        counter.value = i + 1
    done.value = time.perf_counter() - start
    time.sleep(2.0)  # let the last PUBACKs arrive before disconnecting
    client.disconnect()
    client.loop_stop()


class _Timed:
    """Storage proxy that adds up the time spent in ``put_many``."""

    def __init__(self, store):
        self._store = store
        self.seconds = 0.0
        self.calls = 0

    def put_many(self, *args, **kwargs):
        t = time.perf_counter()
        try:
            return self._store.put_many(*args, **kwargs)
        finally:
            self.seconds += time.perf_counter() - t
            self.calls += 1

    def __getattr__(self, name):
        return getattr(self._store, name)


def cpu_seconds(pid: int) -> float | None:
    """User + system CPU seconds of process ``pid`` so far (Linux ``/proc``), or None."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return None


def ingest_worker(url: str, host: str, port: int, building: str, options: dict, worker: int,
                  received, stored, state, stop) -> None:
    """Child process: ``zonecast ingest --worker N`` as the benchmark needs it (one more
    member of the share group, storing into the same schema); publishes its counters, its
    PostgreSQL backend's pid (``state[0]``), readiness (``state[1]``) and at the end its
    own CPU seconds since it was ready (``state[2]``; start-up and imports excluded)."""
    from zonecast.service.ingest import PointSpec
    from zonecast.service.mqtt import Ingester
    from zonecast.service.settings import MqttSettings
    from zonecast.service.storage import open_storage

    store = open_storage(url)
    state[0] = float(store._conn.execute("SELECT pg_backend_pid()").fetchone()[0])
    ingester = Ingester(MqttSettings(host=host, port=port, **options), store,
                        {building: {p: PointSpec("temperature") for p in POINTS}},
                        worker=worker, weather=False).start()
    ready_cpu = time.process_time()
    if ingester.wait_ready(10):
        state[1] = 1.0
    while not stop.wait(0.05):
        c = ingester.counters()
        received.value, stored.value = c["messages_in"], c["messages_stored"]
    ingester.stop()
    c = ingester.counters()
    received.value, stored.value = c["messages_in"], c["messages_stored"]
    store.close()
    state[2] = time.process_time() - ready_cpu


def mqtt_at_rate(store, conn, url: str, building: str, host: str, port: int, rate: float,
                 seconds: float, options: dict, workers: int = 1,
                 broker_pid: int | None = None) -> dict[str, float]:
    from zonecast.service.ingest import PointSpec
    from zonecast.service.mqtt import Ingester
    from zonecast.service.settings import MqttSettings

    timed = _Timed(store)
    options = dict(options, client_id=f"zonecast-bench-{uuid.uuid4().hex[:6]}")
    if workers > 1:
        options["share_group"] = f"bench{uuid.uuid4().hex[:6]}"
    settings = MqttSettings(host=host, port=port, **options)
    ingester = Ingester(settings, timed, {building: {p: PointSpec("temperature")
                                                     for p in POINTS}}).start()
    if not ingester.wait_ready(10):
        ingester.abort()
        raise ConnectionError(f"no MQTT broker answered at {host}:{port}")
    ctx = mp.get_context("spawn")
    stop = ctx.Event()
    procs = []
    for w in range(1, workers):
        counts = (ctx.Value("l", 0), ctx.Value("l", 0), ctx.Array("d", 3))
        proc = ctx.Process(target=ingest_worker, args=(url, host, port, building, options, w,
                                                       *counts, stop))
        proc.start()
        procs.append((proc, *counts))
    deadline = time.perf_counter() + 30
    while any(state[1] == 0.0 for *_, state in procs) and time.perf_counter() < deadline:
        time.sleep(0.05)
    if any(state[1] == 0.0 for *_, state in procs):
        stop.set()
        ingester.abort()
        raise ConnectionError("an ingest worker did not subscribe within 30 s")

    def counts() -> tuple[int, int]:
        c = ingester.counters()
        return (c["messages_in"] + sum(r.value for _, r, _, _ in procs),
                c["messages_stored"] + sum(s_.value for _, _, s_, _ in procs))

    backends = [int(store._conn.execute("SELECT pg_backend_pid()").fetchone()[0])] + \
        [int(state[0]) for *_, state in procs]
    published, done = ctx.Value("l", 0), ctx.Value("d", 0.0)
    proc = ctx.Process(target=publisher, args=(host, port, f"zonecast/{building}/telemetry",
                                               rate, seconds, published, done))
    cpu0 = time.process_time()
    pg0 = [cpu_seconds(b) for b in backends]
    broker0 = cpu_seconds(broker_pid) if broker_pid else None
    proc.start()
    backlog = []
    start = None
    pub_cpu = None
    while proc.is_alive() and done.value == 0.0:
        time.sleep(1.0)
        if published.value and start is None:
            start = time.perf_counter()
        pub_cpu = cpu_seconds(proc.pid) if proc.is_alive() else pub_cpu
        backlog.append(published.value - counts()[1])
    total = published.value
    end_pub = time.perf_counter()
    deadline = end_pub + 60
    last, idle_since = counts(), time.perf_counter()
    while counts()[1] < total and time.perf_counter() < deadline:
        time.sleep(0.05)
        now = counts()
        if now != last:
            last, idle_since = now, time.perf_counter()
        elif not proc.is_alive() and time.perf_counter() - idle_since > 3.0 \
                and ingester.unacknowledged_for() == 0:
            break  # nothing more is coming: the broker dropped the rest
    drain = time.perf_counter() - end_pub
    cpu = time.process_time() - cpu0
    pg = [cpu_seconds(b) for b in backends]
    broker_cpu = cpu_seconds(broker_pid) - broker0 if broker0 is not None else None
    proc.join(10)
    stop.set()
    for p_, *_ in procs:
        p_.join(30)
    worker_cpu = sum(state[2] for *_, state in procs)
    counters = ingester.counters()
    ingester.stop()
    received, stored_messages = counts()
    stored = conn.execute("SELECT count(*) FROM readings WHERE building = %s AND time >= %s "
                          "AND time < %s", (building, T0,
                                            T0 + timedelta(minutes=15 * total))).fetchone()[0]
    expected = total * len(POINTS)
    n = max(stored_messages, 1)
    pg_cpu = sum(b - a for a, b in zip(pg0, pg, strict=True)) \
        if None not in pg0 and None not in pg else None
    us = 1e6 / n
    return {"published": total, "publish_seconds": done.value,
            "rate_published": total / done.value if done.value else 0.0,
            "expected_readings": expected, "stored_readings": int(stored),
            "lost_readings": expected - int(stored),
            "messages_received": received, "workers": workers,
            "backlog_max": max(backlog or [0]), "drain_seconds": drain,
            "rate_stored": stored_messages / (end_pub + drain - start) if start else 0.0,
            "storage_ms_per_message": timed.seconds / max(counters["messages_stored"], 1) * 1e3,
            "commits": timed.calls,
            # CPU per stored message [us] of each component over publish + drain: the
            # ingesting processes (this one, which also polls, and the workers), their
            # PostgreSQL backends, the broker (only when the benchmark started it) and the
            # publisher (sampled up to its last second)
            "cpu_us_ingest": (cpu + worker_cpu) * us,
            "cpu_us_postgres": pg_cpu * us if pg_cpu is not None else None,
            "cpu_us_broker": broker_cpu * us if broker_cpu is not None else None,
            "cpu_us_publisher": pub_cpu / max(total, 1) * 1e6 if pub_cpu else None,
            "process_cpu_ms_per_message": cpu / max(counters["messages_stored"], 1) * 1e3}


def private_broker(workdir: Path):
    """A mosquitto of our own on a free port, configured as the machine's (defaults,
    persistence on): (host, port, process)."""
    from bench_ingest import start_mosquitto

    workdir.chmod(0o777)  # mosquitto started as root runs as user mosquitto
    port, proc = start_mosquitto(workdir, f"allow_anonymous true\npersistence true\n"
                                          f"persistence_location {workdir}/\n")
    if proc is None:
        raise ConnectionError("--private-broker: mosquitto is not installed")
    return "127.0.0.1", port, proc


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--url", default=os.environ.get("ZONECAST_BENCH_POSTGRES_URL",
                                                    "postgresql://postgres@127.0.0.1:5432/test"))
    ap.add_argument("--host", default="127.0.0.1")
    ap.add_argument("--port", type=int, default=1883)
    ap.add_argument("--history", type=int, nargs="+", default=[0, 1_000_000, 10_000_000])
    ap.add_argument("--rate", type=float, default=1500.0, help="messages/s")
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--single", type=int, default=300, help="messages of the storage-alone part")
    ap.add_argument("--no-mqtt", action="store_true", help="storage-alone part only")
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--receive-maximum", type=int, default=None,
                    help="MqttSettings.receive_maximum (default: the code's default)")
    ap.add_argument("--batch", type=int, default=None,
                    help="MqttSettings.batch_max_messages (default: the code's default)")
    ap.add_argument("--workers", type=int, default=1,
                    help="ingesting processes: this one and N-1 more (zonecast ingest "
                         "--worker), members of one MQTT shared subscription")
    ap.add_argument("--private-broker", action="store_true",
                    help="start a mosquitto of our own on a free port (configured as the "
                         "machine's: defaults, persistence on), so that its CPU can be "
                         "measured and nobody else's traffic shares it")
    args = ap.parse_args(argv)

    import psycopg
    from zonecast.service.storage import open_storage

    sys.path.insert(0, str(Path(__file__).parent))
    from bench_ingest import ensure_broker

    try:
        psycopg.connect(args.url, connect_timeout=3).close()
    except psycopg.Error as exc:
        print(f"no PostgreSQL answered at {args.url} ({str(exc).strip().splitlines()[0]}): "
              "skipped; pass --url")
        return 0
    tmp = tempfile.TemporaryDirectory()
    if args.private_broker and not args.no_mqtt:
        args.host, args.port, broker = private_broker(Path(tmp.name))
    elif not args.no_mqtt:
        args.port, broker = ensure_broker(args.host, args.port, Path(tmp.name))
    else:
        broker = None
    import zonecast.service.storage as storage_module

    print(f"machine: {platform.node()} {platform.machine()}, {os.cpu_count()} cores, "
          f"load {os.getloadavg()[0]:.2f}; code: {Path(storage_module.__file__).parent}")
    results = []
    for n in args.history:
        schema = f"zc_bench_{uuid.uuid4().hex[:10]}"
        url = f"{args.url}{'&' if '?' in args.url else '?'}schema={schema}"
        building = "benchpg"
        store = open_storage(url)
        conn = psycopg.connect(args.url, autocommit=True)
        conn.execute(f'SET search_path TO "{schema}"')
        try:
            loaded = load_history(conn, building, n)
            rows = conn.execute("SELECT count(*) FROM readings").fetchone()[0]
            res = {"history": int(rows), "load_seconds": loaded,
                   "schema_version": store.schema_version,
                   "load_before": os.getloadavg()[0]}
            if not args.no_mqtt:
                options = {k: v for k, v in (("receive_maximum", args.receive_maximum),
                                             ("batch_max_messages", args.batch)) if v}
                res.update(mqtt_at_rate(store, conn, url, building, args.host, args.port,
                                        args.rate, args.seconds, options, args.workers,
                                        broker.pid if broker is not None else None))
            res.update(single_message_cost(store, building, args.single))
            res["load_after"] = os.getloadavg()[0]
            results.append(res)
            print(json.dumps(res), flush=True)
        finally:
            store.close()
            conn.execute(f'DROP SCHEMA "{schema}" CASCADE')
            conn.close()
    if broker is not None:
        broker.terminate()
        broker.wait()
    tmp.cleanup()
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))
    ok = all(r.get("lost_readings", 0) == 0 for r in results)
    print("zero loss at every history size: " + ("yes" if ok else "NO"))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
