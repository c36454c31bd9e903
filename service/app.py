"""The FastAPI application: ``create_app(settings)``.

Nothing heavy happens at import or in :func:`create_app`; the lifespan opens storage,
loads every building's model, starts the MQTT ingester (if enabled), the MQTT publisher
of state and forecasts, and one runner thread per building, and stops them in reverse
order. Routes (docs/service.md, "REST API"): one router per resource under ``/api/v1``
plus ``/healthz``, ``/readyz`` and ``/metrics`` at the root.
"""

from __future__ import annotations

import functools
import gc
import hmac
import json
import logging
import threading
from collections import Counter
from contextlib import asynccontextmanager
from datetime import UTC, datetime
from typing import Annotated, Any

import numpy as np
import pandas as pd
from fastapi import APIRouter, Depends, FastAPI, HTTPException, Path, Query, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, Response
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from starlette.concurrency import run_in_threadpool
from zonecast.estimator.pipeline import Pipeline
from zonecast.service import schemas as S
from zonecast.service.ingest import MessageRejected, PointSpec, validate_message
from zonecast.service.settings import ServiceSettings

__all__ = ["ServiceContext", "catalogue_for_site", "create_app"]

log = logging.getLogger(__name__)
API = "/api/v1"
BuildingId = Annotated[str, Path(pattern=r"^[A-Za-z0-9_-]{1,64}$",
                                 description="building identifier")]


# --------------------------------------------------------------------------- context
def catalogue_for_site(site) -> dict[str, PointSpec]:
    """Point catalogue of a site: every mapped point with its kind, wire unit and the
    kind's plausible range converted to that unit."""
    from zonecast.estimator.units import _CONVERSIONS, to_si

    kinds = {"temperature": "temperature", "airflow": "airflow", "irradiance": "irradiance"}
    out = {}
    for point, unit in site.point_units().items():
        quantity = _CONVERSIONS[unit][0]
        spec = PointSpec(kinds[quantity])
        if unit != spec.unit:  # affine unit: invert to_si for the range
            a0, a1 = to_si(np.array([0.0, 1.0]), unit)
            lo, hi = sorted(((spec.low - a0) / (a1 - a0), (spec.high - a0) / (a1 - a0)))
            spec = PointSpec(kinds[quantity], unit=unit, low=lo, high=hi)
        out[point] = spec
    return out


class ServiceContext:
    """Everything the running service holds (``app.state.zc``)."""

    def __init__(self, settings: ServiceSettings):
        self.settings = settings
        self.storage: Any = None
        self.bundles: dict[str, Any] = {}
        self.runners: dict[str, Any] = {}
        self.load_errors: dict[str, str] = {}
        self.catalogues: dict[str, dict[str, PointSpec]] = {}
        self.ingester: Any = None
        self.publisher: Any = None
        self.stop = threading.Event()
        self.threads: list[threading.Thread] = []
        self.rest = Counter()  # REST telemetry counters
        self.rest_rejected = Counter()
        self.metrics: Any = None

    # lifecycle --------------------------------------------------------------------
    def start(self) -> None:
        from zonecast.service.metrics import ServiceMetrics
        from zonecast.service.runner import Runner
        from zonecast.service.storage import open_storage

        s = self.settings
        self.metrics = ServiceMetrics(self)
        self.storage = open_storage(s.storage_url)
        for bid, path in s.buildings.items():
            try:
                bundle = Pipeline.from_model_file(path).bundle
                if bundle.building != bid:
                    log.info("building %s: site names it %s; serving it as %s", bid,
                             bundle.building, bid)
                    bundle.building = bid
                self.bundles[bid] = bundle
                self.catalogues[bid] = catalogue_for_site(bundle.site)
            except ValueError as exc:
                self.load_errors[bid] = str(exc)
                log.error("building %s: model not loaded: %s", bid, exc)
        if s.mqtt_enabled:
            from zonecast.service.mqtt import Ingester
            from zonecast.service.replay import connect_publisher

            self.ingester = Ingester(s.mqtt, self.storage, self.catalogues).start()
            if s.runner.publish:
                self.publisher = connect_publisher(s.mqtt, client_id=s.mqtt.client_id + "-pub")
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

    def _published(self, kind: str, runner) -> None:
        if kind == "state" and runner.latencies:
            self.metrics.observe_step(runner.building, runner.latencies[-1])
        if self.publisher is None:
            return
        prefix = self.settings.mqtt.topic_prefix
        # the forecast body is the REST endpoint's cached 24 h body (built once per forecast)
        body = (state_body(self, runner).model_dump_json() if kind == "state"
                else forecast_json(runner, 96))
        self.publisher.publish(f"{prefix}/{runner.building}/{kind}", body, qos=1, retain=True)


# --------------------------------------------------------------------------- bodies
def _iso(t) -> datetime | None:
    return None if t is None else pd.Timestamp(t).tz_convert(UTC).to_pydatetime()


def _num(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def state_body(ctx: ServiceContext, runner) -> S.StateBody:
    now = datetime.now(UTC)
    with runner.lock:
        est = runner.est
        zones = []
        flags = []
        if est.started:
            mean, std = est.zone_estimate()
            zones = [S.ZoneState(zone=z, temperature=float(m), std=float(s),
                                 measured=_num(y))
                     for z, m, s, y in zip(est.bundle.zones, mean, std, est.last_y)]
        else:
            flags.append("not_started")
        rep = runner.last_report
        if rep is not None:
            flags += [f"missing_sensor:{z}" for z in rep.missing_zones]
            flags += [f"held_input:{n}" for n in rep.held_inputs]
        if est.resets:
            flags.append("filter_restarted")
        last = est.time
        steps, nis = est.steps, (est.nis_sum / est.dof_sum if est.dof_sum else None)
    wm = runner.watermark
    fresh = (now - wm).total_seconds() if wm is not None else None
    age = (now - last).total_seconds() if last is not None else None
    limit = 2 * 900 + ctx.settings.runner.grace
    if age is not None and age > limit:
        flags.append("stale")
    return S.StateBody(building=runner.building, last_update=_iso(last), data_freshness_s=fresh,
                       update_age_s=age, zones=zones, steps=steps, nis_per_dof=nis,
                       quality=flags)


def forecast_body(runner, steps: int, fc=None) -> S.ForecastBody:
    fc = runner.forecast if fc is None else fc
    if fc is None:
        raise HTTPException(404, f"no forecast for building {runner.building!r} yet: the runner "
                                 "has not processed a step with a measurement")
    sl = slice(0, steps)
    zones = [S.ZoneForecast(zone=z, mean=fc.mean[sl, i].tolist(), lower=fc.lower[sl, i].tolist(),
                            upper=fc.upper[sl, i].tolist(), std=fc.std[sl, i].tolist(),
                            internal_gains=fc.f_ig[sl, i].tolist())
             for i, z in enumerate(fc.zones)]
    return S.ForecastBody(building=runner.building, issued=_iso(fc.issued),
                          model_version=fc.model_version, step_s=900.0,
                          times=[_iso(t) for t in fc.times[sl]], zones=zones)


def forecast_json(runner, steps: int) -> bytes:
    """JSON of :func:`forecast_body` for the runner's current forecast, built once per
    forecast and horizon (the REST endpoint and the MQTT publisher serve these bytes)."""
    fc = runner.forecast
    cached = runner.__dict__.get("_body_cache")
    if cached is None or cached[0] is not fc:  # a new forecast: start a new cache
        cached = (fc, {})
        runner.__dict__["_body_cache"] = cached
    body = cached[1].get(steps)
    if body is None:
        body = forecast_body(runner, steps, fc).model_dump_json().encode()
        cached[1][steps] = body
    return body


@functools.lru_cache(maxsize=256)
def horizon_steps(horizon: str) -> int:
    """``horizon`` (e.g. 24h, 6h, 90min) -> number of 15-min steps; ValueError if it is not
    a positive multiple of 15 min up to 24 h."""
    try:
        span = pd.Timedelta(horizon)
    except (ValueError, TypeError):
        raise ValueError(f"horizon {horizon!r} is not a duration; use e.g. 24h, 6h or 90min") \
            from None
    steps = span / pd.Timedelta("15min")
    if not (0 < steps <= 96) or steps != int(steps):
        raise ValueError(f"horizon {horizon!r} must be a positive multiple of 15 min up to 24h")
    return int(steps)


# --------------------------------------------------------------------------- dependencies
# The dependencies and the forecast route are coroutines: they do not block (no storage,
# no lock), and FastAPI runs a plain ``def`` in the thread pool, a thread hand-off per
# dependency and request.
_bearer = HTTPBearer(auto_error=False, description="API token from the service settings")


async def get_ctx(request: Request) -> ServiceContext:
    return request.app.state.zc


Ctx = Annotated[ServiceContext, Depends(get_ctx)]


async def require_token(ctx: Ctx, cred: Annotated[HTTPAuthorizationCredentials | None,
                                             Depends(_bearer)]) -> None:
    """Bearer-token check, constant time per configured token."""
    challenge = {"WWW-Authenticate": "Bearer"}
    if cred is None:
        raise HTTPException(401, "missing bearer token: send 'Authorization: Bearer <token>'",
                            headers=challenge)
    given = cred.credentials.encode()
    ok = False
    for token in ctx.settings.api_tokens:
        ok |= hmac.compare_digest(given, token.get_secret_value().encode())
    if not ok:
        raise HTTPException(401, "invalid bearer token" if ctx.settings.api_tokens else
                            "no API tokens are configured (settings api_tokens)",
                            headers=challenge)


async def get_runner(ctx: Ctx, building_id: BuildingId):
    runner = ctx.runners.get(building_id)
    if runner is None:
        if building_id in ctx.load_errors:
            raise HTTPException(404, f"building {building_id!r} is configured but its model "
                                     f"did not load: {ctx.load_errors[building_id]}")
        raise HTTPException(404, f"unknown building {building_id!r}; known: "
                                 f"{sorted(ctx.runners)}")
    return runner


RunnerDep = Annotated[Any, Depends(get_runner)]
_auth = [Depends(require_token)]
_errors = {401: {"model": S.ErrorBody}, 404: {"model": S.ErrorBody},
           422: {"model": S.ErrorBody}}


# --------------------------------------------------------------------------- routers
buildings = APIRouter(prefix="/buildings", tags=["buildings"], dependencies=_auth,
                      responses=_errors)
state = APIRouter(prefix="/buildings", tags=["state"], dependencies=_auth, responses=_errors)
gains = APIRouter(prefix="/buildings", tags=["internal-gains"], dependencies=_auth,
                  responses=_errors)
forecast = APIRouter(prefix="/buildings", tags=["forecast"], dependencies=_auth,
                     responses=_errors)
telemetry = APIRouter(prefix="/buildings", tags=["telemetry"], dependencies=_auth,
                      responses={**_errors, 413: {"model": S.ErrorBody}})
health = APIRouter(tags=["health"])
metrics = APIRouter(tags=["metrics"], dependencies=_auth, responses={401: {"model": S.ErrorBody}})


def _summary(bid: str, runner) -> S.BuildingSummary:
    return S.BuildingSummary(id=bid, zones=runner.bundle.zones,
                             model_version=runner.bundle.version,
                             last_update=_iso(runner.est.time))


@buildings.get("", response_model=list[S.BuildingSummary], summary="List buildings")
def list_buildings(ctx: Ctx):
    return [_summary(bid, r) for bid, r in sorted(ctx.runners.items())]


@buildings.get("/{building_id}", response_model=S.BuildingDetail, summary="One building")
def get_building(building_id: BuildingId, runner: RunnerDep):
    b = runner.bundle
    site = b.site
    return S.BuildingDetail(
        **_summary(building_id, runner).model_dump(), timezone=site.timezone,
        latitude=site.location.latitude, longitude=site.location.longitude,
        step_s=site.step.total_seconds(), n_states=b.model.n, boxes=list(site.boxes),
        points=dict(site.point_units()), parameters=dict(zip(b.model.params.param_names, map(float, b.model.params.values))),
        notes=b.notes)


@state.get("/{building_id}/state", response_model=S.StateBody, summary="Current state estimate")
def get_state(ctx: Ctx, building_id: BuildingId, runner: RunnerDep):
    return state_body(ctx, runner)


@gains.get("/{building_id}/internal-gains", response_model=S.InternalGains,
           summary="Online internal gains and the weekly profile")
def get_gains(building_id: BuildingId, runner: RunnerDep):
    b = runner.bundle
    with runner.lock:
        online, last, t = runner.est.online_gains, runner.est.last_f, runner.est.time
    prof = np.nan_to_num(b.profile.values)
    zones = [S.ZoneGains(zone=z, online=float(online[i]), last_estimate=_num(last[i]),
                         profile=prof[:, i].tolist()) for i, z in enumerate(b.zones)]
    return S.InternalGains(building=building_id, time=_iso(t),
                           profile_timezone=b.profile.timezone, zones=zones)


@forecast.get("/{building_id}/forecast", response_model=S.ForecastBody,
              summary="Day-ahead zone temperature forecast with 90 % intervals")
async def get_forecast(building_id: BuildingId, runner: RunnerDep,
                       horizon: Annotated[str, Query(max_length=32, description=(
                           "how far ahead, a multiple of 15 min up to 24 h, e.g. 24h, 6h, "
                           "90min"))] = "24h"):
    # cached bytes: the body of a forecast is built once per horizon, not per request
    return Response(forecast_json(runner, horizon_steps(horizon)), media_type="application/json")


_telemetry_body = {"requestBody": {"required": True, "content": {"application/json": {"schema": {
    "type": "object", "description": "map form {time, readings: {point: value}} or batch form "
    "{readings: [{point, time, value}]}; times ISO-8601 with offset, values in the point's unit",
    "properties": {"time": {"type": "string", "format": "date-time"},
                   "readings": {"oneOf": [
                       {"type": "object", "additionalProperties": {"type": "number"}},
                       {"type": "array", "items": {"type": "object", "properties": {
                           "point": {"type": "string"}, "time": {"type": "string"},
                           "value": {"type": "number"}}}}]}},
    "required": ["readings"]}}}}}


@telemetry.post("/{building_id}/telemetry", response_model=S.TelemetryResult,
                summary="Ingest readings (same validation and storage as MQTT)",
                openapi_extra=_telemetry_body)
async def post_telemetry(ctx: Ctx, building_id: BuildingId, request: Request):
    limit = ctx.settings.max_body_bytes
    declared = request.headers.get("content-length")
    if declared is not None and declared.isdigit() and int(declared) > limit:
        raise HTTPException(413, f"body is {declared} bytes, the limit is {limit}")
    body = await request.body()
    if len(body) > limit:
        raise HTTPException(413, f"body is {len(body)} bytes, the limit is {limit}")
    if building_id not in ctx.catalogues:
        await get_runner(ctx, building_id)  # raises 404 with the reason
    topic = f"{ctx.settings.mqtt.topic_prefix}/{building_id}/telemetry"
    received = datetime.now(UTC)
    ctx.rest["messages_in"] += 1
    try:
        result = validate_message(topic, body, ctx.catalogues, now=received,
                                  limits=ctx.settings.mqtt.limits,
                                  prefix=ctx.settings.mqtt.topic_prefix)
    except MessageRejected as rej:
        ctx.rest["messages_rejected"] += 1
        ctx.rest_rejected[rej.reason.value] += 1
        await run_in_threadpool(ctx.storage.put_dead_letter, topic, body, str(rej),
                                building=building_id, received_at=received)
        raise HTTPException(422, str(rej)) from None
    letters = [{"topic": topic, "payload": body, "reason": f"{r.reason.value}: {r.detail}",
                "building": building_id, "received_at": received} for r in result.rejected]
    for r in result.rejected:
        ctx.rest_rejected[r.reason.value] += 1
    stored = await run_in_threadpool(ctx.storage.put_many,
                                     [(building_id, result.readings)], letters,
                                     received_at=received)
    ctx.rest["readings_stored"] += stored[0].inserted
    return S.TelemetryResult(
        building=building_id, accepted=len(result.readings), stored=stored[0].inserted,
        duplicates=stored[0].duplicates,
        rejected=[S.TelemetryRejection(point=r.point, reason=r.reason.value, detail=r.detail)
                  for r in result.rejected])


@health.get("/healthz", response_model=S.Health, summary="Liveness (no authentication)")
async def healthz():
    return S.Health(status="ok")


@health.get("/readyz", response_model=S.Readiness, summary="Readiness (no authentication)",
            responses={503: {"model": S.Readiness}})
def readyz(ctx: Ctx):
    errors = dict(ctx.load_errors)
    storage_ok = False
    try:
        ctx.storage.reading_bounds("__readyz__")
        storage_ok = True
    except Exception as exc:  # noqa: BLE001 - any storage failure means not ready
        errors["storage"] = str(exc)
    broker = None
    if ctx.ingester is not None:
        broker = ctx.ingester.wait_ready(0)
        if not broker:
            errors["broker"] = f"not connected to {ctx.settings.mqtt.host}:{ctx.settings.mqtt.port}"
    models = {b: b in ctx.bundles for b in ctx.settings.buildings}
    ready = storage_ok and broker is not False and all(models.values())
    body = S.Readiness(ready=ready, storage=storage_ok, broker=broker, models=models,
                       errors=errors)
    return JSONResponse(json.loads(body.model_dump_json()), status_code=200 if ready else 503)


@metrics.get("/metrics", summary="Prometheus metrics (text exposition format)",
             response_class=Response,
             responses={200: {"content": {"text/plain": {"schema": {"type": "string"}}}}})
def get_metrics(ctx: Ctx):
    from prometheus_client import CONTENT_TYPE_LATEST, generate_latest

    return Response(generate_latest(ctx.metrics.registry), media_type=CONTENT_TYPE_LATEST)


# --------------------------------------------------------------------------- app
def _message(exc: RequestValidationError) -> str:
    parts = []
    for err in exc.errors():
        where = ".".join(str(x) for x in err.get("loc", ()) if x != "body")
        parts.append(f"{where}: {err.get('msg')}")
    return "; ".join(parts) or "invalid request"


def create_app(settings: ServiceSettings | None = None) -> FastAPI:
    """The zonecast service as a FastAPI app (start it with uvicorn or ``zonecast serve``).

    Parameters
    ----------
    settings : ServiceSettings, optional
        Default: :func:`~zonecast.service.settings.load_settings` (environment only).
    """
    if settings is None:
        from zonecast.service.settings import load_settings

        settings = load_settings()

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        ctx = ServiceContext(settings)
        app.state.zc = ctx
        await run_in_threadpool(ctx.start)
        # Move what start-up created (modules, models, ~150,000 objects) out of the cyclic
        # garbage collector's reach: a full collection of them took 90-170 ms, a pause for
        # every request in flight (the p99 latency under load); later objects are collected
        # as usual.
        gc.collect()
        gc.freeze()
        try:
            yield
        finally:
            gc.unfreeze()
            await run_in_threadpool(ctx.close)

    app = FastAPI(title="zonecast", version="1", lifespan=lifespan,
                  description="Online state, internal gains and day-ahead forecasts of "
                              "buildings from a bilinear RC model (docs/service.md).")

    @app.exception_handler(ValueError)
    async def _value_error(request: Request, exc: ValueError):
        return JSONResponse({"detail": str(exc)}, status_code=422)

    @app.exception_handler(RequestValidationError)
    async def _invalid(request: Request, exc: RequestValidationError):
        return JSONResponse({"detail": _message(exc)}, status_code=422)

    for router in (buildings, state, gains, forecast, telemetry):
        app.include_router(router, prefix=API)
    app.include_router(health)
    app.include_router(metrics)
    return app
