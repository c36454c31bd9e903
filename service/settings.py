"""Service settings: defaults < YAML file < environment (``ZONECAST_...``) < arguments.

Environment variables carry the prefix ``ZONECAST_`` and use ``__`` for nesting, e.g.
``ZONECAST_STORAGE_URL=postgresql://...``, ``ZONECAST_MQTT__HOST=broker``,
``ZONECAST_API_TOKENS='["token-1"]'`` (JSON for lists and mappings),
``ZONECAST_BUILDINGS__office6=/models/office6.json``. The YAML file (e.g.
``configs/service.yaml``) has the same structure with lower-case keys. See
``docs/service.md`` for every field.
"""

from __future__ import annotations

import contextvars
import re
from dataclasses import dataclass
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any, Literal

from pydantic import (
    AwareDatetime,
    BaseModel,
    Field,
    SecretStr,
    field_validator,
    model_validator,
)
from pydantic_settings import (
    BaseSettings,
    PydanticBaseSettingsSource,
    SettingsConfigDict,
    YamlConfigSettingsSource,
)

__all__ = [
    "DEFAULT_PREFIX",
    "DEFAULT_URL",
    "SCOPE_PATTERN",
    "IngestLimits",
    "MqttSettings",
    "RunnerSettings",
    "ServiceSettings",
    "TLSSettings",
    "load_settings",
]

#: storage of ``zonecast serve`` unless ``storage_url`` says otherwise (docs/service.md, "Storage")
DEFAULT_URL = "sqlite:///zonecast.db"
#: first topic level of the MQTT topics
DEFAULT_PREFIX = "zonecast"

#: API token scopes (docs/security.md): ``admin`` (everything), ``metrics`` (``/metrics``),
#: ``building:<id>`` (read and write that building), ``building:<id>:read`` (read only)
SCOPE_PATTERN = r"admin|metrics|building:[A-Za-z0-9_-]{1,64}(:read)?"

_YAML: contextvars.ContextVar[Path | None] = contextvars.ContextVar("zonecast_yaml", default=None)


@dataclass(frozen=True)
class IngestLimits:
    """Limits that protect storage from broken or hostile publishers.

    Parameters
    ----------
    max_payload_bytes : int
        Largest accepted payload [bytes]; default 64 KiB.
    max_readings : int
        Most readings accepted in one message; default 5000.
    max_future : timedelta
        How far ahead of ``now`` a timestamp may lie (clock skew allowance);
        default 10 minutes.
    earliest : datetime, optional
        Earliest plausible reading time for every building (tz-aware). Default None: each
        building's own (``zonecast.service.ingest.Catalogue.earliest``: one year before the
        site's first experiment), else 1970-01-01.
    grid : timedelta, optional
        Readings must be stamped on this grid (a multiple of it since the Unix epoch,
        docs/data.md) unless the building's catalogue names its own step; default 15 min,
        the model step. None: any time.
    """

    max_payload_bytes: int = 64 * 1024
    max_readings: int = 5000
    max_future: timedelta = timedelta(minutes=10)
    earliest: datetime | None = None
    grid: timedelta | None = timedelta(minutes=15)


class TLSSettings(BaseModel):
    """TLS towards the broker.

    Parameters
    ----------
    ca_certs : str, optional
        CA bundle file; default: the system's trusted CAs.
    certfile, keyfile : str, optional
        Client certificate and key for mutual TLS.
    insecure : bool
        Skip the broker hostname check (testing only).
    """

    ca_certs: str | None = None
    certfile: str | None = None
    keyfile: str | None = None
    insecure: bool = False


class MqttSettings(BaseModel):
    """Connection, session and validation settings of the ingester.

    Parameters
    ----------
    host, port : str, int
        Broker address.
    client_id : str, optional
        Client id of the ingester. The broker keys the persistent session on it, so it
        must stay the same across restarts (a restarted ingester then receives what it
        missed) and differ between ingesters. Default None: ``zonecast-ingest-<host>-<random>``
        generated once and kept in storage (``Storage.instance_value``), so each storage
        (database or PostgreSQL schema) has its own stable id.
    username, password : str, optional
        Broker credentials of the service (``docs/security.md``: the service user reads
        all telemetry and is the only one allowed to write state, forecast and dead
        letters); used by the ingester and by the state/forecast publisher.
    tls : TLSSettings, optional
        Enable TLS (use port 8883 on most brokers).
    protocol : {"5", "3.1.1"}
        MQTT version. "3.1.1" for brokers without v5 (e.g. amqtt); the bare
        number point payload needs v5 (its time is a user property).
    session_expiry : int
        MQTT v5: how long the broker keeps the session while the ingester is
        disconnected [s]; default 7 days. (3.1.1 sessions do not expire unless
        the broker is configured so.)
    keepalive : int
        [s].
    receive_maximum : int
        MQTT v5: most unacknowledged messages the broker may send at once; default
        1000, so the broker keeps sending while a group is being committed (with 100 the
        ingester idled during every commit, docs/benchmarks.md).
    batch_max_messages : int
        Most messages committed in one storage transaction (default 500).
    topic_prefix : str
        First topic level (``zonecast``).
    max_payload_bytes, max_readings, max_future : int, int, float
        Validation limits, see :class:`IngestLimits`
        (``max_future`` in seconds).
    earliest_time : datetime, optional
        Earliest plausible reading time for all buildings (ISO-8601 with offset); readings
        before it are dead-lettered as ``past_time``. Default: per building, one year before
        the site's first experiment, else 1970-01-01.
    stall_after : float
        ``/readyz`` reports ingest not ready when a received message has waited longer
        than this for its acknowledgement [s] (storage unavailable, worker stuck).
    share_group : str, optional
        Subscribe to telemetry and point topics as a member of the MQTT v5 shared
        subscription ``$share/<share_group>/...``: the broker hands each message to one
        member, so several ingesting processes (``zonecast serve`` and ``zonecast ingest
        --worker N``, each with its own persistent session) share the load. Default None:
        an ordinary subscription (this process receives every message). Weather forecasts
        are never shared: ``zonecast serve``'s ingester receives all of them.
    """

    host: str = "127.0.0.1"
    port: int = Field(1883, ge=1, le=65535)
    client_id: str | None = Field(None, min_length=1, max_length=128)
    username: str | None = None
    password: SecretStr | None = None
    tls: TLSSettings | None = None
    protocol: Literal["5", "3.1.1"] = "5"
    session_expiry: int = Field(7 * 24 * 3600, ge=1)
    keepalive: int = Field(30, ge=5)
    receive_maximum: int = Field(1000, ge=1, le=65535)
    batch_max_messages: int = Field(500, ge=1)
    topic_prefix: str = DEFAULT_PREFIX
    max_payload_bytes: int = Field(64 * 1024, ge=1)
    max_readings: int = Field(5000, ge=1)
    max_future: float = Field(600.0, ge=0)
    earliest_time: AwareDatetime | None = None
    stall_after: float = Field(60.0, gt=0)
    share_group: str | None = Field(None, min_length=1, max_length=64,
                                    pattern=r"^[A-Za-z0-9_.-]+$")

    @property
    def limits(self) -> IngestLimits:
        """The validation limits as :class:`IngestLimits`."""
        return IngestLimits(self.max_payload_bytes, self.max_readings,
                            timedelta(seconds=self.max_future), earliest=self.earliest_time)


class RunnerSettings(BaseModel):
    """When the online runner processes a step (docs/service.md, "Runner")."""

    grace: float = Field(300.0, ge=0, description="late readings of a row are waited for until "
                         "data stamped row + step + grace has arrived [s]")
    idle_timeout: float = Field(1800.0, gt=0, description="wall-clock time without any new "
                                "reading after which an incomplete row is processed anyway [s]")
    poll_interval: float = Field(1.0, gt=0, description="how often the runner looks for new "
                                 "readings [s]")
    forecast_every: int = Field(1, ge=1, description="issue a forecast every N steps (on the "
                                "step grid since the epoch)")
    max_gap: float = Field(6 * 3600.0, gt=0, description="longest data gap bridged by "
                           "prediction; longer gaps restart the filter [s]")
    publish: bool = Field(True, description="publish state and forecast (retained) on "
                          "<prefix>/<building>/state and .../forecast")
    watermark_support: int = Field(2, ge=1, description="readings of this many points at one "
                                   "time make it a watermark that closes earlier rows (a lone "
                                   "reading ahead of the stream does not)")
    gap_tolerance: float = Field(0.0, ge=0, description="runs of 15-min steps without a "
                                 "reading of a point up to this long are not reported as gaps "
                                 "[s]; 0: every missing step is")
    thermostat_forecast: bool = Field(True, description="forecast the boxes' reheat and "
                                      "cooling as the rooms' thermostats would (docs/"
                                      "forecasts.md); false: by the learned input forecasts "
                                      "alone (about 2-4x less CPU per forecast, a less "
                                      "accurate served forecast)")


class ServiceSettings(BaseSettings):
    """All settings of ``zonecast serve``.

    Attributes
    ----------
    storage_url : str
        ``sqlite:///path.db`` (default ``sqlite:///zonecast.db``) or ``postgresql://...``.
    mqtt_enabled : bool
        Run the MQTT ingester (off: REST ingest only).
    mqtt : MqttSettings
        Broker host, port, username, password, TLS, client id, validation limits.
    api_tokens : dict of secret str -> scopes
        Bearer tokens accepted by the API (compared in constant time) and what each may do
        (docs/security.md): a mapping token -> scopes (``admin``, ``metrics``,
        ``building:<id>``, ``building:<id>:read``), or a list of tokens, each then
        ``admin`` (the form before scopes existed). Empty: every authenticated endpoint
        answers 401.
    buildings : dict
        Building id -> identified-model file (``zonecast identify`` output). Relative paths
        are resolved against the settings file's folder (else the working directory).
    diagnoses : dict
        Building id -> ``diagnosis.json`` of ``zonecast diagnose`` (optional), shown by
        ``/api/v1/buildings/{id}/diagnosis`` and the operator page; relative paths as for
        ``buildings``.
    runner : RunnerSettings
    max_body_bytes : int
        Largest accepted REST request body [bytes] (telemetry POST).
    """

    model_config = SettingsConfigDict(env_prefix="ZONECAST_", env_nested_delimiter="__",
                                      extra="forbid")

    storage_url: str = DEFAULT_URL
    mqtt_enabled: bool = True
    mqtt: MqttSettings = Field(default_factory=MqttSettings)
    api_tokens: dict[SecretStr, tuple[str, ...]] = Field(default_factory=dict)
    buildings: dict[str, Path] = Field(default_factory=dict)
    diagnoses: dict[str, Path] = Field(default_factory=dict)
    runner: RunnerSettings = Field(default_factory=RunnerSettings)
    max_body_bytes: int = Field(1024 * 1024, ge=1024)

    @field_validator("buildings")
    @classmethod
    def _ids(cls, v: dict[str, Path]) -> dict[str, Path]:
        bad = [k for k in v if not re.fullmatch(r"[A-Za-z0-9_-]+", k)]
        if bad:
            raise ValueError(f"building ids {bad} may only use letters, digits, '-' and '_'")
        return v

    @field_validator("api_tokens", mode="before")
    @classmethod
    def _token_forms(cls, v: Any) -> Any:
        if isinstance(v, list | tuple | set):  # list form: every token is admin
            return {t: ("admin",) for t in v}
        if isinstance(v, dict):  # one scope may be given as a plain string
            return {t: (s,) if isinstance(s, str) else s for t, s in v.items()}
        return v

    @model_validator(mode="after")
    def _token_scopes(self) -> ServiceSettings:
        for token, scopes in self.api_tokens.items():
            secret = token.get_secret_value()
            if not secret or secret != secret.strip():
                raise ValueError("api_tokens: a token is empty or has surrounding whitespace "
                                 "(e.g. a newline from a file); generate one with "
                                 "`python -c 'import secrets; print(secrets.token_urlsafe(32))'`")
            if not scopes:
                raise ValueError("api_tokens: a token has no scope; give it 'admin', 'metrics', "
                                 "'building:<id>' or 'building:<id>:read'")
            for scope in scopes:
                if not re.fullmatch(SCOPE_PATTERN, scope):
                    raise ValueError(f"api_tokens: unknown scope {scope!r}; use 'admin', "
                                     "'metrics', 'building:<id>' or 'building:<id>:read'")
                bid = scope.split(":")[1] if scope.startswith("building:") else None
                if bid is not None and bid not in self.buildings:
                    raise ValueError(f"api_tokens: scope {scope!r} names no configured building "
                                     f"(buildings: {sorted(self.buildings)}); fix the id or "
                                     "remove the scope")
        return self

    @classmethod
    def settings_customise_sources(
        cls,
        settings_cls: type[BaseSettings],
        init_settings: PydanticBaseSettingsSource,
        env_settings: PydanticBaseSettingsSource,
        dotenv_settings: PydanticBaseSettingsSource,
        file_secret_settings: PydanticBaseSettingsSource,
    ) -> tuple[PydanticBaseSettingsSource, ...]:
        sources: list[PydanticBaseSettingsSource] = [init_settings, env_settings]
        path = _YAML.get()
        if path is not None:
            sources.append(YamlConfigSettingsSource(settings_cls, yaml_file=path))
        return tuple(sources)


def load_settings(path: str | Path | None = None, **overrides: Any) -> ServiceSettings:
    """Settings from defaults, the YAML file ``path`` (if given), the environment and
    ``overrides`` (highest priority).

    Raises
    ------
    ValueError
        The YAML file does not exist, or a value is invalid (pydantic's message).
    """
    base = Path.cwd()
    token = None
    if path is not None:
        path = Path(path)
        if not path.is_file():
            raise ValueError(f"settings file {path} not found")
        base = path.resolve().parent
        token = _YAML.set(path)
    try:
        settings = ServiceSettings(**overrides)
    finally:
        if token is not None:
            _YAML.reset(token)
    settings.buildings = {k: (p if p.is_absolute() else base / p)
                          for k, p in settings.buildings.items()}
    unknown = sorted(set(settings.diagnoses) - set(settings.buildings))
    if unknown:
        raise ValueError(f"diagnoses of buildings that are not configured: {unknown}; "
                         f"buildings: {sorted(settings.buildings)}")
    settings.diagnoses = {k: (p if p.is_absolute() else base / p)
                          for k, p in settings.diagnoses.items()}
    return settings
