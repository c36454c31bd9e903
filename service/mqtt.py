"""MQTT ingester: BMS telemetry -> validation -> durable storage -> acknowledgement.

Delivery contract (see ``docs/service.md``):

- QoS 1 subscription on a persistent session (MQTT v5 ``clean_start=False``
  with a session expiry interval, or MQTT 3.1.1 ``clean_session=False``) under
  a client id that stays the same across restarts (``MqttSettings.client_id``, default
  generated once per storage: :func:`ingester_client_id`), so the broker keeps queueing
  while the ingester is down.
- Manual acknowledgement: a message's PUBACK is sent only after the readings
  it carries, or the dead letter recording why it was rejected, are committed
  to storage. A crash before the commit leaves the message unacknowledged and
  the broker delivers it again on reconnection; storage is idempotent, so a
  redelivery after the commit but before the PUBACK adds nothing.
- Rejected messages and readings go to the ``dead_letters`` table and to the
  topic ``<prefix>/<building>/deadletter``; a bad message never stops ingest: every
  message ends acknowledged, stored or dead-lettered with its reason. Validation runs per
  message and cannot raise (``accept``: an unexpected exception is the reason
  ``internal_error``); a message that storage refuses as data is dead-lettered
  (``storage_rejected``); only an unavailable storage holds acknowledgements back.

Threads: paho's network thread validates each incoming message and queues it; one
worker thread commits a group of queued messages in one transaction (one disk sync for
many messages), publishes dead letters and acknowledges, in the order the messages
arrived. Validating on the network thread lets it run while the worker waits for the
database (a commit releases the GIL), so validation and storage overlap; the broker keeps
sending during a commit as long as fewer than ``receive_maximum`` messages are
unacknowledged.
"""

from __future__ import annotations

import json
import logging
import queue
import sqlite3
import struct
import threading
import time
from collections import Counter, deque
from collections.abc import Callable, Mapping
from datetime import UTC, datetime
from typing import Any, Self

import paho.mqtt.client as mqtt
from paho.mqtt.enums import CallbackAPIVersion
from paho.mqtt.packettypes import PacketTypes
from paho.mqtt.properties import Properties
from paho.mqtt.subscribeoptions import SubscribeOptions
from zonecast.service.ingest import (
    Accepted,
    MessageRejected,
    PointCatalogue,
    Reason,
    RejectedReading,
    accept,
    log_rejections,
    refuse,
)
from zonecast.service.replay import unique_client_id
from zonecast.service.settings import DEFAULT_PREFIX, MqttSettings
from zonecast.service.storage import PutResult, Storage
from zonecast.service.weather import WEATHER_SUFFIX, accept_weather, is_weather_topic

__all__ = ["CLIENT_ID_KEY", "Ingester", "dead_letter_topic", "ingester_client_id"]

#: key of the generated ingester client id in storage (``Storage.instance_value``)
CLIENT_ID_KEY = "mqtt_client_id"

log = logging.getLogger(__name__)


def dead_letter_topic(building: str | None, prefix: str = DEFAULT_PREFIX) -> str:
    """``<prefix>/<building>/deadletter``, or ``<prefix>/deadletter`` without a building."""
    return f"{prefix}/{building}/deadletter" if building else f"{prefix}/deadletter"


def ingester_client_id(settings: MqttSettings, storage: Storage, worker: int = 0) -> str:
    """The ingester's MQTT client id: ``settings.client_id`` if set, else the id kept in
    ``storage`` under :data:`CLIENT_ID_KEY`, generated on first use as
    ``zonecast-ingest-<host>-<16 hex>``. Stable across restarts on the same storage (the
    broker's queued messages are keyed on it), different for every storage, so two service
    instances with their own databases never take over each other's session.

    ``worker`` > 0 (``zonecast ingest --worker N``, a member of ``settings.share_group``):
    its own id, kept under ``<CLIENT_ID_KEY>:<N>`` (``<client_id>-w<N>`` when
    ``settings.client_id`` is set), so each worker resumes its own session."""
    if worker < 0:
        raise ValueError(f"worker {worker} must be 0 (the service) or a positive number")
    if settings.client_id is not None:
        return settings.client_id if worker == 0 else f"{settings.client_id}-w{worker}"
    key = CLIENT_ID_KEY if worker == 0 else f"{CLIENT_ID_KEY}:{worker}"
    return storage.instance_value(key, unique_client_id("ingest", random_hex=16))


def _notice(message: mqtt.MQTTMessage, received: datetime, acc: Accepted) -> dict[str, Any]:
    """What the ingester publishes on the dead-letter topic about a message."""
    return {
        "topic": message.topic,
        "building": acc.building,
        "received_at": received.isoformat(),
        "rejections": [{"point": r.point, "reason": r.reason.value, "detail": r.detail}
                       for r in acc.rejections],
        "payload": message.payload[:1024].decode("utf-8", errors="replace"),
    }


#: a received message, what to store of it and its dead-letter notice (None if no rejection)
_Checked = tuple[mqtt.MQTTMessage, Accepted, dict[str, Any] | None]


class _Stopped(Exception):
    """Internal: the ingester is stopping while storage is unavailable."""


class _DataError(Exception):
    """Internal: storage refused the data of a commit (the cause is chained)."""


def _is_data_error(exc: BaseException) -> bool:
    """True if storage refused the data itself (retrying cannot help), False for an
    outage (retry): Python's value/type/arithmetic errors, SQLite's data and integrity
    errors, and PostgreSQL's SQLSTATE classes 22 (data exception) and 23 (integrity)."""
    if isinstance(exc, (ValueError, TypeError, ArithmeticError, sqlite3.DataError,
                        sqlite3.IntegrityError)):
        return True
    state = getattr(exc, "sqlstate", None)
    return isinstance(state, str) and state[:2] in ("22", "23")


def _ack_all(client: mqtt.Client, messages: list[mqtt.MQTTMessage]) -> None:
    """Acknowledge ``messages`` in order. QoS 1 PUBACKs go to paho's outgoing queue as ONE
    write (one wake-up of its network thread and one ``send`` instead of one each per
    message, ~20 us of CPU per message in the ingester and the broker, docs/benchmarks.md);
    paho's ``ack`` when its private ``_packet_queue`` is not there (another paho version)."""
    mids = [m.mid for m in messages if m.qos == 1]
    queue_packet = getattr(client, "_packet_queue", None)
    rest = [m for m in messages if m.qos > 0]
    if len(mids) > 1 and queue_packet is not None:
        # PUBACK: type 4 (0x40), remaining length 2, packet id; v5 allows omitting the
        # reason code when it is 0 (success), as paho's own ack does
        try:
            queue_packet(PUBACK_BYTE,
                         b"".join(_PUBACK.pack(PUBACK_BYTE, 2, mid) for mid in mids), 0, 0)
        except TypeError:  # a paho whose private method takes other arguments: one by one
            pass
        else:
            rest = [m for m in messages if m.qos > 1]
    for message in rest:
        client.ack(message.mid, message.qos)


PUBACK_BYTE = 0x40
_PUBACK = struct.Struct("!BBH")


class Ingester:
    """Subscribe to BMS telemetry and store it durably.

    Parameters
    ----------
    settings : MqttSettings
        Broker, session and validation settings.
    storage : Storage
        Where readings and dead letters go (see :func:`open_storage`).
    catalogues : Mapping[str, PointCatalogue]
        Known buildings -> point catalogues. Read on every message, so a
        mutable mapping may be updated while running.
    on_weather : callable, optional
        Called with (building, WeatherForecast) for each accepted weather forecast.
    worker : int
        0 for the service's own ingester; N > 0 for ``zonecast ingest --worker N`` (its own
        client id, :func:`ingester_client_id`).
    weather : bool
        Subscribe to weather forecasts (default True; an ingest worker has no runner to
        hand them to and leaves them to the service).

    Examples
    --------
    >>> with Ingester(MqttSettings(), open_storage(), {"office6": catalogue}) as ing:
    ...     ing.wait_ready(10)
    ...     ...  # runs until the block ends; ing.counters() for metrics
    """

    def __init__(self, settings: MqttSettings, storage: Storage,
                 catalogues: Mapping[str, PointCatalogue], *,
                 on_weather: Callable[[str, Any], None] | None = None, worker: int = 0,
                 weather: bool = True):
        if worker and settings.share_group is None:
            raise ValueError("an ingest worker needs mqtt.share_group: without a shared "
                             "subscription every worker would receive every message")
        self.settings = settings
        self.weather = weather
        #: called with (building, WeatherForecast) for each accepted weather forecast
        self.on_weather = on_weather
        self.storage = storage
        self.catalogues = catalogues
        self._limits = settings.limits
        #: the MQTT client id (:func:`ingester_client_id`)
        self.client_id = ingester_client_id(settings, storage, worker)
        self._queue: queue.Queue[tuple[_Checked, datetime]] = queue.Queue()
        self._stopping = threading.Event()
        self._aborted = False
        self._ready = threading.Event()
        self._worker: threading.Thread | None = None
        self._client: mqtt.Client | None = None
        self._count_lock = threading.Lock()
        self._counts: Counter[str] = Counter()
        self._rejected: Counter[str] = Counter()
        # monotonic receive times of the messages not yet acknowledged, oldest first
        self._pending: deque[float] = deque()

    # --- public API --------------------------------------------------------------
    def start(self) -> Self:
        """Connect (retrying in the background) and start ingesting."""
        if self._client is not None:
            raise RuntimeError("ingester already started; create a new one to restart")
        self._client = self._make_client()
        self._worker = threading.Thread(target=self._run, name="zonecast-ingest", daemon=True)
        self._worker.start()
        self._connect()
        self._client.loop_start()
        return self

    def wait_ready(self, timeout: float | None = None) -> bool:
        """Wait until connected and subscribed; True if so within ``timeout`` [s]."""
        return self._ready.wait(timeout)

    def stop(self, timeout: float = 30.0) -> None:
        """Store and acknowledge what was received, then disconnect cleanly.

        The session stays on the broker: messages published meanwhile are
        delivered to the next ingester started with the same client id (the same storage,
        or the same ``MqttSettings.client_id``).
        """
        if self._client is None:
            return
        self._stopping.set()
        self._join_worker(timeout)
        self._client.disconnect()
        self._client.loop_stop()
        self._client = None

    def abort(self) -> None:
        """Stop as a crash would: nothing more is acknowledged, no DISCONNECT.

        Messages received but not yet acknowledged stay on the broker and are
        delivered again on the next connection (used by the tests).
        """
        if self._client is None:
            return
        self._aborted = True
        self._stopping.set()
        self._join_worker(5.0)
        client, self._client = self._client, None
        client.loop_stop()
        sock = client.socket()
        if sock is not None:
            sock.close()

    def unacknowledged_for(self) -> float:
        """Seconds since the oldest message still waiting for its acknowledgement arrived
        (0 when none waits). Grows while storage is unavailable; ``/readyz`` reports the
        ingester not ready when it exceeds ``MqttSettings.stall_after``."""
        try:
            oldest = self._pending[0]
        except IndexError:
            return 0.0
        return time.monotonic() - oldest

    def counters(self) -> dict[str, int | dict[str, int]]:
        """Snapshot of the counters (plain data for /metrics).

        Keys: ``messages_in``, ``messages_stored`` (acknowledged after commit,
        with or without readings), ``messages_rejected`` (whole message),
        ``readings_stored``, ``readings_duplicate``, ``readings_conflict``,
        ``readings_rejected``, ``dead_letters``, ``storage_errors``,
        ``worker_errors`` (unexpected errors of the worker; that batch stays
        unacknowledged), ``connects``, ``weather_forecasts`` (accepted weather
        forecasts) and ``rejected`` (reason code -> count of messages or readings
        rejected for it).
        """
        keys = ("messages_in", "messages_stored", "messages_rejected", "readings_stored",
                "readings_duplicate", "readings_conflict", "readings_rejected",
                "dead_letters", "storage_errors", "worker_errors", "connects",
                "weather_forecasts")
        with self._count_lock:
            out: dict[str, int | dict[str, int]] = {k: self._counts[k] for k in keys}
            out["rejected"] = dict(self._rejected)
        return out

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # --- MQTT -------------------------------------------------------------------
    def _make_client(self) -> mqtt.Client:
        s = self.settings
        v5 = s.protocol == "5"
        kwargs: dict[str, Any] = {"protocol": mqtt.MQTTv5 if v5 else mqtt.MQTTv311}
        if not v5:
            kwargs["clean_session"] = False
        client = mqtt.Client(callback_api_version=CallbackAPIVersion.VERSION2,
                             client_id=self.client_id, manual_ack=True, **kwargs)
        if s.username is not None:
            client.username_pw_set(s.username,
                                   s.password.get_secret_value() if s.password else None)
        if s.tls is not None:
            client.tls_set(ca_certs=s.tls.ca_certs, certfile=s.tls.certfile,
                           keyfile=s.tls.keyfile)
            client.tls_insecure_set(s.tls.insecure)
        client.reconnect_delay_set(1, 30)
        client.on_connect = self._on_connect
        client.on_disconnect = self._on_disconnect
        client.on_subscribe = self._on_subscribe
        client.on_message = self._on_message
        return client

    def _connect(self) -> None:
        s = self.settings
        if s.protocol == "5":
            props = Properties(PacketTypes.CONNECT)
            props.SessionExpiryInterval = s.session_expiry
            props.ReceiveMaximum = s.receive_maximum
            self._client.connect_async(s.host, s.port, s.keepalive, clean_start=False,
                                       properties=props)
        else:
            self._client.connect_async(s.host, s.port, s.keepalive)

    def _topics(self) -> tuple[list[str], list[str]]:
        """(topics to subscribe, topics to unsubscribe): telemetry and point topics as
        ``$share/<group>/...`` with a share group, else plain; weather forecasts plain (or
        not at all for a worker). The other form is unsubscribed because a persistent
        session keeps the subscriptions of earlier runs: a plain one left over from before
        the share group would deliver every message to this member as well."""
        p, group = self.settings.topic_prefix, self.settings.share_group
        data = [f"{p}/+/telemetry", f"{p}/+/points/#"]
        weather = [f"{p}/+/{WEATHER_SUFFIX}"]
        if not self.weather:
            weather = []
        if group is None:
            return data + weather, []
        shared = [f"$share/{group}/{t}" for t in data]
        stale = data if self.weather else data + [f"{p}/+/{WEATHER_SUFFIX}"]
        return shared + weather, stale

    def _on_connect(self, client, userdata, flags, reason_code, properties) -> None:
        if reason_code.is_failure:
            log.error("MQTT connect to %s:%d refused: %s", self.settings.host,
                      self.settings.port, reason_code)
            return
        self._count("connects")
        log.info("MQTT connected to %s:%d as %s (session present: %s)", self.settings.host,
                 self.settings.port, self.client_id, flags.session_present,
                 extra={"broker": f"{self.settings.host}:{self.settings.port}",
                        "client_id": self.client_id,
                        "session_present": bool(flags.session_present)})
        topics, stale = self._topics()
        if self.settings.protocol == "5":
            # retainHandling=1: retained messages only for a new subscription.
            options = SubscribeOptions(qos=1, retainHandling=1)
            client.subscribe([(t, options) for t in topics])
        else:
            client.subscribe([(t, 1) for t in topics])
        if stale and flags.session_present:  # after the new ones: no moment without either
            client.unsubscribe(stale)

    def _on_subscribe(self, client, userdata, mid, reason_codes, properties) -> None:
        failed = [rc for rc in reason_codes if rc.is_failure]
        if failed:
            log.error("MQTT subscription refused: %s", failed)
            return
        if any(rc.value == 0 for rc in reason_codes):
            log.warning("broker granted QoS 0 only: messages can be lost on a crash")
        self._ready.set()

    def _on_disconnect(self, client, userdata, flags, reason_code, properties) -> None:
        self._ready.clear()
        if not self._stopping.is_set():
            log.warning("MQTT disconnected (%s); reconnecting", reason_code)

    def _on_message(self, client, userdata, message) -> None:
        # Network thread: count, validate (cannot raise) and queue; the worker stores.
        self._count("messages_in")
        self._pending.append(time.monotonic())
        received = datetime.now(UTC)
        self._queue.put((self._accept(message, received), received))

    # --- worker -----------------------------------------------------------------
    def _join_worker(self, timeout: float) -> None:
        if self._worker is not None and self._worker is not threading.current_thread():
            self._worker.join(timeout)
            if self._worker.is_alive():
                log.warning("ingest worker did not finish within %.0f s", timeout)

    def _run(self) -> None:
        while True:
            try:
                first = self._queue.get(timeout=0.1)
            except queue.Empty:
                if self._stopping.is_set():
                    return
                continue
            if self._aborted:
                return
            batch = [first]
            while len(batch) < self.settings.batch_max_messages:
                try:
                    batch.append(self._queue.get_nowait())
                except queue.Empty:
                    break
            try:
                self._process(batch)
            except _Stopped:
                return
            except Exception:  # never let one batch kill the worker
                log.exception("ingest worker: unexpected error; %d messages left "
                              "unacknowledged (the broker redelivers them on the next "
                              "connection)", len(batch))
                self._count("worker_errors")

    def _accept(self, message: mqtt.MQTTMessage, received: datetime) -> _Checked:
        """(message, what to store, dead-letter notice or None), counted. Never raises:
        whatever goes wrong with one message is that message's dead letter."""
        if is_weather_topic(message.topic, self.settings.topic_prefix):
            return self._accept_weather(message, received)
        try:
            props = getattr(message, "properties", None)
            user = dict(getattr(props, "UserProperty", []) or [])
            acc = accept(message.topic, message.payload, received, self.catalogues,
                         limits=self._limits, prefix=self.settings.topic_prefix,
                         properties=user)
        except Exception as exc:  # noqa: BLE001 - e.g. a malformed user property
            acc = refuse(message.topic, message.payload, received, MessageRejected(
                Reason.INTERNAL_ERROR, f"{type(exc).__name__}: {str(exc)[:300]}"))
        if not acc.rejections:
            return message, acc, None
        self._count_rejections(acc)
        log_rejections(acc, message.topic, "mqtt")
        return message, acc, _notice(message, received, acc)

    def _accept_weather(self, message: mqtt.MQTTMessage, received: datetime) -> _Checked:
        """A weather forecast (:mod:`zonecast.service.weather`): handed to ``on_weather``
        when valid, else a dead letter in the same transaction as the batch's."""
        wa = accept_weather(message.topic, message.payload, received, self.catalogues,
                            prefix=self.settings.topic_prefix,
                            max_bytes=self._limits.max_payload_bytes)
        if wa.forecast is not None:
            self._count("weather_forecasts")
            if self.on_weather is not None:
                try:
                    self.on_weather(wa.building, wa.forecast)
                except Exception:  # the forecast is lost, ingest goes on
                    log.exception("building %s: using a weather forecast failed", wa.building)
            return message, Accepted(wa.building), None
        rejection = RejectedReading(None, Reason.BAD_WEATHER_FORECAST,
                                    f"{wa.reason}: {wa.detail}")
        acc = Accepted(wa.building, (), (rejection,), wa.dead_letters,
                       MessageRejected(Reason.BAD_WEATHER_FORECAST, f"{wa.reason}: {wa.detail}",
                                       wa.building))
        self._count_rejections(acc)
        return message, acc, _notice(message, received, acc)

    def _count_rejections(self, acc: Accepted) -> None:
        with self._count_lock:
            if acc.error is not None:
                self._counts["messages_rejected"] += 1
            else:
                self._counts["readings_rejected"] += len(acc.rejections)
            self._rejected.update(acc.reasons)

    def _process(self, batch: list[tuple[_Checked, datetime]]) -> None:
        checked = [item for item, _ in batch]
        try:
            results = self._commit(checked)
        except _DataError:
            # Storage refused some data validation let through: commit message
            # by message and dead-letter the culprit instead of stalling.
            results = []
            for i, (message, acc, notice) in enumerate(checked):
                try:
                    results += self._commit([(message, acc, notice)])
                except _DataError as exc:
                    cause = exc.__cause__ or exc
                    log.error("storage rejected a validated message on %s: %s", message.topic,
                              cause, exc_info=cause,
                              extra={"building": acc.building, "reason": "storage_rejected"})
                    building = acc.building if acc.error is None else None
                    received = batch[i][1]
                    refused = refuse(message.topic, message.payload, received, MessageRejected(
                        Reason.STORAGE_REJECTED, f"{type(cause).__name__}: {str(cause)[:300]}",
                        building))
                    self._count_reason(Reason.STORAGE_REJECTED.value)
                    checked[i] = (message, refused, _notice(message, received, refused))
                    results += self._commit([checked[i]])
        client = self._client
        if self._aborted or client is None:
            return  # simulated crash: committed but never acknowledged
        letters = 0
        for message, acc, notice in checked:
            letters += len(acc.dead_letters)
            if notice is not None:
                try:  # live monitoring only: the table holds the durable record
                    client.publish(dead_letter_topic(notice["building"],
                                                     self.settings.topic_prefix),
                                   json.dumps(notice), qos=1)
                except Exception:  # never hold back the acknowledgement
                    log.exception("publishing a dead-letter notice failed")
        _ack_all(client, [message for (message, _, _), _ in batch])
        for _ in batch:
            try:
                self._pending.popleft()
            except IndexError:
                pass
        self._count("messages_stored", len(batch))
        self._count("dead_letters", letters)
        self._count("readings_stored", sum(r.inserted for r in results))
        self._count("readings_duplicate", sum(r.duplicates for r in results))
        self._count("readings_conflict", sum(r.conflicts for r in results))

    def _commit(self, checked: list[_Checked]) -> list[PutResult]:
        """One transaction; on storage outage retry (messages stay unacknowledged)."""
        batches = [(acc.building, acc.readings) for _, acc, _ in checked if acc.readings]
        letters = [row for _, acc, _ in checked for row in acc.dead_letters]
        delay = 0.1
        while True:
            try:
                return self.storage.put_many(batches, letters)
            except Exception as exc:
                if _is_data_error(exc):  # a data problem: retrying cannot help
                    raise _DataError(str(exc)) from exc
                self._count("storage_errors")
                log.error("storage write failed (%s); retrying in %.1f s", exc, delay)
                if self._stopping.wait(delay):
                    raise _Stopped from exc
                delay = min(delay * 2, 5.0)

    def _count(self, key: str, n: int = 1) -> None:
        with self._count_lock:
            self._counts[key] += n

    def _count_reason(self, reason: str) -> None:
        with self._count_lock:
            self._rejected[reason] += 1
