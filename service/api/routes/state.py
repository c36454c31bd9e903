"""``/api/v1/buildings/{building_id}/state``: the current state estimate."""

from __future__ import annotations

from fastapi import APIRouter
from zonecast.service import schemas as S
from zonecast.service.api.deps import AUTH, ERRORS, BuildingId, Ctx, RunnerDep
from zonecast.service.bodies import state_body

router = APIRouter(prefix="/buildings", tags=["state"], dependencies=AUTH, responses=ERRORS)


@router.get("/{building_id}/state", response_model=S.StateBody, summary="Current state estimate")
def get_state(ctx: Ctx, building_id: BuildingId, runner: RunnerDep):
    return state_body(ctx, runner)
