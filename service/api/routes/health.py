"""``/healthz`` and ``/readyz``: liveness and readiness probes (no authentication)."""

from __future__ import annotations

import json

from fastapi import APIRouter
from fastapi.responses import JSONResponse
from zonecast.service import schemas as S
from zonecast.service.api.deps import Ctx

router = APIRouter(tags=["health"])


@router.get("/healthz", response_model=S.Health, summary="Liveness (no authentication)")
async def healthz():
    return S.Health(status="ok")


@router.get("/readyz", response_model=S.Readiness, summary="Readiness (no authentication)",
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
        waiting = ctx.ingester.unacknowledged_for()
        if waiting > ctx.settings.mqtt.stall_after:
            broker = False
            errors["ingest"] = (f"a message has waited {waiting:.0f} s for storage and its "
                                "acknowledgement (see the storage_errors and worker_errors "
                                "counters in /metrics)")
    models = {b: b in ctx.bundles for b in ctx.settings.buildings}
    ready = storage_ok and broker is not False and all(models.values())
    body = S.Readiness(ready=ready, storage=storage_ok, broker=broker, models=models,
                       errors=errors)
    return JSONResponse(json.loads(body.model_dump_json()), status_code=200 if ready else 503)
