"""The ingester's MQTT client id (docs/security.md): unique per service instance (per
storage), stable across restarts, so the broker's queued messages reach the restarted
service; against the ``broker`` fixture (Mosquitto or amqtt)."""

from __future__ import annotations

import json
import re
import time
import uuid

import paho.mqtt.client as mqtt
import pytest
from paho.mqtt.enums import CallbackAPIVersion

pytestmark = pytest.mark.timeout(120)


def settings_for(tmp_path, broker, db: str, prefix: str):
    from zonecast.service.settings import load_settings

    return load_settings(storage_url=f"sqlite:///{tmp_path / db}", mqtt={
        "host": broker.host, "port": broker.port, "username": broker.username,
        "protocol": "5" if broker.mqtt5 else "3.1.1", "topic_prefix": prefix},
        runner={"publish": False})


def running(settings):
    from fastapi.testclient import TestClient
    from zonecast.service.app import create_app

    client = TestClient(create_app(settings))
    client.__enter__()
    zc = client.app.state.zc
    assert zc.ingester.wait_ready(15), "ingester did not connect"
    return client, zc


def publish(broker, topic: str, payload: str) -> None:
    c = mqtt.Client(callback_api_version=CallbackAPIVersion.VERSION2,
                    client_id=f"bms-{uuid.uuid4().hex[:8]}",
                    protocol=mqtt.MQTTv5 if broker.mqtt5 else mqtt.MQTTv311)
    c.username_pw_set(broker.username, "secret")
    c.connect(broker.host, broker.port)
    c.loop_start()
    try:
        info = c.publish(topic, payload, qos=1)
        info.wait_for_publish(10)
        assert info.is_published()
    finally:
        c.disconnect()
        c.loop_stop()


def test_default_client_id_is_unique_per_instance_and_kept_across_restarts(tmp_path, broker):
    """Two services with their own storage get different generated ids; a service restarted
    on the same storage gets its id back and with it the messages the broker queued while it
    was down (here a message for an unknown building, stored as a dead letter)."""
    prefix = f"zc{uuid.uuid4().hex[:8]}"
    one = settings_for(tmp_path, broker, "one.db", prefix)
    two = settings_for(tmp_path, broker, "two.db", f"{prefix}x")
    assert one.mqtt.client_id is None  # the default: generated and kept in storage

    client, zc = running(one)
    first = zc.ingester.client_id
    client.__exit__(None, None, None)
    assert re.fullmatch(r"zonecast-ingest-[A-Za-z0-9_-]+-[0-9a-f]{16}", first), first

    # published while the first service is down: the broker queues it for its session
    publish(broker, f"{prefix}/nowhere/telemetry", json.dumps({"readings": {}}))

    other, zc2 = running(two)
    assert zc2.ingester.client_id != first
    other.__exit__(None, None, None)

    client, zc = running(one)
    try:
        assert zc.ingester.client_id == first
        deadline = time.monotonic() + 15
        while time.monotonic() < deadline and not zc.storage.dead_letters(building="nowhere"):
            time.sleep(0.05)
        letters = zc.storage.dead_letters(building="nowhere")
        assert [d.topic for d in letters] == [f"{prefix}/nowhere/telemetry"]
    finally:
        client.__exit__(None, None, None)


def test_configured_client_id_wins_over_the_stored_one(tmp_path):
    from zonecast.service.mqtt import CLIENT_ID_KEY, ingester_client_id
    from zonecast.service.settings import MqttSettings
    from zonecast.service.storage import open_storage

    with open_storage(f"sqlite:///{tmp_path / 'zc.db'}") as store:
        generated = ingester_client_id(MqttSettings(), store)
        assert store.instance_value(CLIENT_ID_KEY, "x") == generated
        assert ingester_client_id(MqttSettings(), store) == generated
        assert ingester_client_id(MqttSettings(client_id="site-a-ingest"), store) == \
            "site-a-ingest"
