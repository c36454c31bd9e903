"""``/api/v1/buildings/{building_id}/history``: the measured zone temperatures of the last
hours, as the model sees them (read-only; the operator page plots them)."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query
from zonecast.estimator.constants import STEP_S
from zonecast.service import schemas as S
from zonecast.service.api.deps import AUTH, ERRORS, BuildingId, RunnerDep
from zonecast.service.bodies import as_utc, finite_or_none
from zonecast.service.recent import window, zone_history

router = APIRouter(prefix="/buildings", tags=["history"], dependencies=AUTH, responses=ERRORS)

#: longest window served [h]
MAX_HOURS = 168


# a plain def: the storage read blocks (FastAPI runs it in the thread pool)
@router.get("/{building_id}/history", response_model=S.HistoryBody,
            summary="Measured zone temperatures of the last hours")
def get_history(building_id: BuildingId, runner: RunnerDep,
                hours: Annotated[int, Query(ge=1, le=MAX_HOURS, description=(
                    "length of the window ending at the last processed step [h]"))] = 48):
    times = window(runner, hours)
    y = zone_history(runner, times)
    return S.HistoryBody(
        building=building_id, step_s=STEP_S, times=[as_utc(t) for t in times],
        zones=[S.ZoneHistory(zone=z, measured=[finite_or_none(v) for v in y[:, j]])
               for j, z in enumerate(runner.bundle.zones)])
