"""Replay recorded telemetry to a broker like a BMS, and the MQTT publisher of the service.

``zonecast replay --data DIR --broker mqtt://HOST:PORT --building ID [--speed X]``
publishes one message per telemetry row on ``<prefix>/<ID>/telemetry`` (QoS 1), map
form ``{"time": T, "readings": {point: value}}`` with the values as recorded (the
site's units; empty cells are left out), and waits for each PUBACK: a message without one
within 30 s, or with a failure reason code (MQTT v5), raises ConnectionError (the CLI exits
with status 2). Its client id is unique per run (``zonecast-replay-<host>-<random>``), so
two replays never disconnect each other.
"""

from __future__ import annotations

import json
import logging
import math
import socket
import threading
import time
import uuid
from collections.abc import Callable
from datetime import datetime
from pathlib import Path
from urllib.parse import urlsplit

import paho.mqtt.client as mqtt
import pandas as pd
from paho.mqtt.enums import CallbackAPIVersion
from zonecast.estimator.constants import STEP_S
from zonecast.estimator.site import load_site
from zonecast.service.settings import MqttSettings

__all__ = ["ReplayResult", "connect_publisher", "parse_broker_url", "replay", "unique_client_id"]

log = logging.getLogger(__name__)


def unique_client_id(role: str, random_hex: int = 6) -> str:
    """``zonecast-<role>-<host>-<random_hex hex digits>``: a client id no other process uses,
    for clients without a persistent session (replay, the service's publisher). The
    ingester's id must stay the same across restarts (the broker keys its queued messages on
    it): it is generated once with this function (16 hex digits, hard to guess) and kept in
    storage (``zonecast.service.mqtt.ingester_client_id``)."""
    host = "".join(c for c in socket.gethostname() if c.isalnum() or c in "-_")[:32] or "host"
    return f"zonecast-{role}-{host}-{uuid.uuid4().hex[:random_hex]}"


def parse_broker_url(url: str) -> tuple[str, int, bool]:
    """``mqtt://host:port`` or ``mqtts://host:port`` -> (host, port, tls)."""
    parts = urlsplit(url)
    if parts.scheme not in ("mqtt", "mqtts") or not parts.hostname:
        raise ValueError(f"broker {url!r} must look like mqtt://HOST:PORT or mqtts://HOST:PORT")
    tls = parts.scheme == "mqtts"
    try:
        port = parts.port or (8883 if tls else 1883)
    except ValueError:
        raise ValueError(f"broker {url!r} has an invalid port") from None
    return parts.hostname, port, tls


def connect_publisher(settings: MqttSettings, *, client_id: str,
                      timeout: float | None = None) -> mqtt.Client:
    """A paho client (v2 callback API) connected in the background; with ``timeout`` wait
    for the connection [s] and raise ConnectionError if it does not come."""
    v5 = settings.protocol == "5"
    client = mqtt.Client(callback_api_version=CallbackAPIVersion.VERSION2, client_id=client_id,
                         protocol=mqtt.MQTTv5 if v5 else mqtt.MQTTv311)
    if settings.username is not None:
        client.username_pw_set(settings.username, settings.password.get_secret_value()
                               if settings.password else None)
    if settings.tls is not None:
        client.tls_set(ca_certs=settings.tls.ca_certs, certfile=settings.tls.certfile,
                       keyfile=settings.tls.keyfile)
        client.tls_insecure_set(settings.tls.insecure)
    connected = threading.Event()

    def on_connect(c, userdata, flags, reason_code, properties) -> None:
        if reason_code.is_failure:  # e.g. bad user name or password; paho retries
            log.error("MQTT connect of %s to %s:%d refused: %s", client_id, settings.host,
                      settings.port, reason_code)
        else:
            connected.set()

    client.on_connect = on_connect
    client.reconnect_delay_set(1, 30)
    client.connect_async(settings.host, settings.port, settings.keepalive)
    client.loop_start()
    if timeout is not None and not connected.wait(timeout):
        client.loop_stop()
        raise ConnectionError(f"no connection to the broker {settings.host}:{settings.port} "
                              f"within {timeout} s (refused credentials are logged; check "
                              "the user name and password)")
    return client


class ReplayResult(dict):
    """``messages``, ``readings``, ``first``, ``last`` (ISO times) and ``seconds``."""


def _rows(data: Path, start: str | datetime | None,
          end: str | datetime | None) -> tuple[pd.DataFrame, list[str]]:
    path = data / "telemetry.csv" if data.is_dir() else data
    if not path.is_file():
        raise ValueError(f"no telemetry file {path}")
    frame = pd.read_csv(path, dtype={"time": str})
    if "time" not in frame.columns:
        raise ValueError(f"{path}: no 'time' column")
    points = [c for c in frame.columns if c != "time"]
    site = path.parent / "site.yaml"
    if site.is_file():
        mapped = set(load_site(site).point_units())
        points = [p for p in points if p in mapped]
    times = pd.to_datetime(frame["time"], format="ISO8601", utc=True)
    keep = pd.Series(True, index=frame.index)
    if start is not None:
        keep &= times >= pd.Timestamp(start)
    if end is not None:
        keep &= times < pd.Timestamp(end)
    return frame[keep.to_numpy()], points


def replay(data: str | Path, settings: MqttSettings, building: str, *, speed: float = 0.0,
           start: str | datetime | None = None, end: str | datetime | None = None,
           client_id: str | None = None,
           progress: Callable[[int, int], None] | None = None) -> ReplayResult:
    """Publish recorded telemetry like a BMS.

    Parameters
    ----------
    data : path
        Folder holding telemetry.csv (and site.yaml: then only the points it maps are
        sent), or the telemetry file.
    settings : MqttSettings
        Broker address, credentials, TLS and topic prefix.
    building : str
        Building id of the topic.
    speed : float
        Time-lapse factor: 1 = real time (one row per 15 min), 96 = one day per 15 min;
        0 = as fast as the broker acknowledges.
    start, end : tz-aware time, optional
        Replay only rows with start <= time < end.
    client_id : str, optional
        Default: :func:`unique_client_id` (``zonecast-replay-<host>-<random>``).

    Raises
    ------
    ConnectionError
        No connection, or a message not acknowledged (no PUBACK within 30 s, or a PUBACK
        with a failure reason code): the replay stops there.
    """
    frame, points = _rows(Path(data), start, end)
    client = connect_publisher(settings, client_id=client_id or unique_client_id("replay"),
                               timeout=10)
    refused: dict[int, str] = {}

    def on_publish(c, userdata, mid, reason_code, properties) -> None:
        if getattr(reason_code, "is_failure", False):
            refused[mid] = str(reason_code)

    client.on_publish = on_publish
    topic = f"{settings.topic_prefix}/{building}/telemetry"
    t0 = time.monotonic()
    sent = readings = 0
    try:
        for i, (_, row) in enumerate(frame.iterrows()):
            values = {p: float(row[p]) for p in points
                      if isinstance(row[p], (int, float)) and math.isfinite(row[p])}
            if not values:
                continue
            if speed > 0 and i:
                due = t0 + i * STEP_S / speed
                time.sleep(max(0.0, due - time.monotonic()))
            info = client.publish(topic, json.dumps({"time": row["time"], "readings": values}),
                                  qos=1)
            info.wait_for_publish(30)
            if not info.is_published():
                raise ConnectionError(f"message {i} ({row['time']}) was not acknowledged "
                                      f"within 30 s; {sent} messages were")
            if info.mid in refused:
                raise ConnectionError(f"message {i} ({row['time']}) was refused by the broker: "
                                      f"{refused[info.mid]} (check the user's ACL for {topic}); "
                                      f"{sent} messages were acknowledged")
            sent += 1
            readings += len(values)
            if progress is not None:
                progress(i + 1, len(frame))
    finally:
        client.disconnect()
        client.loop_stop()
    return ReplayResult(messages=sent, readings=readings,
                        first=str(frame["time"].iloc[0]) if len(frame) else None,
                        last=str(frame["time"].iloc[-1]) if len(frame) else None,
                        seconds=time.monotonic() - t0)
