"""``/api/v1/buildings/{building_id}/health``: the model's health over the last hours —
innovation RMS per zone, missing measurements and readings, the last reading (read-only)."""

from __future__ import annotations

from typing import Annotated

import numpy as np
from fastapi import APIRouter, Query
from zonecast.service import schemas as S
from zonecast.service.api.deps import AUTH, ERRORS, BuildingId, Ctx, RunnerDep
from zonecast.service.bodies import as_utc, finite_or_none, state_body
from zonecast.service.recent import (
    innovation_rms,
    missing_per_point,
    readings,
    window,
    zone_history,
)

router = APIRouter(prefix="/buildings", tags=["model-health"], dependencies=AUTH,
                   responses=ERRORS)


# a plain def: the storage reads block (FastAPI runs it in the thread pool)
@router.get("/{building_id}/health", response_model=S.ModelHealth,
            summary="Model health: innovations, missing measurements and readings")
def get_model_health(ctx: Ctx, building_id: BuildingId, runner: RunnerDep,
                     hours: Annotated[int, Query(ge=1, le=168, description=(
                         "length of the window ending at the last processed step [h]"))] = 48):
    state = state_body(ctx, runner)
    times = window(runner, hours)
    every = readings(runner, times, runner.points)  # one read for both
    y = zone_history(runner, times, every)
    seen = np.isfinite(y)
    rms, n = innovation_rms(runner, times[0] if len(times) else None)
    gaps = missing_per_point(runner, every)
    _, last_reading, _ = runner.storage.reading_bounds(runner.building)
    zones = []
    for j, z in enumerate(runner.bundle.zones):
        idx = np.flatnonzero(seen[:, j])
        zones.append(S.ZoneHealth(
            zone=z, innovation_rms=finite_or_none(rms[j]), innovation_steps=int(n[j]),
            missing_steps=int(len(times) - len(idx)),
            last_measured=as_utc(times[idx[-1]]) if len(idx) else None))
    missing = sorted(((p, k) for p, k in gaps.items() if k), key=lambda pk: (-pk[1], pk[0]))
    return S.ModelHealth(
        building=building_id, window_start=as_utc(times[0]) if len(times) else None,
        window_end=as_utc(times[-1]) if len(times) else None, window_steps=len(times),
        last_update=state.last_update, last_reading=as_utc(last_reading),
        nis_per_dof=state.nis_per_dof, zones=zones,
        points_missing=[S.PointGaps(point=p, missing=k) for p, k in missing],
        quality=state.quality)
