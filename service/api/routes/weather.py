"""``/api/v1/buildings/{building_id}/weather_forecast``: receive a weather forecast (the
acceptance of MQTT's ``<prefix>/<building>/weather_forecast``, :mod:`zonecast.service.weather`)
and show the one in use.

POST answers 200 with what was taken (``in_use`` false when a forecast issued later is
already in use), 422 with the reason when the forecast is rejected (the message is
dead-lettered as over MQTT), 413 for a body over ``max_body_bytes``.
"""

from __future__ import annotations

from datetime import UTC, datetime

from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import JSONResponse
from starlette.concurrency import run_in_threadpool
from zonecast.service import schemas as S
from zonecast.service.api.deps import AUTH, ERRORS, BuildingId, Ctx, RunnerDep, read_body
from zonecast.service.weather import WEATHER_SUFFIX, accept_weather

router = APIRouter(prefix="/buildings", tags=["weather"], dependencies=AUTH,
                   responses={**ERRORS})

_body = {"requestBody": {"required": True, "content": {"application/json": {"schema": {
    "type": "object", "description": "a 24-48 h weather forecast (docs/data.md): issued and "
    "times ISO-8601 with offset; temperature [degC], ghi, dni, dhi [W/m2] per time",
    "properties": {"issued": {"type": "string", "format": "date-time"},
                   "source": {"type": "string"},
                   "times": {"type": "array", "items": {"type": "string"}},
                   "temperature": {"type": "array", "items": {"type": "number"}},
                   "ghi": {"type": "array", "items": {"type": "number"}},
                   "dni": {"type": "array", "items": {"type": "number"}},
                   "dhi": {"type": "array", "items": {"type": "number"}}},
    "required": ["issued", "times", "temperature", "ghi", "dni", "dhi"]}}}}}


def _summary(building: str, wf, in_use: bool) -> dict:
    return {"building": building, "issued": wf.issued.isoformat(), "source": wf.source,
            "first": wf.times[0].isoformat(), "last": wf.times[-1].isoformat(),
            "points": len(wf.times), "in_use": in_use}


@router.post("/{building_id}/weather_forecast", summary="Receive a weather forecast",
             openapi_extra=_body, responses={413: {"model": S.ErrorBody},
                                             422: {"model": S.ErrorBody}})
async def post_weather_forecast(ctx: Ctx, building_id: BuildingId, runner: RunnerDep,
                                request: Request):
    body = await read_body(request, ctx.settings.max_body_bytes)
    prefix = ctx.settings.mqtt.topic_prefix
    received = datetime.now(UTC)
    acc = accept_weather(f"{prefix}/{building_id}/{WEATHER_SUFFIX}", body, received,
                         ctx.runners, prefix=prefix, max_bytes=ctx.settings.max_body_bytes)
    if acc.forecast is None:
        await run_in_threadpool(ctx.storage.put_many, [], acc.dead_letters,
                                received_at=received)
        ctx.rest_rejected.update([f"weather_{acc.reason}"])
        return JSONResponse({"detail": f"weather forecast rejected: {acc.reason}: "
                                       f"{acc.detail}"}, status_code=422)
    taken = await run_in_threadpool(runner.set_weather_forecast, acc.forecast)
    return _summary(building_id, acc.forecast, taken)


@router.get("/{building_id}/weather_forecast", summary="The weather forecast in use")
async def get_weather_forecast(building_id: BuildingId, runner: RunnerDep):
    wf = runner.est.weather
    if wf is None:
        raise HTTPException(404, f"building {building_id!r} has no weather forecast; the "
                                 "served forecast uses the diurnal fallback (docs/forecasts.md)")
    return {**wf.to_json(), "in_use": True}
