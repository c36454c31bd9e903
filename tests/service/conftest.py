"""Fixtures for the service tests: real storage backends and a real MQTT broker.

PostgreSQL: ``ZONECAST_TEST_POSTGRES_URL`` (default: try
``postgresql://postgres@127.0.0.1:5432/test`` then ``postgresql://root@...``);
every test gets its own schema, dropped afterwards. Tests on PostgreSQL are
skipped, with the reason, when no server answers within 2 s.

MQTT: ``mosquitto`` from PATH on a free port with a temporary config, else the
pure-Python ``amqtt`` broker (MQTT 3.1.1 only); ``ZONECAST_TEST_BROKER=amqtt``
forces the latter.
"""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
import time
import uuid
from dataclasses import dataclass
from pathlib import Path

import pytest

PG_CANDIDATES = [
    "postgresql://postgres@127.0.0.1:5432/test",
    "postgresql://root@127.0.0.1:5432/test",
]
_pg_probe: tuple[str | None, str] | None = None


def _postgres_url() -> tuple[str | None, str]:
    """The first PostgreSQL URL that answers, or None and why not (cached)."""
    global _pg_probe
    if _pg_probe is None:
        import psycopg

        env = os.environ.get("ZONECAST_TEST_POSTGRES_URL")
        errors = []
        for url in [env] if env else PG_CANDIDATES:
            try:
                with psycopg.connect(url, connect_timeout=2):
                    _pg_probe = (url, "")
                    break
            except psycopg.Error as exc:
                errors.append(f"{url}: {str(exc).strip().splitlines()[0]}")
        else:
            _pg_probe = (None, "no PostgreSQL server answered (" + "; ".join(errors) + ")")
    return _pg_probe


@pytest.fixture
def postgres_url():
    """A PostgreSQL URL with a fresh schema (``?schema=``); dropped afterwards."""
    base, why = _postgres_url()
    if base is None:
        pytest.skip(why)
    import psycopg

    schema = f"zc_test_{uuid.uuid4().hex[:12]}"
    yield f"{base}?schema={schema}"
    with psycopg.connect(base, autocommit=True) as conn:
        conn.execute(f'DROP SCHEMA IF EXISTS "{schema}" CASCADE')


@pytest.fixture(params=["sqlite", "postgresql"])
def storage_url(request, tmp_path):
    """The same test on both backends."""
    if request.param == "sqlite":
        return f"sqlite:///{tmp_path / 'zonecast.db'}"
    return request.getfixturevalue("postgres_url")


@pytest.fixture
def storage(storage_url):
    from zonecast.service.storage import open_storage

    store = open_storage(storage_url)
    yield store
    store.close()


@dataclass
class Broker:
    """A broker process the tests started."""

    kind: str  # "mosquitto" or "amqtt"
    host: str
    port: int
    mqtt5: bool  # False: MQTT 3.1.1 only
    username: str  # clients log in with this name (any password)
    process: subprocess.Popen
    log: Path

    def stop(self) -> None:
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(10)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait_listening(port: int, proc: subprocess.Popen, log: Path, timeout: float = 15.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"broker exited with {proc.returncode}: {log.read_text()[-2000:]}")
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.5):
                return
        except OSError:
            time.sleep(0.05)
    proc.kill()
    raise RuntimeError(f"broker did not listen on port {port} within {timeout} s")


def start_broker(workdir: Path) -> Broker:
    """Start mosquitto (if on PATH) or amqtt on a free port under ``workdir``."""
    port = _free_port()
    log = workdir / "broker.log"
    mosquitto = shutil.which("mosquitto") or next(
        (p for p in ("/usr/sbin/mosquitto", "/usr/local/sbin/mosquitto") if Path(p).exists()),
        None)
    if os.environ.get("ZONECAST_TEST_BROKER", "") != "amqtt" and mosquitto:
        conf = workdir / "mosquitto.conf"
        conf.write_text(
            f"listener {port} 127.0.0.1\n"
            "allow_anonymous true\n"
            "persistence true\n"
            f"persistence_location {workdir}/\n"
            "max_queued_messages 100000\n"
            "max_inflight_messages 100\n")
        cmd, kind, mqtt5 = [mosquitto, "-c", str(conf)], "mosquitto", True
    else:
        conf = workdir / "amqtt.yaml"
        conf.write_text(
            "listeners:\n  default:\n    type: tcp\n"
            f"    bind: 127.0.0.1:{port}\n"
            # amqtt drops the session of an anonymous client on disconnect:
            # require a user name (any) so persistent sessions survive.
            "plugins:\n  amqtt.plugins.authentication.AnonymousAuthPlugin:\n"
            "    allow_anonymous: false\n")
        cmd = [sys.executable, "-m", "amqtt.scripts.broker_script", "-c", str(conf)]
        kind, mqtt5 = "amqtt", False
    with open(log, "wb") as out:
        proc = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, cwd=workdir)
    _wait_listening(port, proc, log)
    return Broker(kind, "127.0.0.1", port, mqtt5, "zonecast-test", proc, log)


@pytest.fixture(scope="session")
def broker(tmp_path_factory) -> Broker:
    """A real MQTT broker on a free local port for the whole session."""
    b = start_broker(tmp_path_factory.mktemp("broker"))
    yield b
    b.stop()
