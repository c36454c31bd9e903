"""``/api/v1/buildings/{building_id}/forecast``: the day-ahead forecast."""

from __future__ import annotations

import functools
from typing import Annotated

import pandas as pd
from fastapi import APIRouter, Query
from fastapi.responses import Response
from zonecast.estimator.constants import HORIZON, STEP
from zonecast.service import schemas as S
from zonecast.service.api.deps import AUTH, ERRORS, BuildingId, RunnerDep
from zonecast.service.bodies import forecast_json

router = APIRouter(prefix="/buildings", tags=["forecast"], dependencies=AUTH,
                   responses={**ERRORS, 409: {"model": S.ErrorBody, "description": (
                       "no forecast to serve: the filter has not started, or an input has "
                       "never had a value (the detail names the points)")}})


@functools.lru_cache(maxsize=256)
def horizon_steps(horizon: str) -> int:
    """``horizon`` (e.g. 24h, 6h, 90min) -> number of 15-min steps; ValueError if it is not
    a positive multiple of 15 min up to 24 h."""
    try:
        span = pd.Timedelta(horizon)
    except (ValueError, TypeError):
        raise ValueError(f"horizon {horizon!r} is not a duration; use e.g. 24h, 6h or 90min") \
            from None
    steps = span / STEP
    if not (0 < steps <= HORIZON) or steps != int(steps):
        raise ValueError(f"horizon {horizon!r} must be a positive multiple of 15 min up to 24h")
    return int(steps)


# a coroutine, as the dependencies: nothing here blocks
@router.get("/{building_id}/forecast", response_model=S.ForecastBody,
            summary="Day-ahead zone temperature forecast with 90 % intervals")
async def get_forecast(building_id: BuildingId, runner: RunnerDep,
                       horizon: Annotated[str, Query(max_length=32, description=(
                           "how far ahead, a multiple of 15 min up to 24 h, e.g. 24h, 6h, "
                           "90min"))] = "24h"):
    # cached bytes: the body of a forecast is built once per horizon, not per request
    return Response(forecast_json(runner, horizon_steps(horizon)), media_type="application/json")
