"""Sustained MQTT ingest rate into SQLite, with a zero-loss check.

A simulated BMS publishes telemetry (``--points`` readings per message, QoS 1)
to a running broker; the zonecast ingester stores it in a fresh SQLite file
(WAL, synchronous=FULL, acknowledgement after commit). The publisher stays at
most ``--window`` messages ahead of what the ingester has stored, so the broker
never has to drop queued messages and the figure is the ingester's sustained
rate. At the end every expected reading is looked up in storage.

Reference measured in the same run: the same readings written straight into
another SQLite file with one ``put_readings`` transaction per message (no
MQTT), i.e. the storage ceiling.

Usage::

    python benchmarks/bench_ingest.py [--host 127.0.0.1 --port 1883]
                                      [--messages 1000 --points 100]

Without a broker at ``--host:--port`` it starts a private ``mosquitto`` (if on
PATH) on a free port. Target: >= 2,000 readings/s with every reading stored
exactly once.
"""

from __future__ import annotations

import argparse
import json
import platform
import shutil
import socket
import subprocess
import sys
import tempfile
import time
import uuid
from datetime import UTC, datetime, timedelta
from pathlib import Path

import paho.mqtt.client as mqtt
from paho.mqtt.enums import CallbackAPIVersion
from zonecast.service.ingest import PointSpec
from zonecast.service.mqtt import Ingester
from zonecast.service.settings import MqttSettings
from zonecast.service.storage import open_storage

TARGET = 2000.0  # readings/s
T0 = datetime(2015, 4, 11, 0, 0, tzinfo=UTC)


def ensure_broker(host: str, port: int, workdir: Path) -> tuple[int, subprocess.Popen | None]:
    """Use the broker at host:port, or start mosquitto on a free port."""
    try:
        socket.create_connection((host, port), timeout=1).close()
        return port, None
    except OSError:
        pass
    started, proc = start_mosquitto(workdir, "allow_anonymous true\n")
    return (started, proc) if proc is not None else (port, None)


def start_mosquitto(workdir: Path, conf: str) -> tuple[int, subprocess.Popen | None]:
    """mosquitto on a free local port with the configuration lines ``conf`` (port,
    process), or (0, None) when mosquitto is not installed."""
    exe = shutil.which("mosquitto") or shutil.which("/usr/sbin/mosquitto")
    if exe is None:
        return 0, None
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    path = workdir / "mosquitto.conf"
    path.write_text(f"listener {port} 127.0.0.1\n{conf}")
    proc = subprocess.Popen([exe, "-c", str(path)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    for _ in range(100):
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
            break
        except OSError:
            time.sleep(0.05)
    print(f"started mosquitto on port {port}")
    return port, proc


def storage_ceiling(db: Path, building: str, payloads: list[str]) -> float:
    """Readings/s writing the same messages straight to storage (the reference)."""
    store = open_storage(f"sqlite:///{db}")
    parsed = [json.loads(p) for p in payloads]
    start = time.perf_counter()
    n = 0
    for body in parsed:
        n += store.put_readings(building, [(pt, body["time"], v)
                                           for pt, v in body["readings"].items()]).inserted
    elapsed = time.perf_counter() - start
    store.close()
    return n / elapsed


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--host", default="127.0.0.1")
    ap.add_argument("--port", type=int, default=1883)
    ap.add_argument("--username", default=None)
    ap.add_argument("--protocol", choices=["5", "3.1.1"], default="5")
    ap.add_argument("--messages", type=int, default=1000)
    ap.add_argument("--points", type=int, default=100, help="readings per message")
    ap.add_argument("--window", type=int, default=500,
                    help="most messages published but not yet stored")
    ap.add_argument("--db", type=Path, default=None, help="SQLite file (default: temporary)")
    args = ap.parse_args(argv)

    building = f"bench{uuid.uuid4().hex[:6]}"
    points = [f"T_Zone_{i:03d}" for i in range(args.points)]
    tmp = tempfile.TemporaryDirectory()
    db = args.db or Path(tmp.name) / "bench.db"
    args.port, broker = ensure_broker(args.host, args.port, Path(tmp.name))
    store = open_storage(f"sqlite:///{db}")
    settings = MqttSettings(host=args.host, port=args.port, username=args.username,
                            protocol=args.protocol,
                            client_id=f"zonecast-bench-{uuid.uuid4().hex[:6]}")
    ingester = Ingester(settings, store, {building: {p: PointSpec("temperature")
                                                     for p in points}}).start()
    if not ingester.wait_ready(10):
        print(f"no MQTT broker answered at {args.host}:{args.port}", file=sys.stderr)
        ingester.abort()
        return 2

    pub = mqtt.Client(callback_api_version=CallbackAPIVersion.VERSION2,
                      client_id=f"bench-bms-{uuid.uuid4().hex[:6]}",
                      protocol=mqtt.MQTTv5 if args.protocol == "5" else mqtt.MQTTv311)
    if args.username:
        pub.username_pw_set(args.username)
    pub.max_inflight_messages_set(100)
    pub.connect(args.host, args.port)
    pub.loop_start()

    payloads = [json.dumps({
        "time": (T0 + timedelta(minutes=15 * i)).isoformat(),  # on the 15-min grid
        "readings": {p: round(20 + (i % 97) / 10 + k / 1000, 3) for k, p in enumerate(points)},
    }) for i in range(args.messages)]

    start = time.perf_counter()
    for i, payload in enumerate(payloads):
        while i - ingester.counters()["messages_stored"] >= args.window:
            time.sleep(0.001)
        pub.publish(f"zonecast/{building}/telemetry", payload, qos=1)
    expected = args.messages * args.points
    deadline = time.perf_counter() + 120
    while ingester.counters()["messages_stored"] < args.messages \
            and time.perf_counter() < deadline:
        time.sleep(0.002)
    elapsed = time.perf_counter() - start
    counters = ingester.counters()
    ingester.stop()
    pub.disconnect()
    pub.loop_stop()

    df = store.readings(building, T0, T0 + timedelta(minutes=15 * args.messages))
    stored = int(df.notna().sum().sum())
    store.close()
    if broker is not None:
        broker.terminate()
        broker.wait()
    ceiling = storage_ceiling(Path(tmp.name) / "reference.db", building, payloads)
    rate = counters["readings_stored"] / elapsed
    complete = stored == expected and counters["readings_duplicate"] == 0
    print(f"machine: {platform.node()} {platform.machine()} {platform.processor() or ''}".strip())
    print(f"published {args.messages} messages x {args.points} readings = {expected} readings")
    print(f"stored {stored} readings in {elapsed:.2f} s: {rate:,.0f} readings/s "
          f"({counters['messages_stored'] / elapsed:,.0f} messages/s)")
    print(f"reference, same readings straight into SQLite (1 transaction/message): "
          f"{ceiling:,.0f} readings/s")
    print(f"every reading arrived exactly once: {'yes' if complete else 'NO'}; "
          f"target {TARGET:,.0f} readings/s: {'met' if rate >= TARGET else 'NOT met'}")
    tmp.cleanup()
    return 0 if complete and rate >= TARGET else 1


if __name__ == "__main__":
    sys.exit(main())
