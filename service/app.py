"""The FastAPI application: ``create_app(settings)``.

Nothing heavy happens at import or in :func:`create_app`; the lifespan opens storage,
loads every building's model, starts the MQTT ingester (if enabled), the MQTT publisher
of state and forecasts, and one runner thread per building (:class:`ServiceContext`), and
stops them in reverse order. Routes (docs/service.md, "REST API"): one router per resource
(``api/routes/``) under ``/api/v1`` plus ``/healthz``, ``/readyz`` and ``/metrics`` at the
root; their dependencies are in ``api/deps.py``. The operator's page ``/ui`` (``ui/``) is
static files that read the API with the operator's token.
"""

from __future__ import annotations

import gc
from contextlib import asynccontextmanager

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.concurrency import run_in_threadpool
from zonecast.service import ui
from zonecast.service.api.routes import (
    buildings,
    diagnosis,
    forecast,
    gaps,
    health,
    history,
    internal_gains,
    metrics,
    model_health,
    state,
    telemetry,
    weather,
)
from zonecast.service.context import ServiceContext
from zonecast.service.settings import ServiceSettings, load_settings

__all__ = ["create_app"]

API = "/api/v1"


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

    for module in (buildings, state, internal_gains, forecast, gaps, telemetry, history,
                   model_health, diagnosis, weather):
        app.include_router(module.router, prefix=API)
    app.include_router(health.router)
    app.include_router(metrics.router)
    app.include_router(ui.router)  # the operator's page /ui (docs/service.md)
    return app
