"""Ingest at rate: acknowledgements of a group sent together, several ingesting processes
sharing one stream (MQTT shared subscription), validated readings handed to storage
without a second check. Against the real broker of the ``broker`` fixture."""

from __future__ import annotations

import json
import logging
import sqlite3
import threading
import time
import uuid
from datetime import UTC, datetime

import pytest
from zonecast.service.ingest import CheckedReadings, validate_message
from zonecast.service.mqtt import Ingester, ingester_client_id
from zonecast.service.settings import MqttSettings
from zonecast.service.storage import open_storage

from tests.service.helpers import wait_until
from tests.service.test_mqtt_ingester import (
    T0,
    Publisher,
    catalogue,
    count,
    telemetry,
)

pytestmark = pytest.mark.timeout(120)


@pytest.fixture
def building():
    return f"bld{uuid.uuid4().hex[:8]}"


@pytest.fixture
def publisher(broker):
    pub = Publisher(broker)
    yield pub
    pub.close()


def _settings(broker, **kw) -> MqttSettings:
    return MqttSettings(host=broker.host, port=broker.port,
                        client_id=kw.pop("client_id", f"zonecast-test-{uuid.uuid4().hex[:8]}"),
                        username=broker.username, password="secret",
                        protocol="5" if broker.mqtt5 else "3.1.1", **kw)


def _send_all(publisher, building, steps) -> None:
    """Publish without waiting for each PUBACK (the ingester receives them in a burst)."""
    infos = [publisher.client.publish(f"zonecast/{building}/telemetry",
                                      json.dumps(telemetry(step)), qos=1) for step in steps]
    for info in infos:
        info.wait_for_publish(10)
        assert info.is_published()


class SlowFirstCommit:
    """Storage proxy: the first commit waits, so messages pile up into one group; records
    the group sizes."""

    def __init__(self, store):
        self._store = store
        self.groups: list[int] = []

    def put_many(self, batches, dead_letters=(), **kw):
        if not self.groups:
            time.sleep(0.5)
        self.groups.append(len(batches))
        return self._store.put_many(batches, dead_letters, **kw)

    def __getattr__(self, name):
        return getattr(self._store, name)


def test_a_group_is_acknowledged_together_and_never_redelivered(broker, building, publisher,
                                                                 tmp_path):
    store = open_storage(f"sqlite:///{tmp_path}/z.db")
    slow = SlowFirstCommit(store)
    settings = _settings(broker)
    with Ingester(settings, slow, {building: catalogue()}) as first:
        assert first.wait_ready(15)
        _send_all(publisher, building, range(200))
        wait_until(lambda: first.counters()["messages_stored"] == 200, what="200 stored")
    assert max(slow.groups) > 1  # the acknowledgements of a group went out as one write
    # every PUBACK reached the broker: a restarted session gets nothing again
    with Ingester(settings, store, {building: catalogue()}) as second:
        assert second.wait_ready(15)
        time.sleep(1.0)
        assert second.counters()["messages_in"] == 0
    assert count(store, building) == 2000
    store.close()


def _mosquitto_only(broker):
    if broker.kind != "mosquitto":
        pytest.skip("shared subscriptions need Mosquitto (amqtt has none)")


def test_share_group_members_split_the_stream_and_store_each_message_once(
        broker, storage, building, publisher):
    _mosquitto_only(broker)
    settings = _settings(broker, share_group=f"g{uuid.uuid4().hex[:6]}")
    with Ingester(settings, storage, {building: catalogue()}) as a, \
            Ingester(settings, storage, {building: catalogue()}, worker=1,
                     weather=False) as b:
        assert a.client_id != b.client_id
        assert a.wait_ready(15) and b.wait_ready(15)
        _send_all(publisher, building, range(60))
        wait_until(lambda: a.counters()["messages_stored"] + b.counters()["messages_stored"]
                   == 60, what="60 stored by the two")
        time.sleep(0.3)
        got = [a.counters()["messages_in"], b.counters()["messages_in"]]
        duplicates = a.counters()["readings_duplicate"] + b.counters()["readings_duplicate"]
    assert sum(got) == 60 and min(got) > 0, got  # each message to one member, both worked
    assert duplicates == 0 and count(storage, building) == 600


def test_joining_a_share_group_drops_the_plain_subscription(broker, building, publisher,
                                                            tmp_path):
    """The persistent session keeps the plain subscription of a run before the share group:
    the ingester unsubscribes it, or it would receive every message besides its share."""
    _mosquitto_only(broker)
    store = open_storage(f"sqlite:///{tmp_path}/z.db")
    plain = _settings(broker)
    with Ingester(plain, store, {building: catalogue()}) as before:
        assert before.wait_ready(15)
    shared = plain.model_copy(update={"share_group": f"g{uuid.uuid4().hex[:6]}"})
    with Ingester(shared, store, {building: catalogue()}) as a, \
            Ingester(shared, store, {building: catalogue()}, worker=1) as b:
        assert a.wait_ready(15) and b.wait_ready(15)
        time.sleep(0.3)  # the unsubscription follows the subscription
        _send_all(publisher, building, range(40))
        wait_until(lambda: count(store, building) == 400, what="400 readings")
        time.sleep(0.5)
        received = a.counters()["messages_in"] + b.counters()["messages_in"]
    assert received == 40
    store.close()


def test_worker_ids_are_their_own_and_need_a_share_group(broker, storage):
    settings = _settings(broker, client_id=None)
    with pytest.raises(ValueError, match="share_group"):
        Ingester(settings, storage, {}, worker=1)
    ids = [ingester_client_id(settings, storage, w) for w in (0, 1, 2, 1)]
    assert len(set(ids[:3])) == 3 and ids[3] == ids[1]  # distinct, and kept in storage
    fixed = _settings(broker, client_id="zc-a")
    assert [ingester_client_id(fixed, storage, w) for w in (0, 2)] == ["zc-a", "zc-a-w2"]
    with pytest.raises(ValueError, match="share_group"):
        MqttSettings(share_group="a/b")  # not a topic level


def test_validated_readings_are_marked_only_when_their_keys_are_distinct(storage, building):
    cat = {building: catalogue()}
    when = T0.isoformat()
    mapped = validate_message(f"zonecast/{building}/telemetry",
                              json.dumps({"time": when, "readings": {"T_Room_0": 20.5,
                                                                     "T_Room_1": 21}}),
                              cat, now=datetime.now(UTC))
    assert type(mapped.readings) is CheckedReadings
    assert [tuple(r) for r in mapped.readings] == [("T_Room_0", T0, 20.5),
                                                   ("T_Room_1", T0, 21.0)]
    assert all(type(r.value) is float for r in mapped.readings)
    repeated = validate_message(
        f"zonecast/{building}/telemetry",
        json.dumps({"readings": [{"point": "T_Room_0", "time": when, "value": 20.5},
                                 {"point": "T_Room_0", "time": when, "value": 22.0}]}),
        cat, now=datetime.now(UTC))
    assert type(repeated.readings) is tuple  # storage checks these (and keeps the first)
    result = storage.put_readings(building, repeated.readings)
    assert (tuple(result), result.conflicts) == ((1, 1), 1)
    assert tuple(storage.put_readings(building, mapped.readings)) == (1, 1)


def test_concurrent_members_on_one_storage_do_not_lose_a_commit(storage, building):
    """Two ingesters of one process share a storage object: put_many from both threads,
    new rows and redeliveries mixed, every reading stored once."""
    cat = catalogue()

    def rows(step):
        return validate_message(f"zonecast/{building}/telemetry", json.dumps(telemetry(step)),
                                {building: cat}, now=datetime.now(UTC)).readings

    def writer(offset):
        for s in range(0, 40, 4):
            storage.put_many([(building, rows(s + offset)), (building, rows(s + offset + 1)),
                              (building, rows(s))])  # the last one: sometimes stored already

    threads = [threading.Thread(target=writer, args=(k,)) for k in (0, 2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert count(storage, building) == 400


def test_ingest_worker_command_stores_its_share_and_needs_a_group(broker, building, publisher,
                                                                   tmp_path, monkeypatch):
    """``zonecast ingest --worker 1``: refuses to run without mqtt.share_group; with one, it
    stores (here: dead-letters, no model is configured) what the group hands it and stops
    on request after acknowledging."""
    from typer.testing import CliRunner
    from zonecast.service.context import run_ingest_worker
    from zonecast.service.settings import load_settings

    from zonecast.cli import app

    url = f"sqlite:///{tmp_path / 'zc.db'}"
    monkeypatch.setenv("ZONECAST_STORAGE_URL", url)
    root = logging.getLogger()
    handlers, level = root.handlers[:], root.level
    try:  # the command points logging at the runner's output, closed afterwards
        res = CliRunner().invoke(app, ["ingest", "--worker", "1"])
    finally:
        root.handlers[:], root.level = handlers, level
    assert res.exit_code == 2 and "share_group" in res.output
    _mosquitto_only(broker)
    settings = load_settings(storage_url=url, mqtt=_settings(
        broker, client_id=None, share_group=f"g{uuid.uuid4().hex[:6]}").model_dump())
    stop = threading.Event()
    done: list = []
    worker = threading.Thread(target=lambda: done.append(run_ingest_worker(settings, 1, stop)))
    worker.start()
    store = None
    try:  # opened while the worker opens and migrates the same file (SQLite's WAL switch)
        store = open_storage(url)

        def has_id() -> bool:  # read only: instance_value would store a default
            with sqlite3.connect(tmp_path / "zc.db") as db:
                return bool(db.execute("SELECT count(*) FROM instance WHERE key = "
                                       "'mqtt_client_id:1'").fetchone()[0])

        wait_until(has_id, 15, "the worker's client id")
        time.sleep(1.5)  # connected and subscribed
        _send_all(publisher, building, range(10))
        wait_until(lambda: len(store.dead_letters(building=building)) == 10, 15,
                   "10 dead letters (unknown building)")
    finally:
        stop.set()
        worker.join(30)
        if store is not None:
            store.close()
    assert done and done[0].counters()["messages_stored"] == 10


def test_grouped_acks_fall_back_to_one_by_one_when_paho_differs():
    """The group PUBACK uses paho's private queue; a paho whose method takes other
    arguments (TypeError) gets every QoS 1 and 2 message acknowledged one by one, none lost;
    with the queue, QoS 1 goes as one write and only QoS 2 one by one."""
    from types import SimpleNamespace

    from zonecast.service.mqtt import _ack_all

    messages = [SimpleNamespace(mid=m, qos=q) for m, q in ((1, 1), (2, 1), (3, 0), (4, 2))]

    class Client:
        def __init__(self, queue):
            self.acked, self.queued = [], []
            if queue == "other":
                self._packet_queue = lambda *a: (_ for _ in ()).throw(TypeError("signature"))
            elif queue:
                self._packet_queue = lambda cmd, packet, mid, qos: self.queued.append(packet)

        def ack(self, mid, qos):
            self.acked.append(mid)

    other, paho = Client("other"), Client(True)
    _ack_all(other, messages)
    _ack_all(paho, messages)
    assert other.acked == [1, 2, 4] and other.queued == []
    assert paho.acked == [4] and len(paho.queued) == 1 and len(paho.queued[0]) == 8
