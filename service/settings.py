"""Service settings: defaults < YAML file < environment (``ZONECAST_...``) < arguments.

Environment variables carry the prefix ``ZONECAST_`` and use ``__`` for nesting, e.g.
``ZONECAST_STORAGE_URL=postgresql://...``, ``ZONECAST_MQTT__HOST=broker``,
``ZONECAST_API_TOKENS='["token-1"]'`` (JSON for lists),
``ZONECAST_BUILDINGS__office6=/models/office6.json``. The YAML file (e.g.
``configs/service.yaml``) has the same structure with lower-case keys. See
``docs/service.md`` for every field.
"""

from __future__ import annotations

import contextvars
from pathlib import Path
from typing import Any

from pydantic import BaseModel, Field, SecretStr, field_validator
from pydantic_settings import (
    BaseSettings,
    PydanticBaseSettingsSource,
    SettingsConfigDict,
    YamlConfigSettingsSource,
)
from zonecast.service.mqtt import MqttSettings
from zonecast.service.storage import DEFAULT_URL

__all__ = ["RunnerSettings", "ServiceSettings", "load_settings"]

_YAML: contextvars.ContextVar[Path | None] = contextvars.ContextVar("zonecast_yaml", default=None)


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
    api_tokens : list of secret str
        Bearer tokens accepted by the API (compared in constant time). Empty: every
        authenticated endpoint answers 401.
    buildings : dict
        Building id -> identified-model file (``zonecast identify`` output). Relative paths
        are resolved against the settings file's folder (else the working directory).
    runner : RunnerSettings
    max_body_bytes : int
        Largest accepted REST request body [bytes] (telemetry POST).
    """

    model_config = SettingsConfigDict(env_prefix="ZONECAST_", env_nested_delimiter="__",
                                      extra="forbid")

    storage_url: str = DEFAULT_URL
    mqtt_enabled: bool = True
    mqtt: MqttSettings = Field(default_factory=MqttSettings)
    api_tokens: list[SecretStr] = Field(default_factory=list)
    buildings: dict[str, Path] = Field(default_factory=dict)
    runner: RunnerSettings = Field(default_factory=RunnerSettings)
    max_body_bytes: int = Field(1024 * 1024, ge=1024)

    @field_validator("buildings")
    @classmethod
    def _ids(cls, v: dict[str, Path]) -> dict[str, Path]:
        import re

        bad = [k for k in v if not re.fullmatch(r"[A-Za-z0-9_-]+", k)]
        if bad:
            raise ValueError(f"building ids {bad} may only use letters, digits, '-' and '_'")
        return v

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
    return settings
