"""What the running service holds (``app.state.zc``): storage, models, runners, ingester,
publisher and counters, with their start and stop.

A module of its own, not part of ``app.py``: the route dependencies (``api/deps.py``) need
the class at run time for their ``Annotated`` types, and ``app.py`` imports the routes.
"""

from __future__ import annotations

import logging
import threading
from collections import Counter
from datetime import timedelta

import numpy as np
import paho.mqtt.client as mqtt
from zonecast.estimator.artifact import ModelBundle
from zonecast.estimator.constants import HORIZON
from zonecast.estimator.pipeline import Pipeline
from zonecast.estimator.site import Site
from zonecast.estimator.units import _CONVERSIONS, to_si
from zonecast.service.bodies import forecast_json, state_body
from zonecast.service.ingest import Catalogue, PointSpec
from zonecast.service.metrics import ServiceMetrics
from zonecast.service.mqtt import Ingester
from zonecast.service.replay import connect_publisher, unique_client_id
from zonecast.service.runner import Runner
from zonecast.service.settings import ServiceSettings
from zonecast.service.storage import Storage, open_storage

__all__ = ["ServiceContext", "catalogue_for_site", "load_buildings", "run_ingest_worker"]

log = logging.getLogger(__name__)


#: how long before a site's first experiment readings are still plausible
PLAUSIBLE_BEFORE = timedelta(days=365)


def catalogue_for_site(site: Site) -> Catalogue:
    """Point catalogue of a site: every mapped point with its kind, wire unit and the
    kind's plausible range converted to that unit; the site's step as the time grid and,
    if the site lists experiments, one year before the first as the earliest plausible
    reading time (else the ingest default, 1970)."""
    kinds = {"temperature": "temperature", "airflow": "airflow", "irradiance": "irradiance",
             "power": "power", "cloud_cover": "cloud_cover"}
    starts = [e.start for e in getattr(site, "experiments", None) or ()]
    earliest = min(starts) - PLAUSIBLE_BEFORE if starts else None
    out = Catalogue(earliest=earliest, step=getattr(site, "step", None))
    for point, unit in site.point_units().items():
        quantity = _CONVERSIONS[unit][0]
        spec = PointSpec(kinds[quantity])
        if unit != spec.unit:  # affine unit: invert to_si for the range
            a0, a1 = to_si(np.array([0.0, 1.0]), unit)
            lo, hi = sorted(((spec.low - a0) / (a1 - a0), (spec.high - a0) / (a1 - a0)))
            spec = PointSpec(kinds[quantity], unit=unit, low=lo, high=hi)
        out[point] = spec
    return out


def _log_refused_publish(client, userdata, mid, reason_code, properties) -> None:
    """MQTT v5: the broker refused a state/forecast publish (e.g. 0x87 not authorised: the
    service user lacks write access to ``<prefix>/<building>/state|forecast`` in the ACL)."""
    if getattr(reason_code, "is_failure", False):
        log.error("broker refused a state/forecast publish: %s (check the service user's "
                  "ACL, docs/security.md)", reason_code)


def load_buildings(s: ServiceSettings) -> tuple[dict[str, ModelBundle], dict[str, Catalogue],
                                                dict[str, str]]:
    """The model bundles and point catalogues of the configured buildings, and the
    buildings whose model did not load with the reason (logged)."""
    bundles: dict[str, ModelBundle] = {}
    catalogues: dict[str, Catalogue] = {}
    errors: dict[str, str] = {}
    for bid, path in s.buildings.items():
        try:
            bundle = Pipeline.from_model_file(path).bundle
            if bundle.building != bid:
                log.info("building %s: site names it %s; serving it as %s", bid,
                         bundle.building, bid)
                bundle.building = bid
            bundles[bid] = bundle
            catalogues[bid] = cat = catalogue_for_site(bundle.site)
            log.info("building %s: model %s loaded (%d points; readings accepted from %s)",
                     bid, bundle.version, len(cat),
                     (s.mqtt.earliest_time or cat.earliest or "1970-01-01"),
                     extra={"building": bid, "model_version": bundle.version})
        except ValueError as exc:
            errors[bid] = str(exc)
            log.error("building %s: model not loaded: %s", bid, exc, extra={"building": bid})
    return bundles, catalogues, errors


def run_ingest_worker(s: ServiceSettings, worker: int, stop: threading.Event) -> Ingester:
    """``zonecast ingest --worker N``: one more member of ``mqtt.share_group``, storing
    telemetry into the service's storage until ``stop`` is set (then what was received is
    stored and acknowledged before disconnecting); returns the stopped ingester."""
    if s.mqtt.share_group is None:
        raise ValueError("set mqtt.share_group (ZONECAST_MQTT__SHARE_GROUP) for the service "
                         "and its ingest workers: without it every worker receives every "
                         "message")
    storage = open_storage(s.storage_url)
    try:
        _, catalogues, _ = load_buildings(s)
        ingester = Ingester(s.mqtt, storage, catalogues, worker=worker, weather=False).start()
        log.info("ingest worker %d started (client id %s, share group %s)", worker,
                 ingester.client_id, s.mqtt.share_group,
                 extra={"client_id": ingester.client_id, "worker": worker})
        try:
            stop.wait()
        finally:
            ingester.stop()
            log.info("ingest worker %d stopped: %s", worker, ingester.counters())
        return ingester
    finally:
        storage.close()


class ServiceContext:
    """Everything the running service holds (``app.state.zc``)."""

    def __init__(self, settings: ServiceSettings):
        self.settings = settings
        self.storage: Storage | None = None
        self.bundles: dict[str, ModelBundle] = {}
        self.runners: dict[str, Runner] = {}
        self.load_errors: dict[str, str] = {}
        self.catalogues: dict[str, dict[str, PointSpec]] = {}
        self.ingester: Ingester | None = None
        self.publisher: mqtt.Client | None = None
        self.stop = threading.Event()
        self.threads: list[threading.Thread] = []
        self.rest: Counter[str] = Counter()  # REST telemetry counters
        self.rest_rejected: Counter[str] = Counter()
        self.metrics: ServiceMetrics | None = None

    # lifecycle --------------------------------------------------------------------
    def start(self) -> None:
        s = self.settings
        self.metrics = ServiceMetrics(self)
        self.storage = open_storage(s.storage_url)
        self.bundles, self.catalogues, self.load_errors = load_buildings(s)
        if s.mqtt_enabled:
            self.ingester = Ingester(s.mqtt, self.storage, self.catalogues,
                                     on_weather=self._weather_received).start()
            if s.runner.publish:
                self.publisher = connect_publisher(s.mqtt, client_id=unique_client_id("pub"))
                self.publisher.on_publish = _log_refused_publish
        for bid, bundle in self.bundles.items():
            runner = Runner(bundle, self.storage, s.runner, publish=self._published)
            self.runners[bid] = runner
            th = threading.Thread(target=runner.run, args=(self.stop,), daemon=True,
                                  name=f"zonecast-runner-{bid}")
            th.start()
            self.threads.append(th)

    def close(self) -> None:
        self.stop.set()
        for th in self.threads:
            th.join(60)
        if self.ingester is not None:
            self.ingester.stop()
        if self.publisher is not None:
            self.publisher.disconnect()
            self.publisher.loop_stop()
        if self.storage is not None:
            self.storage.close()

    def _weather_received(self, building: str, forecast) -> None:
        """A weather forecast accepted by the MQTT ingester -> the building's runner."""
        runner = self.runners.get(building)
        if runner is not None:
            runner.set_weather_forecast(forecast)

    def _published(self, kind: str, runner: Runner) -> None:
        if kind == "state" and runner.latencies:
            self.metrics.observe_step(runner.building, runner.latencies[-1])
        if self.publisher is None:
            return
        prefix = self.settings.mqtt.topic_prefix
        # the forecast body is the REST endpoint's cached 24 h body (built once per forecast)
        body = (state_body(self, runner).model_dump_json() if kind == "state"
                else forecast_json(runner, HORIZON))
        self.publisher.publish(f"{prefix}/{runner.building}/{kind}", body, qos=1, retain=True)
