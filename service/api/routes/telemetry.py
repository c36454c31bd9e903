"""``/api/v1/buildings/{building_id}/telemetry``: REST ingest, the same validation, dead
letters and storage as MQTT.

Answers, consistent with MQTT (where the good readings of a message are stored and each bad
one is dead-lettered): 200 when at least one reading passed validation (stored, or already
stored: ``duplicates``), with the rejected readings listed; 422 when none did (the whole
message was rejected, or every reading was), with the reasons; 413 for a body over
``max_body_bytes``. Never 500 on input: validation cannot raise (``accept``), and storage
refusing validated data is answered 422 ``storage_rejected`` and dead-lettered.
"""

from __future__ import annotations

from datetime import UTC, datetime

from fastapi import APIRouter, Request
from fastapi.responses import JSONResponse
from starlette.concurrency import run_in_threadpool
from zonecast.service import schemas as S
from zonecast.service.api.deps import (
    AUTH,
    ERRORS,
    BuildingId,
    Ctx,
    PrincipalDep,
    get_runner,
    read_body,
)
from zonecast.service.ingest import (
    MessageRejected,
    Reason,
    accept,
    log_rejections,
    refuse,
)

router = APIRouter(prefix="/buildings", tags=["telemetry"], dependencies=AUTH,
                   responses={**ERRORS, 413: {"model": S.ErrorBody},
                              422: {"model": S.TelemetryRefused}})

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


def _rejections(acc) -> list[S.TelemetryRejection]:
    return [S.TelemetryRejection(point=r.point, reason=r.reason.value, detail=r.detail)
            for r in acc.rejections]


@router.post("/{building_id}/telemetry", response_model=S.TelemetryResult,
             summary="Ingest readings (same validation and storage as MQTT)",
             openapi_extra=_telemetry_body)
async def post_telemetry(ctx: Ctx, building_id: BuildingId, request: Request,
                         principal: PrincipalDep):
    body = await read_body(request, ctx.settings.max_body_bytes)
    if building_id not in ctx.catalogues:
        await get_runner(ctx, building_id, principal)  # raises 404 with the reason
    prefix = ctx.settings.mqtt.topic_prefix
    topic = f"{prefix}/{building_id}/telemetry"
    received = datetime.now(UTC)
    ctx.rest["messages_in"] += 1
    acc = accept(topic, body, received, ctx.catalogues, limits=ctx.settings.mqtt.limits,
                 prefix=prefix)
    batches = [] if acc.error is not None else [(building_id, acc.readings)]
    try:
        stored = await run_in_threadpool(ctx.storage.put_many, batches, acc.dead_letters,
                                         received_at=received)
    except ValueError as exc:  # storage refused validated data (a bug): dead-letter it
        acc = refuse(topic, body, received, MessageRejected(
            Reason.STORAGE_REJECTED, f"{type(exc).__name__}: {str(exc)[:300]}", building_id))
        await run_in_threadpool(ctx.storage.put_many, [], acc.dead_letters,
                                received_at=received)
    if acc.error is not None:
        ctx.rest["messages_rejected"] += 1
    ctx.rest_rejected.update(acc.reasons)
    log_rejections(acc, topic, "rest")
    if acc.error is not None or not acc.readings:
        detail = (str(acc.error) if acc.error is not None else
                  "no reading accepted: " + "; ".join(f"{r.reason.value}: {r.detail}"
                                                      for r in acc.rejections[:5]))
        return JSONResponse(S.TelemetryRefused(detail=detail, rejected=_rejections(acc))
                            .model_dump(), status_code=422)
    ctx.rest["readings_stored"] += stored[0].inserted
    return S.TelemetryResult(
        building=building_id, accepted=len(acc.readings), stored=stored[0].inserted,
        duplicates=stored[0].duplicates, rejected=_rejections(acc))
