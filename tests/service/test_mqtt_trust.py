"""The MQTT trust model (docs/security.md) against a real Mosquitto started with the SHIPPED
``configs/mosquitto.conf`` (only its port, file paths and process user replaced) and the
password file and ACL of ``zonecast mqtt-config``.

Mosquitto drops an unauthorised publish silently (MQTT v5 answers PUBACK 0x87 "Not
authorized", 3.1.1 an ordinary PUBACK), so every test asserts on what the service stored and
serves, not only on what the client was told. Skipped without ``mosquitto`` (the amqtt
fallback broker of the other tests has no password file or ACL).
"""

from __future__ import annotations

import getpass
import json
import shutil
import socket
import subprocess
import threading
import time
import uuid
from pathlib import Path

import paho.mqtt.client as mqtt
import pandas as pd
import pytest
from paho.mqtt.enums import CallbackAPIVersion
from paho.mqtt.packettypes import PacketTypes
from paho.mqtt.properties import Properties

from tests.service.helpers import body_of, wait_until

ROOT = Path(__file__).resolve().parents[2]
MOSQUITTO = shutil.which("mosquitto") or next(
    (p for p in ("/usr/sbin/mosquitto", "/usr/local/sbin/mosquitto") if Path(p).exists()), None)
pytestmark = [pytest.mark.skipif(MOSQUITTO is None, reason="needs the mosquitto broker on PATH "
                                 "(password file and ACL; amqtt has neither)"),
              pytest.mark.timeout(180)]
ADMIN = "trust-admin-token-01"
BUILDINGS = ["office6", "office7"]


# --------------------------------------------------------------------------- broker
def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def shipped_config(workdir: Path, auth: Path, port: int, tls_port: int | None = None) -> Path:
    """configs/mosquitto.conf with this test's port and files; with ``tls_port`` its
    commented TLS listener enabled on that port (certificates in ``auth``)."""
    text = (ROOT / "configs" / "mosquitto.conf").read_text()
    lines = text.splitlines()
    for required in ("allow_anonymous false", "password_file /mosquitto/auth/passwd",
                     "acl_file /mosquitto/auth/acl", "listener 1883", "#listener 8883"):
        assert required in lines, f"shipped mosquitto.conf lost {required!r}"
    out = []
    for line in lines:
        if tls_port is not None and line.startswith("#") and line[1:].split(" ")[0] in (
                "listener", "cafile", "certfile", "keyfile", "tls_version"):
            line = line[1:]
        key = line.split(" ", 1)[0]
        if key == "listener":
            line = f"listener {tls_port if line.endswith('8883') else port} 127.0.0.1"
        elif key in ("password_file", "acl_file", "cafile", "certfile", "keyfile"):
            line = line.replace("/mosquitto/auth", str(auth))
        elif key == "persistence_location":
            line = f"persistence_location {workdir}/"
        out.append(line)
    # started as root, Mosquitto would switch to the user "mosquitto", which cannot read the
    # 0600 files this test's user wrote (as the operator must chown them, docs/security.md)
    out.append(f"user {getpass.getuser()}")
    conf = workdir / "mosquitto.conf"
    conf.write_text("\n".join(out) + "\n")
    return conf


class Mosquitto:
    def __init__(self, workdir: Path, conf: Path, ports: list[int]):
        self.log = workdir / "mosquitto.log"
        with open(self.log, "wb") as f:
            self.proc = subprocess.Popen([MOSQUITTO, "-c", str(conf)], stdout=f,
                                         stderr=subprocess.STDOUT, cwd=workdir)
        deadline = time.monotonic() + 15
        for port in ports:
            while True:
                if self.proc.poll() is not None:
                    raise RuntimeError(f"mosquitto exited: {self.log.read_text()[-2000:]}")
                try:
                    with socket.create_connection(("127.0.0.1", port), timeout=0.5):
                        break
                except OSError:
                    if time.monotonic() > deadline:
                        self.stop()
                        raise RuntimeError(f"mosquitto not listening on {port}") from None
                    time.sleep(0.05)

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


@pytest.fixture(scope="module")
def secured(tmp_path_factory):
    """Mosquitto with the shipped config, users zonecast, office6, office7 (passwords in
    ``.passwords``) on ``.port``."""
    from zonecast.service.brokerconf import write_broker_files

    workdir = tmp_path_factory.mktemp("secured")
    files = write_broker_files(BUILDINGS, workdir / "auth")
    port = free_port()
    broker = Mosquitto(workdir, shipped_config(workdir, workdir / "auth", port), [port])
    broker.port, broker.passwords = port, files.passwords
    yield broker
    broker.stop()


class Client:
    """A paho client that records its CONNACK, received messages and PUBACK reason codes."""

    def __init__(self, port: int, user: str | None, password: str | None = None, *,
                 v5: bool = True, client_id: str | None = None, persistent: bool = False,
                 tls_ca: Path | None = None):
        self.messages: list[mqtt.MQTTMessage] = []
        self.acks: dict[int, str] = {}
        self.connack = None
        self._connected = threading.Event()
        kwargs = {} if v5 else {"clean_session": not persistent}
        self.c = mqtt.Client(callback_api_version=CallbackAPIVersion.VERSION2,
                             client_id=client_id or f"t-{uuid.uuid4().hex[:10]}",
                             protocol=mqtt.MQTTv5 if v5 else mqtt.MQTTv311, **kwargs)
        if user is not None:
            self.c.username_pw_set(user, password)
        if tls_ca is not None:
            self.c.tls_set(ca_certs=str(tls_ca))
        self.c.on_connect = self._on_connect
        self.c.on_message = lambda c, u, m: self.messages.append(m)
        self.c.on_publish = lambda c, u, mid, rc, p: self.acks.__setitem__(mid, str(rc))
        props = None
        if v5:
            props = Properties(PacketTypes.CONNECT)
            props.SessionExpiryInterval = 3600 if persistent else 0
            self.c.connect("127.0.0.1", port, clean_start=not persistent, properties=props)
        else:
            self.c.connect("127.0.0.1", port)
        self.c.loop_start()
        assert self._connected.wait(10), "no CONNACK"

    def _on_connect(self, c, u, flags, rc, p):
        self.connack = (str(rc), rc.is_failure, flags.session_present)
        self._connected.set()

    @property
    def refused(self) -> bool:
        return self.connack[1]

    def publish(self, topic: str, payload, *, retain: bool = False) -> str:
        """Publish QoS 1 and wait for the PUBACK; its reason code ("Success", "Not
        authorized"; 3.1.1: always "Success")."""
        body = payload if isinstance(payload, (bytes, str)) else json.dumps(payload)
        info = self.c.publish(topic, body, qos=1, retain=retain)
        info.wait_for_publish(10)
        assert info.is_published(), f"no PUBACK for {topic}"
        return self.acks[info.mid]

    def subscribe(self, *topics: str) -> None:
        self.c.subscribe([(t, 1) for t in topics])

    def topics(self) -> list[str]:
        return [m.topic for m in self.messages]

    def close(self) -> None:
        self.c.disconnect()
        self.c.loop_stop()


def start_service(tmp_path, secured, buildings: dict[str, str], **mqtt_extra):
    from fastapi.testclient import TestClient
    from zonecast.service.app import create_app
    from zonecast.service.settings import load_settings

    settings = load_settings(
        storage_url=f"sqlite:///{tmp_path / 'zc.db'}", api_tokens={ADMIN: ["admin"]},
        buildings=buildings,
        mqtt={"host": "127.0.0.1", "port": secured.port, "username": "zonecast",
              "password": secured.passwords["zonecast"], **mqtt_extra},
        runner={"poll_interval": 0.05, "forecast_every": 1, "publish": True})
    client = TestClient(create_app(settings))
    client.__enter__()
    assert client.app.state.zc.ingester.wait_ready(15), "service did not connect"
    return client


def stored(zc, building: str) -> int:
    frame = zc.storage.readings(building, "2000-01-01T00:00:00Z", "2100-01-01T00:00:00Z")
    return int(frame.notna().to_numpy().sum())


# --------------------------------------------------------------------------- tests
@pytest.mark.parametrize("v5", [True, False], ids=["v5", "v3.1.1"])
def test_anonymous_and_wrong_passwords_are_refused_at_connect(secured, v5):
    for user, password in ((None, None), ("office6", "wrong"), ("zonecast", "wrong"),
                           ("intruder", "x")):
        c = Client(secured.port, user, password, v5=v5)
        try:
            assert c.refused, (user, c.connack)
        finally:
            c.close()
    ok = Client(secured.port, "office6", secured.passwords["office6"], v5=v5)
    ok.close()
    assert not ok.refused, ok.connack


def test_buildings_are_confined_and_only_the_service_writes_state_and_forecast(
        tmp_path, secured, vb, telemetry):
    """office6 publishes its own telemetry (stored, forecast served and published); office6
    writing office7's telemetry and office7 writing state/forecast (retained) are refused
    and nothing of them is stored or served; office7 subscribed to everything receives only
    its own topics."""
    model = str(vb / "model.json")
    app = start_service(tmp_path, secured, {b: model for b in BUILDINGS})
    zc = app.app.state.zc
    pw = secured.passwords
    spy7 = Client(secured.port, "office7", pw["office7"])
    spy7.subscribe("zonecast/#")
    pub6 = Client(secured.port, "office6", pw["office6"])
    pub7 = Client(secured.port, "office7", pw["office7"])
    old6 = Client(secured.port, "office6", pw["office6"], v5=False)
    old7 = Client(secured.port, "office7", pw["office7"], v5=False)
    clients = [spy7, pub6, pub7, old6, old7]
    n = 9
    try:
        fake = {"issued": "2015-04-13T07:00:00Z", "zones": [], "fake": True}
        for topic in ("zonecast/office6/forecast", "zonecast/office6/state",
                      "zonecast/office7/forecast", "zonecast/office7/state",
                      "zonecast/office6/deadletter"):
            assert pub7.publish(topic, fake, retain=True) == "Not authorized", topic
            assert old7.publish(topic, fake, retain=True) == "Success"  # 3.1.1: silent drop
        for i in range(n):  # office6 writing office7's telemetry, both protocols
            row = body_of(telemetry.iloc[i])
            assert pub6.publish("zonecast/office7/telemetry", row) == "Not authorized"
            assert old6.publish("zonecast/office7/telemetry", row) == "Success"
        assert pub6.publish("zonecast/office7/points/T_Room_NW_1",
                            {"time": telemetry.iloc[0]["time"], "value": 30.0}) == \
            "Not authorized"
        for i in range(n):  # office6's own telemetry
            assert pub6.publish("zonecast/office6/telemetry", body_of(telemetry.iloc[i])) == \
                "Success"
        assert pub7.publish("zonecast/office7/telemetry", b"not json") == "Success"

        last = pd.Timestamp(telemetry.iloc[n - 1]["time"]).tz_convert("UTC")
        runner6 = zc.runners["office6"]
        def stepped() -> bool:  # under the lock: the row's forecast is set with its step
            with runner6.lock:
                return runner6.est.time is not None and runner6.est.time >= last

        wait_until(stepped, what="office6 runner")
        wait_until(lambda: zc.storage.dead_letters(building="office7"), what="dead letter")
        rest = app.get("/api/v1/buildings/office6/forecast",
                       headers={"Authorization": f"Bearer {ADMIN}"})
        assert rest.status_code == 200, rest.text

        # the service: office6 stored, nothing of office7 but its own malformed message
        readings6 = sum(len(body_of(telemetry.iloc[i])["readings"]) for i in range(n))
        assert stored(zc, "office6") == readings6
        assert stored(zc, "office7") == 0
        letters = zc.storage.dead_letters(limit=1000)
        assert [(d.building, d.topic) for d in letters] == \
            [("office7", "zonecast/office7/telemetry")]
        state7 = app.get("/api/v1/buildings/office7/state",
                         headers={"Authorization": f"Bearer {ADMIN}"}).json()
        assert "not_started" in state7["quality"]

        # the retained forecast and state are the service's, not the fakes
        reader6 = Client(secured.port, "office6", pw["office6"])
        clients.append(reader6)
        reader6.subscribe("zonecast/office6/forecast", "zonecast/office6/state")
        issued = rest.json()["issued"]

        def newest() -> dict:
            return {m.topic: json.loads(m.payload) for m in list(reader6.messages)}

        # the last step's forecast may be published just after the retained one is sent
        wait_until(lambda: {"zonecast/office6/forecast", "zonecast/office6/state"}
                   <= set(newest()) and newest()["zonecast/office6/forecast"]["issued"] == issued,
                   10, "retained state and forecast")
        got = newest()
        assert got["zonecast/office6/forecast"] == rest.json()
        assert "fake" not in got["zonecast/office6/state"]
        reader7 = Client(secured.port, "office7", pw["office7"])
        clients.append(reader7)
        reader7.subscribe("zonecast/office7/#")
        time.sleep(1.0)  # a retained message would arrive right after the SUBACK
        assert reader7.topics() == []

        # office7, subscribed to everything, saw only its own dead letter
        wait_until(lambda: "zonecast/office7/deadletter" in spy7.topics(), 10, "dead letter")
        assert set(spy7.topics()) == {"zonecast/office7/deadletter"}
    finally:
        for c in clients:
            c.close()
        app.__exit__(None, None, None)


def test_a_client_with_the_service_client_id_gets_no_telemetry(tmp_path, secured):
    """The attack of issue 14 (20 of 20 messages stolen with the fixed id): another user
    connects with the ingester's client id while the service is down and takes over its
    session; with the ACL it receives none of the telemetry. The restarted service stores
    what is published after the intruder left."""
    app = start_service(tmp_path, secured, {})
    zc = app.app.state.zc
    ingest_id = zc.ingester.client_id
    app.__exit__(None, None, None)

    pw = secured.passwords
    thief = Client(secured.port, "office7", pw["office7"], client_id=ingest_id, persistent=True)
    pub6 = Client(secured.port, "office6", pw["office6"])
    try:
        assert not thief.refused and thief.connack[2] is True  # took over the session
        thief.subscribe("zonecast/+/telemetry", "zonecast/#")
        for i in range(20):
            assert pub6.publish("zonecast/office6/telemetry", {"i": i}) == "Success"
        time.sleep(1.0)
        assert thief.topics() == []
        thief.close()

        app = start_service(tmp_path, secured, {})
        zc = app.app.state.zc
        assert zc.ingester.client_id == ingest_id
        assert pub6.publish("zonecast/office6/telemetry", {"after": True}) == "Success"
        wait_until(lambda: any('"after"' in d.payload
                               for d in zc.storage.dead_letters(building="office6")),
                   15, "the message published after the intruder left")
        app.__exit__(None, None, None)
    finally:
        pub6.close()
        thief.close()


def test_replay_with_another_buildings_credentials_fails_loudly(secured, vb):
    from zonecast.service.replay import replay
    from zonecast.service.settings import MqttSettings

    wrong = MqttSettings(host="127.0.0.1", port=secured.port, username="office6",
                         password=secured.passwords["office6"])
    with pytest.raises(ConnectionError, match="refused by the broker: Not authorized"):
        replay(vb, wrong, "office7", end="2015-04-13T01:00:00-07:00")
    res = replay(vb, wrong, "office6", end="2015-04-13T01:00:00-07:00")
    assert res["messages"] == 4


def make_certificates(folder: Path) -> None:
    """A test CA, a broker certificate for 127.0.0.1 signed by it and an unrelated CA
(openssl CLI, EC P-256 keys)."""
    def run(*args: str) -> None:
        subprocess.run(["openssl", *args], cwd=folder, check=True, capture_output=True)

    ec = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes"]
    run("req", "-x509", *ec, "-keyout", "ca.key", "-out", "ca.crt", "-days", "2",
        "-subj", "/CN=zonecast test CA")
    run("req", *ec, "-keyout", "server.key", "-out", "server.csr", "-subj", "/CN=127.0.0.1")
    (folder / "san.ext").write_text("subjectAltName=IP:127.0.0.1,DNS:localhost\n")
    run("x509", "-req", "-in", "server.csr", "-CA", "ca.crt", "-CAkey", "ca.key",
        "-CAcreateserial", "-out", "server.crt", "-days", "2", "-extfile", "san.ext")
    run("req", "-x509", *ec, "-keyout", "other-ca.key", "-out", "other-ca.crt", "-days", "2",
        "-subj", "/CN=some other CA")
    for name in ("server.key", "ca.key", "other-ca.key"):
        (folder / name).chmod(0o600)


@pytest.mark.skipif(shutil.which("openssl") is None, reason="needs the openssl CLI to make "
                    "test certificates")
def test_tls_listener_of_the_shipped_config_with_the_service_tls_settings(tmp_path):
    """The commented TLS listener of configs/mosquitto.conf, enabled: the ingester connects
    with ``mqtt.tls.ca_certs`` and stores what a building publishes over TLS; a client that
    does not trust the CA cannot connect."""
    import ssl

    from zonecast.service.brokerconf import write_broker_files
    from zonecast.service.mqtt import Ingester
    from zonecast.service.settings import MqttSettings, TLSSettings
    from zonecast.service.storage import open_storage

    auth = tmp_path / "auth"
    files = write_broker_files(BUILDINGS, auth)
    make_certificates(auth)
    port, tls_port = free_port(), free_port()
    broker = Mosquitto(tmp_path, shipped_config(tmp_path, auth, port, tls_port),
                       [port, tls_port])
    pw = files.passwords
    store = open_storage(f"sqlite:///{tmp_path / 'zc.db'}")
    ingester = Ingester(MqttSettings(port=tls_port, username="zonecast", password=pw["zonecast"],
                                     tls=TLSSettings(ca_certs=str(auth / "ca.crt"))),
                        store, {})
    pub = None
    try:
        ingester.start()
        assert ingester.wait_ready(15), broker.log.read_text()[-2000:]
        pub = Client(tls_port, "office6", pw["office6"], tls_ca=auth / "ca.crt")
        assert pub.publish("zonecast/office6/telemetry", {"over": "tls"}) == "Success"
        wait_until(lambda: store.dead_letters(building="office6"), 15, "message over TLS")
        assert '"over": "tls"' in store.dead_letters(building="office6")[0].payload
        with pytest.raises(ssl.SSLCertVerificationError):
            Client(tls_port, "office6", pw["office6"], tls_ca=auth / "other-ca.crt")
    finally:
        if pub is not None:
            pub.close()
        ingester.stop()
        store.close()
        broker.stop()


def two_listener_config(workdir: Path, auth: Path, service_port: int,
                        building_port: int) -> Path:
    """The shipped config split into two listeners (docs/security.md, "Client ids"): the
    service's, whose password file holds the service user alone, and the buildings', where
    ``use_username_as_clientid`` replaces every client id by the user name."""
    base = shipped_config(workdir, auth, service_port).read_text().splitlines()
    keep = [line for line in base if line.split(" ", 1)[0] not in (
        "per_listener_settings", "allow_anonymous", "password_file", "acl_file", "listener")]
    service_users = [line for line in (auth / "passwd").read_text().splitlines()
                     if line.startswith("zonecast:")]
    (auth / "passwd-service").write_text("\n".join(service_users) + "\n")
    (auth / "passwd-service").chmod(0o600)
    conf = workdir / "mosquitto-2l.conf"
    conf.write_text("\n".join(keep + [
        "per_listener_settings true",
        f"listener {service_port} 127.0.0.1",
        "allow_anonymous false",
        f"password_file {auth}/passwd-service",
        f"acl_file {auth}/acl",
        f"listener {building_port} 127.0.0.1",
        "allow_anonymous false",
        f"password_file {auth}/passwd",
        f"acl_file {auth}/acl",
        "use_username_as_clientid true"]) + "\n")
    return conf


def test_a_listener_for_the_service_and_user_names_as_ids_for_buildings_keep_its_session(
        tmp_path, vb):
    """Closes the session takeover the ACL leaves open: a building user with the ingester's
    client id cannot disconnect it (its id becomes its user name), cannot log in on the
    service's listener, replays still work, and the service's persistent session keeps what
    is published while it is down."""
    from zonecast.service.brokerconf import write_broker_files
    from zonecast.service.replay import replay
    from zonecast.service.settings import MqttSettings

    files = write_broker_files(BUILDINGS, tmp_path / "auth")
    service_port, building_port = free_port(), free_port()
    broker = Mosquitto(tmp_path, two_listener_config(tmp_path, tmp_path / "auth", service_port,
                                                     building_port),
                       [service_port, building_port])
    pw = files.passwords
    hardened = type("B", (), {"port": service_port, "passwords": pw})
    clients = []
    app = start_service(tmp_path, hardened, {})
    try:
        zc = app.app.state.zc
        ingest_id = zc.ingester.client_id
        connects = zc.ingester.counters()["connects"]
        # on the service's listener a building user is refused
        refused = Client(service_port, "office7", pw["office7"], client_id=ingest_id)
        clients.append(refused)
        assert refused.refused
        # on the buildings' listener the id is replaced by the user name
        thief = Client(building_port, "office7", pw["office7"], client_id=ingest_id,
                       persistent=True)
        clients.append(thief)
        assert not thief.refused and thief.connack[2] is False  # not the service's session
        pub6 = Client(building_port, "office6", pw["office6"])
        clients.append(pub6)
        for i in range(20):
            assert pub6.publish("zonecast/office6/telemetry", {"i": i}) == "Success"
        wait_until(lambda: len(zc.storage.dead_letters(building="office6")) == 20, 15,
                   "20 messages at the service")  # unknown building: each a dead letter
        assert zc.ingester.counters()["connects"] == connects  # never disconnected
        # a replay with a building's credentials through the buildings' listener
        res = replay(vb, MqttSettings(host="127.0.0.1", port=building_port, username="office6",
                                      password=pw["office6"]), "office6",
                     end="2015-04-13T01:00:00-07:00")
        assert res["messages"] == 4
        wait_until(lambda: len(zc.storage.dead_letters(building="office6")) == 24, 15,
                   "the replayed messages")
        # the replay connected as "office6" too and so disconnected pub6 (the price of user
        # names as client ids, docs/security.md): a new connection of the building
        pub6.close()
        pub6 = Client(building_port, "office6", pw["office6"])
        clients.append(pub6)
        # the persistent session: published while the service is down, stored after
        app.__exit__(None, None, None)
        for i in range(5):
            assert pub6.publish("zonecast/office6/telemetry", {"down": i}) == "Success"
        app = start_service(tmp_path, hardened, {})
        zc = app.app.state.zc
        assert zc.ingester.client_id == ingest_id
        wait_until(lambda: len(zc.storage.dead_letters(building="office6")) == 29, 15,
                   "the 5 messages published while the service was down")
    finally:
        for c in clients:
            c.close()
        app.__exit__(None, None, None)
        broker.stop()
