"""``/metrics``: Prometheus metrics of the service (bearer token with scope ``metrics`` or
``admin``)."""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.responses import Response
from prometheus_client import CONTENT_TYPE_LATEST, generate_latest
from zonecast.service import schemas as S
from zonecast.service.api.deps import METRICS_AUTH, Ctx

router = APIRouter(tags=["metrics"], dependencies=METRICS_AUTH,
                   responses={401: {"model": S.ErrorBody}, 403: {"model": S.ErrorBody}})


@router.get("/metrics", summary="Prometheus metrics (text exposition format)",
            response_class=Response,
            responses={200: {"content": {"text/plain": {"schema": {"type": "string"}}}}})
def get_metrics(ctx: Ctx):
    return Response(generate_latest(ctx.metrics.registry), media_type=CONTENT_TYPE_LATEST)
